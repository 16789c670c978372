// SPDX-License-Identifier: Apache-2.0
#pragma once
// Input checks shared by the implicit nodes' constructors (internal to lib/src/implicit).

#include <ivdb/implicit/Implicit.h>

#include <openvdb/Exceptions.h>

#include <cmath>
#include <sstream>

namespace ivdb::implicit::detail {

/// @throw openvdb::ValueError naming @a what and the value unless every component is finite
inline void requireFinite(const Vec3d& v, const char* what)
{
    for (int i = 0; i < 3; ++i) {
        if (!std::isfinite(v[i])) {
            std::ostringstream os;
            os << what << " must be finite, got [" << v[0] << ", " << v[1] << ", " << v[2] << "]";
            OPENVDB_THROW(openvdb::ValueError, os.str());
        }
    }
}

/// @throw openvdb::ValueError naming @a what and the value unless 0 < v < infinity
inline void requirePositive(double v, const char* what)
{
    if (!(v > 0.0) || !std::isfinite(v)) {
        std::ostringstream os;
        os << what << " must be > 0 and finite, got " << v;
        OPENVDB_THROW(openvdb::ValueError, os.str());
    }
}

} // namespace ivdb::implicit::detail
