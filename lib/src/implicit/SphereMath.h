// SPDX-License-Identifier: Apache-2.0
#pragma once
// A sphere's value and its range over a box, per point (internal to lib/src/implicit): one
// definition for Sphere's own calls and for the loops of a CSG of spheres, inlined into loops
// that vectorize, so every path gives the same bits.

#include <algorithm>
#include <cmath>

namespace ivdb::implicit::detail {

/// |p - c| - r.
inline double sphereValue(double x, double y, double z, double cx, double cy, double cz, double r)
{
    const double dx = x - cx, dy = y - cy, dz = z - cz;
    return std::sqrt(dx * dx + dy * dy + dz * dz) - r;
}

/// The exact range [@a lo, @a hi] of |p - c| - r over a box whose extent, relative to the centre
/// c, is [l_k, u_k] along axis k: the nearest point (clamped) and the farthest corner.
inline void sphereRange(double l0, double u0, double l1, double u1, double l2, double u2,
                        double r, double& lo, double& hi)
{
    const double n0 = l0 > 0.0 ? l0 : (u0 < 0.0 ? u0 : 0.0);
    const double n1 = l1 > 0.0 ? l1 : (u1 < 0.0 ? u1 : 0.0);
    const double n2 = l2 > 0.0 ? l2 : (u2 < 0.0 ? u2 : 0.0);
    const double f0 = std::max(std::abs(l0), std::abs(u0));
    const double f1 = std::max(std::abs(l1), std::abs(u1));
    const double f2 = std::max(std::abs(l2), std::abs(u2));
    lo = std::sqrt(((0.0 + n0 * n0) + n1 * n1) + n2 * n2) - r;
    hi = std::sqrt(((0.0 + f0 * f0) + f1 * f1) + f2 * f2) - r;
}

} // namespace ivdb::implicit::detail
