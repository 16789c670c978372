// SPDX-License-Identifier: Apache-2.0
#include <ivdb/ops/Blend.h>

#include <ivdb/diff/Differential.h>
#include <ivdb/implicit/Blend.h>
#include <ivdb/levelset/Dilate.h>
#include <ivdb/levelset/Redistance.h>
#include <ivdb/util/Interrupt.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include "../levelset/Sweeping.h"
#include "ActiveWithin.h"
#include "BlendDistance.h"
#include "LeafSet.h"

#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tree/LeafManager.h>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <numeric>
#include <optional>
#include <cmath>
#include <sstream>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace ivdb::ops {

namespace {

using FloatTree = openvdb::FloatTree;
using LeafT = FloatTree::LeafNodeType;
using MaskTree = openvdb::MaskTree;
using levelset::SmallMaskTree;
using openvdb::Coord;

constexpr int kLeafLog2 = LeafT::LOG2DIM;
constexpr int kLeafDim = LeafT::DIM;

// Leaf nodes as the voxels of a coarse mask: voxel v stands for the leaf at origin v * 8. The
// blend's regions are decided on this mask, which is 512 times smaller than the band. Read from
// the child masks of the nodes above the leaves (16^3 children each, bit (x << 8) | (y << 4) | z),
// eight rows of eight bits at a time, instead of a voxel set per leaf. On a SmallMaskTree: a
// MaskTree clears a 256 KB table for each top node, eight of them for masks around the origin,
// and grew the coarse mask of one sphere of the radius-400 pair about twice as slowly
// (BM_DilateLeafMask).
template<typename TreeT>
SmallMaskTree::Ptr leafMask(const TreeT& tree)
{
    using Parent = typename TreeT::RootNodeType::ChildNodeType::ChildNodeType;
    static_assert(Parent::LOG2DIM == 4 && kLeafDim == 8,
                  "16^3 leaves under a node, 8^3 in a mask leaf");
    std::vector<const Parent*> parents;
    tree.getNodes(parents);
    auto mask = std::make_shared<SmallMaskTree>();
    openvdb::tree::ValueAccessor<SmallMaskTree> acc(*mask);
    for (const Parent* node : parents) {
        const Coord base = node->origin() >> kLeafLog2; // in leaves: a multiple of 16
        const auto& children = node->getChildMask();
        // The node's 16^3 children are 2^3 leaves of the coarse mask.
        for (int a = 0; a < 2; ++a) {
            for (int b = 0; b < 2; ++b) {
                for (int c = 0; c < 2; ++c) {
                    std::uint64_t words[kLeafDim];
                    std::uint64_t any = 0;
                    for (int xl = 0; xl < kLeafDim; ++xl) {
                        const int x = kLeafDim * a + xl;
                        std::uint64_t w = 0;
                        for (int yl = 0; yl < kLeafDim; ++yl) {
                            const int y = kLeafDim * b + yl;
                            // Word x * 4 + y / 4 holds four rows of 16 bits (z) at x, y.
                            const auto row = children.template getWord<std::uint64_t>(
                                openvdb::Index(x * 4 + (y >> 2)));
                            w |= ((row >> ((y & 3) * 16 + kLeafDim * c)) & 0xFFu)
                                 << (kLeafDim * yl);
                        }
                        words[xl] = w;
                        any |= w;
                    }
                    if (!any) continue;
                    auto& bits = acc.touchLeaf(base.offsetBy(kLeafDim * a, kLeafDim * b,
                                                             kLeafDim * c))->getValueMask();
                    for (int x = 0; x < kLeafDim; ++x) {
                        bits.template getWord<std::uint64_t>(openvdb::Index(x)) |= words[x];
                    }
                }
            }
        }
    }
    return mask;
}

template<typename TreeT>
typename TreeT::Ptr dilatedCopy(const TreeT& mask, int steps)
{
    return levelset::dilatedBox(mask, steps);
}

/// The origins of the leaves a coarse mask (leafMask()) stands for.
std::vector<Coord> leafOrigins(const SmallMaskTree& mask)
{
    std::vector<Coord> out;
    out.reserve(size_t(mask.activeVoxelCount()));
    if (!mask.hasActiveTiles()) {
        // Leaf by leaf, a word of the mask at a time, in the value iterator's order: the 27,249
        // leaves around the radius-400 pair's crease in 0.1 to 0.2 ms, not 0.9. (leafMask(),
        // dilatedBox() and pairwise() make no tiles; a mask with tiles is read below.)
        for (auto leaf = mask.cbeginLeaf(); leaf; ++leaf) {
            const Coord base = leaf->origin();
            const auto& bits = leaf->getValueMask();
            for (openvdb::Index w = 0; w < bits.WORD_COUNT; ++w) {
                for (std::uint64_t word = bits.template getWord<std::uint64_t>(w); word;
                     word &= word - 1) {
                    const openvdb::Index i = 64 * w + openvdb::util::FindLowestOn(word);
                    const Coord v = base + SmallMaskTree::LeafNodeType::offsetToLocalCoord(i);
                    out.emplace_back(v.x() * kLeafDim, v.y() * kLeafDim, v.z() * kLeafDim);
                }
            }
        }
        return out;
    }
    for (auto it = mask.cbeginValueOn(); it; ++it) {
        const openvdb::CoordBBox box = it.getBoundingBox(); // a voxel, or a tile of them
        // Multiplied, not shifted: shifting a negative coordinate left is undefined in C++17.
        for (auto c = box.begin(); c; ++c) {
            const Coord v = *c;
            out.emplace_back(v.x() * kLeafDim, v.y() * kLeafDim, v.z() * kLeafDim);
        }
    }
    return out;
}

int leavesFor(double voxels) { return int(std::ceil(voxels / kLeafDim)); }

using detail::dilatedOver;
using detail::LeafSet;
using detail::MaskBits;

/// The band voxels' surface points c = x - phi(x) n and unit normals n (index space): the
/// planes the extension passes on, seed k's at index k. Apart, so that the search for the
/// nearest point reads 12 bytes a seed, not 24.
struct Seeds
{
    std::vector<openvdb::Vec3s> point, normal;
};

/// An input's band grown around the crease, for blendValues(): its values, the known voxels
/// active.
struct GrownBand
{
    openvdb::FloatGrid::Ptr values;
};

using InputAccessor = openvdb::tree::ValueAccessor<const FloatTree>;

/// Seeds for the voxels @a voxels of the leaf at @a origin of a band (@a acc reads it): seed
/// first + j for the j-th of them, its surface point c = x - phi(x) n and normal
/// n = grad(phi)(x) / |grad(phi)(x)| (central differences, one-sided at the band's edge), in
/// index space (@a dx: the voxel size). @a seedOf (the leaf's 512 voxels, by offset) gets each
/// seeded voxel's index.
void seedVoxels(const Coord& origin, const MaskBits& voxels, InputAccessor& acc, double dx,
                Seeds& seeds, size_t first, int* seedOf)
{
    // The input's values and states at the leaf's voxels and their face neighbours.
    constexpr int D = kLeafDim + 2;
    auto index = [](int x, int y, int z) { return ((x + 1) * D + (y + 1)) * D + (z + 1); };
    float value[D * D * D];
    bool on[D * D * D];
    const LeafT* center = acc.probeConstLeaf(origin);
    bool dense = center != nullptr;
    if (dense) {
        std::fill(std::begin(on), std::end(on), false);
        std::fill(std::begin(value), std::end(value), 0.0f); // read only where on
        // A row along z at a time: the leaf's buffer and the row's 8 bits of its mask word.
        const float* values = center->buffer().data();
        const auto& mask = center->getValueMask();
        for (int x = 0; x < kLeafDim; ++x) {
            const auto word = mask.template getWord<std::uint64_t>(openvdb::Index(x));
            for (int y = 0; y < kLeafDim; ++y) {
                const float* row = values + (x << (2 * kLeafLog2)) + (y << kLeafLog2);
                const unsigned bits = unsigned(word >> (kLeafDim * y)) & 0xFFu;
                const int to = index(x, y, 0);
                for (int z = 0; z < kLeafDim; ++z) {
                    value[to + z] = row[z];
                    on[to + z] = (bits >> z) & 1u;
                }
            }
        }
    }
    for (int a = 0; a < 3 && dense; ++a) {
        for (int side = -1; side <= 1 && dense; side += 2) {
            Coord o = origin;
            o[a] += side * kLeafDim;
            const LeafT* n = acc.probeConstLeaf(o);
            if (!n) {
                dense = !acc.isValueOn(o); // an active tile: read voxel by voxel
                continue;
            }
            // The slab at from along a in the neighbour, by the other two axes u and v (in
            // order): its voxel's offset there, and where it sits around the leaf (at to). With
            // a Coord made and the leaf asked for each voxel, the seeding of the radius-400 pair
            // at p = 320 took 19 to 22 ms an input (both side by side), now 14 to 17.
            const int from = side < 0 ? kLeafDim - 1 : 0, to = side < 0 ? -1 : kLeafDim;
            constexpr int kOffset[3] = {kLeafDim * kLeafDim, kLeafDim, 1}; // a leaf's strides
            constexpr int kAround[3] = {D * D, D, 1};                      // value's and on's
            const int ua = a == 0 ? 1 : 0, va = a == 2 ? 1 : 2;
            const float* values = n->buffer().data();
            const auto& mask = n->getValueMask();
            for (int u = 0; u < kLeafDim; ++u) {
                for (int v = 0; v < kLeafDim; ++v) {
                    const int m = from * kOffset[a] + u * kOffset[ua] + v * kOffset[va];
                    const int t = index(0, 0, 0) + to * kAround[a] + u * kAround[ua] +
                                  v * kAround[va];
                    value[t] = values[m];
                    on[t] = (mask.template getWord<std::uint64_t>(openvdb::Index(m >> 6)) >>
                             (m & 63)) & 1u;
                }
            }
        }
    }
    // The input's value and state at a voxel of the leaf or a face neighbour.
    auto sample = [&](const Coord& ijk, float& v) {
        if (!dense) return acc.probeValue(ijk, v);
        const Coord l = ijk - origin;
        const int c = index(l.x(), l.y(), l.z());
        v = value[c];
        return on[c];
    };
    size_t next = first;
    constexpr int kStride[3] = {D * D, D, 1}; // one voxel along x, y, z in value and on
    for (auto it = voxels.beginOn(); it; ++it) {
        const openvdb::Index pos = it.pos();
        const Coord ijk = origin + LeafT::offsetToLocalCoord(pos);
        float v0;
        openvdb::Vec3d g;
        // Central differences where both neighbours are in the band, one-sided at its edge.
        auto difference = [&v0](bool p, float vp, bool m, float vm) {
            return p && m ? 0.5 * (double(vp) - vm) : p ? double(vp) - v0
                 : m      ? double(v0) - vm           : 0.0;
        };
        if (dense) {
            const openvdb::Index o = pos;
            const int c = index(int(o >> 6), int((o >> 3) & 7), int(o & 7));
            v0 = value[c];
            for (int a = 0; a < 3; ++a) {
                const int up = c + kStride[a], down = c - kStride[a];
                g[a] = difference(on[up], value[up], on[down], value[down]);
            }
        } else {
            sample(ijk, v0);
            for (int a = 0; a < 3; ++a) {
                Coord dp = ijk, dm = ijk;
                dp[a] += 1;
                dm[a] -= 1;
                float vp, vm;
                const bool p = sample(dp, vp), m = sample(dm, vm);
                g[a] = difference(p, vp, m, vm);
            }
        }
        const double len = g.length();
        const openvdb::Vec3d x(ijk.x(), ijk.y(), ijk.z());
        const openvdb::Vec3d nv = len > 0.0 ? g / len : openvdb::Vec3d(0.0);
        seeds.point[next] = openvdb::Vec3s(x - nv * (double(v0) / dx));
        seeds.normal[next] = openvdb::Vec3s(nv);
        seedOf[pos] = int(next++);
    }
}

/// The seeds of a leaf's voxels and of the shell of voxels around it, as a dense array (-1
/// where none is known), and the search of a voxel's 26 neighbours for the nearest seed.
struct SeedNeighbourhood
{
    static constexpr int kDim = kLeafDim + 2, kSize = kDim * kDim * kDim;
    static constexpr int index(int x, int y, int z)
    {
        return ((x + 1) * kDim + (y + 1)) * kDim + (z + 1);
    }
    /// The 26 neighbours, in the order ties between equally near points are broken.
    static inline const Coord kNeighbours[26] = {
        {-1,-1,-1},{-1,-1,0},{-1,-1,1},{-1,0,-1},{-1,0,0},{-1,0,1},{-1,1,-1},{-1,1,0},{-1,1,1},
        {0,-1,-1},{0,-1,0},{0,-1,1},{0,0,-1},{0,0,1},{0,1,-1},{0,1,0},{0,1,1},
        {1,-1,-1},{1,-1,0},{1,-1,1},{1,0,-1},{1,0,0},{1,0,1},{1,1,-1},{1,1,0},{1,1,1}};

