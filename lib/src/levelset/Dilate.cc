// SPDX-License-Identifier: Apache-2.0
#include <ivdb/levelset/Dilate.h>

#include <algorithm>
#include <array>
#include <cstdint>

namespace ivdb::levelset {

namespace {

using MaskTree = openvdb::MaskTree;
using MaskLeaf = MaskTree::LeafNodeType;
using openvdb::Coord;
using Word = std::uint64_t;

constexpr int kDim = int(MaskLeaf::DIM); // 8: a leaf's voxels along each axis
static_assert(kDim == 8 && MaskLeaf::NodeMaskType::WORD_COUNT == 8,
              "one 64-bit word per x slice of a leaf, bit y * 8 + z");

/// A leaf's eight words: word x holds the slice at local x, bit (y << 3) | z.
using Words = std::array<Word, kDim>;

/// Every byte of a word set to @a byte.
constexpr Word everyByte(unsigned byte) { return Word(byte & 0xFFu) * 0x0101010101010101ull; }

/// The leaf's voxels moved by @a t (-7..7) along @a axis within the leaf; what leaves it is lost.
Words shifted(const Words& w, int axis, int t)
{
    Words out{};
    for (int x = 0; x < kDim; ++x) {
        if (axis == 0) {
            const int from = x - t;
            out[x] = from >= 0 && from < kDim ? w[from] : 0;
        } else if (axis == 1) { // rows of 8 bits
            out[x] = t >= 0 ? w[x] << (8 * t) : w[x] >> (-8 * t);
        } else { // bits within each row
            out[x] = t >= 0 ? (w[x] << t) & everyByte(0xFFu << t)
                            : (w[x] >> -t) & everyByte(0xFFu >> -t);
        }
    }
    return out;
}

Words orOf(const Words& a, const Words& b)
{
    Words out;
    for (int x = 0; x < kDim; ++x) out[x] = a[x] | b[x];
    return out;
}

/// One axis of the cube: every active voxel of @a in spreads to the voxels up to @a d away along
/// @a axis. A voxel at local c of a leaf reaches local c' of the leaf k leaves over when
/// |8k + c' - c| <= d; with t = c' - c in -7..7, the words of leaf k are the OR of the leaf
/// shifted by each t in [-d - 8k, d - 8k]: a prefix or suffix of the 15 shifts, or all of them.
template<typename TreeT>
typename TreeT::Ptr dilateAxis(const TreeT& in, int axis, int d)
{
    auto out = std::make_shared<TreeT>();
    openvdb::tree::ValueAccessor<TreeT> acc(*out);
    constexpr int kShifts = 2 * kDim - 1; // t = -7..7 at index t + 7
    std::array<Words, kShifts> shifts, prefix, suffix; // each shift; OR up to t; OR from t
    const int kLow = -((d + kDim - 1) / kDim), kHigh = (d + kDim - 1) / kDim;
    for (auto leaf = in.cbeginLeaf(); leaf; ++leaf) {
        if (leaf->isEmpty()) continue;
        Words w;
        for (int x = 0; x < kDim; ++x) w[x] = leaf->getValueMask().template getWord<Word>(x);
        for (int i = 0; i < kShifts; ++i) shifts[i] = shifted(w, axis, i - (kDim - 1));
        prefix[0] = shifts[0];
        for (int i = 1; i < kShifts; ++i) prefix[i] = orOf(prefix[i - 1], shifts[i]);
        suffix[kShifts - 1] = shifts[kShifts - 1];
        for (int i = kShifts - 2; i >= 0; --i) suffix[i] = orOf(suffix[i + 1], shifts[i]);
        for (int k = kLow; k <= kHigh; ++k) {
            const int lo = std::max(-(kDim - 1), -d - kDim * k);
            const int hi = std::min(kDim - 1, d - kDim * k);
            if (lo > hi) continue;
            Words add;
            if (lo == -(kDim - 1)) {
                add = prefix[hi + kDim - 1];
            } else if (hi == kDim - 1) {
                add = suffix[lo + kDim - 1];
            } else { // the leaf itself (k = 0) when d < 7: [-d, d]
                add = shifts[lo + kDim - 1];
                for (int t = lo + 1; t <= hi; ++t) add = orOf(add, shifts[t + kDim - 1]);
            }
            Word any = 0;
            for (Word v : add) any |= v;
            if (any == 0) continue;
            Coord o = leaf->origin();
            o[axis] += kDim * k;
            MaskLeaf* target = acc.touchLeaf(o);
            auto& mask = target->getValueMask();
            for (int x = 0; x < kDim; ++x) mask.template getWord<Word>(x) |= add[x];
        }
    }
    return out;
}

template<typename TreeT>
typename TreeT::Ptr dilatedBoxOf(const TreeT& mask, int voxels)
{
    auto out = std::make_shared<TreeT>(mask);
    out->voxelizeActiveTiles();
    if (voxels <= 0) return out;
    for (int axis = 0; axis < 3; ++axis) out = dilateAxis(*out, axis, voxels);
    return out;
}

} // namespace

openvdb::MaskTree::Ptr dilatedBox(const openvdb::MaskTree& mask, int voxels)
{
    return dilatedBoxOf(mask, voxels);
}

SmallMaskTree::Ptr dilatedBox(const SmallMaskTree& mask, int voxels)
{
    return dilatedBoxOf(mask, voxels);
}

} // namespace ivdb::levelset
