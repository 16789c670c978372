// SPDX-License-Identifier: Apache-2.0
#pragma once

/// @file LeafSet.h
/// @brief The leaves of a mask as one flat list, each with its 26 neighbours, and bit masks
/// held by leaf of such a list grown by a cube of voxels: the grid blend's flat arrays
/// (internal to ops; tests reach it by path).

#include <openvdb/openvdb.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdlib>
#include <vector>

namespace ivdb::ops::detail {

using MaskBits = openvdb::MaskTree::LeafNodeType::NodeMaskType;
using openvdb::Coord;
using openvdb::MaskTree;

constexpr int kLog2 = 3; // 8^3 leaves
constexpr int kDim = 1 << kLog2;
static_assert(MaskBits::WORD_COUNT == 8, "one 64-bit word per x slice of a leaf, bit y * 8 + z");

/// The leaves of a mask as one list, for arrays indexed by leaf and voxel, with each leaf's
/// neighbours.
class LeafSet
{
public:
    /// Small internal nodes (8^3 children each): the index holds one voxel a leaf, few and
    /// close together, and a tree of OpenVDB's config clears a 256 KB table for each top node
    /// (a voxel in each of the eight octants around the origin took 186 us to set, one 21 us).
    using IndexTree = openvdb::tree::Tree4<std::int32_t, 3, 3, 3>::Type;
    using IndexAccessor = openvdb::tree::ValueAccessor<const IndexTree>;

    /// Which neighbours around lists: all 26, or only the 6 across a face (dilatedOver()
    /// reads no others; the others are then -1).
    enum class Around { All, Faces };

    explicit LeafSet(const MaskTree& mask) : LeafSet(originsOf(mask)) {}