    int seed[kSize];
    int step[26]; // each neighbour's offset in seed

    SeedNeighbourhood()
    {
        for (int j = 0; j < 26; ++j) {
            step[j] = index(kNeighbours[j].x(), kNeighbours[j].y(), kNeighbours[j].z()) -
                      index(0, 0, 0);
        }
    }

    /// Fill from the (up to 27) leaves @a around the leaf (LeafSet::around, -1: none), whose
    /// seed indices are @a seedOf's 512 from leaf * 512 (by offset, -1 where not known); a row
    /// along z at a time. Only the parts next to a voxel of @a front (the voxels nearest() will
    /// be asked for) are filled: the others are never read. Filling all (the 1000 entries
    /// cleared, then every part copied) took 48 to 60 million cycles of the layers' 195 to 285
    /// on the radius-400 pair at p = 320 (13,437 leaves, summed over the layers and inputs);
    /// this, 28 to 40.
    void gather(const std::array<int, 27>& around, const int* seedOf, const MaskBits& front)
    {
        using Word = std::uint64_t;
        constexpr int kLast = kLeafDim - 1;
        // front's voxels on each face of the leaf, as words: x = 0 and 7 (whole words), y = 0
        // and 7 (a row of each word), z = 0 and 7 (a bit of each row).
        constexpr Word kRowFirst = 0xFFull, kRowLast = kRowFirst << 56;
        constexpr Word kBitFirst = 0x0101010101010101ull, kBitLast = kBitFirst << 7;
        for (int dx = -1; dx <= 1; ++dx) {
            for (int dy = -1; dy <= 1; ++dy) {
                for (int dz = -1; dz <= 1; ++dz) {
                    // Is a voxel of front next to this part?
                    const Word rows = dy < 0 ? kRowFirst : dy > 0 ? kRowLast : ~Word(0);
                    const Word bits = dz < 0 ? kBitFirst : dz > 0 ? kBitLast : ~Word(0);
                    Word any = 0;
                    for (int x = dx > 0 ? kLast : 0; x <= (dx < 0 ? 0 : kLast); ++x) {
                        any |= front.getWord<Word>(openvdb::Index(x)) & rows & bits;
                    }
                    if (!any) continue;
                    const int leaf = around[LeafSet::aroundIndex(Coord(dx, dy, dz))];
                    const int* from = leaf < 0 ? nullptr : seedOf + size_t(leaf) * LeafT::SIZE;
                    // The part of that leaf within the shell: all of it along an axis where
                    // it is the leaf itself, else its last or first slice.
                    const int x0 = dx < 0 ? kLast : 0, x1 = dx > 0 ? 0 : kLast;
                    const int y0 = dy < 0 ? kLast : 0, y1 = dy > 0 ? 0 : kLast;
                    const int z0 = dz < 0 ? kLast : 0, z1 = dz > 0 ? 0 : kLast;
                    for (int x = x0; x <= x1; ++x) {
                        for (int y = y0; y <= y1; ++y) {
                            int* to = seed + index(x + dx * kLeafDim, y + dy * kLeafDim,
                                                   z0 + dz * kLeafDim);
                            if (!from) {
                                std::fill(to, to + (z1 - z0 + 1), -1);
                                continue;
                            }
                            const int* row = from + LeafT::coordToOffset(Coord(x, y, z0));
                            for (int z = 0; z <= z1 - z0; ++z) to[z] = row[z];
                        }
                    }
                }
            }
        }
    }

    /// The seed, of those the 26 neighbours of the leaf's voxel @a local hold, whose point is
    /// nearest @a y (-1: none), and its squared distance in @a best.
    int nearest(const Coord& local, const openvdb::Vec3d& y, const openvdb::Vec3s* points,
                double& best) const
    {
        const int center = index(local.x(), local.y(), local.z());
        best = std::numeric_limits<double>::max();
        int from = -1, last = -1;
        for (int j = 0; j < 26; ++j) {
            const int k = seed[center + step[j]];
            if (k < 0 || k == last) continue; // a seed just weighed gives the same distance
            last = k;
            const double dist = (y - openvdb::Vec3d(points[k])).lengthSqr();
            if (dist < best) best = dist, from = k;
        }
        return from;
    }
};

/// The value a voxel y takes from seed @a k, @a best from it (squared): the distance to the
/// seed's tangent plane, |(y - c) . n| (to c itself where it has no normal), in world units,
/// with the sign of the input's value @a inputValue there (which holds the sign beyond the band).
float planeValue(const openvdb::Vec3d& y, const Seeds& seeds, int k, double best,
                 float inputValue, double dx)
{
    const openvdb::Vec3d c(seeds.point[size_t(k)]), nv(seeds.normal[size_t(k)]);
    double d = (y - c).dot(nv);
    if (nv.lengthSqr() == 0.0) d = std::sqrt(best); // no normal: the point
    const double sign = inputValue < 0.0f ? -1.0 : 1.0;
    return float(sign * std::abs(d) * dx);
}

/// An input's band grown over a LeafSet by closest points (extendOverLeaves()): by
/// leaf * 512 + voxel offset, each known voxel's seed (-1: not known) and value.
struct FlatBand
{
    std::vector<MaskBits> keep, known; // by leaf: the voxels to grow over, those with a value
    std::unique_ptr<int[]> seedOf;
    std::unique_ptr<float[]> value;
    Seeds seeds;
};

// The voxels of @a grid's band within @a keep (by leaf of @a leaves), extended by up to
// @a dilation voxels within @a keep by closest-point propagation. Every band voxel x is a seed:
// its surface point c = x - phi(x) n and normal n = grad(phi)(x) / |grad(phi)(x)| (central
// differences, one-sided at the band's edge). Then, one layer of voxels at a time, each new
// voxel y takes the neighbour (of 26) whose seed's point c is nearest, and the distance to that
// point's tangent plane, (y - c) . n, passing the same seed on. The plane keeps the error second
// order in the angle between neighbours' normals (the distance to c itself is off by about
// spacing^2 / (2 distance) on the concave side). The sign comes from the input, which holds it
// beyond the band. A voxel holds its seed's index (4 bytes), not a copy of its point and normal
// (24). openvdb::tools::dilateSdf (fast sweeping) took about 1.3 us a voxel on this job; this
// is several times cheaper.
//
// On flat arrays indexed by leaf and voxel: with trees, each layer's leaves were allocated,
// copied and looked up serially in part, and on the radius-400 pair at p = 1000 seeding took
// 27 ms an input and each of three layers 13 ms.
FlatBand extendOverLeaves(const openvdb::FloatGrid& grid, const LeafSet& leaves,
                          std::vector<MaskBits> keep, int dilation)
{
    constexpr size_t kSize = LeafT::SIZE;
    const size_t n = leaves.size();
    const double dx = grid.voxelSize()[0];
    FlatBand b;
    b.keep = std::move(keep);
    b.known.assign(n, MaskBits());
    b.seedOf.reset(new int[n * kSize]);
    b.value.reset(new float[n * kSize]);
    // The band's voxels within keep are their own seeds: counted, numbered leaf by leaf, then
    // each leaf's computed.
    std::vector<size_t> first(n + 1, 0);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
        InputAccessor acc(grid.tree());
        for (size_t k = r.begin(); k < r.end(); ++k) {
            std::fill_n(b.seedOf.get() + k * kSize, kSize, -1);
            const LeafT* leaf = acc.probeConstLeaf(leaves.origin[k]);
            if (!leaf) continue;
            b.known[k] = leaf->getValueMask() & b.keep[k];
            first[k + 1] = b.known[k].countOn();
            std::copy_n(leaf->buffer().data(), kSize, b.value.get() + k * kSize);
        }
    });
    std::partial_sum(first.begin(), first.end(), first.begin());
    b.seeds.point.resize(first[n]);
    b.seeds.normal.resize(first[n]);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
        InputAccessor acc(grid.tree());
        for (size_t k = r.begin(); k < r.end(); ++k) {
            if (b.known[k].isOff()) continue;
            seedVoxels(leaves.origin[k], b.known[k], acc, dx, b.seeds, first[k],
                       b.seedOf.get() + k * kSize);
        }
    });
    // The layers: each voxel of keep not known yet with a known neighbour takes the nearest
    // seed they hold, in the leaves where the last layer added voxels or next to them. A layer
    // reads only the last one's seeds: what it finds is written once it is done.
    struct Found
    {
        std::uint32_t leaf, voxel;
        int seed;
        float value;
    };
    tbb::enumerable_thread_specific<std::vector<Found>> found;
    std::vector<char> changed(n), next(n);
    for (size_t k = 0; k < n; ++k) changed[k] = !b.known[k].isOff();
    for (int layer = 0; layer < dilation; ++layer) {
        std::vector<std::uint32_t> todo;
        for (size_t k = 0; k < n; ++k) {
            if ((b.keep[k] & !b.known[k]).isOff()) continue; // complete
            const auto& a = leaves.around[k];
            const auto near = [&](int j) { return j >= 0 && changed[size_t(j)]; };
            if (std::any_of(a.begin(), a.end(), near)) todo.push_back(std::uint32_t(k));
        }
        if (todo.empty()) break;
        for (auto& f : found) f.clear();
        tbb::parallel_for(tbb::blocked_range<size_t>(0, todo.size()),
                          [&](const tbb::blocked_range<size_t>& r) {
            InputAccessor in(grid.tree());
            auto nb = std::make_unique<SeedNeighbourhood>();
            std::vector<Found>& out = found.local();
            const openvdb::Vec3s* points = b.seeds.point.data();
            for (size_t t = r.begin(); t < r.end(); ++t) {
                const size_t k = todo[t];
                const Coord origin = leaves.origin[k];
                const LeafT* sign = in.probeConstLeaf(origin);
                const float tile = sign ? 0.0f : in.getValue(origin);
                // Of keep's voxels not known yet, those with a known neighbour.
                const MaskBits* known[27];
                for (size_t j = 0; j < 27; ++j) {
                    const int at = leaves.around[k][j];
                    known[j] = at >= 0 ? &b.known[size_t(at)] : nullptr;
                }
                const MaskBits front = b.keep[k] & !b.known[k] & detail::withinOne(known);
                if (front.isOff()) continue;
                nb->gather(leaves.around[k], b.seedOf.get(), front);
                for (auto it = front.beginOn(); it; ++it) {
                    const openvdb::Index m = it.pos();
                    const Coord local = LeafT::offsetToLocalCoord(m);
                    const Coord ijk = origin + local;
                    const openvdb::Vec3d y(ijk.x(), ijk.y(), ijk.z());
                    double best;
                    const int from = nb->nearest(local, y, points, best);
                    out.push_back(Found{std::uint32_t(k), std::uint32_t(m), from,
                                        planeValue(y, b.seeds, from, best,
                                                   sign ? sign->getValue(m) : tile, dx)});
                }
            }
        });
        std::fill(next.begin(), next.end(), 0);
        bool any = false;
        for (const auto& list : found) {
            for (const Found& f : list) {
                const size_t at = size_t(f.leaf) * kSize + f.voxel;
                b.seedOf[at] = f.seed;
                b.value[at] = f.value;
                b.known[f.leaf].setOn(f.voxel);
                next[f.leaf] = 1;
                any = true;
            }
        }
        if (!any) break;
        changed.swap(next);
    }
    return b;
}

