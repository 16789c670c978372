// SPDX-License-Identifier: Apache-2.0
#include <ivdb/raster/Rasterize.h>
#include <ivdb/raster/Partition.h>

#include "Distances.h"
#include "../util/Simd.h"

#include <ivdb/levelset/Redistance.h>

#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/GridShape.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/util/Interrupt.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tree/LeafManager.h>

#include <tbb/blocked_range.h>
#include <tbb/concurrent_vector.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <vector>

namespace ivdb::raster {

namespace {

using implicit::BBoxd;
using implicit::Implicit;
using implicit::Interval;
using implicit::Vec3d;
using openvdb::Coord;
using openvdb::CoordBBox;
using FloatTree = openvdb::FloatTree;
using LeafT = FloatTree::LeafNodeType;
using Int2T = FloatTree::RootNodeType::ChildNodeType;
using Int1T = Int2T::ChildNodeType;

enum class Verdict { Outside, Inside, Straddle };

/// Everything the two sampling paths share: the band rule and the per-voxel values, so sparse
/// and dense give the same grid.
struct Context
{
    Implicit::Ptr shape;
    double dx = 0.0;
    double band = 0.0;      // half width in world units, also the background
    bool exact = false;     // the shape's value is the exact signed distance
    int reachSteps = 0;     // non-exact: voxel steps from the interface a band voxel can be
    double reach = 0.0;     // world distance a box is dilated by before the interval test
    detail::DistanceSettings distances; // non-exact: how true distances are found
    bool boundedByDistance = false; // non-exact: |f| <= the distance (Implicit::isDistanceBound)
    double lipschitz = 1.0;          // there, how fast f changes (Implicit::lipschitzBound)
    CoordBBox region;       // index box that holds every voxel of the result
    openvdb::util::NullInterrupter* interrupter = nullptr;
    std::uint64_t memoryLimit = 0;

    BBoxd worldBox(const CoordBBox& b) const
    {
        return BBoxd(Vec3d(b.min().x(), b.min().y(), b.min().z()) * dx,
                     Vec3d(b.max().x(), b.max().y(), b.max().z()) * dx);
    }

    BBoxd dilatedWorldBox(const CoordBBox& b) const
    {
        BBoxd w = worldBox(b);
        return BBoxd(w.min() - Vec3d(reach), w.max() + Vec3d(reach));
    }

    /// Can the box hold a voxel of the result? Exact: a band voxel has |f| < band, and so has
    /// one of a 1-Lipschitz shape (|f| <= its distance: boundedByDistance); otherwise a band voxel has the
    /// surface within the band: a sign change within `reach` of the box.
    Verdict classify(const Implicit& f, const CoordBBox& b) const
    {
        if (exact || boundedByDistance) {
            const Interval iv = f.interval(worldBox(b));
            const double eps = 1e-6 * dx;
            if (iv.lo >= band + eps) return Verdict::Outside;
            if (iv.hi <= -(band + eps)) return Verdict::Inside;
            return Verdict::Straddle;
        }
        const Interval iv = f.interval(dilatedWorldBox(b));
        const double eps = 1e-12 * (std::abs(iv.lo) + std::abs(iv.hi));
        if (iv.lo > eps) return Verdict::Outside;
        if (iv.hi < -eps) return Verdict::Inside;
        return Verdict::Straddle;
    }

    /// The band rule, on the stored float value: strictly inside the float background, so
    /// every active value is a distance smaller than the background.
    bool inBand(float v) const { return std::abs(v) < static_cast<float>(band); }
};

/// Counts of how voxels' distances were found, summed over threads, and the voxels no local
/// method could answer (left for fast sweeping).
struct Counts
{
    tbb::concurrent_vector<Coord> unknown;
    std::atomic<bool> anyInside{false}; // a strictly negative value was seen

    /// Each thread adds to its own counts (in a cache line of their own): shared atomic counters,
    /// added to once a leaf, passed their cache line between the cores at every leaf.
    void add(const detail::DistanceCounts& c) { mPerThread.local() += c; }

    detail::DistanceCounts total() const
    {
        detail::DistanceCounts sum;
        for (const detail::DistanceCounts& c : mPerThread) sum += c;
        return sum;
    }