    /// The leaves at @a origins (leaf origins, each once).
    explicit LeafSet(std::vector<Coord> origins, Around neighbours = Around::All)
        : origin(std::move(origins)), mIndex(-1)
    {
        {
            openvdb::tree::ValueAccessor<IndexTree> index(mIndex);
            for (std::size_t k = 0; k < origin.size(); ++k) {
                index.setValueOn(origin[k] >> kLog2, int(k));
            }
        }
        around.resize(origin.size());
        // By leaf of the index (8^3 of the set's leaves), with the 26 index leaves around it at
        // hand. Asked for each leaf's neighbours, an accessor traded its cached leaf whenever one
        // lay across an index leaf's face (more than half of the set's leaves have one): with
        // it, listing the 27,249 leaves around the radius-400 pair's crease took 3.3 ms, now
        // 1.7 to 2.2 (temporary timers).
        using IndexLeaf = IndexTree::LeafNodeType;
        constexpr int kIndexDim = int(IndexLeaf::DIM);
        std::vector<const IndexLeaf*> indexLeaves;
        mIndex.getNodes(indexLeaves);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, indexLeaves.size()),
                          [&](const tbb::blocked_range<std::size_t>& r) {
            IndexAccessor acc(mIndex);
            for (std::size_t l = r.begin(); l < r.end(); ++l) {
                const IndexLeaf& leaf = *indexLeaves[l];
                const IndexLeaf* near[27];
                for (int dx = -1; dx <= 1; ++dx) {
                    for (int dy = -1; dy <= 1; ++dy) {
                        for (int dz = -1; dz <= 1; ++dz) {
                            near[aroundIndex(Coord(dx, dy, dz))] = acc.probeConstLeaf(
                                leaf.origin().offsetBy(dx * kIndexDim, dy * kIndexDim,
                                                       dz * kIndexDim));
                        }
                    }
                }
                // Which index leaf (-1, 0, 1 along an axis) holds a local coordinate of -1..8.
                const auto side = [](int v) { return v < 0 ? -1 : v >= kIndexDim ? 1 : 0; };
                for (auto it = leaf.cbeginValueOn(); it; ++it) {
                    const std::size_t k = std::size_t(*it);
                    const Coord local = IndexLeaf::offsetToLocalCoord(it.pos());
                    for (int dx = -1; dx <= 1; ++dx) {
                        for (int dy = -1; dy <= 1; ++dy) {
                            for (int dz = -1; dz <= 1; ++dz) {
                                const Coord d(dx, dy, dz);
                                const bool face = std::abs(dx) + std::abs(dy) + std::abs(dz) <= 1;
                                int& to = around[k][aroundIndex(d)];
                                to = -1; // no leaf there (an index leaf's inactive voxels too)
                                if (neighbours != Around::All && !face) continue;
                                const Coord q = local + d;
                                const Coord w(side(q.x()), side(q.y()), side(q.z()));
                                if (const IndexLeaf* n = near[aroundIndex(w)]) {
                                    to = n->getValue(IndexLeaf::coordToOffset(
                                        q.offsetBy(-w.x() * kIndexDim, -w.y() * kIndexDim,
                                                   -w.z() * kIndexDim)));
                                }
                            }
                        }
                    }
                }
            }
        });
    }

    std::size_t size() const { return origin.size(); }
    IndexAccessor accessor() const { return IndexAccessor(mIndex); }

    /// Where around (below) holds the leaf @a d leaves away (each of d's coordinates in
    /// -1..1).
    static std::size_t aroundIndex(const Coord& d)
    {
        return std::size_t((d.x() + 1) * 9 + (d.y() + 1) * 3 + d.z() + 1);
    }

    /// The masks of @a mask's leaves at this set's leaves, in its order (none where it has no
    /// leaf).
    std::vector<MaskBits> masksOf(const MaskTree& mask) const
    {
        std::vector<MaskBits> out(origin.size());
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, origin.size()),
                          [&](const tbb::blocked_range<std::size_t>& r) {
            openvdb::tree::ValueAccessor<const MaskTree> acc(mask);
            for (std::size_t k = r.begin(); k < r.end(); ++k) {
                const auto* leaf = acc.probeConstLeaf(origin[k]);
                if (leaf) out[k] = leaf->getValueMask();
            }
        });
        return out;
    }

    /// The index of the leaf holding the voxel @a ijk (-1: none), looked up among the
    /// neighbours of leaf @a near where it is one of them.
    int find(const Coord& ijk, int near, IndexAccessor& acc) const
    {
        const Coord c = ijk >> kLog2;
        if (near >= 0) {
            const Coord d = c - (origin[std::size_t(near)] >> kLog2);
            if (std::abs(d.x()) <= 1 && std::abs(d.y()) <= 1 && std::abs(d.z()) <= 1) {
                return around[std::size_t(near)][aroundIndex(d)];
            }
        }
        return acc.getValue(c);
    }

    std::vector<Coord> origin;
    /// Each leaf's 27 neighbours (itself among them), at aroundIndex(); -1: none (or not
    /// listed: Around::Faces).
    std::vector<std::array<int, 27>> around;

private:
    static std::vector<Coord> originsOf(const MaskTree& mask)
    {
        std::vector<Coord> out;
        for (auto it = mask.cbeginLeaf(); it; ++it) out.push_back(it->origin());
        return out;
    }

    IndexTree mIndex; // coarse (voxel v stands for the leaf at v * 8): each leaf's index
};