/// extendOverLeaves() within @a keep, as a grid: the known voxels active.
GrownBand extendByClosestPoints(const openvdb::FloatGrid& grid, const MaskTree& keep, int dilation)
{
    const LeafSet leaves(keep);
    const FlatBand b = extendOverLeaves(grid, leaves, leaves.masksOf(keep), dilation);
    auto values = openvdb::FloatGrid::create(grid.background());
    values->setTransform(grid.transform().copy());
    values->setGridClass(openvdb::GRID_LEVEL_SET);
    std::vector<LeafT*> out(leaves.size(), nullptr);
    for (size_t k = 0; k < leaves.size(); ++k) {
        if (b.known[k].isOff()) continue;
        out[k] = new LeafT(leaves.origin[k], grid.background());
        values->tree().addLeaf(out[k]);
    }
    tbb::parallel_for(tbb::blocked_range<size_t>(0, out.size()),
                      [&](const tbb::blocked_range<size_t>& r) {
        for (size_t k = r.begin(); k < r.end(); ++k) {
            if (!out[k]) continue;
            std::copy_n(b.value.get() + k * LeafT::SIZE, LeafT::SIZE, out[k]->buffer().data());
            out[k]->setValueMask(b.known[k]);
        }
    });
    return GrownBand{values};
}

// extendLocally() for long extensions: by fast sweeping (openvdb::tools::dilateSdf), which
// handles fronts that meet (past a medial axis). The leaves around are copied with their voxels
// inactive, and leaf-sized tiles carry the inside sign, so the sweep sees on which side of the
// surface each new voxel lies, as on the whole grid.
openvdb::FloatGrid::Ptr extendBySweeping(const openvdb::FloatGrid& grid, const MaskTree& keep,
                                      int dilation)
{
    auto clip = openvdb::FloatGrid::create(grid.background());
    clip->setTransform(grid.transform().copy());
    clip->setGridClass(openvdb::GRID_LEVEL_SET);
    openvdb::tree::ValueAccessor<const FloatTree> acc(grid.tree());
    openvdb::tree::ValueAccessor<const MaskTree> keepAcc(keep);
    // The leaves the grown band can reach (new voxels take their sign from there).
    const SmallMaskTree::Ptr around = leafMask(*dilatedCopy(keep, dilation + 1));
    for (const Coord& o : leafOrigins(*around)) {
        if (const LeafT* leaf = acc.probeConstLeaf(o)) {
            auto* copy = new LeafT(*leaf);
            const MaskTree::LeafNodeType* k = keepAcc.probeConstLeaf(o);
            copy->setValueMask(k ? leaf->getValueMask() & k->getValueMask()
                                 : LeafT::NodeMaskType());
            clip->tree().addLeaf(copy);
        } else if (acc.getValue(o) < 0.0f) {
            clip->tree().addTile(1, o, -grid.background(), false);
        }
    }
    if (dilation <= 0 || clip->tree().activeVoxelCount() == 0) return clip;
    return levelset::detail::dilateSdf(*clip, dilation);
}

// Closest-point propagation loses accuracy where fronts from opposite sides meet (a medial
// axis): inside a sphere of radius 15 voxels extended by 30, the blended surface was off by
// 0.8 voxel. Up to this many layers it matches fast sweeping's accuracy or beats it (the
// grid-blend tests, p = 10 and 50); beyond, fast sweeping takes over.
constexpr int kMaxClosestPointLayers = 8;

GrownBand extendLocally(const openvdb::FloatGrid& grid, const MaskTree& keep, int dilation)
{
    return dilation <= kMaxClosestPointLayers ? extendByClosestPoints(grid, keep, dilation)
                                              : GrownBand{extendBySweeping(grid, keep, dilation)};
}

void checkSettings(size_t inputs, const BlendSettings& settings)
{
    blendKernel(settings);
    check(limits::kTolerance, settings.tolerance);
    if (inputs < 2) {
        throw ParamError(param::kInputs, "must be at least two level sets, got " +
                                             std::to_string(inputs));
    }
}

/// Step 1, the plan: how far each input's band must reach (the output band plus the blend's
/// reach and swell), and the memory that may take.
struct BlendPlan
{
    implicit::BlendKernel kernel;
    double dx = 0.0, halfWidth = 0.0, reachVox = 0.0, memoryLimit = 0.0;
    float bg = 0.0f; // the output's background, as for the sharp operation
    size_t n = 0;
    int needVox = 0;
    std::vector<int> dilation;           // voxels each input's band must grow
    std::vector<SmallMaskTree::Ptr> leaves; // each input's leaves, as a coarse mask

    /// How far (voxels) around the crease the fast-sweeping re-distancing reads the surface: a
    /// band width and two voxels (the region).
    int regionReach() const { return int(std::ceil(halfWidth)) + 2; }

    [[noreturn]] void refuse(double estimate) const
    {
        std::ostringstream os;
        os << "blend with " << kernel.describe() << " reaches " << std::ceil(reachVox)
           << " voxels beyond the surfaces, so the bands must grow to " << needVox
           << " voxels where the inputs meet: about " << util::formatBytes(estimate)
           << ", more than the " << util::formatBytes(memoryLimit) << " available. "
           << alternatives();
        OPENVDB_THROW(openvdb::RuntimeError, os.str());
    }

    /// What else would do: the scene-level operation, a sharper kernel.
    std::string alternatives() const
    {
        return kernel.kind == implicit::BlendKernel::Kind::SuperElliptic
            ? "Use the scene-level blend ({\"type\": \"blend\", ...} in a scene file, which needs "
              "no band extension), a larger p, or a larger tolerance"
            : "Use the scene-level smooth CSG ({\"type\": \"smooth\", ...} in a scene file, "
              "which needs no band extension) or a smaller k";
    }

    /// The sweep keeps a few copies of the grown band (values, masks, slices): about 16 bytes a
    /// voxel. A bound: the leaves of @a mask grown by @a d voxels, or its bounding box so grown,
    /// whichever is smaller.
    static double grownBytes(const SmallMaskTree& mask, int d)
    {
        openvdb::CoordBBox box;
        mask.evalActiveVoxelBoundingBox(box);
        return grownBytes(double(mask.activeVoxelCount()), box, d);
    }

    /// grownBytes() of @a leaves leaves within @a box (in leaves: leaf origins / 8).
    static double grownBytes(double leaves, const openvdb::CoordBBox& box, int d)
    {
        const double k = 2.0 * leavesFor(d) + 1.0;
        const double byLeaves = leaves * k * k * k;
        const openvdb::Coord dim = box.dim();
        const double byBox = (dim.x() + k - 1.0) * (dim.y() + k - 1.0) * (dim.z() + k - 1.0);
        return std::min(byLeaves, byBox) * double(LeafT::SIZE) * 16.0;
    }

    /// Refuse now if growing the masks @a grownFrom by each input's dilation would not fit.
    void checkMemory(const std::vector<SmallMaskTree::Ptr>& grownFrom) const
    {
        double estimate = 0.0;
        for (size_t i = 0; i < n; ++i) estimate += grownBytes(*grownFrom[i], dilation[i]);
        if (estimate > memoryLimit) refuse(estimate);
    }

    /// checkMemory() with every input grown from the leaves at @a origins.
    void checkMemory(const std::vector<Coord>& origins) const
    {
        openvdb::CoordBBox box;
        for (const Coord& o : origins) box.expand(o >> kLeafLog2);
        double estimate = 0.0;
        for (size_t i = 0; i < n; ++i) {
            estimate += grownBytes(double(origins.size()), box, dilation[i]);
        }
        if (estimate > memoryLimit) refuse(estimate);
    }
};

