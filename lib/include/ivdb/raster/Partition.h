// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>
#include <ivdb/raster/Rasterize.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <vector>

namespace ivdb::raster {

/// @brief One rank's share of a Partition: a contiguous run of the grid's leaves in the order a
/// .vdb file stores them (root children by origin, then each internal node's children by
/// offset: x, then y, then z).
struct RankShare
{
    std::uint64_t firstLeaf = 0;   ///< its first leaf's index in file order
    std::uint64_t leaves = 0;      ///< leaves in its run (0: nothing to do)
    openvdb::Coord first, last;    ///< origins of its first and last leaf (when leaves > 0)
    double activeVoxels = 0.0;     ///< estimated active voxels
    double memoryBytes = 0.0;      ///< estimated memory of its part of the grid
    double cpuSeconds = 0.0;       ///< estimated compute on one thread
};

/// @brief How a rasterization splits over ranks, computed without rasterizing.
struct Partition
{
    std::vector<RankShare> ranks;
    std::uint64_t leaves = 0;         ///< leaves the band may cross, by interval tests
    double gridLeaves = 0.0;          ///< estimated leaves of the grid (those with band voxels)
    double activeVoxels = 0.0;        ///< estimated for the whole grid
    double memoryBytes = 0.0;         ///< estimated for the whole grid
    double cpuSeconds = 0.0;          ///< estimated for the whole grid on one thread
    double balance = 1.0;             ///< max / mean of the ranks' leaves (1 is perfect)
    std::uint64_t sampledLeaves = 0;  ///< leaves built to calibrate the estimates
};

/// @brief Split the rasterization of @a shape with @a settings (voxel size, half width, bounds,
/// distance mode) into @a ranks contiguous runs of leaves in file order, balanced by leaf count.
/// @details The sparse path's interval descent, down to the leaves, finds every leaf the band
/// may cross without evaluating a voxel (a superset of the grid's leaves: for shapes that are
/// not exact distances the test reaches a voxel beyond the band); these leaves are the unit of
/// work, since the rasterizer evaluates each of them. Up to @a sampleLeaves of them, one in
/// each of as many equal stretches of the file order (at a fixed pseudo-random place in it), are
/// built as the rasterizer builds them, on one thread, to estimate active voxels, compute time
/// per leaf and the share of leaves the grid keeps; memory counts the kept leaves and the
/// internal nodes above them. The cost grows with the surface (the leaves), not with @a ranks.
/// @throw ParamError for a bad voxel size, half width or @a ranks (limits::kRanks)
/// @throw openvdb::ValueError for an unbounded shape without bounds, or one far too large
Partition partition(const implicit::Implicit::Ptr& shape, const RasterSettings& settings,
                    int ranks, int sampleLeaves = 4096);

} // namespace ivdb::raster
