// SPDX-License-Identifier: Apache-2.0
// The voxels of a leaf within s voxels of a tree's active voxels (lib/src/ops/ActiveWithin.h,
// internal), against OpenVDB's own dilation: openvdb::tools::dilateActiveValues, s passes over
// all 26 neighbours.
#include "../../lib/src/ops/ActiveWithin.h"

#include <openvdb/tools/Morphology.h>

#include <gtest/gtest.h>

#include <random>
#include <vector>

using namespace ivdb::ops::detail;
using openvdb::Coord;

namespace {

/// Scattered voxels in a box that spans several leaves, a leaf-sized active tile among them.
template<typename TreeT>
typename TreeT::Ptr scattered(unsigned seed, typename TreeT::ValueType on)
{
    auto tree = std::make_shared<TreeT>();
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> coord(-20, 27);
    for (int k = 0; k < 60; ++k) tree->setValueOn(Coord(coord(rng), coord(rng), coord(rng)), on);
    tree->addTile(1, Coord(40, 0, 8), on, true); // the leaf at (40, 0, 8), as one tile
    return tree;
}

/// Every voxel of every leaf within reach of the box: activeWithin() against the dilated copy.
template<typename TreeT>
void expectSameAsDilation(const TreeT& tree, int s)
{
    openvdb::MaskTree reference(tree, false, openvdb::TopologyCopy());
    openvdb::tools::dilateActiveValues(reference, s, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::EXPAND_TILES);
    openvdb::tree::ValueAccessor<const TreeT> acc(tree);
    openvdb::tree::ValueAccessor<const openvdb::MaskTree> ref(reference);
    int on = 0;
    for (int x = -32; x <= 56; x += kMaskDim) {
        for (int y = -32; y <= 40; y += kMaskDim) {
            for (int z = -32; z <= 40; z += kMaskDim) {
                const Coord origin(x, y, z);
                const LeafMask bits = activeWithin(origin, acc, s);
                for (openvdb::Index m = 0; m < LeafMask::SIZE; ++m) {
                    const Coord ijk = origin + Coord((m >> 6) & 7, (m >> 3) & 7, m & 7);
                    ASSERT_EQ(bits.isOn(m), ref.isValueOn(ijk)) << "s = " << s << " at " << ijk;
                    on += bits.isOn(m);
                }
            }
        }
    }
    EXPECT_GT(on, 60 * 8) << "s = " << s; // the check saw dilated voxels, not only empty leaves
}

} // namespace

TEST(TestActiveWithin, MaskTreeEqualsDilationForEveryReach)
{
    const auto tree = scattered<openvdb::MaskTree>(1, true);
    for (int s = 1; s <= kMaskDim; ++s) expectSameAsDilation(*tree, s);
}

TEST(TestActiveWithin, FloatTreeEqualsDilationForEveryReach)
{
    const auto tree = scattered<openvdb::FloatTree>(2, 1.0f);
    for (int s = 1; s <= kMaskDim; ++s) expectSameAsDilation(*tree, s);
}

// withinOne(), the band extension's front, from 27 leaves' masks: against OpenVDB's one-voxel
// dilation of a tree holding those masks, every leaf around present, missing, empty or full.
TEST(TestActiveWithin, WithinOneEqualsOneVoxelDilation)
{
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    int on = 0;
    for (int trial = 0; trial < 40; ++trial) {
        openvdb::MaskTree tree;
        std::vector<LeafMask> masks(27);
        const LeafMask* around[27];
        const double density = trial % 4 == 0 ? 0.002 : trial % 4 == 1 ? 0.02 : 0.2;
        for (int j = 0; j < 27; ++j) {
            const Coord d(j / 9 - 1, (j / 3) % 3 - 1, j % 3 - 1);
            const int kind = int(unit(rng) * 5); // 0: missing, 1: empty, 2: full, else random
            around[j] = kind == 0 ? nullptr : &masks[size_t(j)];
            if (kind == 0) continue;
            for (openvdb::Index m = 0; m < LeafMask::SIZE; ++m) {
                if (kind == 2 || (kind > 2 && unit(rng) < density)) masks[size_t(j)].setOn(m);
            }
            for (auto it = masks[size_t(j)].beginOn(); it; ++it) {
                const openvdb::Index m = it.pos();
                const Coord v(int((m >> 6) & 7), int((m >> 3) & 7), int(m & 7));
                tree.setValueOn(Coord(d.x() * kMaskDim, d.y() * kMaskDim, d.z() * kMaskDim) + v);
            }
        }
        openvdb::tools::dilateActiveValues(tree, 1, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                           openvdb::tools::EXPAND_TILES);
        const LeafMask bits = withinOne(around);
        openvdb::tree::ValueAccessor<const openvdb::MaskTree> ref(tree);
        for (openvdb::Index m = 0; m < LeafMask::SIZE; ++m) {
            const Coord ijk((m >> 6) & 7, (m >> 3) & 7, m & 7);
            ASSERT_EQ(bits.isOn(m), ref.isValueOn(ijk)) << "trial " << trial << " at " << ijk;
            on += bits.isOn(m);
        }
    }
    EXPECT_GT(on, 40 * 50); // dilated voxels seen, not only empty leaves
}