BlendPlan planBlend(const std::vector<openvdb::FloatGrid::Ptr>& grids, const BlendSettings& settings)
{
    BlendPlan plan;
    const openvdb::FloatGrid& finest = finestInput(grids);
    plan.kernel = blendKernel(settings);
    plan.dx = finest.voxelSize()[0];
    plan.bg = finest.background();
    plan.halfWidth = double(plan.bg) / plan.dx;
    plan.n = grids.size();
    plan.memoryLimit = util::memoryBudget(settings.memoryLimit);
    plan.reachVox = plan.kernel.reach(settings.tolerance * plan.dx) / plan.dx;
    const double swellVox = plan.kernel.swell(plan.n) / plan.dx;
    if (!(plan.halfWidth + plan.reachVox + swellVox < 1e6)) {
        OPENVDB_THROW(openvdb::RuntimeError, "blend with " + plan.kernel.describe() +
            " reaches " + util::formatNumber(std::ceil(plan.reachVox + swellVox)) +
            " voxels beyond the surfaces, far more than any band can hold. " +
            plan.alternatives());
    }
    // The swell of the blended surface too; see the lead rule in blendValues().
    plan.needVox = int(std::ceil(plan.halfWidth + plan.reachVox + swellVox)) + 1;
    for (const auto& g : grids) {
        // The band's half width in whole voxels. A float background of 3 voxels of a double
        // size is often a hair under 3 (0.03f / 0.01 = 2.99999993): floored as it was, that grew
        // every band a layer more than the reach needs (7 at p = 320 on the radius-400 pair,
        // where 6 reach 9 voxels): 13% more voxels grown and 14% more visited there, 32% and 23%
        // at p = 1000 (4 layers for 3), and extensions of 8 voxels went to fast sweeping.
        const int band = int(std::floor(double(g->background()) / plan.dx + 1e-6));
        plan.dilation.push_back(std::max(0, plan.needVox - band));
        plan.leaves.push_back(leafMask(g->tree()));
    }
    plan.checkMemory(plan.leaves); // a first bound, before any mask is grown
    return plan;
}

/// The voxels in two or more of @a masks.
template<typename TreeT>
typename TreeT::Ptr pairwise(const std::vector<typename TreeT::Ptr>& masks)
{
    auto out = std::make_shared<TreeT>();
    for (size_t i = 0; i < masks.size(); ++i) {
        for (size_t j = i + 1; j < masks.size(); ++j) {
            TreeT both(*masks[i]);
            both.topologyIntersection(*masks[j]);
            out->topologyUnion(both);
        }
    }
    return out;
}

/// The voxels in two or more of @a masks (each by leaf of one LeafSet), leaf @a k's.
MaskBits inTwoOrMore(const std::vector<std::vector<MaskBits>>& masks, size_t k)
{
    MaskBits one, two;
    for (const auto& m : masks) {
        two |= one & m[k];
        one |= m[k];
    }
    return two;
}

/// findCrease()'s voxels for extensions longer than a leaf: each input's band, in the leaves
/// within its extension of a candidate, grown into a tree by dilatedBox(), then intersected.
/// dilatedBox() crosses several leaves in one pass, where dilatedOver() steps a leaf at a time
/// over every leaf of its list, most of them empty that far out: with the flat passes,
/// `ivdb blend -p 4` on spheres of radius 60 voxels (174 voxels, refused for memory once its
/// crease is found) took 3.96 s against 2.16.
MaskTree::Ptr creaseOnTrees(const BlendPlan& plan,
                            const std::vector<openvdb::FloatGrid::Ptr>& grids,
                            const SmallMaskTree& candidates)
{
    std::vector<MaskTree::Ptr> reach(plan.n);
    tbb::parallel_for(size_t(0), plan.n, [&](size_t i) {
        auto band = std::make_shared<MaskTree>();
        InputAccessor acc(grids[i]->tree());
        const SmallMaskTree::Ptr near = dilatedCopy(candidates, leavesFor(plan.dilation[i]));
        for (const Coord& o : leafOrigins(*near)) {
            if (const LeafT* leaf = acc.probeConstLeaf(o)) {
                band->touchLeaf(o)->setValueMask(leaf->getValueMask());
            }
        }
        reach[i] = dilatedCopy(*band, plan.dilation[i]);
    });
    return pairwise<MaskTree>(reach);
}

/// findCrease()'s flat arrays (extensions of up to a leaf), kept for blendDomain(): the
/// candidate leaves and every leaf around them, and by leaf of those the crease's voxels and
/// every input's band (an active tile's voxels too).
struct FlatCrease
{
    std::unique_ptr<LeafSet> leaves;
    std::vector<MaskBits> crease, bands;

    /// The crease as a tree.
    MaskTree::Ptr creaseTree() const
    {
        auto out = std::make_shared<MaskTree>();
        openvdb::tree::ValueAccessor<MaskTree> acc(*out);
        for (size_t k = 0; k < crease.size(); ++k) {
            if (!crease[k].isOff()) acc.touchLeaf(leaves->origin[k])->setValueMask(crease[k]);
        }
        return out;
    }
};

/// Step 2, the crease: where the blend differs from the sharp operation by more than the
/// tolerance, two inputs are within needVox of their surfaces. First in leaves (a leaf of one
/// input's band within reach of a leaf of another's: the candidates), then in voxels within
/// those leaves: each input's band grown by its extension and intersected. For extensions of
/// up to a leaf (those of localBlend()), on flat arrays over the leaves within the longest
/// extension of a candidate (all that reaches a candidate's voxels), kept in @a flat; for
/// longer ones, on trees (@a flat left empty). Returns the crease as a tree for longer
/// extensions (null with the flat arrays: the tree is built where it is asked for, which
/// localBlend() does not).
MaskTree::Ptr findCrease(const BlendPlan& plan, const std::vector<openvdb::FloatGrid::Ptr>& grids,
                         FlatCrease& flat)
{
    // Each input's leaf masks by one thread: a dilation is serial, and the inputs are
    // independent.
    std::vector<SmallMaskTree::Ptr> reach(plan.n);
    tbb::parallel_for(size_t(0), plan.n, [&](size_t i) {
        reach[i] = dilatedCopy(*plan.leaves[i], leavesFor(plan.dilation[i]));
    });
    const SmallMaskTree::Ptr candidates = pairwise<SmallMaskTree>(reach);
    const int longest = *std::max_element(plan.dilation.begin(), plan.dilation.end());
    if (longest > kLeafDim) return creaseOnTrees(plan, grids, *candidates);
    // At least a leaf around them, which blendDomain() reads too.
    flat.leaves = std::make_unique<LeafSet>(
        leafOrigins(*dilatedCopy(*candidates, std::max(1, leavesFor(longest)))),
        LeafSet::Around::Faces);
    const LeafSet& leaves = *flat.leaves;
    const size_t count = leaves.size();
    std::vector<std::vector<MaskBits>> band(plan.n), grown(plan.n);
    std::vector<std::vector<char>> tile(plan.n); // an active tile where the input has no leaf
    tbb::parallel_for(size_t(0), plan.n, [&](size_t i) {
        band[i].resize(count);
        tile[i].assign(count, 0);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, count),
                          [&](const tbb::blocked_range<size_t>& r) {
            InputAccessor acc(grids[i]->tree());
            for (size_t k = r.begin(); k < r.end(); ++k) {
                if (const LeafT* leaf = acc.probeConstLeaf(leaves.origin[k])) {
                    band[i][k] = leaf->getValueMask();
                } else {
                    tile[i][k] = acc.isValueOn(leaves.origin[k]);
                }
            }
        });
        grown[i] = dilatedOver(leaves, band[i], plan.dilation[i]);
    });
    flat.crease.resize(count);
    flat.bands.resize(count);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, count),
                      [&](const tbb::blocked_range<size_t>& r) {
        for (size_t k = r.begin(); k < r.end(); ++k) {
            flat.crease[k] = inTwoOrMore(grown, k);
            for (size_t i = 0; i < plan.n; ++i) {
                if (tile[i][k]) flat.bands[k].setOn();
                flat.bands[k] |= band[i][k];
            }
        }
    });
    return nullptr;
}

/// The sign of input @a i's term in union form: an intersection is the union of the
/// complements, and a difference negates the inputs it subtracts.
double termSign(CsgOp op, size_t i)
{
    const double sign = op == CsgOp::Union ? 1.0 : -1.0;
    return (op == CsgOp::Difference && i > 0) ? -sign : sign;
}

/// How far around the crease input @a i's band grows where the fast-sweeping re-distancing
/// reads values (over the whole region): a crease voxel at layer L (its 26-connected distance
/// from the band, at most the dilation d) takes its seed along a path within L of it, so d + 1
/// voxels give every crease voxel the unbounded extension's value; further where the region is
/// wider than that. (Where localBlend() applies, the bands grow over its voxels alone:
/// blendDomain().)
int keepReach(const BlendPlan& plan, size_t i)
{
    return std::max(plan.dilation[i] + 1, plan.regionReach());
}

/// The voxels of @a leaf (an input's) beyond its band on the side that decides the blend:
/// inactive, with its term (the value times @a side, termSign()) negative.
MaskBits beyondOf(const LeafT& leaf, double side)
{
    MaskBits out;
    const float* v = leaf.buffer().data();
    for (openvdb::Index w = 0; w < MaskBits::WORD_COUNT; ++w) {
        std::uint64_t negative = 0;
        const float* x = v + 64 * w;
#if defined(__SSE2__)
        // Four values a comparison: on the radius-400 pair, the voxels to blend took 1.3 to 1.5
        // ms to find this way, 2.5 to 2.6 one value at a time (temporary timers, medians of five
        // runs, p = 1000).
        const __m128 zero = _mm_setzero_ps();
        for (int b = 0; b < 64; b += 4) {
            const __m128 four = _mm_loadu_ps(x + b);
            const __m128 beyond = side > 0.0 ? _mm_cmplt_ps(four, zero) : _mm_cmpgt_ps(four, zero);
            negative |= std::uint64_t(unsigned(_mm_movemask_ps(beyond))) << b;
        }
#else
        for (int b = 0; b < 64; ++b) {
            negative |= std::uint64_t(side > 0.0 ? x[b] < 0.0f : x[b] > 0.0f) << b;
        }
#endif
        out.getWord<std::uint64_t>(w) = negative & ~leaf.getValueMask().getWord<std::uint64_t>(w);
    }
    return out;
}