    /// The totals into @a stats.
    void report(RasterStats& stats) const
    {
        const detail::DistanceCounts sum = total();
        stats.localDistances = sum.local;
        stats.searchedDistances = sum.searched;
        stats.approximateDistances = sum.approximate;
        stats.sweptDistances = unknown.size();
    }

private:
    tbb::enumerable_thread_specific<detail::DistanceCounts> mPerThread;
};

/// World coordinates of the 512 voxels of the leaf at @a origin, in leaf offset order.
void leafPoints(const Coord& origin, double dx, double* x, double* y, double* z)
{
    for (int i = 0, n = 0; i < 8; ++i) {
        for (int j = 0; j < 8; ++j) {
            for (int k = 0; k < 8; ++k, ++n) {
                x[n] = double(origin.x() + i) * dx;
                y[n] = double(origin.y() + j) * dx;
                z[n] = double(origin.z() + k) * dx;
            }
        }
    }
}

/// The centres of the leaf's 64 groups of 2^3 voxels (group g at voxel offsets 2 (g >> 4),
/// 2 ((g >> 2) & 3), 2 (g & 3)), in world coordinates.
void groupCentres(const Coord& origin, double dx, double* cx, double* cy, double* cz)
{
    for (int g = 0; g < 64; ++g) {
        cx[g] = (double(origin.x() + 2 * (g >> 4)) + 0.5) * dx;
        cy[g] = (double(origin.y() + 2 * ((g >> 2) & 3)) + 0.5) * dx;
        cz[g] = (double(origin.z() + 2 * (g & 3)) + 0.5) * dx;
    }
}

/// The values of a leaf of a shape whose |f| never exceeds the distance (Context::
/// boundedByDistance), first at the centre of each 2^3 group of voxels: f changes by at most
/// Context::lipschitz per unit of length (1 but for interpolated grids), so where |f| exceeds the
/// band by that times the half diagonal (sqrt(3)/2 voxels) every voxel of the group is beyond
/// the band, on the centre's side: +/- the band into @a v, and @a inside or @a outside set. The other groups' voxels are evaluated in one call: their
/// coordinates (@a x, @a y, @a z), values (@a u) and offsets (@a at), as many as returned.
int boundedLeafValues(const Context& ctx, const Implicit& f, const Coord& origin, double* v,
                      double* x, double* y, double* z, double* u, int* at, bool& inside,
                      bool& outside)
{
    double cx[64], cy[64], cz[64], cv[64];
    groupCentres(origin, ctx.dx, cx, cy, cz);
    f.values(cx, cy, cz, cv, 64);
    const double clear = ctx.band + (0.5 * std::sqrt(3.0) * ctx.lipschitz + 1e-6) * ctx.dx;
    int count = 0;
    for (int g = 0; g < 64; ++g) {
        const int a = 2 * (g >> 4), b = 2 * ((g >> 2) & 3), c = 2 * (g & 3);
        const bool skip = std::abs(cv[g]) > clear;
        const double side = cv[g] > 0.0 ? ctx.band : -ctx.band;
        for (int i = a; i < a + 2; ++i)
        for (int j = b; j < b + 2; ++j)
        for (int k = c; k < c + 2; ++k) {
            const int n = (i << 6) | (j << 3) | k;
            if (skip) {
                v[n] = side;
                continue;
            }
            // leafPoints()' coordinates, for this voxel alone.
            x[count] = double(origin.x() + i) * ctx.dx;
            y[count] = double(origin.y() + j) * ctx.dx;
            z[count] = double(origin.z() + k) * ctx.dx;
            at[count++] = n;
        }
        inside = inside || (skip && cv[g] < 0.0);
        outside = outside || (skip && cv[g] > 0.0);
    }
    if (count > 0) f.values(x, y, z, u, std::size_t(count));
    return count;
}

/// The values of a leaf for a shape that is not an exact SDF: true distances for the voxels
/// that can be in the band, +/- the band (by sign) for the others. Which voxels can be: for a
/// 1-Lipschitz shape (|f| <= the distance), those with |f| < band; otherwise those in the
/// leaf's 2^3 groups of voxels whose box, grown by the band, holds a sign change of the shape's
/// interval (then only those voxels are evaluated at all, and no other voxel's coordinates are
/// made). Returns false if no voxel can be (the leaf has no band voxel), with @a allInside
/// telling whether every voxel is inside.
bool leafDistances(const Context& ctx, const Implicit& f, const Coord& origin, double* v,
                   Counts* counts, bool& allInside)
{
    alignas(64) double sx[512], sy[512], sz[512], sv[512], d[512];
    int index[512];
    int m = 0;
    bool inside = false, outside = false;
    if (ctx.boundedByDistance) {
        alignas(64) double x[512], y[512], z[512], u[512];
        int at[512];
        const int count = boundedLeafValues(ctx, f, origin, v, x, y, z, u, at, inside, outside);
        for (int t = 0; t < count; ++t) {
            const int n = at[t];
            inside = inside || u[t] < 0.0;
            if (std::abs(u[t]) < ctx.band) {
                sx[m] = x[t];
                sy[m] = y[t];
                sz[m] = z[t];
                sv[m] = u[t];
                index[m++] = n;
                v[n] = u[t];
            } else {
                v[n] = u[t] > 0.0 ? ctx.band : -ctx.band;
                outside = outside || v[n] > 0.0;
            }
        }
    } else {
        // The 64 groups' boxes (voxel centres), grown by the band, in one call.
        const double grow = ctx.band + 1e-9 * ctx.dx;
        double cx[64], cy[64], cz[64], lo[64], hi[64];
        groupCentres(origin, ctx.dx, cx, cy, cz);
        f.intervals(cx, cy, cz, Vec3d(0.5 * ctx.dx + grow), 64, lo, hi);
        for (int g = 0; g < 64; ++g) {
            const int a = 2 * (g >> 4), b = 2 * ((g >> 2) & 3), c = 2 * (g & 3);
            for (int i = a; i < a + 2; ++i)
            for (int j = b; j < b + 2; ++j)
            for (int k = c; k < c + 2; ++k) {
                const int n = (i << 6) | (j << 3) | k;
                if (lo[g] > 0.0) {
                    v[n] = ctx.band; // no surface within the band
                    outside = true;
                } else if (hi[g] < 0.0) {
                    v[n] = -ctx.band;
                    inside = true;
                } else {
                    // leafPoints()' coordinates, for this voxel alone.
                    sx[m] = double(origin.x() + i) * ctx.dx;
                    sy[m] = double(origin.y() + j) * ctx.dx;
                    sz[m] = double(origin.z() + k) * ctx.dx;
                    index[m++] = n;
                }
            }
        }
    }
    detail::DistanceCounts dc;
    if (m > 0 && ctx.boundedByDistance) {
        detail::trueDistances(f, origin, index, sx, sy, sz, sv, std::size_t(m), ctx.distances,
                              d, dc);
    } else if (m > 0) {
        // The values with the distances: a node whose foot points start from the same
        // evaluations (a blend) makes them once.
        detail::valuesAndTrueDistances(f, origin, index, sx, sy, sz, std::size_t(m),
                                       ctx.distances, sv, d, dc);
        for (int k = 0; k < m; ++k) inside = inside || sv[k] < 0.0;
    }
    if (counts && inside && !counts->anyInside) counts->anyInside = true;
    if (m == 0) {
        allInside = !outside;
        return false;
    }
    if (counts) counts->add(dc);
    for (int k = 0; k < m; ++k) v[index[k]] = d[k];
    return true;
}

/// What storeLeafValues() found, as bits.
constexpr unsigned kSomeOutside = 1u, kSomeUnknown = 2u;

/// A leaf's 512 values @a v as stored in @a buf: the value (as a float) where it is in the band,
/// else +/- the background @a bg by its sign; @a in says which (one byte a voxel, 1 in the band;
/// 0 for an unknown, NaN). Returns kSomeOutside if a voxel is beyond the band outside,
/// kSomeUnknown if one is unknown. One loop without branches (whether a voxel is in the band is
/// close to random along a row), compiled for each vector width: at two doubles a vector it was
/// a third of an exact sphere's time.
IVDB_VECTOR_CLONES
unsigned storeLeafValues(const double* __restrict v, float bg, float* __restrict buf,
                         std::uint8_t* __restrict in)
{
    unsigned outside = 0, unknown = 0;
    for (int n = 0; n < 512; ++n) {
        const float fv = static_cast<float>(v[n]);
        const bool band = std::abs(fv) < bg; // Context::inBand(); false for NaN
        buf[n] = band ? fv : (fv > 0.0f ? bg : -bg);
        in[n] = std::uint8_t(band);
        outside |= unsigned(!band & (fv > 0.0f));
        unknown |= unsigned(fv != fv);
    }
    return (outside ? kSomeOutside : 0u) | (unknown ? kSomeUnknown : 0u);
}

/// Eight bytes of 0 or 1 as the bits of one byte (byte k to bit k): read as a little-endian
/// word, byte k's bit is bit 8k, and the product's top byte collects it at 8k + 56 - 7k = 56 + k
/// (no two of the product's terms share a bit, so nothing carries).
inline std::uint64_t packBits(const std::uint8_t* bytes)
{
    static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "packBits() reads bytes as little-endian");
    std::uint64_t word;
    std::memcpy(&word, bytes, sizeof(word));
    return (word * 0x0102040810204080ull) >> 56;
}

/// Build the leaf at @a origin from the shape's values (exact) or true distances (otherwise),
/// or return null with @a inside telling whether the leaf holds only inside voxels.
LeafT* buildLeaf(const Context& ctx, const Implicit& f, const Coord& origin, bool& inside,
                 Counts* counts)
{
    alignas(64) double v[512];
    if (ctx.exact) {
        // Every voxel: an exact SDF's values cost less than boundedLeafValues()' selection (the
        // sphere of radius 1 at voxel 0.0025 took 0.046 s with it, 0.035 s without).
        alignas(64) double x[512], y[512], z[512];
        leafPoints(origin, ctx.dx, x, y, z);
        f.values(x, y, z, v, 512);
    } else if (!leafDistances(ctx, f, origin, v, counts, inside)) {
        return nullptr; // every voxel beyond the band: no leaf
    }
    const float bg = static_cast<float>(ctx.band);
    // The buffer left unfilled: every value is written below.
    auto leaf = std::make_unique<LeafT>(openvdb::PartialCreate(), origin, bg);
    leaf->buffer().allocate();
    float* buf = leaf->buffer().data();
    auto& mask = leaf->getValueMask();
    // The values, then the mask a word at a time from their bytes; unknown voxels (rare) after.
    alignas(64) std::uint8_t in[512];
    const unsigned found = storeLeafValues(v, bg, buf, in);
    const bool anyOutside = found & kSomeOutside;
    const bool anyUnknown = found & kSomeUnknown;
    bool anyActive = false;
    for (int w = 0; w < 8; ++w) {
        std::uint64_t word = 0;
        for (int j = 0; j < 8; ++j) word |= packBits(in + 64 * w + 8 * j) << (8 * j);
        mask.getWord<std::uint64_t>(w) = word;
        anyActive = anyActive | (word != 0);
    }
    for (int n = 0; anyUnknown && n < 512; ++n) {
        if (!std::isnan(v[n])) continue;
        // Unknown: fast sweeping decides it later (sweepUnknown); kept active till then.
        buf[n] = 0.0f;
        mask.setOn(n);
        anyActive = true;
        if (counts) counts->unknown.push_back(leaf->offsetToGlobalCoord(n));
    }
    if (!anyActive) {
        inside = !anyOutside;
        return nullptr;
    }
    return leaf.release();
}

struct Level1Result
{
    Coord origin;
    Int1T* node = nullptr;  // owned until added to the tree
    bool inside = false;    // the whole level-1 box is an inside tile
};

/// Voxels a certified true distance may be off (implicit::FootQuery::tolerance).
constexpr double kDistanceTolerance = 1e-3;
/// The lattice search's window reaches at most this many voxels (17^3 values a voxel): a wider
/// band leaves what lies beyond to fast sweeping (sweepUnknown).
constexpr int kMaxSearchRadius = 8;

/// Blocks between OpenVDB's 128^3 internal nodes and its 8^3 leaves in the descent.
constexpr int kBlock = 32;

int alignDown(int v, int dim) { return v & ~(dim - 1); }

/// Call @a fn(origin) for every cube of side @a dim (a power of two, at multiples of it) that
/// overlaps @a box, in x, y, z order.
template<typename Fn>
void forEachCube(const CoordBBox& box, int dim, Fn&& fn)
{
    for (int a = alignDown(box.min().x(), dim); a <= box.max().x(); a += dim)
        for (int b = alignDown(box.min().y(), dim); b <= box.max().y(); b += dim)
            for (int c = alignDown(box.min().z(), dim); c <= box.max().z(); c += dim)
                fn(Coord(a, b, c));
}

/// The part of the cube of side @a dim at @a origin inside @a region.
CoordBBox clipped(const Coord& origin, int dim, const CoordBBox& region)
{
    CoordBBox b = CoordBBox::createCube(origin, dim);
    b.intersect(region);
    return b;
}

/// A node of the descent: a cube and the shape pruned to it.
struct Task
{
    Coord origin;
    Implicit::Ptr node;
};

/// The sparse path's memory, estimated before it allocates: the straddling level-2 nodes are
/// known; up to 8 of them (evenly spread) count their straddling 128^3 children, and up to 16 of
/// those count their straddling leaves (interval tests only, no voxels). Refuses, with the
/// estimate, when the grid would not fit (a voxel size far too small for the shape, typically).
void checkSparseMemory(const Context& ctx, const std::vector<Task>& level2)
{
    if (level2.empty()) return;
    const int d2 = Int2T::DIM, d1 = Int1T::DIM, d0 = LeafT::DIM;
    const size_t sample2 = std::min<size_t>(level2.size(), 8);
    std::vector<Task> straddling1; // in the sampled level-2 nodes
    for (size_t s = 0; s < sample2; ++s) {
        const Task& t2 = level2[s * level2.size() / sample2];
        forEachCube(clipped(t2.origin, d2, ctx.region), d1, [&](const Coord& o) {
            if (ctx.classify(*t2.node, CoordBBox::createCube(o, d1)) == Verdict::Straddle) {
                straddling1.push_back({o, t2.node});
            }
        });
        util::checkInterrupt(ctx.interrupter);
    }
    const double level1 = double(straddling1.size()) * double(level2.size()) / double(sample2);
    const size_t sample1 = std::min<size_t>(straddling1.size(), 16);
    double leaves = 0.0;
    for (size_t s = 0; s < sample1; ++s) {
        const Task& t1 = straddling1[s * straddling1.size() / sample1];
        forEachCube(clipped(t1.origin, d1, ctx.region), d0, [&](const Coord& o) {
            if (ctx.classify(*t1.node, CoordBBox::createCube(o, d0)) == Verdict::Straddle) {
                leaves += 1.0;
            }
        });
    }
    const double leafCount = sample1 ? level1 * leaves / double(sample1) : 0.0;
    // A leaf's values and masks (true distances are found in place, no copies).
    const double perLeaf = double(sizeof(LeafT) + LeafT::SIZE * sizeof(float));
    const double need = leafCount * perLeaf + level1 * double(sizeof(Int1T));
    const double limit = util::memoryBudget(ctx.memoryLimit);
    if (need > limit) {
        std::ostringstream os;
        os << "the narrow band at voxel size " << util::formatNumber(ctx.dx) << " would need about "
           << util::formatBytes(need) << " (about " << std::uint64_t(leafCount)
           << " leaves of 8^3 voxels) but only " << util::formatBytes(limit)
           << " may be used: use a larger voxel size (the memory grows as 1/voxel_size^2), a "
              "smaller half width or smaller bounds";
        OPENVDB_THROW(openvdb::RuntimeError, os.str());
    }
}

/// The leaves (or inside tiles) of one 32^3 block into @a int1: @a node is the shape pruned to
/// the block, null when the whole block is inside. @a straddling(o, box, node, int1, inside)
/// settles a leaf the band may cross: it adds what the leaf becomes to @a int1 and returns true,
/// or returns false, with @a inside set when the leaf is an inside tile. Returns true if it
/// added anything.
template<typename Fn>
bool fillBlock(const Context& ctx, Int1T& int1, const CoordBBox& part, const Implicit* node,
               Fn&& straddling)
{
    bool any = false;
    const int d0 = LeafT::DIM;
    forEachCube(part, d0, [&](const Coord& o) {
        bool inside = node == nullptr;
        if (node) {
            const CoordBBox box0 = CoordBBox::createCube(o, d0);
            const Verdict v0 = ctx.classify(*node, box0);
            inside = v0 == Verdict::Inside;
            if (v0 == Verdict::Straddle && straddling(o, box0, *node, int1, inside)) {
                any = true;
                return;
            }
        }
        if (inside) {
            int1.addTile(int1.coordToOffset(o), -static_cast<float>(ctx.band), false);
            any = true;
        }
    });
    return any;
}

/// fillBlock's leaves built from the shape, as the rasterizer builds them.
struct BuildLeaves
{
    const Context& ctx;
    Counts& counts;

