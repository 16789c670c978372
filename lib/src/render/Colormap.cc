// SPDX-License-Identifier: Apache-2.0
#include <ivdb/render/Colormap.h>

#include <ivdb/util/Params.h>

#include "ColormapTables.h"

#include <openvdb/Exceptions.h>

#include <algorithm>
#include <cmath>

namespace ivdb::render {

const std::vector<std::string>& Colormap::names()
{
    static const std::vector<std::string> kNames{"hsv", "viridis", "coolwarm", "gray"};
    return kNames;
}

Colormap::Colormap(const std::string& name): mName(name)
{
    if (name == "hsv") mTable = detail::kHsv;
    else if (name == "viridis") mTable = detail::kViridis;
    else if (name == "coolwarm") mTable = detail::kCoolwarm;
    else if (name != "gray") {
        throw ParamError(param::kColormap, "'" + name + "' is unknown: use hsv, viridis, "
                         "coolwarm or gray");
    }
}

openvdb::Vec3f Colormap::at(double t) const
{
    if (!(t > 0.0)) t = 0.0; // also NaN
    t = std::min(t, 1.0);
    // matplotlib's lookup: 256 entries, the last for t = 1 too.
    const int i = std::min(int(t * detail::kEntries), detail::kEntries - 1);
    if (!mTable) return openvdb::Vec3f(float(i) / float(detail::kEntries - 1));
    return openvdb::Vec3f(mTable[i][0], mTable[i][1], mTable[i][2]);
}

openvdb::Vec3f directionColor(const openvdb::Vec3d& v)
{
    const double len = v.length();
    const openvdb::Vec3d n = len > 0.0 ? v / len : openvdb::Vec3d(0.0);
    return openvdb::Vec3f(n * 0.5 + openvdb::Vec3d(0.5));
}

} // namespace ivdb::render
