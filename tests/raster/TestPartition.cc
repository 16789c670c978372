// SPDX-License-Identifier: Apache-2.0
// raster::partition against the rasterized grid itself: its leaves, their order in a .vdb file,
// active voxels and memory.
#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/implicit/Quadric.h>
#include <ivdb/raster/Partition.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/util/Params.h>

#include <gtest/gtest.h>

#include <algorithm>

#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

using namespace ivdb;
using implicit::Vec3d;
using openvdb::Coord;

namespace {

/// A leaf's place in a .vdb file: its 4096^3 node (the root's children, by origin), then its
/// 128^3 node (by offset in the parent: x, then y, then z), then itself.
std::tuple<Coord, Coord, Coord> fileKey(const Coord& c)
{
    auto align = [&](int dim) { return Coord(c.x() & ~(dim - 1), c.y() & ~(dim - 1), c.z() & ~(dim - 1)); };
    return {align(4096), align(128), c};
}

struct Case
{
    const char* name;
    implicit::Implicit::Ptr shape;
    double dx;
    double halfWidth = 3.0;
    bool clipped = false; // to the box [-1, 1]^3 (RasterSettings::bounds)
};

std::vector<Case> cases()
{
    auto a = std::make_shared<implicit::Sphere>(Vec3d(-0.35, 0.02, 0.0), 0.6);
    auto b = std::make_shared<implicit::Sphere>(Vec3d(0.35, 0.0, -0.03), 0.6);
    return {
        {"sphere (exact)", std::make_shared<implicit::Sphere>(Vec3d(0.1, -0.2, 0.05), 1.0), 0.01},
        {"union of two spheres (true distances)",
         std::make_shared<implicit::Csg>(implicit::Csg::Op::Union,
                                         std::vector<implicit::Implicit::Ptr>{a, b}), 0.01},
        {"ellipsoid (a quadric)", implicit::makeEllipsoid(Vec3d(0.0), Vec3d(1.0, 0.8, 0.6)), 0.0125},
    };
}

} // namespace

// One rank's run holds every leaf the band crosses, and no rasterized leaf lies outside the
// runs: the descent's interval tests find a superset of the grid's leaves, and in the order
// OpenVDB iterates (and writes) them.
TEST(TestPartition, RunsCoverTheGridsLeavesInFileOrder)
{
    for (const Case& c : cases()) {
        raster::RasterSettings s;
        s.voxelSize = c.dx;
        const auto grid = raster::rasterize(c.shape, s);
        std::vector<Coord> leaves;
        for (auto it = grid->tree().cbeginLeaf(); it; ++it) leaves.push_back(it->origin());
        ASSERT_GT(leaves.size(), 1000u) << c.name;
        for (size_t i = 1; i < leaves.size(); ++i) {
            ASSERT_LT(fileKey(leaves[i - 1]), fileKey(leaves[i])) << c.name << ": OpenVDB's order";
        }
        const raster::Partition one = raster::partition(c.shape, s, 1);
        ASSERT_EQ(one.ranks.size(), 1u);
        EXPECT_GE(one.leaves, leaves.size()) << c.name;
        // Exact distances: only leaves whose corners reach the band without a voxel in it are
        // extra. The others' test reaches a voxel beyond the band (the lattice search's window).
        const double extra = c.shape->isExactSdf() ? 1.01 : 1.6;
        EXPECT_LE(double(one.leaves), extra * double(leaves.size())) << c.name;
        EXPECT_LE(fileKey(one.ranks[0].first), fileKey(leaves.front())) << c.name;
        EXPECT_GE(fileKey(one.ranks[0].last), fileKey(leaves.back())) << c.name;

        for (int ranks : {2, 3, 7, 64}) {
            const raster::Partition p = raster::partition(c.shape, s, ranks);
            ASSERT_EQ(p.ranks.size(), size_t(ranks));
            EXPECT_EQ(p.leaves, one.leaves);
            std::uint64_t next = 0, most = 0;
            for (int r = 0; r < ranks; ++r) {
                const raster::RankShare& share = p.ranks[size_t(r)];
                EXPECT_EQ(share.firstLeaf, next) << c.name << ", rank " << r << " of " << ranks;
                next += share.leaves;
                most = std::max(most, share.leaves);
                // Equal shares: floor(n / ranks) or one more.
                EXPECT_LE(share.leaves, p.leaves / ranks + 1);
                EXPECT_GE(share.leaves, p.leaves / ranks);
                ASSERT_GT(share.leaves, 0u);
                EXPECT_LE(fileKey(share.first), fileKey(share.last));
                if (r > 0) EXPECT_LT(fileKey(p.ranks[size_t(r) - 1].last), fileKey(share.first));
            }
            EXPECT_EQ(next, p.leaves) << c.name;
            EXPECT_DOUBLE_EQ(p.balance, double(most) * ranks / double(p.leaves));
            EXPECT_LE(p.balance, 1.0 + double(ranks) / double(p.leaves));
        }
    }
}

