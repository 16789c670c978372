// SPDX-License-Identifier: Apache-2.0
#pragma once

/// @file ActiveWithin.h
/// @brief The voxels of a leaf within one voxel of the voxels of the leaves around it: the
/// front of each layer the grid blend grows its bands by (internal to ops; tests reach it by
/// path).

#include <openvdb/openvdb.h>

#include <cstdint>

namespace ivdb::ops::detail {

/// A leaf's voxels as bits (the masks of every 8^3 leaf type), and the leaf's side.
using LeafMask = openvdb::util::NodeMask<3>;

constexpr int kMaskDim = 8;

/// @brief The voxels of a leaf within one voxel (a step to any of 26 neighbours) of the voxels
/// of @a around, the masks of the 27 leaves around it (index (dx + 1) * 9 + (dy + 1) * 3 +
/// dz + 1 for the leaf dx, dy, dz leaves over; null for none), on their 64-bit words (word x
/// holds the slice at x, bit y * 8 + z): one pass along z, then y, then x, each an OR of the
/// words shifted by one voxel and the neighbour's edge. The grid blend's band extension takes
/// each layer's front this way: with rows of bits, each read and grown on its own (a version
/// for any reach, since removed), the fronts took 24 to 37 million cycles on the radius-400
/// pair at p = 320 (13,437 leaves, summed over the layers and inputs), now 10 to 17.
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

} // namespace ivdb::ops::detail