    LeafT* build(const Coord& o, const CoordBBox& box0, const Implicit& node, bool& inside) const
    {
        const Implicit::Ptr node0 = node.prune(ctx.dilatedWorldBox(box0));
        return buildLeaf(ctx, *node0, o, inside, &counts);
    }

    bool operator()(const Coord& o, const CoordBBox& box0, const Implicit& node, Int1T& int1,
                    bool& inside) const
    {
        LeafT* leaf = build(o, box0, node, inside);
        if (leaf) int1.addLeaf(leaf);
        return leaf != nullptr;
    }
};

/// The descent below one 128^3 node (the rasterizer's and the partition's): the node's verdict,
/// and if it straddles, @a onBlock(part, node) for each of its 32^3 blocks that is not outside,
/// with the block's part of the region and the shape pruned to it (null: the block is inside).
template<typename Fn>
Verdict descendLevel1(const Context& ctx, const Task& task, Fn&& onBlock)
{
    const int d1 = Int1T::DIM;
    const CoordBBox box1 = CoordBBox::createCube(task.origin, d1);
    const Verdict v1 = ctx.classify(*task.node, box1);
    if (v1 != Verdict::Straddle) return v1;
    const Implicit::Ptr node1 = task.node->prune(ctx.dilatedWorldBox(box1));
    const CoordBBox sub = clipped(task.origin, d1, ctx.region);
    // Blocks of 4^3 leaves in between: a leaf then tests the few primitives near its block
    // instead of the hundreds near its 128^3 node (1000 spheres: ~3x faster).
    forEachCube(sub, kBlock, [&](const Coord& o) {
        const CoordBBox block = CoordBBox::createCube(o, kBlock);
        const Verdict vb = ctx.classify(*node1, block);
        if (vb == Verdict::Outside) return;
        CoordBBox part = block;
        part.intersect(sub);
        if (vb == Verdict::Inside) {
            onBlock(part, static_cast<const Implicit*>(nullptr));
            return;
        }
        const Implicit::Ptr nodeB = node1->prune(ctx.dilatedWorldBox(block));
        onBlock(part, static_cast<const Implicit*>(nodeB.get()));
    });
    return v1;
}

/// One 128^3 node of the sparse path: its 32^3 blocks, then their leaves, each leaf the band
/// may cross settled by @a straddling (fillBlock).
template<typename Fn>
Level1Result buildLevel1(const Context& ctx, const Task& task, Fn&& straddling)
{
    Level1Result res;
    res.origin = task.origin;
    std::unique_ptr<Int1T> int1;
    bool any = false;
    const Verdict v1 = descendLevel1(ctx, task, [&](const CoordBBox& part, const Implicit* node) {
        if (!int1) int1 = std::make_unique<Int1T>(task.origin, static_cast<float>(ctx.band));
        any = fillBlock(ctx, *int1, part, node, straddling) || any;
    });
    res.inside = v1 == Verdict::Inside;
    if (any) res.node = int1.release();
    return res;
}

/// Level-1 nodes into their level-2 parents, those (and inside level-2 tiles) into the root.
void assembleTree(FloatTree& tree, std::vector<Level1Result>& results,
                  const std::vector<Coord>& insideLevel2, float bg)
{
    const int d2 = Int2T::DIM;
    std::map<Coord, std::unique_ptr<Int2T>> level2;
    for (auto& r : results) {
        if (!r.node && !r.inside) continue;
        const Coord o2(alignDown(r.origin.x(), d2), alignDown(r.origin.y(), d2),
                       alignDown(r.origin.z(), d2));
        auto& parent = level2[o2];
        if (!parent) parent = std::make_unique<Int2T>(o2, bg);
        if (r.node) {
            parent->addChild(r.node);
            r.node = nullptr;
        } else {
            parent->addTile(parent->coordToOffset(r.origin), -bg, false);
        }
    }
    for (auto& [o2, node] : level2) tree.root().addChild(node.release());
    for (const Coord& o2 : insideLevel2) tree.root().addTile(o2, -bg, false);
}

/// The sparse descent's first two levels: the straddling 4096^3 nodes (serial: few), then the
/// 128^3 children of each that overlap the region, in file order; the 4096^3 nodes wholly
/// inside go to @a insideLevel2. With @a checkMemory, refuses a grid that would not fit.
std::vector<Task> level1Tasks(const Context& ctx, std::vector<Coord>& insideLevel2,
                              bool checkMemory)
{
    const int d2 = Int2T::DIM, d1 = Int1T::DIM;
    std::vector<Task> straddling2;
    forEachCube(ctx.region, d2, [&](const Coord& o) {
        const CoordBBox box2 = CoordBBox::createCube(o, d2);
        const Verdict v = ctx.classify(*ctx.shape, box2);
        if (v == Verdict::Inside) insideLevel2.push_back(o);
        if (v == Verdict::Straddle) straddling2.push_back({o, ctx.shape->prune(ctx.dilatedWorldBox(box2))});
    });
    util::checkInterrupt(ctx.interrupter, 0);
    // The level-1 task list itself: 24 bytes per 128^3 node of every straddling 4096^3 node.
    if (double(straddling2.size()) * double((d2 / d1) * (d2 / d1) * (d2 / d1)) > 2e8) {
        OPENVDB_THROW(openvdb::RuntimeError, "the surface crosses " +
            std::to_string(straddling2.size()) + " nodes of 4096^3 voxels at voxel size " +
            util::formatNumber(ctx.dx) + ", too many to visit: use a larger voxel size or "
            "smaller bounds");
    }
    if (checkMemory) checkSparseMemory(ctx, straddling2);
    std::vector<Task> tasks;
    for (const Task& t2 : straddling2) {
        forEachCube(clipped(t2.origin, d2, ctx.region), d1,
                    [&](const Coord& o) { tasks.push_back({o, t2.node}); });
    }
    util::checkInterrupt(ctx.interrupter, 0);
    return tasks;
}

/// Sparse path: interval descent over OpenVDB's node sizes (4096, 128, 8 voxels), with 32^3
/// blocks between the last two.
openvdb::FloatGrid::Ptr sampleSparse(const Context& ctx, Counts& counts)
{
    const float bg = static_cast<float>(ctx.band);
    auto grid = openvdb::FloatGrid::create(bg);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(ctx.dx));