// The estimates from 4096 leaves built (of 9,000 to 16,000 here) against the whole grid: leaves,
// active voxels and memory (OpenVDB's own count, Tree::memUsage) within 6%.
TEST(TestPartition, EstimatesMatchTheRasterizedGrid)
{
    for (const Case& c : cases()) {
        raster::RasterSettings s;
        s.voxelSize = 0.005;
        const auto grid = raster::rasterize(c.shape, s);
        const raster::Partition p = raster::partition(c.shape, s, 4);
        EXPECT_EQ(p.sampledLeaves, 4096u);
        EXPECT_GT(p.leaves, 2 * p.sampledLeaves) << c.name;
        const double active = double(grid->activeVoxelCount());
        const double memory = double(grid->tree().memUsage());
        std::printf("%s: %llu leaves crossed, %.0f estimated in the grid (%llu); active voxels %.0f estimated, %.0f in the grid; "
                    "memory %.0f estimated, %.0f in the grid; %.3g CPU-seconds\n", c.name,
                    (unsigned long long)p.leaves, p.gridLeaves,
                    (unsigned long long)grid->tree().leafCount(),
                    p.activeVoxels, active, p.memoryBytes, memory, p.cpuSeconds);
        EXPECT_NEAR(p.activeVoxels, active, 0.06 * active) << c.name;
        const double leaves = double(grid->tree().leafCount());
        EXPECT_NEAR(p.gridLeaves, leaves, 0.06 * leaves) << c.name;
        EXPECT_NEAR(p.memoryBytes, memory, 0.06 * memory) << c.name;
        EXPECT_GT(p.cpuSeconds, 0.0) << c.name;
        double activeSum = 0.0, cpuSum = 0.0;
        for (const auto& r : p.ranks) activeSum += r.activeVoxels, cpuSum += r.cpuSeconds;
        EXPECT_NEAR(activeSum, p.activeVoxels, 1e-6 * p.activeVoxels) << c.name;
        EXPECT_NEAR(cpuSum, p.cpuSeconds, 1e-6 * p.cpuSeconds) << c.name;
    }
}

// More ranks than leaves: the first ranks get none, the others one each; the balance says so.
TEST(TestPartition, MoreRanksThanLeavesAndBadCounts)
{
    raster::RasterSettings s;
    s.voxelSize = 0.05;
    const auto shape = std::make_shared<implicit::Sphere>(Vec3d(0.0), 1.0);
    const raster::Partition p = raster::partition(shape, s, 100000); // the most accepted
    ASSERT_EQ(p.ranks.size(), 100000u);
    ASSERT_GT(p.leaves, 0u);
    ASSERT_LT(p.leaves, 100000u);
    std::uint64_t busy = 0;
    for (const auto& r : p.ranks) {
        EXPECT_LE(r.leaves, 1u);
        busy += r.leaves;
    }
    EXPECT_EQ(busy, p.leaves);
    EXPECT_DOUBLE_EQ(p.balance, 100000.0 / double(p.leaves));
    for (int bad : {0, -3, 100001}) {
        try {
            raster::partition(shape, s, bad);
            ADD_FAILURE() << bad << " ranks accepted";
        } catch (const ParamError& e) {
            EXPECT_EQ(e.param(), "ranks");
            EXPECT_NE(std::string(e.what()).find(std::to_string(bad)), std::string::npos) << e.what();
        }
    }
}

namespace {

/// A grid's nodes, tiles and voxels as a .vdb file stores them (topology, then buffers).
std::string treeBytes(const openvdb::FloatGrid& g)
{
    std::ostringstream os(std::ios::binary);
    g.tree().writeTopology(os, false);
    g.tree().writeBuffers(os, false);
    return os.str();
}

} // namespace