/// One axis of dilatedOver(): every voxel of @a w (a leaf's words: word x, bit y * 8 + z)
/// spreads up to @a s (1..8) voxels along @a axis, into the leaf and from @a below and
/// @a above (its neighbours one leaf down and up that axis, null for none). Along y and z, by
/// doubling (the voxels spread by t after by up to c, t <= c + 1, reach c + t) and, from the
/// neighbours, the voxels within s of the leaf smeared to its edge: a few shifts a word, where
/// a shift for each voxel of reach took about three times as many operations (in a profile of
/// the radius-400 pair's blend at p = 320, this function's share fell by a fifth).
inline MaskBits spreadAlong(int axis, int s, const MaskBits& w, const MaskBits* below,
                            const MaskBits* above)
{
    using Word = std::uint64_t;
    static const MaskBits kNone;
    const MaskBits& lo = below ? *below : kNone;
    const MaskBits& hi = above ? *above : kNone;
    auto word = [](const MaskBits& m, int x) { return m.getWord<Word>(openvdb::Index(x)); };
    auto bytes = [](unsigned b) { return Word(b & 0xFFu) * 0x0101010101010101ull; };
    MaskBits out;
    if (axis == 0) { // whole words: the slices within s along x
        for (int x = 0; x < kDim; ++x) {
            Word o = word(w, x);
            for (int t = 1; t <= s; ++t) {
                o |= x - t >= 0 ? word(w, x - t) : word(lo, x - t + kDim);
                o |= x + t < kDim ? word(w, x + t) : word(hi, x + t - kDim);
            }
            out.getWord<Word>(openvdb::Index(x)) = o;
        }
    } else if (axis == 1) { // rows of 8 bits: a row t over is 8 t bits over
        const int u = 8 * (kDim - s); // below's rows kDim - s.. move to 0.., above's up to 7
        for (int x = 0; x < kDim; ++x) {
            Word o = word(w, x);
            for (int c = 0; c < s;) {
                const int t = std::min(c + 1, s - c);
                o |= (o << (8 * t)) | (o >> (8 * t));
                c += t;
            }
            Word l = word(lo, x) >> u, h = word(hi, x) << u;
            l |= l >> 8, l |= l >> 16, l |= l >> 32; // each row to the rows below it
            h |= h << 8, h |= h << 16, h |= h << 32; // and above
            out.getWord<Word>(openvdb::Index(x)) = o | l | h;
        }
    } else { // bits within each row (byte): kept within it, and across from the neighbours'
        const int u = kDim - s;
        const Word keepLo = bytes(0xFFu >> u), keepHi = bytes(0xFFu << u);
        for (int x = 0; x < kDim; ++x) {
            Word o = word(w, x);
            for (int c = 0; c < s;) {
                const int t = std::min(c + 1, s - c);
                o |= ((o << t) & bytes(0xFFu << t)) | ((o >> t) & bytes(0xFFu >> t));
                c += t;
            }
            Word l = (word(lo, x) >> u) & keepLo, h = (word(hi, x) << u) & keepHi;
            l |= (l >> 1) & bytes(0x7Fu), l |= (l >> 2) & bytes(0x3Fu);
            l |= (l >> 4) & bytes(0x0Fu);
            h |= (h << 1) & bytes(0xFEu), h |= (h << 2) & bytes(0xFCu);
            h |= (h << 4) & bytes(0xF0u);
            out.getWord<Word>(openvdb::Index(x)) = o | l | h;
        }
    }
    return out;
}

/// @a bits (by leaf of @a leaves) grown by @a voxels: to the cube of voxels around each, as
/// levelset::dilatedBox() grows a tree, in one-axis passes (z, y, x) of up to 8 voxels. What
/// would grow beyond the set's leaves is dropped, so a leaf's result is whole where the set
/// holds every leaf within ceil(voxels / 8) of it (the passes' steps from a voxel to another
/// stay in the box between them).
inline std::vector<MaskBits> dilatedOver(const LeafSet& leaves, std::vector<MaskBits> bits,
                                         int voxels)
{
    std::vector<MaskBits> next(bits.size());
    for (int left = voxels; left > 0; left -= kDim) {
        const int s = std::min(left, kDim);
        for (int axis = 2; axis >= 0; --axis) {
            Coord up(0, 0, 0);
            up[axis] = 1;
            const std::size_t below = LeafSet::aroundIndex(-up), above = LeafSet::aroundIndex(up);
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, bits.size()),
                              [&](const tbb::blocked_range<std::size_t>& r) {
                for (std::size_t k = r.begin(); k < r.end(); ++k) {
                    const int lo = leaves.around[k][below], hi = leaves.around[k][above];
                    const MaskBits* l = lo >= 0 ? &bits[std::size_t(lo)] : nullptr;
                    const MaskBits* h = hi >= 0 ? &bits[std::size_t(hi)] : nullptr;
                    if (bits[k].isOff() && (!l || l->isOff()) && (!h || h->isOff())) {
                        next[k].setOff();
                        continue;
                    }
                    next[k] = spreadAlong(axis, s, bits[k], l, h);
                }
            });
            bits.swap(next);
        }
    }
    return bits;
}

} // namespace ivdb::ops::detail