    std::vector<Coord> insideLevel2;
    const std::vector<Task> tasks = level1Tasks(ctx, insideLevel2, true);

    // Level 1 (128^3) in parallel: each task builds a whole internal node of leaves.
    std::vector<Level1Result> results(tasks.size());
    std::atomic<size_t> done{0};
    std::atomic<bool> cancelled{false};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, tasks.size(), 1),
        [&](const tbb::blocked_range<size_t>& r) {
        for (size_t t = r.begin(); t != r.end(); ++t) {
            if (cancelled) return;
            results[t] = buildLevel1(ctx, tasks[t], BuildLeaves{ctx, counts});
            const size_t n = ++done;
            if (util::wasInterrupted(ctx.interrupter, int(100 * n / tasks.size()))) cancelled = true;
        }
    });
    if (cancelled) {
        for (auto& r : results) delete r.node;
        util::throwInterrupted();
    }
    assembleTree(grid->tree(), results, insideLevel2, bg);
    return grid;
}

/// The dense path's samples: every voxel of the region, in x-major order.
class DenseSamples
{
public:
    explicit DenseSamples(const CoordBBox& region)
        : mMin(region.min()), mNy(std::uint64_t(region.dim().y())), mNz(std::uint64_t(region.dim().z()))
    {
        const std::uint64_t nx = std::uint64_t(region.dim().x());
        // The caller checked the estimate against memory. Not zero-filled: sample() writes
        // every value, so the pages are first touched there, in parallel and interruptibly
        // (a serial fill of 2 GB took seconds and ignored Ctrl-C).
        mData.reset(new float[nx * mNy * mNz]);
    }

    float at(int i, int j, int k) const
    {
        return mData[(std::uint64_t(i - mMin.x()) * mNy + std::uint64_t(j - mMin.y())) * mNz +
                     std::uint64_t(k - mMin.z())];
    }

    /// Evaluate the shape at every voxel, rows of z in batches, in parallel.
    void sample(const Context& ctx)
    {
        const std::uint64_t rowsTotal = std::uint64_t(ctx.region.dim().x()) * mNy;
        std::atomic<bool> cancelled{false};
        std::atomic<std::uint64_t> rows{0};
        tbb::parallel_for(tbb::blocked_range<std::uint64_t>(0, rowsTotal, 16),
            [&](const tbb::blocked_range<std::uint64_t>& r) {
            if (cancelled) return;
            alignas(64) double x[implicit::kMaxBatch], y[implicit::kMaxBatch],
                z[implicit::kMaxBatch], v[implicit::kMaxBatch];
            for (std::uint64_t row = r.begin(); row != r.end(); ++row) {
                const int i = mMin.x() + int(row / mNy), j = mMin.y() + int(row % mNy);
                float* out = mData.get() + row * mNz;
                for (std::uint64_t k0 = 0; k0 < mNz; k0 += implicit::kMaxBatch) {
                    const std::size_t n = std::size_t(std::min<std::uint64_t>(implicit::kMaxBatch, mNz - k0));
                    for (std::size_t m = 0; m < n; ++m) {
                        x[m] = double(i) * ctx.dx;
                        y[m] = double(j) * ctx.dx;
                        z[m] = double(mMin.z() + int(k0 + m)) * ctx.dx;
                    }
                    ctx.shape->values(x, y, z, v, n);
                    for (std::size_t m = 0; m < n; ++m) out[k0 + m] = static_cast<float>(v[m]);
                }
            }
            const std::uint64_t done = rows += r.size();
            if (util::wasInterrupted(ctx.interrupter, int(90 * done / rowsTotal))) cancelled = true;
        });
        if (cancelled) util::throwInterrupted();
    }

    void release() { mData.reset(); }

private:
    Coord mMin;
    std::uint64_t mNy, mNz;
    std::unique_ptr<float[]> mData;
};

/// The leaf-sized blocks of the dense region, x-major.
struct BlockGrid
{
    Coord min, count;

    explicit BlockGrid(const CoordBBox& reg)
    {
        const int d0 = LeafT::DIM;
        min = Coord(alignDown(reg.min().x(), d0), alignDown(reg.min().y(), d0),
                    alignDown(reg.min().z(), d0));
        count = Coord((reg.max().x() - min.x()) / d0 + 1, (reg.max().y() - min.y()) / d0 + 1,
                      (reg.max().z() - min.z()) / d0 + 1);
    }
    std::size_t size() const { return std::size_t(count.x()) * count.y() * count.z(); }
    std::size_t index(int bi, int bj, int bk) const
    {
        return (std::size_t(bi) * count.y() + bj) * count.z() + bk;
    }
    Coord origin(std::size_t b) const
    {
        const int d0 = LeafT::DIM;
        const int bi = int(b / (std::size_t(count.y()) * count.z()));
        const int bj = int((b / count.z()) % count.y());
        const int bk = int(b % count.z());
        return Coord(min.x() + bi * d0, min.y() + bj * d0, min.z() + bk * d0);
    }
};

