// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>
#include <ivdb/util/Params.h>

#include <openvdb/openvdb.h>
#include <openvdb/util/NullInterrupter.h>

#include <string>
#include <vector>

namespace ivdb::diff {

/// @brief The largest gradient step, in voxels (limits::kStep).
inline constexpr int kMaxStep = int(limits::kStep.hi);

/// @brief The leaves of a level set an operator computes (null: every leaf): ivdb-mpi's ranks
/// each compute a run of them; the others are only read, as the listed leaves' neighbours.
using LeafList = std::vector<const openvdb::FloatTree::LeafNodeType*>;

/// @brief Central-difference gradient (docs/method.md#discrete-gradient) with a step of @a step voxels:
/// (phi(x + K) - phi(x - K)) / (2 K dx) per axis, in world units.
/// @details The output has the input's transform and active topology (the band), is named
/// "gradient", and is a covariant world-space vector grid. Neighbours outside the band read the
/// input's inactive values (+/- background, clamped), as OpenVDB's tools do. With step 1 it equals
/// openvdb::tools::gradient. Leaf-parallel: each leaf's stencil reads one dense block gathered
/// from the leaf and its neighbours' buffers, not per-voxel accessor calls.
/// @throw ParamError if @a step is not in [1, kMaxStep]; openvdb::ValueError if the grid has a non-uniform
/// voxel size
openvdb::Vec3SGrid::Ptr gradient(const openvdb::FloatGrid& phi, int step = 1,
                                 bool threaded = true, const LeafList* only = nullptr);

/// @brief |gradient| per active voxel, named "gradient_magnitude".
openvdb::FloatGrid::Ptr magnitude(const openvdb::Vec3SGrid& gradient);

/// @brief Curvature conventions (all in 1/world units, positive for a sphere's distance field).
enum class Curvature {
    /// (k1 + k2) / 2: 1/r on a sphere, as openvdb::tools::meanCurvature (same stencil)
    Mean,
    /// k1 k2: 1/r^2 on a sphere
    Gaussian,
    /// the Laplacian of phi (docs/method.md#curvature): 2/r on a sphere's distance field
    Laplacian
};

/// @brief Curvature of the level sets of @a phi at every active voxel (second-order central
/// differences, 3x3x3 stencil), named "curvature". A zero gradient gives 0.
openvdb::FloatGrid::Ptr curvature(const openvdb::FloatGrid& phi, Curvature kind,
                                  bool threaded = true, const LeafList* only = nullptr);

/// @brief Principal curvatures k1 >= k2 (H +/- sqrt(H^2 - K)), named "k1" and "k2".
std::pair<openvdb::FloatGrid::Ptr, openvdb::FloatGrid::Ptr>
principalCurvatures(const openvdb::FloatGrid& phi, bool threaded = true,
                    const LeafList* only = nullptr);

/// @brief Summary statistics of one error measure over the band.
struct ErrorStats
{
    std::size_t count = 0;
    double mean = 0.0, median = 0.0, p95 = 0.0, max = 0.0;
};

/// @brief How a discrete gradient differs from the normalized analytic gradient of its shape,
/// over a set of voxels.
struct GradientErrors
{
    ErrorStats angleDeg;        ///< angle between the two, in degrees
    ErrorStats magnitudeError;  ///< | |discrete gradient| - 1 |
    double meanMagnitude = 0.0; ///< mean |discrete gradient|
    std::size_t skipped = 0;    ///< voxels where either gradient is zero
};

struct GradientComparison
{
    GradientErrors band;     ///< every active voxel
    GradientErrors interior; ///< voxels whose whole stencil (+/- step per axis) is active in phi
};

/// @brief Compare @a grad = gradient(phi, step) with shape.gradient() normalized, at the world
/// position of every active voxel, and separately where the stencil does not read the clamped
/// background outside the band.
GradientComparison compareGradient(const implicit::Implicit& shape, const openvdb::FloatGrid& phi,
                                   const openvdb::Vec3SGrid& grad, int step);

} // namespace ivdb::diff