/// Where localBlend() works, from the crease, on findCrease()'s flat arrays (its leaves, and
/// the bands' masks read there; with a list of its own, the crease's leaves and those around
/// them, and the masks read again, this took 9.7 ms on the radius-400 pair at p = 1000, now
/// 4.8): the crease's voxels where the blend can differ from the sharp value,
/// those that localBlend() visits and every band grows over (growCreaseBands()): where no input
/// is beyond its band on the side that decides the blend, and some input's band is within the
/// swell.
///
/// Beyond a band on the deciding side (in union form inside: the terms of a difference's
/// subtrahends and of an intersection are negated) the deciding term is the inside background
/// or below, and so is the blend (f <= min t), as is the sharp value. Farther than the swell
/// from every band, every term is beyond the band on the other side by more than the swell, and
/// so is the blend (f >= min t - swell): its value is the outside background, as the sharp
/// one's. A step to the best of the 26 neighbours brings a distance of a voxel or more down by
/// at least 1 voxel from a plane, and by 0.98 from a sphere of radius 3 voxels (the worst
/// direction of 400,000), so a voxel within the band and the swell of a surface is within
/// ceil(swell / 0.95) voxels of its band. On the radius-400 pair at p = 320 the others were a
/// quarter of the crease's voxels (860,196 -> 636,344), and the output is the same, bit for
/// bit.
///
/// The bands grow over those voxels alone: localBlend() reads planes at the voxels it blends
/// and at the voxels nearest their foot points, on the blended surface, where both terms are
/// within a few voxels of their surfaces, well inside the crease. A voxel to blend takes its
/// seed along paths within them; where a path would leave them, the nearest seed its
/// neighbours there offer: a tangent plane of the same surface, a voxel or so from the
/// unbounded extension's. A foot point's voxel outside them (rare) leaves the planes asked last.
///
/// Growing them by a voxel more (for the planes just outside) grew 1.5x as many voxels (557,104
/// against 376,632 an input on the radius-400 pair at p = 1000) for 10% (p = 1000) to 16%
/// (p = 320) more of the blend's compute. The two differ by under 0.003 voxel there, with the same
/// error against the exact blended surface (scripts/blend_accuracy.py), and on spheres of
/// radius 10 voxels by up to 0.023 voxel at up to three voxels in a hundred near the crease,
/// none of them farther from the exact blended surface by more than 0.001 voxel and 32 to 88
/// nearer (the largest error the same). Growing within the extension's length of the crease (as the
/// region does) guarantees the unbounded extension's seed, with 1.7x as many voxels again; it
/// differed from a voxel's growth by under 0.001 voxel on the radius-400 pair and by up to 0.04
/// voxel on inputs curved within a few voxels.
struct BlendDomain
{
    std::vector<Coord> origin;               // the crease's leaves with voxels to blend
    std::vector<MaskBits> blend;             // and those voxels
    std::unique_ptr<LeafSet> leaves;         // the leaves of origin
};

BlendDomain blendDomain(CsgOp op, const BlendPlan& plan,
                        const std::vector<openvdb::FloatGrid::Ptr>& grids, const FlatCrease& flat)
{
    const int near = std::clamp(int(std::ceil(plan.kernel.swell(plan.n) / plan.dx / 0.95)), 1,
                                kLeafDim);
    // findCrease()'s leaves hold every leaf the dilation by near (up to a leaf) reads for the
    // crease's leaves: the crease lies within the candidates, and a leaf around them is listed.
    const LeafSet& around = *flat.leaves;
    const size_t count = around.size();
    const std::vector<MaskBits> nearBand = dilatedOver(around, flat.bands, near);
    std::vector<MaskBits> blend(count);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, count),
                      [&](const tbb::blocked_range<size_t>& r) {
        std::vector<InputAccessor> acc;
        for (const auto& g : grids) acc.emplace_back(g->tree());
        for (size_t k = r.begin(); k < r.end(); ++k) {
            MaskBits bits = flat.crease[k] & nearBand[k];
            if (bits.isOff()) continue;
            const Coord o = around.origin[k];
            for (size_t i = 0; i < plan.n; ++i) {
                const double side = termSign(op, i);
                if (const LeafT* leaf = acc[i].probeConstLeaf(o)) {
                    bits &= !beyondOf(*leaf, side);
                } else if (!acc[i].isValueOn(o) && side * double(acc[i].getValue(o)) < 0.0) {
                    bits.setOff(); // beyond over the whole leaf
                }
            }
            blend[k] = bits;
        }
    });
    BlendDomain out;
    for (size_t k = 0; k < count; ++k) {
        if (blend[k].isOff()) continue;
        out.origin.push_back(around.origin[k]);
        out.blend.push_back(blend[k]);
    }
    plan.checkMemory(out.origin);
    out.leaves = std::make_unique<LeafSet>(out.origin);
    return out;
}

/// Step 3 where localBlend() does not apply, the grown bands: each input extended by its
/// dilation within keepReach() of the crease.
std::vector<GrownBand> growBands(const BlendPlan& plan,
                                 const std::vector<openvdb::FloatGrid::Ptr>& grids,
                                 const MaskTree& crease, util::Interrupter* interrupter)
{
    std::map<int, MaskTree::Ptr> byReach; // the inputs' reaches are often the same
    std::vector<MaskTree::Ptr> keep(plan.n);
    std::vector<SmallMaskTree::Ptr> keepLeaves(plan.n);
    for (size_t i = 0; i < plan.n; ++i) {
        const int reach = keepReach(plan, i);
        MaskTree::Ptr& k = byReach[reach];
        if (!k) k = dilatedCopy(crease, reach);
        keep[i] = k;
        keepLeaves[i] = leafMask(*keep[i]);
    }
    plan.checkMemory(keepLeaves);
    // The inputs side by side: each extension's own loops are parallel, but between them are
    // serial steps (a layer's leaves, the dilations), which the other input's work fills.
    std::vector<GrownBand> grown(plan.n);
    tbb::parallel_for(size_t(0), plan.n, [&](size_t i) {
        grown[i] = extendLocally(*grids[i], *keep[i], plan.dilation[i]);
    });
    util::checkInterrupt(interrupter);
    return grown;
}

/// Step 3 where localBlend() applies, the grown bands: each input extended by its dilation over
/// the voxels to blend (blendDomain()), on the flat arrays of extendOverLeaves().
struct CreaseBands
{
    std::unique_ptr<LeafSet> leaves;
    std::vector<FlatBand> band; // by input
};

CreaseBands growCreaseBands(const BlendPlan& plan,
                            const std::vector<openvdb::FloatGrid::Ptr>& grids,
                            BlendDomain& domain, util::Interrupter* interrupter)
{
    CreaseBands out;
    out.leaves = std::move(domain.leaves);
    const LeafSet& leaves = *out.leaves;
    out.band.resize(plan.n);
    // The inputs side by side, as in growBands().
    tbb::parallel_for(size_t(0), plan.n, [&](size_t i) {
        // Over the voxels to blend, which no input is beyond.
        out.band[i] = extendOverLeaves(*grids[i], leaves, domain.blend, plan.dilation[i]);
    });
    util::checkInterrupt(interrupter);
    return out;
}

/// Each input's term at the voxels of one region leaf at a time (seek(), then read()): its
/// grown band's value where known, else plus or minus @a clamp (the grown half width: beyond the
/// blend's reach) by the input's sign, clamped to +/- clamp, negated for the inputs a difference
/// subtracts; and which terms are within their grown bands.
class LeafTerms
{
public:
    /// The grown bands as trees (@a grown) or, with none, as flat arrays (seek()'s CreaseBands).
    LeafTerms(CsgOp op, const std::vector<openvdb::FloatGrid::Ptr>& grids,
              const std::vector<GrownBand>* grown, float clamp)
        : mOp(op), mClamp(clamp), t(grids.size()), reached(grids.size()),
          mKnown(grids.size()), mValue(grids.size()), mOrigLeaf(grids.size()),
          mOrigTile(grids.size())
    {
        for (size_t i = 0; i < grids.size(); ++i) {
            if (grown) mExt.emplace_back((*grown)[i].values->tree());
            mOrig.emplace_back(grids[i]->tree());
        }
    }

    /// The leaf at @a origin, of the trees.
    void seek(const Coord& origin)
    {
        for (size_t i = 0; i < t.size(); ++i) {
            const LeafT* ext = mExt[i].probeConstLeaf(origin);
            mKnown[i] = ext ? &ext->getValueMask() : nullptr;
            mValue[i] = ext ? ext->buffer().data() : nullptr;
        }
        seekInputs(origin);
    }

    /// The leaf at @a origin, leaf @a leaf (-1: none) of @a bands.
    void seek(const Coord& origin, const CreaseBands& bands, int leaf)
    {
        for (size_t i = 0; i < t.size(); ++i) {
            const FlatBand& b = bands.band[i];
            mKnown[i] = leaf >= 0 ? &b.known[size_t(leaf)] : nullptr;
            mValue[i] = leaf >= 0 ? b.value.get() + size_t(leaf) * LeafT::SIZE : nullptr;
        }
        seekInputs(origin);
    }

    void read(openvdb::Index m)
    {
        for (size_t i = 0; i < t.size(); ++i) {
            float v;
            if (mKnown[i] && mKnown[i]->isOn(m)) {
                v = mValue[i][m];
            } else {
                const float sv = mOrigLeaf[i] ? mOrigLeaf[i]->getValue(m) : mOrigTile[i];
                v = sv > 0.0f ? mClamp : -mClamp;
            }
            reached[i] = std::abs(v) < mClamp;
            v = std::max(-mClamp, std::min(mClamp, v));
            t[i] = (mOp == CsgOp::Difference && i > 0) ? -double(v) : double(v);
        }
    }

    /// The reached terms with the least, second and third least @a sign * t (size() for none).
    std::array<size_t, 3> leading(double sign) const
    {
        const size_t n = t.size();
        std::array<size_t, 3> best{n, n, n};
        for (size_t i = 0; i < n; ++i) {
            if (!reached[i]) continue;
            const double v = sign * t[i];
            if (best[0] == n || v < sign * t[best[0]]) best = {i, best[0], best[1]};
            else if (best[1] == n || v < sign * t[best[1]]) best = {best[0], i, best[1]};
            else if (best[2] == n || v < sign * t[best[2]]) best[2] = i;
        }
        return best;
    }

private:
    void seekInputs(const Coord& origin)
    {
        for (size_t i = 0; i < t.size(); ++i) {
            mOrigLeaf[i] = mOrig[i].probeConstLeaf(origin);
            mOrigTile[i] = mOrigLeaf[i] ? 0.0f : mOrig[i].getValue(origin);
        }
    }

    CsgOp mOp;
    float mClamp;

public:
    std::vector<double> t;
    std::vector<char> reached;

private:
    std::vector<openvdb::tree::ValueAccessor<const FloatTree>> mExt, mOrig;
    std::vector<const MaskBits*> mKnown; // each term's known voxels in the leaf (null: none)
    std::vector<const float*> mValue;    // and values
    std::vector<const LeafT*> mOrigLeaf;
    std::vector<float> mOrigTile;
};

