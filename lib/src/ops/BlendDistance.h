// SPDX-License-Identifier: Apache-2.0
#pragma once

/// @file BlendDistance.h
/// @brief The distance to the blend of two planes, in closed form up to a one-dimensional
/// minimization: what the grid blend solves at each voxel near the crease (internal to ops;
/// tests reach it by path).

#include <ivdb/implicit/Blend.h>

#include <limits>

namespace ivdb::ops::detail {

/// @brief A union blend's kernel in the units of the distances it takes (voxels).
struct UnionKernel
{
    bool polynomial = false;
    double p = 0.0; ///< super-elliptic sharpness, per unit
    double k = 0.0; ///< smooth-minimum width, in units

    /// @a kernel with distances measured in units of @a unit world units.
    static UnionKernel inUnits(const implicit::BlendKernel& kernel, double unit);
};

/// @brief The distance to the blend of two planes, and where it is attained.
struct PlaneBlendDistance
{
    double distance = 0.0; ///< signed: negative inside the blended union
    double weight = 0.5;   ///< w: the nearest point's normal is w n_a + (1 - w) n_b, normalized
    bool ok = true;        ///< false if the planes face each other too closely to tell
    double blend = 0.0;    ///< the blend at x, U(a, b) (planeBlendEstimate() only)
    /// The iteration's variable (logit w for the super-elliptic blend, w for the smooth
    /// minimum) at the least; planeBlendEstimate(): at x's first-order foot point, where
    /// planeBlendDistance() starts by default.
    double start = 0.0;
};

/// @brief The signed distance from a point x to the zero set of the union blend of two planes,
/// U(a(y), b(y)) = 0, given the planes' values at x, @a a and @a b, and the cosine @a c of the
/// angle between their unit normals.
/// @details The blended union's solid is the complement of K = {U >= 0}, which is convex: the
/// kernel is concave. A convex set's boundary is the envelope of its tangent planes, and
/// the signed distance from x to the boundary of K's complement is the least signed distance
/// from x to those planes (exact on both sides: from inside K, the nearest supporting plane;
/// from outside, the farthest separating one). The tangent plane where the kernel's gradient
/// is (w, 1 - w) lies at signed distance
///     h(w) = (w a + (1 - w) b - S(w)) / sqrt(1 - 2 (1 - c) w (1 - w))
/// from x, where S(w) is the kernel's support term: H(w)/p for the super-elliptic blend (H the
/// entropy -w ln w - (1 - w) ln(1 - w)) and k w (1 - w) for the smooth minimum. The distance is
/// the least h over w in [0, 1], found by a safeguarded Newton iteration (on logit w for the
/// super-elliptic blend, whose minimum is always inside (0, 1)), from @a start (the iteration's
/// variable: a previous answer's, or planeBlendEstimate()'s for nearby planes) if it is given
/// (not NaN), else from the kernel's weight at x's first-order foot point (x - f g / |g|^2, f
/// the blend at x and g its gradient), which is near the least.
PlaneBlendDistance planeBlendDistance(const UnionKernel& kernel, double a, double b, double c,
                                      double start = std::numeric_limits<double>::quiet_NaN());

/// @brief The first-order estimate of planeBlendDistance(): the blend f at x over the length of
/// its gradient g = w n_a + (1 - w) n_b, and w, so that x - (distance / |g|) g is x's
/// first-order foot point, and the kernel's weight there as planeBlendDistance()'s start. No
/// minimization (one exponential and one logarithm): enough to say near which voxel the nearest
/// point lies.
PlaneBlendDistance planeBlendEstimate(const UnionKernel& kernel, double a, double b, double c);

/// @brief How far beyond plane a the blend's surface lies where the other term, @a b (voxels),
/// is at least the kernel's reach (one term weighs nearly all there): U(delta, b) = 0, that is
/// delta = -ln(1 - e^(-p b)) / p for the super-elliptic blend (about e^(-p b) / p), and 0 for
/// the smooth minimum, whose reach is k (its flat part).
double blendOffset(const UnionKernel& kernel, double b);

} // namespace ivdb::ops::detail
