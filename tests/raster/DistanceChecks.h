// SPDX-License-Identifier: Apache-2.0
// Checks of rasterized level sets against reference distances, shared by the raster tests.
#pragma once

#include <ivdb/implicit/Implicit.h>

#include <openvdb/math/Operators.h>
#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>

namespace ivdb::test {

using implicit::Vec3d;

/// Every active voxel within @a tolVoxels of @a reference, and the active voxels exactly those
/// whose reference distance is within the band (up to voxels within 2 tolerances of its edge).
/// Returns the worst error in voxels.
inline double expectDistances(const openvdb::FloatGrid& g, const std::function<double(const Vec3d&)>& reference,
                       double dx, double halfWidth, double tolVoxels, const std::string& what,
                       const implicit::BBoxd& box)
{
    double worst = 0.0;
    std::size_t off = 0, missing = 0, extra = 0;
    auto acc = g.getConstAccessor();
    const openvdb::Coord lo(int(std::floor(box.min()[0] / dx)), int(std::floor(box.min()[1] / dx)),
                            int(std::floor(box.min()[2] / dx)));
    const openvdb::Coord hi(int(std::ceil(box.max()[0] / dx)), int(std::ceil(box.max()[1] / dx)),
                            int(std::ceil(box.max()[2] / dx)));
    for (int i = lo.x(); i <= hi.x(); ++i)
        for (int j = lo.y(); j <= hi.y(); ++j)
            for (int k = lo.z(); k <= hi.z(); ++k) {
                const Vec3d p(i * dx, j * dx, k * dx);
                const double ref = reference(p) / dx;
                float v;
                const bool on = acc.probeValue(openvdb::Coord(i, j, k), v);
                const bool edge = std::abs(std::abs(ref) - halfWidth) < 2.0 * tolVoxels;
                if (std::abs(ref) < halfWidth && !on && !edge) ++missing;
                if (std::abs(ref) >= halfWidth && on && !edge) ++extra;
                if (!on) continue;
                const double err = std::abs(double(v) / dx - ref);
                worst = std::max(worst, err);
                if (err > tolVoxels) ++off;
            }
    EXPECT_EQ(off, 0u) << what << ": worst error " << worst << " voxel";
    EXPECT_EQ(missing, 0u) << what << ": band voxels missing";
    EXPECT_EQ(extra, 0u) << what << ": voxels beyond the band active";
    return worst;
}

/// Fraction of the voxels within 1.5 voxels of the surface with |grad phi| in [0.9, 1.1].
inline double unitGradientFraction(const openvdb::FloatGrid& g)
{
    const double dx = g.voxelSize()[0];
    auto acc = g.getConstAccessor();
    std::size_t n = 0, good = 0;
    for (auto it = g.cbeginValueOn(); it; ++it) {
        if (std::abs(*it) >= 1.5 * dx) continue;
        const auto grad = openvdb::math::ISGradient<openvdb::math::CD_2ND>::result(acc, it.getCoord());
        const double len = grad.length() / dx;
        ++n;
        if (len >= 0.9 && len <= 1.1) ++good;
    }
    return n ? double(good) / double(n) : 0.0;
}

} // namespace ivdb::test