/// Step 4, the blended values over @a region, and which of them differ from the sharp value.
struct BlendedValues
{
    openvdb::FloatGrid::Ptr values; // the blend over the region; its sign beyond
    MaskTree::Ptr blended = std::make_shared<MaskTree>(); // the voxels not keeping the sharp value
};

/// Outside a grown band an input counts as +/- the extended half width (beyond the blend's
/// reach), by its sign.
///
/// Which voxels keep the sharp value: take a union (an intersection is the union of the
/// complements) and the deciding term s = min t_i, with the next term s + g. The blended surface
/// leaves the sharp one only where two terms are within the reach R of each other and the
/// surface has swollen by at most ln(n)/p: there every term is below R + ln(n)/p. From a voxel
/// outside (s >= 0) those points are at least s + g - R - ln(n)/p away, so the sharp value s is
/// the distance if g >= R + ln(n)/p. From inside (s < 0), the nearest sharp surface point (|s|
/// away) is in the swollen part only if g < R + ln(n)/p + 2|s|. So a voxel whose lead g exceeds
/// R + ln(n)/p + 2 max(0, -s) (plus a voxel) keeps the sharp value; the others are marked as
/// blended and get re-distanced values.
BlendedValues blendValues(CsgOp op, const BlendPlan& plan, const BlendSettings& settings,
                          const std::vector<openvdb::FloatGrid::Ptr>& grids,
                          const std::vector<GrownBand>& grown,
                          const MaskTree& region, const openvdb::math::Transform& transform)
{
    const size_t n = plan.n;
    const float clamp = float(plan.needVox * plan.dx);
    const double lead = plan.kernel.reach(settings.tolerance * plan.dx) + plan.kernel.swell(n) +
                        plan.dx;
    BlendedValues out;
    out.values = openvdb::FloatGrid::create(clamp);
    out.values->setTransform(transform.copy());
    std::vector<const MaskTree::LeafNodeType*> in;
    for (auto it = region.cbeginLeaf(); it; ++it) in.push_back(it.getLeaf());
    std::vector<LeafT*> leaves(in.size());
    std::vector<MaskTree::LeafNodeType*> marks(in.size());
    for (size_t k = 0; k < in.size(); ++k) {
        leaves[k] = out.values->tree().touchLeaf(in[k]->origin());
        marks[k] = out.blended->touchLeaf(in[k]->origin());
    }
    const double sign = op == CsgOp::Union ? 1.0 : -1.0;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, in.size()),
                      [&](const tbb::blocked_range<size_t>& r) {
        LeafTerms terms(op, grids, &grown, clamp);
        for (size_t k = r.begin(); k < r.end(); ++k) {
            LeafT& leaf = *leaves[k];
            MaskTree::LeafNodeType& mark = *marks[k];
            terms.seek(leaf.origin());
            for (openvdb::Index m = 0; m < LeafT::SIZE; ++m) {
                terms.read(m);
                const float f = float(plan.kernel.combine(op, terms.t.data(), n));
                if (!in[k]->isValueOn(m)) { // outside the region: its sign only
                    leaf.setValueOff(m, f > 0.0f ? clamp : -clamp);
                    continue;
                }
                leaf.setValueOn(m, f);
                // The lead of the deciding term over the next; a term beyond its grown band is
                // beyond the blend's reach, however near it looks after clamping.
                const auto [first, second, third] = terms.leading(sign);
                (void)third;
                if (second != n && !implicit::leadKeepsDistance(sign * terms.t[first],
                                                                 sign * terms.t[second], lead)) {
                    mark.setValueOn(m); // two terms within reach, the second close enough
                }
            }
        }
    });
    openvdb::tools::signedFloodFill(out.values->tree());
    out.values->setGridClass(openvdb::GRID_LEVEL_SET);
    return out;
}

/// How close (voxels) two successive distances must be to stop, and the most steps taken. The
/// planes come from the voxel nearest y, so y may alternate between two voxels whose planes
/// differ by the grid's own noise (about 3e-4 voxel on a radius-400 sphere): the distances
/// then agree within this.
constexpr double kSettled = 2e-3;
constexpr int kMaxSteps = 8;
/// Planes of two voxels that send y to each other are taken as agreeing if the distances they
/// give are this close (voxels), and the answer is their mean (they differed by up to 0.006
/// voxel on spheres of radius 60 voxels).
constexpr double kCycle = 0.02;
/// A weight this close to 0 or 1 is one term's alone.
constexpr double kEnd = 1e-6;

/// The distance where the planes of a few voxels send y round in a cycle, giving the
/// distances @a phi with weights @a w (the deciding term's) in turn, @a ownA and @a ownB each
/// term's own distance at x. Within kCycle, the middle of their range (two voxels' planes: their
/// mean). Apart (surfaces curved within a few voxels: on spheres of radius 6 to 20 voxels they
/// differed by up to 0.24 voxel): where one term weighs all throughout, the distance is that
/// term's own, from x's plane, which the extension found nearest; where each weighs all at some
/// step (the middle of a valley, each side's planes sending y to the other), the nearer term's
/// own; else the middle of the range. On two spheres of radius 10 voxels the crease is then
/// within 0.045 and 0.021 voxel of the exact distance (p = 1/dx and 2/dx), where fast sweeping,
/// which took the whole crease when one voxel did not settle, was 0.167 and 0.169 voxel off
/// (TestBlendGrid.CurvedInputsStayLocal).
double cycleDistance(const double* phi, const double* w, int n, double ownA, double ownB)
{
    const auto [lo, hi] = std::minmax_element(phi, phi + n);
    const auto [wLo, wHi] = std::minmax_element(w, w + n);
    if (*hi - *lo < kCycle) return 0.5 * (*lo + *hi);
    if (*wLo > 1.0 - kEnd) return ownA;
    if (*wHi < kEnd) return ownB;
    if (*wLo < kEnd && *wHi > 1.0 - kEnd) return std::min(ownA, ownB);
    return 0.5 * (*lo + *hi);
}

/// The voxel nearest @a y (index space), as openvdb::Coord::round() gives it: floor(y + 0.5)
/// each, without the library call that floor() is where the target lacks SSE4.1's roundsd
/// (a blended voxel asks two or three times). @a y within the int range.
inline Coord nearestVoxel(const openvdb::Vec3d& y)
{
    auto down = [](double v) {
        const double t = v + 0.5;
        const int i = int(t); // toward zero
        return i - int(t < double(i));
    };
    return Coord(down(y.x()), down(y.y()), down(y.z()));
}