/// Which leaf-sized blocks the result needs: exact shapes, those with a band voxel; others,
/// those with a sign change to a face neighbour, grown by the re-distancing's reach.
std::vector<std::uint8_t> neededBlocks(const Context& ctx, const DenseSamples& samples,
                                       const BlockGrid& blocks)
{
    const CoordBBox& reg = ctx.region;
    const int d0 = LeafT::DIM;
    auto inRegion = [&](int i, int j, int k) { return reg.isInside(Coord(i, j, k)); };
    std::vector<std::uint8_t> needed(blocks.size(), 0);
    tbb::parallel_for(tbb::blocked_range<int>(0, blocks.count.x()), [&](const tbb::blocked_range<int>& r) {
        for (int bi = r.begin(); bi != r.end(); ++bi)
        for (int bj = 0; bj < blocks.count.y(); ++bj)
        for (int bk = 0; bk < blocks.count.z(); ++bk) {
            bool need = false;
            for (int i = 0; i < d0 && !need; ++i)
            for (int j = 0; j < d0 && !need; ++j)
            for (int k = 0; k < d0 && !need; ++k) {
                const int x = blocks.min.x() + bi * d0 + i, y = blocks.min.y() + bj * d0 + j,
                          z = blocks.min.z() + bk * d0 + k;
                if (!inRegion(x, y, z)) continue;
                const float v = samples.at(x, y, z);
                if (ctx.exact) {
                    need = ctx.inBand(v);
                    continue;
                }
                // A sign change to a face neighbour marks an interface voxel.
                const bool s = v > 0.0f;
                auto differs = [&](int a, int b, int c) {
                    return inRegion(a, b, c) && (samples.at(a, b, c) > 0.0f) != s;
                };
                need = differs(x + 1, y, z) || differs(x - 1, y, z) || differs(x, y + 1, z) ||
                       differs(x, y - 1, z) || differs(x, y, z + 1) || differs(x, y, z - 1);
            }
            needed[blocks.index(bi, bj, bk)] = need ? 1 : 0;
        }
    });
    if (ctx.exact) return needed;
    // Every voxel within reachSteps (+1) of the interface can be in the band.
    const int nb = (ctx.reachSteps + 1 + d0 - 1) / d0;
    std::vector<std::uint8_t> grown(blocks.size(), 0);
    for (int bi = 0; bi < blocks.count.x(); ++bi)
    for (int bj = 0; bj < blocks.count.y(); ++bj)
    for (int bk = 0; bk < blocks.count.z(); ++bk) {
        if (!needed[blocks.index(bi, bj, bk)]) continue;
        for (int a = std::max(0, bi - nb); a <= std::min(blocks.count.x() - 1, bi + nb); ++a)
        for (int b = std::max(0, bj - nb); b <= std::min(blocks.count.y() - 1, bj + nb); ++b)
        for (int c = std::max(0, bk - nb); c <= std::min(blocks.count.z() - 1, bk + nb); ++c)
            grown[blocks.index(a, b, c)] = 1;
    }
    return grown;
}

/// The shape as the sparse descent sees it at the leaf at @a o: pruned in turn to the dilated
/// boxes of its 4096^3 node, 128^3 node, 32^3 block and the leaf itself. True distances depend
/// on the node's children (not only on its values), so the dense path takes the same nodes.
Implicit::Ptr prunedForLeaf(const Context& ctx, const Coord& o)
{
    Implicit::Ptr node = ctx.shape;
    for (int dim : {int(Int2T::DIM), int(Int1T::DIM), kBlock, int(LeafT::DIM)}) {
        const Coord a(alignDown(o.x(), dim), alignDown(o.y(), dim), alignDown(o.z(), dim));
        node = node->prune(ctx.dilatedWorldBox(CoordBBox::createCube(a, dim)));
    }
    return node;
}

/// A dense-path leaf at @a o: for an exact SDF from the samples (or the shape, beyond the
/// region) by the same band rule as buildLeaf(); otherwise buildLeaf() itself, on the same node.
LeafT* denseLeaf(const Context& ctx, const DenseSamples& samples, const Coord& o, Counts& counts)
{
    if (!ctx.exact) {
        bool inside = false;
        return buildLeaf(ctx, *prunedForLeaf(ctx, o), o, inside, &counts);
    }
    const float bg = static_cast<float>(ctx.band);
    const int d0 = LeafT::DIM;
    auto leaf = new LeafT(o, bg);
    float* buf = leaf->buffer().data();
    for (int i = 0, n = 0; i < d0; ++i)
    for (int j = 0; j < d0; ++j)
    for (int k = 0; k < d0; ++k, ++n) {
        const int x = o.x() + i, y = o.y() + j, z = o.z() + k;
        const Vec3d p(double(x) * ctx.dx, double(y) * ctx.dx, double(z) * ctx.dx);
        const float v = ctx.region.isInside(Coord(x, y, z))
                            ? samples.at(x, y, z) : static_cast<float>(ctx.shape->value(p));
        if (ctx.inBand(v)) {
            buf[n] = v;
            leaf->setValueOn(n);
        } else {
            buf[n] = v > 0.0f ? bg : -bg;
        }
    }
    return leaf;
}

/// Dense path: sample every voxel of the region into an array, then build the same grid.
openvdb::FloatGrid::Ptr sampleDense(const Context& ctx, Counts& counts)
{
    DenseSamples samples(ctx.region);
    samples.sample(ctx);
    const BlockGrid blocks(ctx.region);
    const std::vector<std::uint8_t> needed = neededBlocks(ctx, samples, blocks);
    std::vector<LeafT*> leaves(blocks.size(), nullptr);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks.size()),
                      [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t b = r.begin(); b != r.end(); ++b) {
            if (needed[b]) leaves[b] = denseLeaf(ctx, samples, blocks.origin(b), counts);
        }
    });
    samples.release();

    const float bg = static_cast<float>(ctx.band);
    auto grid = openvdb::FloatGrid::create(bg);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(ctx.dx));
    openvdb::tree::ValueAccessor<FloatTree> acc(grid->tree());
    for (LeafT* leaf : leaves) {
        if (leaf) acc.addLeaf(leaf);
    }
    // Inside tiles: the dense path has no intervals, so the sign spreads from the band.
    openvdb::tools::signedFloodFill(grid->tree());
    return grid;
}

/// The last resort, for voxels no local method answered (a band wider than the lattice window,
/// and the surface beyond the window: deep inside near a medial axis, typically): the old way,
/// fast sweeping from first-order estimates f / |grad f| (levelset::redistance), but only over
/// those voxels grown by the band, so it costs what they need. Sets the voxels @a targets
/// (those of @a unknown that @a tree holds) in @a tree.
void sweepUnknown(const Context& ctx, FloatTree& tree, const std::vector<Coord>& unknown,
                  const std::vector<Coord>& targets)
{
    openvdb::MaskTree region;
    for (const Coord& c : unknown) region.setValueOn(c);
    openvdb::tools::dilateActiveValues(region, ctx.reachSteps + 2,
                                       openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::IGNORE_TILES);
    auto samples = openvdb::FloatGrid::create(static_cast<float>(ctx.band));
    samples->setTransform(openvdb::math::Transform::createLinearTransform(ctx.dx));
    samples->tree().topologyUnion(region);
    openvdb::tree::LeafManager<FloatTree> leaves(samples->tree());
    const double limit = 4.0 * ctx.reach;
    leaves.foreach([&](LeafT& leaf, size_t) {
        alignas(64) double x[512], y[512], z[512], v[512], gx[512], gy[512], gz[512];
        leafPoints(leaf.origin(), ctx.dx, x, y, z);
        ctx.shape->values(x, y, z, v, 512);
        ctx.shape->gradients(x, y, z, gx, gy, gz, 512);
        for (auto it = leaf.beginValueOn(); it; ++it) {
            const int n = int(it.pos());
            const double g = std::sqrt(gx[n] * gx[n] + gy[n] * gy[n] + gz[n] * gz[n]);
            double e = g > 0.0 && std::isfinite(g) ? v[n] / g : (v[n] > 0.0 ? limit : -limit);
            e = std::max(-limit, std::min(limit, e));
            it.setValue(static_cast<float>(e));
        }
    });
    const openvdb::FloatGrid::Ptr swept =
        levelset::redistance(*samples, ctx.band / ctx.dx, ctx.interrupter);
    openvdb::tree::ValueAccessor<FloatTree> out(tree);
    openvdb::tree::ValueAccessor<const FloatTree> in(swept->tree()), est(samples->tree());
    const float bg = static_cast<float>(ctx.band);
    for (const Coord& c : targets) {
        float v;
        if (in.probeValue(c, v) && ctx.inBand(v)) {
            out.setValueOn(c, v);
        } else {
            out.setValueOff(c, est.getValue(c) > 0.0f ? bg : -bg);
        }
    }
}

} // namespace

