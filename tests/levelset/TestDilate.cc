// SPDX-License-Identifier: Apache-2.0
// levelset::dilatedBox against OpenVDB's own dilation (repeated 26-neighbour steps).
#include <ivdb/levelset/Dilate.h>

#include <openvdb/tools/Morphology.h>

#include <gtest/gtest.h>

#include <random>

using namespace ivdb;

namespace {

/// Scattered voxels, a dense clump, a leaf-sized active tile and voxels on both sides of zero
/// in every axis: every case of the word shifts (within a leaf, across leaves, both signs).
openvdb::MaskTree randomMask(unsigned seed)
{
    openvdb::MaskTree mask;
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> coord(-70, 70);
    for (int i = 0; i < 60; ++i) mask.setValueOn(openvdb::Coord(coord(rng), coord(rng), coord(rng)));
    for (int x = 3; x < 14; ++x) {
        for (int y = -5; y < 4; ++y) {
            for (int z = 0; z < 9; ++z) {
                if ((x * 7 + y * 3 + z) % 4 != 0) mask.setValueOn(openvdb::Coord(x, y, z));
            }
        }
    }
    mask.addTile(1, openvdb::Coord(-40, 24, 80), true, true);
    return mask;
}

openvdb::MaskTree::Ptr openVdbDilation(const openvdb::MaskTree& mask, int voxels)
{
    auto out = std::make_shared<openvdb::MaskTree>(mask);
    if (voxels > 0) {
        openvdb::tools::dilateActiveValues(*out, voxels, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                           openvdb::tools::EXPAND_TILES);
    }
    out->voxelizeActiveTiles();
    return out;
}

/// Voxels in @a a but not in @a b.
openvdb::Index64 missing(const openvdb::MaskTree& a, const openvdb::MaskTree& b)
{
    openvdb::MaskTree d(a);
    d.topologyDifference(b);
    return d.activeVoxelCount();
}

} // namespace

TEST(TestDilate, EqualsOpenVdbsRepeatedNeighbourDilation)
{
    for (unsigned seed : {1u, 2u}) {
        const openvdb::MaskTree mask = randomMask(seed);
        for (int voxels : {0, 1, 2, 3, 5, 7, 8, 9, 15, 16, 17, 30}) {
            const auto ours = levelset::dilatedBox(mask, voxels);
            const auto theirs = openVdbDilation(mask, voxels);
            EXPECT_GT(ours->activeVoxelCount(), mask.activeVoxelCount() / 2);
            EXPECT_EQ(ours->activeVoxelCount(), theirs->activeVoxelCount())
                << "seed " << seed << ", " << voxels << " voxels";
            EXPECT_EQ(missing(*ours, *theirs), 0u) << "seed " << seed << ", " << voxels;
            EXPECT_EQ(missing(*theirs, *ours), 0u) << "seed " << seed << ", " << voxels;
            EXPECT_FALSE(ours->hasActiveTiles());
        }
    }
}

TEST(TestDilate, OneVoxelBecomesTheCube)
{
    openvdb::MaskTree mask;
    const openvdb::Coord c(-1, 7, 8); // on leaf edges: the cube spans eight leaves
    mask.setValueOn(c);
    for (int voxels : {1, 4, 11}) {
        const auto out = levelset::dilatedBox(mask, voxels);
        const openvdb::Index64 side = 2 * voxels + 1;
        EXPECT_EQ(out->activeVoxelCount(), side * side * side);
        openvdb::CoordBBox box;
        out->evalActiveVoxelBoundingBox(box);
        EXPECT_EQ(box, openvdb::CoordBBox(c.offsetBy(-voxels), c.offsetBy(voxels)));
    }
    EXPECT_EQ(levelset::dilatedBox(openvdb::MaskTree(), 5)->activeVoxelCount(), 0u);
}

// The SmallMaskTree overload (coarse masks: a voxel per leaf) grows the same voxels.
TEST(TestDilate, SmallMaskTreeEqualsOpenVdbsDilation)
{
    for (unsigned seed : {3u, 4u}) {
        const openvdb::MaskTree mask = randomMask(seed);
        levelset::SmallMaskTree small; // the same voxels (the tile's among them)
        for (auto it = mask.cbeginValueOn(); it; ++it) small.sparseFill(it.getBoundingBox(), true);
        for (int voxels : {0, 1, 2, 7, 8, 9, 17}) {
            const auto ours = levelset::dilatedBox(small, voxels);
            openvdb::MaskTree oursAsMask;
            for (auto it = ours->cbeginValueOn(); it; ++it) oursAsMask.setValueOn(it.getCoord());
            const auto theirs = openVdbDilation(mask, voxels);
            EXPECT_GT(ours->activeVoxelCount(), mask.activeVoxelCount() / 2);
            EXPECT_EQ(ours->activeVoxelCount(), theirs->activeVoxelCount())
                << "seed " << seed << ", " << voxels << " voxels";
            EXPECT_EQ(missing(oursAsMask, *theirs), 0u) << "seed " << seed << ", " << voxels;
            EXPECT_EQ(missing(*theirs, oursAsMask), 0u) << "seed " << seed << ", " << voxels;
            EXPECT_FALSE(ours->hasActiveTiles());
        }
    }
}
