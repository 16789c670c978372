// SPDX-License-Identifier: Apache-2.0
// The voxels of a leaf within one voxel of the voxels of the leaves around it
// (lib/src/ops/ActiveWithin.h, internal), against OpenVDB's own dilation:
// openvdb::tools::dilateActiveValues over all 26 neighbours.
#include "../../lib/src/ops/ActiveWithin.h"

#include <openvdb/tools/Morphology.h>

#include <gtest/gtest.h>

#include <random>
#include <vector>

using namespace ivdb::ops::detail;
using openvdb::Coord;

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
