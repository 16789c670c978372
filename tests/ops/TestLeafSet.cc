// SPDX-License-Identifier: Apache-2.0
// The grid blend's flat leaf lists (lib/src/ops/LeafSet.h, internal): each leaf's neighbours
// against the tree's own lookups, and masks grown over a list (dilatedOver) against OpenVDB's
// own dilation, openvdb::tools::dilateActiveValues (repeated steps to all 26 neighbours).
#include "../../lib/src/ops/LeafSet.h"

#include <openvdb/tools/Morphology.h>

#include <gtest/gtest.h>

#include <random>

using namespace ivdb::ops::detail;

namespace {

/// The leaf origins of a box of leaves, from @a lo to @a hi leaves along each axis.
std::vector<Coord> boxOfLeaves(int lo, int hi)
{
    std::vector<Coord> out;
    for (int x = lo; x <= hi; ++x) {
        for (int y = lo; y <= hi; ++y) {
            for (int z = lo; z <= hi; ++z) out.emplace_back(x * kDim, y * kDim, z * kDim);
        }
    }
    return out;
}

/// Scattered voxels within the leaves from -3 to 4 along each axis, and a few whole rows and
/// slices (runs across leaf faces).
MaskTree scattered(unsigned seed)
{
    MaskTree tree;
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> coord(-3 * kDim, 5 * kDim - 1);
    for (int k = 0; k < 400; ++k) tree.setValueOn(Coord(coord(rng), coord(rng), coord(rng)));
    for (int z = -3 * kDim; z < 5 * kDim; ++z) tree.setValueOn(Coord(3, -5, z));
    for (int y = -3 * kDim; y < 5 * kDim; ++y) {
        for (int z = 0; z < 9; ++z) tree.setValueOn(Coord(-9, y, z));
    }
    return tree;
}

} // namespace

TEST(TestLeafSet, NeighboursAreTheTreesLeaves)
{
    // Every other leaf of a box, so that some neighbours are missing.
    std::vector<Coord> origins;
    for (const Coord& o : boxOfLeaves(-2, 2)) {
        if (((o.x() + o.y() + o.z()) / kDim) % 2 == 0 || o.x() == 0) origins.push_back(o);
    }
    const LeafSet all(origins), faces(origins, LeafSet::Around::Faces);
    ASSERT_EQ(all.size(), origins.size());
    auto index = all.accessor();
    int listed = 0, missing = 0;
    for (std::size_t k = 0; k < all.size(); ++k) {
        for (int dx = -1; dx <= 1; ++dx) {
            for (int dy = -1; dy <= 1; ++dy) {
                for (int dz = -1; dz <= 1; ++dz) {
                    const Coord d(dx, dy, dz);
                    const Coord o = origins[k].offsetBy(dx * kDim, dy * kDim, dz * kDim);
                    const auto at = std::find(origins.begin(), origins.end(), o);
                    const int expected = at == origins.end() ? -1 : int(at - origins.begin());
                    const std::size_t j = LeafSet::aroundIndex(d);
                    EXPECT_EQ(all.around[k][j], expected) << origins[k] << " + " << d;
                    const bool face = std::abs(dx) + std::abs(dy) + std::abs(dz) <= 1;
                    EXPECT_EQ(faces.around[k][j], face ? expected : -1) << origins[k] << " + " << d;
                    // find() of a voxel in that leaf, from the leaf k and from nowhere.
                    const Coord voxel = o + Coord(dx + 1, dy + 5, 7);
                    EXPECT_EQ(all.find(voxel, int(k), index), expected);
                    EXPECT_EQ(all.find(voxel, -1, index), expected);
                    expected < 0 ? ++missing : ++listed;
                }
            }
        }
    }
    EXPECT_GT(listed, 0);
    EXPECT_GT(missing, 0);
}

TEST(TestLeafSet, DilatedOverEqualsDilation)
{
    // Over the leaves from -3 to 4, the grown masks of the leaves with every leaf within
    // ceil(s / 8) in the set are whole (OpenVDB's dilation's), and no leaf holds a voxel the
    // dilation does not. Reaches within a leaf, of exactly a leaf, and over one and two leaves.
    const LeafSet leaves(boxOfLeaves(-3, 4), LeafSet::Around::Faces);
    for (unsigned seed : {1u, 2u}) {
        const MaskTree tree = scattered(seed);
        for (int s : {1, 3, 6, 8, 9, 13}) {
            MaskTree reference(tree);
            openvdb::tools::dilateActiveValues(reference, s, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                               openvdb::tools::EXPAND_TILES);
            const std::vector<MaskBits> grown = dilatedOver(leaves, leaves.masksOf(tree), s);
            ASSERT_EQ(grown.size(), leaves.size());
            const int margin = (s + kDim - 1) / kDim;
            openvdb::tree::ValueAccessor<const MaskTree> ref(reference);
            std::size_t whole = 0, on = 0;
            for (std::size_t k = 0; k < leaves.size(); ++k) {
                const Coord o = leaves.origin[k];
                const Coord c(o.x() / kDim, o.y() / kDim, o.z() / kDim);
                const bool inner = std::min({c.x(), c.y(), c.z()}) >= -3 + margin &&
                                   std::max({c.x(), c.y(), c.z()}) <= 4 - margin;
                whole += inner;
                for (openvdb::Index m = 0; m < MaskBits::SIZE; ++m) {
                    const Coord ijk = o + Coord((m >> 6) & 7, (m >> 3) & 7, m & 7);
                    const bool expected = ref.isValueOn(ijk);
                    if (inner) {
                        ASSERT_EQ(grown[k].isOn(m), expected) << "s = " << s << " at " << ijk;
                    } else {
                        ASSERT_TRUE(!grown[k].isOn(m) || expected) << "s = " << s << " at " << ijk;
                    }
                    on += grown[k].isOn(m);
                }
            }
            EXPECT_GT(whole, 0u) << "s = " << s;
            EXPECT_GT(on, tree.activeVoxelCount()) << "s = " << s;
        }
    }
}
