// SPDX-License-Identifier: Apache-2.0
#pragma once

/// @file ActiveWithin.h
/// @brief The voxels of a leaf within a few voxels of a tree's active voxels, from the active
/// masks of the leaves around it: what the grid blend grows its bands and trims its crease by
/// (internal to ops; tests reach it by path).

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cstdint>

namespace ivdb::ops::detail {

/// A leaf's voxels as bits (the masks of every 8^3 leaf type), and the leaf's side.
using LeafMask = openvdb::util::NodeMask<3>;

constexpr int kMaskDim = 8;

/// The voxels of the leaf at @a origin within @a s voxels (s steps to any of 26 neighbours,
/// 1 <= s <= 8) of an active voxel of the tree @a acc reads (an active tile counts as active
/// voxels). From the active masks of the 27 leaves around, as rows of bits along z (x and y
/// from -s to 7 + s, bit z + s), grown along z, then y, then x. The reach is a template
/// argument, so that the loops unroll; activeWithin() picks it.
template<int s, typename AccessorT>
LeafMask activeWithinOf(const openvdb::Coord& origin, AccessorT& acc)
{
    static_assert(s >= 1 && s <= kMaskDim, "within a leaf of the leaf");
    constexpr int D = kMaskDim + 2 * s;
    // Each neighbour leaf's rows: a mask, all on (an active tile) or none.
    const LeafMask* masks[3][3][3];
    bool full[3][3][3];
    for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) {
            for (int c = 0; c < 3; ++c) {
                const openvdb::Coord o = origin.offsetBy(
                    (a - 1) * kMaskDim, (b - 1) * kMaskDim, (c - 1) * kMaskDim);
                const auto* leaf = acc.probeConstLeaf(o);
                masks[a][b][c] = leaf ? &leaf->getValueMask() : nullptr;
                full[a][b][c] = !leaf && acc.isValueOn(o);
            }
        }
    }
    auto row = [&](int a, int b, int c, int x, int y) -> std::uint32_t {
        if (full[a][b][c]) return 0xFFu;
        if (!masks[a][b][c]) return 0u;
        const auto word = masks[a][b][c]->template getWord<std::uint64_t>(openvdb::Index(x));
        return std::uint32_t(word >> (kMaskDim * y)) & 0xFFu;
    };
    constexpr std::uint32_t keep = (std::uint32_t(1) << D) - 1u;
    std::uint32_t rows[D][D];
    for (int i = 0; i < D; ++i) {
        const int xi = i - s, a = xi < 0 ? 0 : xi >= kMaskDim ? 2 : 1, x = xi & (kMaskDim - 1);
        for (int j = 0; j < D; ++j) {
            const int yj = j - s, b = yj < 0 ? 0 : yj >= kMaskDim ? 2 : 1, y = yj & (kMaskDim - 1);
            const std::uint32_t r = (row(a, b, 1, x, y) << s) |
                                    (row(a, b, 0, x, y) >> (kMaskDim - s)) |
                                    ((row(a, b, 2, x, y) << (kMaskDim + s)) & keep);
            std::uint32_t grown = r;
            for (int k = 1; k <= s; ++k) grown |= (r << k) | (r >> k);
            rows[i][j] = grown;
        }
    }
    LeafMask out;
    for (int x = 0; x < kMaskDim; ++x) {
        std::uint64_t word = 0;
        for (int y = 0; y < kMaskDim; ++y) {
            std::uint32_t r = 0;
            for (int dx = 0; dx <= 2 * s; ++dx) {
                for (int dy = 0; dy <= 2 * s; ++dy) r |= rows[x + dx][y + dy];
            }
            word |= std::uint64_t((r >> s) & 0xFFu) << (kMaskDim * y);
        }
        out.template getWord<std::uint64_t>(openvdb::Index(x)) = word;
    }
    return out;
}

/// @brief activeWithinOf<1>() from the masks of the 27 leaves around the leaf, @a around
/// (index (dx + 1) * 9 + (dy + 1) * 3 + dz + 1 for the leaf dx, dy, dz leaves over; null for
/// none), on their 64-bit words (word x holds the slice at x, bit y * 8 + z): one pass along z,
/// then y, then x, each an OR of the words shifted by one voxel and the neighbour's edge. The
/// grid blend's band extension takes each layer's front this way: with activeWithinOf<1>()
/// (rows of bits, each read and grown on its own) the fronts took 24 to 37 million cycles on
/// the radius-400 pair at p = 320 (13,437 leaves, summed over the layers and inputs), now 10 to
/// 17.
inline LeafMask withinOne(const LeafMask* const around[27])
{
    using Word = std::uint64_t;
    constexpr Word kFirst = 0x0101010101010101ull; // z = 0 in every row
    constexpr Word kLast = kFirst << 7;             // z = 7
    auto word = [&](int a, int b, int c, int x) -> Word {
        const LeafMask* m = around[a * 9 + b * 3 + c];
        return m ? m->template getWord<Word>(openvdb::Index(x)) : Word(0);
    };
    // Slice x of the leaf a, b (each 0..2) grown along z, from its neighbours along z too.
    auto alongZ = [&](int a, int b, int x) -> Word {
        const Word w = word(a, b, 1, x);
        return w | ((w << 1) & ~kFirst) | ((w >> 1) & ~kLast) |
               ((word(a, b, 0, x) >> 7) & kFirst) | ((word(a, b, 2, x) << 7) & kLast);
    };
    // And along y (rows of eight bits).
    auto alongYZ = [&](int a, int x) -> Word {
        const Word w = alongZ(a, 1, x);
        return w | (w << 8) | (w >> 8) | (alongZ(a, 0, x) >> 56) | (alongZ(a, 2, x) << 56);
    };
    Word slices[kMaskDim + 2]; // x = -1..8
    slices[0] = alongYZ(0, kMaskDim - 1);
    for (int x = 0; x < kMaskDim; ++x) slices[x + 1] = alongYZ(1, x);
    slices[kMaskDim + 1] = alongYZ(2, 0);
    LeafMask out;
    for (int x = 0; x < kMaskDim; ++x) {
        out.template getWord<Word>(openvdb::Index(x)) = slices[x] | slices[x + 1] | slices[x + 2];
    }
    return out;
}

/// activeWithinOf() for a reach @a s known at run time, taken into [1, 8].
template<typename AccessorT>
LeafMask activeWithin(const openvdb::Coord& origin, AccessorT& acc, int s)
{
    switch (std::clamp(s, 1, kMaskDim)) {
    case 1: return activeWithinOf<1>(origin, acc);
    case 2: return activeWithinOf<2>(origin, acc);
    case 3: return activeWithinOf<3>(origin, acc);
    case 4: return activeWithinOf<4>(origin, acc);
    case 5: return activeWithinOf<5>(origin, acc);
    case 6: return activeWithinOf<6>(origin, acc);
    case 7: return activeWithinOf<7>(origin, acc);
    default: return activeWithinOf<8>(origin, acc);
    }
}

} // namespace ivdb::ops::detail