// Runs built apart (as ivdb-mpi's ranks build them) and the skeleton from their leaves' fates
// make rasterize()'s grid node for node and bit for bit, however the leaves are split.
TEST(TestPartition, RunsAndSkeletonMakeTheRasterizedGrid)
{
    std::vector<Case> all = cases();
    auto a = std::make_shared<implicit::Sphere>(Vec3d(-0.35, 0.02, 0.0), 0.6);
    auto b = std::make_shared<implicit::Sphere>(Vec3d(0.35, 0.0, -0.03), 0.6);
    // Inside tiles of every size: a sphere 400 voxels across holds whole 128^3 nodes.
    all.push_back({"large sphere", std::make_shared<implicit::Sphere>(Vec3d(0.0), 2.0), 0.01});
    all.push_back({"difference", std::make_shared<implicit::Csg>(implicit::Csg::Op::Difference,
                   std::vector<implicit::Implicit::Ptr>{a, b}), 0.01});
#ifndef IVDB_SANITIZED // its lattice searches take minutes there
    // A band of 8 voxels around a clipped paraboloid: over 10,000 voxels that no local method
    // answers (inside its bowl, beyond the lattice search's window), fast-swept together across
    // the runs (some leaves are left without band voxels).
    all.push_back({"clipped paraboloid, a wide band",
                   implicit::makeParaboloid(Vec3d(0.0), Vec3d(0.0, 0.0, 1.0), false, 0.5, 0.5), 0.1,
                   8.0, true});
#endif
    for (const Case& c : all) {
        for (auto mode : {raster::Distance::Exact, raster::Distance::Bound}) {
            raster::RasterSettings s;
            s.voxelSize = c.dx;
            s.halfWidth = c.halfWidth;
            if (c.clipped) s.bounds = implicit::BBoxd(Vec3d(-1.0), Vec3d(1.0));
            s.distance = mode;
            const bool bound = mode == raster::Distance::Bound;
            raster::RasterStats whole;
            s.stats = &whole;
            openvdb::FloatGrid::Ptr expected;
            try {
                expected = raster::rasterize(c.shape, s);
            } catch (const openvdb::ValueError&) {
                ASSERT_TRUE(bound) << c.name; // a quadric has no "bound" mode
                continue;
            }
            s.stats = nullptr;
            const std::string want = treeBytes(*expected);
            raster::RasterRuns runs(c.shape, s);
            // Every run sweeps all the runs' voxels: two splits for the wide band.
            const std::vector<std::uint64_t> splits = c.clipped ? std::vector<std::uint64_t>{1, 3}
                                                                : std::vector<std::uint64_t>{1, 2, 5, 13};
            for (std::uint64_t k : splits) {
                const std::string what = std::string(c.name) + (bound ? ", bound" : "") + ", " +
                                         std::to_string(k) + " runs";
                const std::uint64_t n = runs.leaves();
                std::vector<raster::LeafFate> fates;
                std::vector<openvdb::FloatTree::Ptr> parts;
                raster::RasterStats sum;
                bool anyInside = false;
                std::vector<raster::RunResult> built;
                std::vector<openvdb::Coord> unknown;
                for (std::uint64_t r = 0; r < k; ++r) {
                    const std::uint64_t first = n * r / k, last = n * (r + 1) / k;
                    built.push_back(runs.build(first, last - first));
                    const raster::RunResult& run = built.back();
                    ASSERT_EQ(run.fates.size(), last - first) << what;
                    ASSERT_TRUE(std::is_sorted(run.unknown.begin(), run.unknown.end())) << what;
                    ASSERT_EQ(run.unknown.size(), run.stats.sweptDistances) << what;
                    unknown.insert(unknown.end(), run.unknown.begin(), run.unknown.end());
                }
                // Every run's voxels no local method answered, swept together.
                std::sort(unknown.begin(), unknown.end());
                for (raster::RunResult& run : built) {
                    runs.sweep(run, unknown);
                    fates.insert(fates.end(), run.fates.begin(), run.fates.end());
                    parts.push_back(run.leaves);
                    sum.localDistances += run.stats.localDistances;
                    sum.searchedDistances += run.stats.searchedDistances;
                    sum.approximateDistances += run.stats.approximateDistances;
                    sum.sweptDistances += run.stats.sweptDistances;
                    anyInside = anyInside || run.anyInside;
                }
                EXPECT_EQ(sum.localDistances, whole.localDistances) << what;
                EXPECT_EQ(sum.searchedDistances, whole.searchedDistances) << what;
                EXPECT_EQ(sum.approximateDistances, whole.approximateDistances) << what;
                EXPECT_EQ(sum.sweptDistances, whole.sweptDistances) << what;
                if (c.clipped) EXPECT_GT(whole.sweptDistances, 10000u) << what;
                const openvdb::FloatGrid::Ptr skeleton = runs.skeleton(fates, anyInside);
                EXPECT_EQ(skeleton->tree().activeTileCount(), expected->tree().leafCount()) << what;
                EXPECT_EQ(skeleton->getName(), expected->getName());
                EXPECT_EQ(skeleton->getGridClass(), openvdb::GRID_LEVEL_SET);
                EXPECT_EQ(skeleton->transform(), expected->transform()) << what;
                // The leaves in place of the skeleton's active tiles: the rasterized grid.
                for (const auto& part : parts) {
                    for (auto it = part->cbeginLeaf(); it; ++it) {
                        skeleton->tree().addLeaf(new openvdb::FloatTree::LeafNodeType(*it));
                    }
                }
                EXPECT_EQ(skeleton->tree().activeTileCount(), 0u) << what;
                EXPECT_TRUE(treeBytes(*skeleton) == want) << what;
            }
            EXPECT_THROW(runs.build(runs.leaves(), 1), openvdb::ValueError);
            EXPECT_THROW(runs.skeleton({}, true), openvdb::ValueError);
        }
    }
}
