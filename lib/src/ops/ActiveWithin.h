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