Implicit::Ptr clipToBounds(const Implicit::Ptr& shape, const RasterSettings& settings)
{
    if (!settings.bounds) return shape;
    const BBoxd& b = *settings.bounds;
    if (shape->isBounded()) {
        // A shape well inside the bounds is unchanged within its band: keep it (and its
        // exactness) as it is.
        const double margin = (settings.halfWidth + 2.0) * settings.voxelSize;
        const BBoxd s = shape->boundingBox();
        bool inside = true;
        for (int i = 0; i < 3; ++i) {
            inside = inside && s.min()[i] - margin > b.min()[i] && s.max()[i] + margin < b.max()[i];
        }
        if (inside) return shape;
    }
    auto box = std::make_shared<implicit::Box>(b.getCenter(), b.max() - b.min());
    return std::make_shared<implicit::Csg>(implicit::Csg::Op::Intersection,
                                           std::vector<Implicit::Ptr>{shape, box});
}

namespace {

Context makeContext(const Implicit::Ptr& shape, const RasterSettings& s)
{
    if (!shape) OPENVDB_THROW(openvdb::ValueError, "no shape to rasterize");
    check(limits::kVoxelSize, s.voxelSize);
    // OpenVDB's linear transforms refuse a scale whose determinant is below 3e-15.
    if (s.voxelSize * s.voxelSize * s.voxelSize < 3.0 * openvdb::math::Tolerance<double>::value()) {
        throw ParamError(param::kVoxelSize, util::formatNumber(s.voxelSize) + " is below "
            "1.45e-05, the smallest OpenVDB's transforms accept: scale the scene up (a "
            "\"transform\" with \"scale\") and use a larger voxel size");
    }
    check(limits::kHalfWidth, s.halfWidth);
    Context ctx;
    ctx.shape = clipToBounds(shape, s);
    if (!ctx.shape->isBounded()) {
        OPENVDB_THROW(openvdb::ValueError,
            "the shape is unbounded (a plane, cylinder, cone, paraboloid, hyperboloid or an "
            "unbounded quadric or CSG result): add \"bounds\" {\"min\": [...], \"max\": [...]} "
            "to the scene to clip it to a box");
    }
    if (s.distance == Distance::Exact) {
        // The same surface and sign where another shape finds its distances more directly (a
        // scaled sphere's world quadric, a scaled box's moved box): the grid holds distances,
        // the same either way.
        // (Not where that shape's box is unbounded: a quadric's box test can fail for a scale
        // of many orders of magnitude, where the transform's box is the child's mapped.)
        const Implicit::Ptr same = ctx.shape->sameSurface();
        if (same && same->isBounded()) ctx.shape = same;
    }
    ctx.dx = s.voxelSize;
    ctx.band = s.halfWidth * s.voxelSize;
    ctx.exact = ctx.shape->isExactSdf();
    if (s.distance == Distance::Bound && !ctx.exact) {
        if (!ctx.shape->isDistanceBound()) {
            OPENVDB_THROW(openvdb::ValueError,
                "\"distance\": \"bound\" needs a shape whose value never exceeds its distance "
                "(exact distances, and their CSG, blends, smooth CSG, offsets, shells and "
                "transforms); this shape has a quadric (an ellipsoid, cylinder, cone, paraboloid, "
                "hyperboloid or a raw quadric), whose value is not such a bound: remove "
                "\"distance\" to re-distance it");
        }
        ctx.exact = true; // the stored value is f itself
    }
    ctx.boundedByDistance = !ctx.exact && ctx.shape->isDistanceBound();
    ctx.lipschitz = ctx.boundedByDistance ? ctx.shape->lipschitzBound() : 1.0;
    ctx.interrupter = s.interrupter;
    ctx.memoryLimit = s.memoryLimit;
    if (ctx.exact) {
        ctx.reach = ctx.band;
    } else {
        // A voxel v at distance d < halfWidth from its closest surface point s is within
        // Chebyshev distance d of s, and s lies in a lattice cube whose corners (Chebyshev
        // distance <= 1 from s) include a voxel next to a sign change: so v is within
        // ceil(halfWidth) steps of that voxel (the dense path's block rule).
        ctx.reachSteps = int(std::ceil(s.halfWidth));
        // The lattice search looks one voxel beyond the band; the pruned node must hold there.
        ctx.distances.dx = ctx.dx;
        ctx.distances.searchRadius = std::min(ctx.reachSteps + 1, kMaxSearchRadius);
        ctx.distances.band = ctx.band;
        ctx.distances.far = ctx.band + ctx.dx;
        ctx.distances.tolerance = kDistanceTolerance * ctx.dx;
        // The band's straddle test and the pruned nodes must cover the search's window (an
        // axis-aligned cube of searchRadius voxels around each voxel of the box).
        ctx.reach = std::max(ctx.band, ctx.distances.searchRadius * ctx.dx) + 0.25 * ctx.dx;
    }
    const BBoxd b = ctx.shape->boundingBox();
    const double maxIndex = double(1 << 30);
    Coord lo, hi;
    for (int i = 0; i < 3; ++i) {
        const double l = std::floor((b.min()[i] - ctx.reach) / ctx.dx) - 1.0;
        const double h = std::ceil((b.max()[i] + ctx.reach) / ctx.dx) + 1.0;
        if (!(std::abs(l) < maxIndex && std::abs(h) < maxIndex)) {
            std::ostringstream os;
            os << "the shape spans too many voxels (" << (h - l) << " along " << "xyz"[i]
               << "): use a larger voxel size or smaller bounds";
            OPENVDB_THROW(openvdb::ValueError, os.str());
        }
        lo[i] = int(l);
        hi[i] = int(h);
    }
    ctx.region = CoordBBox(lo, hi);
    // The sparse descent visits every 4096^3 node of the region: bound that count (a surface
    // across such a region could not fit in memory anyway).
    double nodes = 1.0;
    for (int i = 0; i < 3; ++i) nodes *= std::ceil(double(hi[i] - lo[i] + 1) / Int2T::DIM);
    if (nodes > 1e7) {
        std::ostringstream os;
        os << "the shape spans " << (hi[0] - lo[0] + 1) << " x " << (hi[1] - lo[1] + 1) << " x "
           << (hi[2] - lo[2] + 1) << " voxels at voxel size " << util::formatNumber(s.voxelSize)
           << ", far more than a narrow band in memory can cover: use a larger voxel size or "
              "smaller bounds";
        OPENVDB_THROW(openvdb::ValueError, os.str());
    }
    return ctx;
}

} // namespace

std::uint64_t denseMemoryEstimate(const Implicit::Ptr& shape, const RasterSettings& settings)
{
    const Context ctx = makeContext(shape, settings);
    const Coord d = ctx.region.dim();
    const double bytes = double(d.x()) * double(d.y()) * double(d.z()) * sizeof(float);
    return bytes >= 1.8e19 ? std::numeric_limits<std::uint64_t>::max() : std::uint64_t(bytes);
}

bool isOwnRaster(const Implicit::Ptr& shape, const RasterSettings& settings)
{
    const auto* g = dynamic_cast<const implicit::GridShape*>(shape.get());
    return g && settings.sampling == Sampling::Sparse && !settings.bounds &&
           g->grid().voxelSize()[0] == settings.voxelSize &&
           std::abs(g->bandWidth() - settings.halfWidth * settings.voxelSize) <=
               1e-6 * settings.voxelSize;
}

