// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>
#include <ivdb/util/Params.h>

#include <openvdb/openvdb.h>
#include <openvdb/util/NullInterrupter.h>

#include <cstdint>
#include <optional>

namespace ivdb::raster {

/// @brief How the rasterizer finds the narrow band.
enum class Sampling {
    /// Top-down over OpenVDB's node sizes with interval bounds: cost grows with the surface.
    Sparse,
    /// Every voxel of the bounding box: the reference and the benchmark baseline.
    Dense
};

/// @brief The widest narrow band accepted, in voxels (limits::kHalfWidth).
inline constexpr double kMaxHalfWidth = limits::kHalfWidth.hi;

/// What a shape that is not an exact distance stores in the band.
enum class Distance
{
    /// True signed distances: shapes that are not exact distances are re-distanced.
    Exact,
    /// The shape's own value, for a shape whose value never exceeds its distance
    /// (Implicit::isDistanceBound): a CSG (union, intersection, difference) of exact distances
    /// stores min / max, as OpenVDB's csg tools give it (exact outside a union, at most the
    /// distance inside near a crease, the mirror for intersections); blends, smooth CSG,
    /// offsets, shells and transforms of exact distances their own values. Much faster: no
    /// distances to find. Other shapes (a quadric among them) are refused.
    Bound
};

/// @brief How the voxels' distances of a shape that is not an exact SDF were found.
struct RasterStats
{
    /// Voxels whose distance the shape's own local method certified (implicit::footPoints).
    std::uint64_t localDistances = 0;
    /// Voxels where it did not, found by the lattice search and certified after refinement.
    std::uint64_t searchedDistances = 0;
    /// Voxels found by the lattice search whose refinement was not certified: the distance to
    /// the nearest crossing of the voxel lattice's edges (a crease or singular point).
    std::uint64_t approximateDistances = 0;
    /// Voxels no local method answered (the surface beyond the search's window in a wide band),
    /// re-distanced by fast sweeping over just those voxels' neighbourhood.
    std::uint64_t sweptDistances = 0;
};

struct RasterSettings
{
    /// World units per voxel; must be > 0.
    double voxelSize = 0.0;
    /// Half width of the narrow band in voxels; in [1, kMaxHalfWidth].
    double halfWidth = 3.0;
    Sampling sampling = Sampling::Sparse;
    /// Clipping box in world units: the shape is intersected with it. Required for unbounded
    /// shapes; a bounded shape that lies well inside it is left as it is.
    std::optional<implicit::BBoxd> bounds;
    /// Run on all TBB threads (true) or on one.
    bool threaded = true;
    /// Progress and cancellation (may be null). Cancellation throws openvdb::RuntimeError.
    openvdb::util::NullInterrupter* interrupter = nullptr;
    /// Exact distances everywhere, or CSG of distances as it is (see Distance).
    Distance distance = Distance::Exact;
    /// Memory the rasterizer may use, in bytes (dense: its sample array; sparse: its estimated
    /// leaves); 0 means 80% of the machine's available memory.
    std::uint64_t memoryLimit = 0;
    /// If set, receives how the distances were found.
    RasterStats* stats = nullptr;
};

/// @brief Rasterize @a shape into a narrow-band level set.
/// @details The result is a FloatGrid of class LEVEL_SET named "surface" with a linear
/// transform of the voxel size (voxel (i,j,k) at world (i,j,k) * voxelSize), background
/// halfWidth * voxelSize, active voxels exactly those whose signed distance is within the band
/// (|d| < background), negative inside (inactive voxels and tiles -background). Shapes whose
/// value is an exact distance are stored as is (rounded to float); for the others (quadrics,
/// CSG, blends, non-uniform scales) each voxel near the surface gets its true distance, found
/// locally: the shape's own foot points (Implicit::footPoints), else a search of the voxel
/// lattice around it (docs/method.md#true-distances). Sparse and dense sampling give the same
/// active voxels and values.
/// @throw ParamError for a bad voxel size or half width
/// @throw openvdb::ValueError for an unbounded shape without bounds
/// @throw openvdb::RuntimeError if dense sampling would not fit in memory
/// @throw openvdb::RuntimeError if the interrupter cancels the run
openvdb::FloatGrid::Ptr rasterize(const implicit::Implicit::Ptr& shape,
                                  const RasterSettings& settings);

/// @brief True when @a shape is a mesh or .vdb level set already on the lattice and band of
/// @a settings (sparse sampling, no bounds): rasterize() returns a copy of its grid.
bool isOwnRaster(const implicit::Implicit::Ptr& shape, const RasterSettings& settings);

/// @brief The shape that is rasterized: @a shape clipped by the settings' bounds when needed.
implicit::Implicit::Ptr clipToBounds(const implicit::Implicit::Ptr& shape,
                                     const RasterSettings& settings);

/// @brief Bytes the dense path allocates for @a shape (its sample array).
std::uint64_t denseMemoryEstimate(const implicit::Implicit::Ptr& shape,
                                  const RasterSettings& settings);

} // namespace ivdb::raster