/// Step 4 and 5 at once, locally: the blended voxels' distances found voxel by voxel from the
/// closest-point extension's planes, instead of the blend's values re-distanced by fast
/// sweeping (docs/method.md#grid-blend).
///
/// Which voxels are blended: blendValues()'s rule, which marks only voxels that two grown bands
/// reach, so only the @a crease's voxels are read. A blended voxel whose blend f has |f| of at
/// least the background is beyond the band, since f is 1-Lipschitz: only its sign is set (inside)
/// or the sharp value stays (outside), with no distance to find. At a blended voxel x the two
/// terms within reach are, near x, planes: the tangent planes at their closest points, which the
/// extension holds for every voxel of the grown bands. The distance from x to the blend of two
/// planes is detail::planeBlendDistance(); the point where it is attained, y, has planes of its own
/// (those of the voxel nearest y), and the distance is taken again with them, until it moves by
/// under kSettled. The planes' error is second order in the distance from y to where they touch
/// (about 0.5^2 / 2R voxel for a surface of radius R voxels), where fast sweeping's is first
/// order in the voxel: against the exact distance to the blend of two spheres of radius 60
/// voxels, within 0.006 voxel where fast sweeping was up to 0.026 to 0.047 voxel off
/// (TestBlendGrid.CreaseVoxelsAreTheDistanceToTheBlendedSurface).
///
/// Inside, where the lead rule's bound on the lead's fall to the nearest point alone sends a voxel
/// here, the next term is read at that point instead, and where it still leads, the distance is
/// the deciding term's less the blend's offset there (detail::blendOffset()): no minimization.
///
/// Returns nothing (and the caller re-distances by fast sweeping) where this does not apply: a
/// third term within reach, two planes facing each other (a gap the blend bridges), or
/// planes that keep changing.
std::optional<std::vector<BlendSplice>> localBlend(CsgOp op, const BlendPlan& plan,
                                                   const BlendSettings& settings,
                                                   const std::vector<openvdb::FloatGrid::Ptr>& grids,
                                                   const CreaseBands& bands,
                                                   const BlendDomain& domain)
{
    const size_t n = plan.n;
    const LeafSet& leaves = *bands.leaves;
    const float clamp = float(plan.needVox * plan.dx);
    const double lead = plan.kernel.reach(settings.tolerance * plan.dx) + plan.kernel.swell(n) +
                        plan.dx;
    const detail::UnionKernel kernel = detail::UnionKernel::inUnits(plan.kernel, plan.dx);
    const float bg = plan.bg;
    const double swell = plan.kernel.swell(n);
    // Union form: an intersection is the union of the complements, a difference subtracts.
    const double sign = op == CsgOp::Union ? 1.0 : -1.0;

    const size_t count = domain.origin.size();
    // The leaves with a changed voxel (most crease leaves have none: a splice for each would be
    // tens of MB of fresh pages at radius 400).
    std::vector<std::unique_ptr<BlendSplice>> changed(count);
    std::atomic<bool> failed{false};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, count),
                      [&](const tbb::blocked_range<size_t>& r) {
        LeafTerms terms(op, grids, nullptr, clamp);
        LeafSet::IndexAccessor index = leaves.accessor();
        int leaf = -1; // the crease leaf's index in leaves
        // A term's plane in union form, index space: u(z) = m . (z - c).
        struct Plane
        {
            openvdb::Vec3d c, m;
            int seed = -1; // the seed it comes from
        };
        // Term i's plane at voxel v of leaves (leaf * 512 + offset). False: p unchanged.
        auto planeOf = [&](size_t i, size_t v, Plane& p) {
            const FlatBand& band = bands.band[i];
            const int k = band.seedOf[v];
            if (k < 0) return false; // not reached
            const Seeds& seeds = band.seeds;
            const openvdb::Vec3d m = termSign(op, i) * openvdb::Vec3d(seeds.normal[size_t(k)]);
            if (m.lengthSqr() < 0.25) return false; // no normal
            p.c = openvdb::Vec3d(seeds.point[size_t(k)]);
            p.m = m;
            p.seed = k;
            return true;
        };
        auto planeAt = [&](size_t i, const Coord& ijk, Plane& p) { // false: p unchanged
            const int at = leaves.find(ijk, leaf, index);
            return at >= 0 && planeOf(i, size_t(at) * LeafT::SIZE + LeafT::coordToOffset(ijk), p);
        };
        // Terms i1's and i2's planes at @a ijk, the voxel found once for both: true if both
        // are there (each unchanged where it has none).
        auto planesAt = [&](size_t i1, size_t i2, const Coord& ijk, Plane& pa, Plane& pb) {
            const int at = leaves.find(ijk, leaf, index);
            if (at < 0) return false;
            const size_t v = size_t(at) * LeafT::SIZE + LeafT::coordToOffset(ijk);
            const bool a = planeOf(i1, v, pa);
            const bool b = planeOf(i2, v, pb);
            return a && b;
        };
        BlendSplice s;
        for (size_t k = r.begin(); k < r.end() && !failed; ++k) {
            s = BlendSplice{};
            const Coord o = domain.origin[k];
            for (int a = 0; a < 3; ++a) s.origin[a] = o[a];
            leaf = leaves.find(o, -1, index);
            terms.seek(o, bands, leaf);
            LeafT::NodeMaskType marked, active;
            // A blended voxel's distance: active within the band, beyond it the background by
            // its sign.
            auto put = [&](openvdb::Index m, float value) {
                marked.setOn(m);
                if (std::abs(value) < bg) {
                    s.values[m] = value;
                    active.setOn(m);
                } else {
                    s.values[m] = value > 0.0f ? bg : -bg;
                }
            };
            for (auto it = domain.blend[k].beginOn(); it; ++it) {
                const openvdb::Index m = it.pos();
                terms.read(m);
                // The deciding term, the next, and a third within reach: blendValues()'s rule.
                const auto [i1, i2, i3] = terms.leading(sign);
                const auto u = [&](size_t i) { return sign * terms.t[i]; };
                if (i2 == n || implicit::leadKeepsDistance(u(i1), u(i2), lead)) continue;
                if (i3 != n && !implicit::leadKeepsDistance(u(i1), u(i3), lead)) {
                    failed = true; // three terms: the blend of two planes does not apply
                    return;
                }
                // The blend is 1-Lipschitz (its gradient a convex combination of the terms'), so
                // |f| is at most the distance to its surface: at |f| >= bg the voxel is beyond the
                // band, and only its sign (f's) counts. Beyond on the outside the sharp value
                // (min t >= f) is there too, with the same sign: the voxel is left as it is. The
                // blend lies within the swell below the least term, which decides most voxels;
                // where that term is at -bg or below (beyond its band: the sharp value is the
                // inside background already), so is the blend.
                const double least = u(i1);
                if (least - swell >= bg || least <= -bg) continue;
                const Coord ijk = o + LeafT::offsetToLocalCoord(m);
                // Inside, where only the lead rule's 2|s| sends the voxel here (its bound on how
                // far the lead falls on the way to the nearest point y, |s| away, both terms
                // 1-Lipschitz): read the next term at y (the deciding term's foot point, from its
                // plane) from the plane of y's voxel; between planes the lead falls by
                // |s| (1 - n1 . n2). If it still leads by the rule's margin, only one term weighs
                // near y: the blended surface is the deciding one moved out by blendOffset(), and
                // the distance is s less that (no other point of the blended surface is nearer:
                // the blended solid holds the sharp one, and the ball of radius |s| about x lies
                // in it). Within 2e-4 voxel of the minimization's planes (TestBlendDistance), and
                // nearer the exact surface on spheres (docs/performance.md#csg-and-blends).
                if (least < 0.0 && u(i2) - least >= lead) {
                    Plane pf, pn;
                    if (planeAt(i1, ijk, pf) && planeAt(i2, nearestVoxel(pf.c), pn)) {
                        const double next = pn.m.dot(pf.c - pn.c); // voxels
                        if (next * plan.dx >= lead) {
                            const double offset = detail::blendOffset(kernel, next);
                            if (offset == 0.0) continue; // the sharp value (a smooth minimum)
                            put(m, float(sign * (least - offset * plan.dx)));
                            continue;
                        }
                    }
                }
                Plane pa, pb;
                const bool planes = planesAt(i1, i2, ijk, pa, pb);
                const openvdb::Vec3d x(ijk.x(), ijk.y(), ijk.z());
                // Each term's own distance at x: what the blend is where one term weighs all.
                const double ownA = pa.m.dot(x - pa.c), ownB = pb.m.dot(x - pb.c);
                // The blend at x: from the planes' values there (the terms, up to a float's
                // rounding), as the first-order estimate below takes it; from the terms where
                // x has no planes (a voxel beyond the band needs none).
                detail::PlaneBlendDistance e;
                if (planes) e = detail::planeBlendEstimate(kernel, ownA, ownB, pa.m.dot(pb.m));
                const double f = planes ? e.blend * plan.dx
                                        : sign * plan.kernel.combine(op, terms.t.data(), n);
                if (f >= bg) continue;
                if (f <= -bg) {
                    marked.setOn(m);
                    s.values[m] = float(-sign) * bg;
                    continue;
                }
                if (!planes) {
                    failed = true;
                    return;
                }
                // Start from the planes of the voxel nearest x's first-order foot point with
                // x's planes (detail::planeBlendEstimate(): no minimization). Started from x's
                // own planes, nearly every voxel took a second minimization (within the band
                // each voxel is its own seed, so y's planes differ); from the predicted ones
                // 94% (p = 1000) to 97% (p = 320) settle after one on the radius-400 pair.
                Coord asked = ijk; // the voxel whose planes pa and pb are (or x's, where none)
                {
                    const openvdb::Vec3d g = e.weight * pa.m + (1.0 - e.weight) * pb.m;
                    const double len = g.length();
                    if (e.ok && len > 1e-6) {
                        const Coord at = nearestVoxel(x - (e.distance / len) * g);
                        if (at != asked) { // x's own planes again, where the foot is nearest x
                            planesAt(i1, i2, at, pa, pb);
                            asked = at;
                        }
                    }
                }
                // The first minimization starts where x's estimate puts the foot point's weight
                // (detail::PlaneBlendDistance::start; the planes there are near x's), the others
                // where the last ended.
                double start = e.start;
                double phi = 0.0, previous = 0.0, weight = -1.0, lastWeight = -1.0;
                double seen[kMaxSteps], seenWeight[kMaxSteps]; // each step's distance, weight
                bool settled = false, cycle = false;
                for (int iter = 0; iter < kMaxSteps && !settled; ++iter) {
                    const detail::PlaneBlendDistance d = detail::planeBlendDistance(
                        kernel, pa.m.dot(x - pa.c), pb.m.dot(x - pb.c), pa.m.dot(pb.m), start);
                    if (!d.ok) {
                        failed = true;
                        return;
                    }
                    settled = iter > 0 && std::abs(d.distance - phi) < kSettled;
                    // The planes of a few voxels taking turns: a distance seen before, at least
                    // two steps ago.
                    for (int j = iter - 2; j >= 0 && !cycle; --j) {
                        if (std::abs(d.distance - seen[j]) < 1e-7) {
                            cycle = true;
                            phi = cycleDistance(seen + j, seenWeight + j, iter - j, ownA, ownB);
                        }
                    }
                    if (cycle) break;
                    previous = phi;
                    phi = d.distance;
                    lastWeight = weight;
                    weight = d.weight;
                    start = d.start;
                    seen[iter] = phi;
                    seenWeight[iter] = weight;
                    const openvdb::Vec3d g = d.weight * pa.m + (1.0 - d.weight) * pb.m;
                    const double len = g.length();
                    if (!(len > 1e-6)) {
                        failed = true;
                        return;
                    }
                    // The planes of the voxel nearest y (the old ones where it has none); the
                    // same planes again (often: a seed passes along its normal) give the same
                    // distance, and the voxel asked last gives them with nothing to read.
                    const Coord at = nearestVoxel(x - (phi / len) * g);
                    if (at == asked) {
                        settled = true;
                        continue;
                    }
                    const int seedA = pa.seed, seedB = pb.seed;
                    planesAt(i1, i2, at, pa, pb);
                    asked = at;
                    if (pa.seed == seedA && pb.seed == seedB) settled = true;
                }
                // Near the middle of a valley the nearest point may be on either term's side,
                // each side's planes sending y to the other: then one term weighs all at either
                // (the smooth minimum's flat parts), and the distance is the nearer term's own.
                if (!settled && !cycle && std::min(weight, lastWeight) < kEnd &&
                    std::max(weight, lastWeight) > 1.0 - kEnd) {
                    phi = std::min(ownA, ownB);
                    settled = true;
                }
                // Beyond the band only the sign is kept, which needs no settling.
                if (!settled && !cycle && std::abs(phi) - std::abs(phi - previous) < plan.halfWidth) {
                    failed = true;
                    return;
                }
                put(m, float(sign * phi * plan.dx));
            }
            if (marked.isOff()) continue;
            for (int w = 0; w < BlendSplice::kWords; ++w) {
                s.marked[w] = marked.getWord<std::uint64_t>(openvdb::Index(w));
                s.active[w] = active.getWord<std::uint64_t>(openvdb::Index(w));
            }
            changed[k] = std::make_unique<BlendSplice>(s);
        }
    });
    if (failed) return std::nullopt;
    std::vector<BlendSplice> out;
    out.reserve(size_t(std::count_if(changed.begin(), changed.end(),
                                     [](const auto& c) { return c != nullptr; })));
    for (const auto& c : changed) {
        if (c) out.push_back(*c);
    }
    return out;
}

/// Step 5, distances for the blended voxels: the blend is not a distance (|grad f| < 1 near
/// the crease), so its values become estimates f / |grad f| (in place), and the surface within a
/// band width of the blended voxels is re-distanced (the other voxels keep their values,
/// inactive, for their signs).
openvdb::FloatGrid::Ptr redistanceBlend(BlendedValues& b, const BlendPlan& plan,
                                        util::Interrupter* interrupter)
{
    const double clamp = double(b.values->background());
    const auto grad = diff::gradient(*b.values, 1);
    openvdb::tree::LeafManager<FloatTree> manager(b.values->tree());
    manager.foreach([&](LeafT& leaf, size_t) {
        const auto* g = grad->tree().probeConstLeaf(leaf.origin());
        if (!g) return;
        for (auto it = leaf.beginValueOn(); it; ++it) {
            const double len = g->getValue(it.pos()).length();
            const double e = *it / std::max(len, 0.1);
            it.setValue(float(std::max(-clamp, std::min(clamp, e))));
        }
    });
    util::checkInterrupt(interrupter);
    auto samples = b.values->deepCopy();
    const MaskTree::Ptr around = dilatedCopy(*b.blended, plan.regionReach());
    openvdb::tree::LeafManager<FloatTree> sampleLeaves(samples->tree());
    sampleLeaves.foreach([&](LeafT& leaf, size_t) {
        const MaskTree::LeafNodeType* m = around->probeConstLeaf(leaf.origin());
        leaf.setValueMask(m ? leaf.getValueMask() & m->getValueMask() : LeafT::NodeMaskType());
    });
    return levelset::redistance(*samples, plan.halfWidth, interrupter);
}

