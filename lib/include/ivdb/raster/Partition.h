// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>
#include <ivdb/raster/Rasterize.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <memory>
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

/// @brief What became of a leaf the band may cross, once built.
enum class LeafFate : std::uint8_t
{
    Outside = 0, ///< no band voxel, outside: the background
    Inside = 1,  ///< no band voxel, inside: an inside tile
    Leaf = 2     ///< a leaf of the grid
};

/// @brief One run of leaves built by RasterRuns::build().
struct RunResult
{
    /// The run's leaves that hold band voxels, exactly as rasterize() makes them, in a tree of
    /// their own (background the band, no tiles).
    openvdb::FloatTree::Ptr leaves;
    /// What each leaf of the run became, in file order.
    std::vector<LeafFate> fates;
    /// How the run's distances were found; sweptDistances counts the voxels no local method
    /// answered (those in `unknown`, which RasterRuns::sweep() decides).
    RasterStats stats;
    /// The run's voxels no local method answered, sorted: active with value 0 in their leaves
    /// until RasterRuns::sweep() sets them.
    std::vector<openvdb::Coord> unknown;
    /// A strictly negative value was seen (rasterize() clears the grid of a shape that is not
    /// an exact distance when no run saw one: a zero set without an inside).
    bool anyInside = false;
};

/// @brief rasterize() in pieces, for processes that each build a run of leaves: the leaves the
/// band may cross in file order (as partition() splits them), each run built on its own, and
/// the grid's nodes and tiles from what every leaf became. Leaves and structure together are
/// rasterize()'s grid, voxel for voxel and node for node.
/// @details Every process constructs it from the same shape and settings (the interval descent:
/// no voxel is evaluated). The voxels no local method answers (in bands wider than the default,
/// near edges and corners of shapes that are not exact distances) are fast-swept together, as
/// rasterize() sweeps them: every process sweeps all runs' (sweep()), which are few.
class RasterRuns
{
public:
    /// @throw what rasterize() throws for bad settings or shapes; openvdb::ValueError for dense
    /// sampling or a shape that is its own raster (isOwnRaster)
    RasterRuns(const implicit::Implicit::Ptr& shape, const RasterSettings& settings);
    ~RasterRuns();
    RasterRuns(const RasterRuns&) = delete;
    RasterRuns& operator=(const RasterRuns&) = delete;

    /// The number of leaves the band may cross (partition()'s Partition::leaves).
    std::uint64_t leaves() const;

    /// Build leaves [first, first + count) in file order, in parallel, as rasterize() builds
    /// them. @throw openvdb::ValueError for a run beyond leaves(); openvdb::RuntimeError if the
    /// settings' interrupter cancels
    RunResult build(std::uint64_t first, std::uint64_t count) const;

    /// Decide @a run's voxels no local method answered (RunResult::unknown) as rasterize()
    /// does: fast sweeping over @a unknown, every run's (sorted; the sweep's region is theirs
    /// grown by the band), setting @a run's own. A leaf left without a band voxel becomes the
    /// tile rasterize()'s pruning makes (its fate Inside or Outside, by its first value).
    /// @throw openvdb::RuntimeError if the settings' interrupter cancels
    void sweep(RunResult& run, const std::vector<openvdb::Coord>& unknown) const;

    /// The grid rasterize() makes, but for its leaves: the same transform, class, name, nodes
    /// and tiles (pruned as rasterize() prunes), with an active tile of value 0 in a 128^3 node
    /// wherever the grid has a leaf. @a fates: every leaf's, in file order (the runs' fates
    /// joined); @a anyInside: any run's. @throw openvdb::ValueError for a wrong number of fates
    openvdb::FloatGrid::Ptr skeleton(const std::vector<LeafFate>& fates, bool anyInside) const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace ivdb::raster
