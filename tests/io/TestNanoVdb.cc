// SPDX-License-Identifier: Apache-2.0
// NanoVDB export against the source grids, read back with NanoVDB's own reader: the same names,
// active voxel counts, and the value and active state at every active voxel (tiles included).
#include <ivdb/io/NanoVdbFile.h>

#include "Grids.h"

#include <nanovdb/util/IO.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include "../TempDirTest.h"

#include <atomic>
#include <cstring>
#include <filesystem>
#include <string>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;

/// NanoVDB's value type for an OpenVDB grid's.
template<typename T> struct NanoType { using Type = T; };
template<> struct NanoType<openvdb::Vec3s> { using Type = nanovdb::Vec3f; };

using Exported = openvdb::TypeList<openvdb::FloatGrid, openvdb::DoubleGrid, openvdb::Int32Grid,
                                   openvdb::Int64Grid, openvdb::Vec3SGrid, openvdb::BoolGrid>;

template<typename GridT>
void expectSameVoxels(const GridT& source, const nanovdb::GridHandle<nanovdb::HostBuffer>& handle,
                      const std::string& what)
{
    using ValueT = typename GridT::ValueType;
    using NanoT = typename NanoType<ValueT>::Type;
    static_assert(sizeof(NanoT) == sizeof(ValueT), "the same bytes per value");
    const auto* nano = handle.grid<NanoT>();
    ASSERT_TRUE(nano) << what << ": NanoVDB grid of the wrong type";
    EXPECT_EQ(std::string(nano->gridName()), source.getName()) << what;
    EXPECT_EQ(nano->activeVoxelCount(), source.activeVoxelCount()) << what;
    auto acc = nano->getAccessor();
    std::size_t voxels = 0, differ = 0;
    for (auto it = source.cbeginValueOn(); it; ++it) {
        const ValueT value = *it;
        const openvdb::CoordBBox box = it.getBoundingBox(); // one voxel, or a whole tile
        for (auto ijk = box.begin(); ijk; ++ijk, ++voxels) {
            const nanovdb::Coord c((*ijk)[0], (*ijk)[1], (*ijk)[2]);
            const NanoT v = acc.getValue(c);
            differ += !acc.isActive(c) || std::memcmp(&v, &value, sizeof(ValueT)) != 0;
        }
    }
    EXPECT_EQ(voxels, source.activeVoxelCount()) << what;
    EXPECT_EQ(differ, 0u) << what << ": voxels that differ, of " << voxels;
}

class TestNanoVdb: public ivdb::test::TempDirTest
{
protected:
    TestNanoVdb(): TempDirTest("nanovdb") {}

};

TEST_F(TestNanoVdb, EveryActiveVoxelAsTheSource)
{
    openvdb::GridCPtrVec grids;
    for (const auto& g : ivdb::test::everyKindOfGrid(/*bools=*/true)) {
        if (ivdb::io::nanoVdbHolds(*g)) grids.push_back(g);
    }
    ASSERT_EQ(grids.size(), 13u) << "all but the vec3d grid";
    ivdb::io::writeNanoVdb(path("all.nvdb"), grids);
    const auto handles = nanovdb::io::readGrids(path("all.nvdb"));
    ASSERT_EQ(handles.size(), grids.size());
    for (std::size_t i = 0; i < grids.size(); ++i) {
        const std::string what = "grid " + std::to_string(i) + " '" + grids[i]->getName() + "'";
        const bool typed = grids[i]->apply<Exported>([&](const auto& g) {
            expectSameVoxels(g, handles[i], what);
        });
        EXPECT_TRUE(typed) << what;
    }
    // A level set stays one, with its voxel size.
    const auto* surface = handles[0].grid<float>();
    ASSERT_TRUE(surface);
    EXPECT_EQ(surface->gridClass(), nanovdb::GridClass::LevelSet);
    EXPECT_DOUBLE_EQ(surface->voxelSize()[0], grids[0]->voxelSize()[0]);
}

TEST_F(TestNanoVdb, RefusesGridsNanoVdbCannotHoldAndWritesNothing)
{
    auto ints = openvdb::Vec3IGrid::create();
    ints->setName("cells");
    ints->tree().setValue(openvdb::Coord(1), openvdb::Vec3i(1, 2, 3));
    EXPECT_FALSE(ivdb::io::nanoVdbHolds(*ints));
    EXPECT_FALSE(ivdb::io::nanoVdbHolds(*openvdb::Vec3DGrid::create()));
    EXPECT_TRUE(ivdb::io::nanoVdbHolds(*ivdb::test::sphere(1.0f, 0.1f)));
    try {
        ivdb::io::writeNanoVdb(path("x.nvdb"), {ivdb::test::sphere(1.0f, 0.1f), ints});
        ADD_FAILURE() << "a vec3i grid was written";
    } catch (const openvdb::ValueError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find("'cells'"), std::string::npos) << msg;
        EXPECT_NE(msg.find("vec3i"), std::string::npos) << msg;
    }
    EXPECT_FALSE(fs::exists(path("x.nvdb")));
    EXPECT_TRUE(fs::is_empty(mDir));
}

} // namespace