/// Step 6, the splice: the re-distanced blend replaces the sharp result at the blended voxels
/// (inside the band), or their sign does (beyond it): per leaf, those voxels' values and states.
std::vector<BlendSplice> spliceLeaves(const BlendedValues& b, const openvdb::FloatGrid& redistanced,
                                      float bg)
{
    std::vector<const MaskTree::LeafNodeType*> marks;
    for (auto it = b.blended->cbeginLeaf(); it; ++it) {
        if (!it->isEmpty()) marks.push_back(it.getLeaf());
    }
    std::vector<BlendSplice> out(marks.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, marks.size()),
                      [&](const tbb::blocked_range<size_t>& r) {
        for (size_t k = r.begin(); k < r.end(); ++k) {
            const MaskTree::LeafNodeType& mark = *marks[k];
            BlendSplice& s = out[k];
            const Coord o = mark.origin();
            for (int a = 0; a < 3; ++a) s.origin[a] = o[a];
            LeafT::NodeMaskType active;
            const LeafT* d = redistanced.tree().probeConstLeaf(o);
            const LeafT* f = b.values->tree().probeConstLeaf(o);
            for (openvdb::Index m = 0; m < LeafT::SIZE; ++m) {
                if (!mark.isValueOn(m)) continue;
                const float v = d ? d->getValue(m) : bg;
                if (d && d->isValueOn(m) && std::abs(v) < bg) {
                    s.values[m] = v;
                    active.setOn(m);
                } else {
                    const float sv = f ? f->getValue(m) : v;
                    s.values[m] = sv > 0.0f ? bg : -bg;
                }
            }
            for (int w = 0; w < BlendSplice::kWords; ++w) {
                s.marked[w] = mark.getValueMask().getWord<std::uint64_t>(openvdb::Index(w));
                s.active[w] = active.getWord<std::uint64_t>(openvdb::Index(w));
            }
        }
    });
    return out;
}

std::string blendNote(const BlendPlan& plan, std::uint64_t creaseVoxels)
{
    std::ostringstream os;
    if (creaseVoxels == 0) {
        os << "the inputs do not come within the blend's reach of each other ("
           << plan.kernel.describe() << "): the result is the sharp operation";
    } else {
        os << "bands extended to " << plan.needVox << " voxels where the inputs meet, for "
           << plan.kernel.describe() << " (reach "
           << util::formatNumber(std::round(plan.reachVox * 10) / 10) << " voxels; "
           << util::formatNumber(double(creaseVoxels))
           << " voxels around the crease checked)";
    }
    return os.str();
}

/// How far (voxels) around the crease compute() reads input @a i's values: the voxels whose
/// bands it grows (keep) and what growing them reads, one voxel beyond for the normals' stencil
/// or the extension's length beyond for fast sweeping.
int readReach(const BlendPlan& plan, size_t i)
{
    const int keep = keepReach(plan, i);
    return keep + plan.dilation[i] + 2;
}

// The blend of level sets already on one transform; consumes @a grids (the sharp operation
// steals their nodes). The result is the sharp operation (OpenVDB's csg tools) everywhere but
// around the crease, which alone needs grown bands and re-distancing.
openvdb::FloatGrid::Ptr blendOnTarget(CsgOp op, const std::vector<openvdb::FloatGrid::Ptr>& grids,
                                      const BlendSettings& settings, std::vector<std::string>* notes)
{
    util::InterruptScope scope(settings.interrupter, "Blending");
    const BlendCrease crease(grids, settings);
    if (notes) notes->push_back(crease.note());
    std::vector<BlendSplice> splice;
    if (!crease.empty()) splice = crease.compute(op, grids, settings.interrupter);
    openvdb::FloatGrid::Ptr result = csgInPlace(op, grids, nullptr);
    if (!crease.empty()) {
        spliceBlend(result->tree(), splice);
        openvdb::tools::pruneLevelSet(result->tree());
    }
    result->setGridClass(openvdb::GRID_LEVEL_SET);
    result->setName("surface");
    scope.end();
    return result;
}

} // namespace

implicit::BlendKernel blendKernel(const BlendSettings& settings)
{
    return settings.k != 0.0 ? implicit::BlendKernel::polynomial(settings.k)
                            : implicit::BlendKernel::superElliptic(settings.p);
}

double blendReach(double p, double toleranceWorld)
{
    return std::max(0.0, std::log(1.0 / (p * toleranceWorld)) / p);
}

struct BlendCrease::Impl
{
    BlendSettings settings;
    BlendPlan plan;
    FlatCrease flat; // the crease's flat arrays, for extensions of up to a leaf
    std::uint64_t creaseVoxels = 0;

    /// The crease as a tree: findCrease()'s, or built from the flat arrays on first use (3 ms
    /// on the radius-400 pair, which localBlend() does without).
    const MaskTree& crease() const
    {
        std::call_once(mBuilt, [this] {
            if (!mCrease) mCrease = flat.creaseTree();
        });
        return *mCrease;
    }

    void setCrease(MaskTree::Ptr tree) { mCrease = std::move(tree); }

    /// The crease's fast-sweeping re-distancing (when the blend of two planes does not apply)
    /// reads the surface within a band width of it: the region it writes.
    MaskTree::Ptr region() const
    {
        return dilatedCopy(crease(), plan.regionReach());
    }

private:
    mutable std::once_flag mBuilt;
    mutable MaskTree::Ptr mCrease;
};

BlendCrease::BlendCrease(const std::vector<openvdb::FloatGrid::Ptr>& grids,
                         const BlendSettings& settings)
    : mImpl(std::make_unique<Impl>())
{
    checkSettings(grids.size(), settings);
    Impl& m = *mImpl;
    m.settings = settings;
    m.plan = planBlend(grids, settings);
    m.setCrease(findCrease(m.plan, grids, m.flat));
    if (m.flat.leaves) {
        for (const MaskBits& bits : m.flat.crease) m.creaseVoxels += bits.countOn();
    } else {
        m.creaseVoxels = m.crease().activeVoxelCount();
    }
    util::checkInterrupt(settings.interrupter);
}

BlendCrease::~BlendCrease() = default;

bool BlendCrease::empty() const { return mImpl->creaseVoxels == 0; }

std::string BlendCrease::note() const
{
    return blendNote(mImpl->plan, mImpl->creaseVoxels);
}

std::vector<Coord> BlendCrease::leavesRead(size_t input) const
{
    const Impl& m = *mImpl;
    if (empty()) return {};
    return leafOrigins(*leafMask(*dilatedCopy(m.crease(), readReach(m.plan, input))));
}

std::vector<Coord> BlendCrease::leavesWritten() const
{
    if (empty()) return {};
    return leafOrigins(*leafMask(*mImpl->region()));
}

std::vector<BlendSplice> BlendCrease::compute(CsgOp op,
                                              const std::vector<openvdb::FloatGrid::Ptr>& grids,
                                              util::Interrupter* interrupter) const
{
    const Impl& m = *mImpl;
    if (empty()) return {};
    // The blend of two planes needs every band grown by closest points.
    const bool closestPoints = std::all_of(m.plan.dilation.begin(), m.plan.dilation.end(),
                                           [](int d) { return d <= kMaxClosestPointLayers; });
    if (closestPoints && m.flat.leaves) { // the flat arrays are there for such extensions
        BlendDomain domain = blendDomain(op, m.plan, grids, m.flat);
        std::optional<std::vector<BlendSplice>> local;
        {
            const CreaseBands bands = growCreaseBands(m.plan, grids, domain, interrupter);
            local = localBlend(op, m.plan, m.settings, grids, bands, domain);
        } // the bands grown for the crease freed
        if (local) return std::move(*local);
    }
    // Where it does not apply: the blend's values over the region, with every band grown over
    // it, re-distanced.
    const std::vector<GrownBand> grown = growBands(m.plan, grids, m.crease(), interrupter);
    BlendedValues blended = blendValues(op, m.plan, m.settings, grids, grown, *m.region(),
                                        finestInput(grids).transform());
    const openvdb::FloatGrid::Ptr redistanced = redistanceBlend(blended, m.plan, interrupter);
    return spliceLeaves(blended, *redistanced, m.plan.bg);
}

void spliceBlend(openvdb::FloatTree& tree, const std::vector<BlendSplice>& leaves)
{
    std::vector<LeafT*> out(leaves.size());
    for (size_t k = 0; k < leaves.size(); ++k) {
        const BlendSplice& s = leaves[k];
        out[k] = tree.touchLeaf(Coord(s.origin[0], s.origin[1], s.origin[2]));
    }
    tbb::parallel_for(tbb::blocked_range<size_t>(0, out.size()),
                      [&](const tbb::blocked_range<size_t>& r) {
        for (size_t k = r.begin(); k < r.end(); ++k) {
            const BlendSplice& s = leaves[k];
            LeafT& leaf = *out[k];
            for (openvdb::Index m = 0; m < LeafT::SIZE; ++m) {
                const std::uint64_t bit = std::uint64_t(1) << (m & 63);
                if (!(s.marked[m >> 6] & bit)) continue;
                if (s.active[m >> 6] & bit) leaf.setValueOn(m, s.values[m]);
                else leaf.setValueOff(m, s.values[m]);
            }
        }
    });
}

openvdb::FloatGrid::Ptr blend(CsgOp op, const std::vector<openvdb::FloatGrid::ConstPtr>& inputs,
                              const BlendSettings& settings, std::vector<std::string>* notes)
{
    checkSettings(inputs.size(), settings);
    const openvdb::math::Transform& target = finestInput(inputs).transform();
    std::vector<openvdb::FloatGrid::Ptr> grids;
    for (const auto& in : inputs) grids.push_back(matchTransform(*in, target, notes));
    return blendOnTarget(op, grids, settings, notes);
}

openvdb::FloatGrid::Ptr blendInPlace(CsgOp op, const std::vector<openvdb::FloatGrid::Ptr>& inputs,
                                     const BlendSettings& settings, std::vector<std::string>* notes)
{
    checkSettings(inputs.size(), settings);
    const openvdb::math::Transform target = finestInput(inputs).transform();
    std::vector<openvdb::FloatGrid::Ptr> grids;
    for (const auto& in : inputs) {
        grids.push_back(in->transform() == target ? in : matchTransform(*in, target, notes));
    }
    return blendOnTarget(op, grids, settings, notes);
}

} // namespace ivdb::ops