openvdb::FloatGrid::Ptr rasterize(const Implicit::Ptr& shape, const RasterSettings& settings)
{
    const Context ctx = makeContext(shape, settings);

    // A mesh or .vdb level set already on this lattice with this band is its own raster.
    if (isOwnRaster(shape, settings)) {
        const auto* g = static_cast<const implicit::GridShape*>(shape.get());
        openvdb::FloatGrid::Ptr grid = g->grid().deepCopy();
        grid->setGridClass(openvdb::GRID_LEVEL_SET);
        grid->setName("surface");
        if (settings.stats) *settings.stats = RasterStats();
        return grid;
    }

    if (settings.sampling == Sampling::Dense) {
        const Coord d = ctx.region.dim();
        // In double: the product of three dimensions of up to 2^31 voxels overflows 64 bits.
        const double need = double(d.x()) * double(d.y()) * double(d.z()) * sizeof(float);
        const double limit = util::memoryBudget(settings.memoryLimit);
        if (need > limit) {
            std::ostringstream os;
            os << "dense sampling of " << d.x() << " x " << d.y() << " x " << d.z()
               << " voxels needs about " << util::formatBytes(need) << " but only "
               << util::formatBytes(limit)
               << " may be used: use sparse sampling, a larger voxel size or smaller bounds";
            OPENVDB_THROW(openvdb::RuntimeError, os.str());
        }
    }

    Counts counts;
    auto run = [&]() {
        util::InterruptScope scope(ctx.interrupter, "Rasterizing");
        openvdb::FloatGrid::Ptr grid = settings.sampling == Sampling::Dense
                                           ? sampleDense(ctx, counts)
                                           : sampleSparse(ctx, counts);
        if (!ctx.exact && !counts.anyInside) {
            // Zeros but no inside (the point x^2 + y^2 + z^2 = 0, the double plane x^2 = 0): a
            // zero set without area is no surface.
            grid->clear();
            counts.unknown.clear();
        }
        if (!counts.unknown.empty()) {
            // In a fixed order, so that both paths and every run sweep the same way.
            std::vector<Coord> unknown(counts.unknown.begin(), counts.unknown.end());
            std::sort(unknown.begin(), unknown.end());
            sweepUnknown(ctx, grid->tree(), unknown, unknown);
        }
        openvdb::tools::pruneLevelSet(grid->tree());
        scope.end();
        return grid;
    };
    openvdb::FloatGrid::Ptr grid;
    if (settings.threaded) {
        grid = run();
    } else {
        tbb::task_arena serial(1);
        grid = serial.execute(run);
    }
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    grid->setName("surface");
    if (settings.stats) counts.report(*settings.stats);
    return grid;
}

namespace {

/// The leaves the band may cross in one 128^3 node, by the descent's interval tests alone (no
/// voxel is evaluated), in file order: by offset in the node, which is x, then y, then z.
std::vector<Coord> straddlingLeaves(const Context& ctx, const Task& task)
{
    std::vector<Coord> out;
    const int d0 = LeafT::DIM;
    descendLevel1(ctx, task, [&](const CoordBBox& part, const Implicit* node) {
        if (!node) return; // an inside block: tiles, no leaves
        forEachCube(part, d0, [&](const Coord& l) {
            if (ctx.classify(*node, CoordBBox::createCube(l, d0)) == Verdict::Straddle) out.push_back(l);
        });
    });
    std::sort(out.begin(), out.end()); // Coord's order is lexicographic: x, then y, then z
    return out;
}

/// The straddling leaves of every 128^3 node in file order, with prefix counts to find the
/// leaf of a given index.
struct LeafIndex
{
    std::vector<Task> tasks;
    std::vector<std::vector<Coord>> leaves;  // per task
    std::vector<std::uint64_t> start;        // index of each task's first leaf; then the total
    std::vector<std::uint64_t> nodesBefore;  // tasks with leaves before each task
    std::vector<std::uint64_t> level2Of;     // each task's 4096^3 node, counted in file order

    std::vector<Coord> insideLevel2;         // 4096^3 nodes wholly inside (root tiles)

    explicit LeafIndex(const Context& ctx)
    {
        tasks = level1Tasks(ctx, insideLevel2, false);
        leaves.resize(tasks.size());
        tbb::parallel_for(tbb::blocked_range<size_t>(0, tasks.size(), 1),
                          [&](const tbb::blocked_range<size_t>& r) {
            for (size_t t = r.begin(); t != r.end(); ++t) leaves[t] = straddlingLeaves(ctx, tasks[t]);
        });
        start.assign(tasks.size() + 1, 0);
        nodesBefore.assign(tasks.size() + 1, 0);
        level2Of.assign(tasks.size(), 0);
        const int d2 = Int2T::DIM;
        auto parent = [](const Coord& o) {
            return Coord(alignDown(o.x(), d2), alignDown(o.y(), d2), alignDown(o.z(), d2));
        };
        for (size_t t = 0; t < tasks.size(); ++t) {
            start[t + 1] = start[t] + leaves[t].size();
            nodesBefore[t + 1] = nodesBefore[t] + (leaves[t].empty() ? 0 : 1);
            if (t > 0) {
                level2Of[t] = level2Of[t - 1] +
                              (parent(tasks[t].origin) == parent(tasks[t - 1].origin) ? 0 : 1);
            }
        }
    }

    std::uint64_t count() const { return start.back(); }

    /// The task holding leaf @a i.
    size_t taskOf(std::uint64_t i) const
    {
        return size_t(std::upper_bound(start.begin(), start.end(), i) - start.begin()) - 1;
    }

    const Coord& leaf(std::uint64_t i) const
    {
        const size_t t = taskOf(i);
        return leaves[t][i - start[t]];
    }

    /// The index of the leaf at @a o of task @a t, which the descent found straddling.
    std::uint64_t indexOf(size_t t, const Coord& o) const
    {
        const auto& l = leaves[t];
        const auto it = std::lower_bound(l.begin(), l.end(), o);
        if (it == l.end() || *it != o) {
            OPENVDB_THROW(openvdb::RuntimeError, "internal error: a leaf the descent found "
                          "straddling is not in the partition's index");
        }
        return start[t] + std::uint64_t(it - l.begin());
    }
};

/// Bytes of the grid's nodes for @a leaves leaves under @a level1 128^3 and @a level2 4096^3
/// nodes: each leaf's values and masks, each internal node's table.
double gridBytes(double leaves, double level1, double level2)
{
    return leaves * double(sizeof(LeafT) + LeafT::SIZE * sizeof(float)) +
           level1 * double(sizeof(Int1T)) + level2 * double(sizeof(Int2T));
}

} // namespace

Partition partition(const Implicit::Ptr& shape, const RasterSettings& settings, int ranks,
                    int sampleLeaves)
{
    check(limits::kRanks, double(ranks));
    const Context ctx = makeContext(shape, settings);
    const LeafIndex index(ctx);
    Partition out;
    out.leaves = index.count();
    const std::uint64_t n = out.leaves;

    // Leaves evenly spread in file order, built as the rasterizer builds them, on this thread.
    const std::uint64_t samples = std::min<std::uint64_t>(n, std::uint64_t(std::max(sampleLeaves, 1)));
    double active = 0.0, seconds = 0.0, built = 0.0;
    std::uint64_t jitter = 0x9E3779B97F4A7C15ull; // a fixed sequence: the same plan every run
    for (std::uint64_t s = 0; s < samples; ++s) {
        // One leaf at a pseudo-random place in each of `samples` equal stretches: evenly spread,
        // without lining up with the nodes' own periods.
        jitter = jitter * 6364136223846793005ull + 1442695040888963407ull;
        const double u = double(jitter >> 11) * 0x1.0p-53;
        const std::uint64_t i = std::min<std::uint64_t>(n - 1, std::uint64_t((double(s) + u) *
                                                                            double(n) / double(samples)));
        const Coord& o = index.leaf(i);
        const auto begin = std::chrono::steady_clock::now();
        const Implicit::Ptr node =
            index.tasks[index.taskOf(i)].node->prune(ctx.dilatedWorldBox(CoordBBox::createCube(o, LeafT::DIM)));
        Counts counts;
        bool inside = false;
        std::unique_ptr<LeafT> leaf(buildLeaf(ctx, *node, o, inside, &counts));
        seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
        if (leaf) active += double(leaf->onVoxelCount()), built += 1.0;
    }
    out.sampledLeaves = samples;
    const double activePerLeaf = samples ? active / double(samples) : 0.0;
    const double secondsPerLeaf = samples ? seconds / double(samples) : 0.0;
    // Not every leaf the band may cross holds a band voxel (most do for exact distances; the
    // test for the others reaches a voxel further): the grid keeps the sampled share.
    const double kept = samples ? built / double(samples) : 0.0;
    out.gridLeaves = kept * double(n);
    out.activeVoxels = activePerLeaf * double(n);
    out.cpuSeconds = secondsPerLeaf * double(n);
    out.memoryBytes = gridBytes(kept * double(n), double(index.nodesBefore.back()),
                                n ? double(index.level2Of.back() + 1) : 0.0);

    // Contiguous runs of floor(n / ranks) or one more leaves.
    out.ranks.resize(size_t(ranks));
    std::uint64_t most = 0;
    for (int r = 0; r < ranks; ++r) {
        RankShare& share = out.ranks[size_t(r)];
        const std::uint64_t a = n * std::uint64_t(r) / std::uint64_t(ranks);
        const std::uint64_t b = n * std::uint64_t(r + 1) / std::uint64_t(ranks);
        share.firstLeaf = a;
        share.leaves = b - a;
        most = std::max(most, share.leaves);
        if (share.leaves == 0) continue;
        const size_t ta = index.taskOf(a), tb = index.taskOf(b - 1);
        share.first = index.leaf(a);
        share.last = index.leaf(b - 1);
        share.activeVoxels = activePerLeaf * double(share.leaves);
        share.cpuSeconds = secondsPerLeaf * double(share.leaves);
        share.memoryBytes = gridBytes(kept * double(share.leaves),
                                      double(index.nodesBefore[tb + 1] - index.nodesBefore[ta]),
                                      double(index.level2Of[tb] - index.level2Of[ta] + 1));
    }
    out.balance = n ? double(most) / (double(n) / double(ranks)) : 1.0;
    return out;
}

struct RasterRuns::Impl
{
    Context ctx;
    LeafIndex index;

    explicit Impl(const Context& c): ctx(c), index(ctx) {}
};

RasterRuns::RasterRuns(const Implicit::Ptr& shape, const RasterSettings& settings)
{
    if (settings.sampling != Sampling::Sparse) {
        OPENVDB_THROW(openvdb::ValueError, "a rasterization in runs of leaves samples sparsely");
    }
    if (isOwnRaster(shape, settings)) {
        OPENVDB_THROW(openvdb::ValueError, "the shape is a level set on the output's lattice, "
                      "its own raster: there is nothing to split (rasterize copies it)");
    }
    mImpl = std::make_unique<Impl>(makeContext(shape, settings));
}

RasterRuns::~RasterRuns() = default;

std::uint64_t RasterRuns::leaves() const { return mImpl->index.count(); }

RunResult RasterRuns::build(std::uint64_t first, std::uint64_t count) const
{
    const Context& ctx = mImpl->ctx;
    const LeafIndex& index = mImpl->index;
    if (first > index.count() || count > index.count() - first) {
        OPENVDB_THROW(openvdb::ValueError, "leaves " + std::to_string(first) + " to " +
                      std::to_string(first + count) + " are beyond the " +
                      std::to_string(index.count()) + " leaves the band may cross");
    }
    const float bg = static_cast<float>(ctx.band);
    RunResult out;
    out.leaves = std::make_shared<FloatTree>(bg);
    out.fates.assign(count, LeafFate::Outside);
    if (count == 0) return out;
    const std::uint64_t end = first + count;
    const size_t ta = index.taskOf(first), tb = index.taskOf(end - 1);
    std::vector<std::vector<LeafT*>> built(tb - ta + 1);
    Counts counts;
    std::atomic<size_t> done{0};
    std::atomic<bool> cancelled{false};
    util::InterruptScope scope(ctx.interrupter, "Rasterizing");
    tbb::parallel_for(tbb::blocked_range<size_t>(ta, tb + 1, 1),
                      [&](const tbb::blocked_range<size_t>& r) {
        for (size_t t = r.begin(); t != r.end(); ++t) {
            if (cancelled) return;
            // The descent of rasterize(), building only the run's leaves.
            descendLevel1(ctx, index.tasks[t], [&](const CoordBBox& part, const Implicit* node) {
                if (!node) return;
                forEachCube(part, LeafT::DIM, [&](const Coord& o) {
                    const CoordBBox box0 = CoordBBox::createCube(o, LeafT::DIM);
                    if (ctx.classify(*node, box0) != Verdict::Straddle) return;
                    const std::uint64_t i = index.indexOf(t, o);
                    if (i < first || i >= end) return;
                    bool inside = false;
                    LeafT* leaf = BuildLeaves{ctx, counts}.build(o, box0, *node, inside);
                    out.fates[i - first] = leaf ? LeafFate::Leaf
                                                : inside ? LeafFate::Inside : LeafFate::Outside;
                    if (leaf) built[t - ta].push_back(leaf);
                });
            });
            const size_t n = ++done;
            if (util::wasInterrupted(ctx.interrupter, int(100 * n / (tb - ta + 1)))) cancelled = true;
        }
    });
    openvdb::tree::ValueAccessor<FloatTree> acc(*out.leaves);
    for (auto& leaves : built) {
        for (LeafT* leaf : leaves) acc.addLeaf(leaf);
    }
    if (cancelled) util::throwInterrupted();
    scope.end();
    counts.report(out.stats);
    out.unknown.assign(counts.unknown.begin(), counts.unknown.end());
    std::sort(out.unknown.begin(), out.unknown.end());
    out.anyInside = counts.anyInside;
    return out;
}

void RasterRuns::sweep(RunResult& run, const std::vector<Coord>& unknown) const
{
    const Context& ctx = mImpl->ctx;
    if (unknown.empty()) return;
    sweepUnknown(ctx, *run.leaves, unknown, run.unknown);
    // rasterize() prunes the whole grid next: a leaf left without an active voxel becomes a tile,
    // inside or outside by its first value. The run's leaves are its fates' Leaf entries, in
    // order.
    std::vector<std::size_t> slots;
    for (std::size_t i = 0; i < run.fates.size(); ++i) {
        if (run.fates[i] == LeafFate::Leaf) slots.push_back(i);
    }
    std::vector<Coord> emptied;
    std::size_t k = 0;
    for (auto it = run.leaves->cbeginLeaf(); it; ++it, ++k) {
        if (!it->isEmpty()) continue;
        if (k >= slots.size()) OPENVDB_THROW(openvdb::ValueError, "a run with more leaves than fates");
        run.fates[slots[k]] = it->getFirstValue() < 0.0f ? LeafFate::Inside : LeafFate::Outside;
        emptied.push_back(it->origin());
    }
    for (const Coord& o : emptied) {
        delete run.leaves->root().stealNode<LeafT>(o, run.leaves->background(), false);
    }
}

openvdb::FloatGrid::Ptr RasterRuns::skeleton(const std::vector<LeafFate>& fates, bool anyInside) const
{
    const Context& ctx = mImpl->ctx;
    const LeafIndex& index = mImpl->index;
    if (fates.size() != index.count()) {
        OPENVDB_THROW(openvdb::ValueError, std::to_string(fates.size()) + " leaf fates for " +
                      std::to_string(index.count()) + " leaves");
    }
    const float bg = static_cast<float>(ctx.band);
    auto grid = openvdb::FloatGrid::create(bg);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(ctx.dx));
    // sampleSparse's descent, each leaf settled by its fate: a leaf becomes an active tile.
    std::vector<Level1Result> results(index.tasks.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, index.tasks.size(), 1),
                      [&](const tbb::blocked_range<size_t>& r) {
        for (size_t t = r.begin(); t != r.end(); ++t) {
            results[t] = buildLevel1(ctx, index.tasks[t],
                [&](const Coord& o, const CoordBBox&, const Implicit&, Int1T& int1, bool& inside) {
                    const LeafFate fate = fates[index.indexOf(t, o)];
                    if (fate == LeafFate::Leaf) int1.addTile(int1.coordToOffset(o), 0.0f, true);
                    inside = fate == LeafFate::Inside;
                    return fate == LeafFate::Leaf;
                });
        }
    });
    assembleTree(grid->tree(), results, index.insideLevel2, bg);
    if (!ctx.exact && !anyInside) grid->clear();
    // As rasterize() prunes: a node without leaves (active tiles here) becomes a tile.
    openvdb::tools::pruneLevelSet(grid->tree());
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    grid->setName("surface");
    return grid;
}

} // namespace ivdb::raster
