// SPDX-License-Identifier: Apache-2.0
// The parallel .vdb reader against OpenVDB's own full load (io::File without delayed loading):
// for files OpenVDB writes (each compression, half floats, streams, shared trees, every grid
// type), the same grids in the same order, with the same metadata, transforms, topology and
// every value (voxels, inactive values and tiles) bit for bit.
#include <ivdb/io/VdbFile.h>
#include <ivdb/io/VdbPieces.h>
#include <ivdb/util/Params.h>

#include "Grids.h"

#include <openvdb/io/File.h>
#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include "../TempDirTest.h"

#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include <tbb/global_control.h>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;
namespace vio = openvdb::io;

using ValueGrids = openvdb::TypeList<openvdb::FloatGrid, openvdb::DoubleGrid, openvdb::Int32Grid,
                                     openvdb::Int64Grid, openvdb::Vec3IGrid, openvdb::Vec3SGrid,
                                     openvdb::Vec3DGrid>;
using ReadTypes = ValueGrids::Append<openvdb::BoolGrid>;

template<typename T>
bool sameBits(const T& a, const T& b)
{
    return std::memcmp(&a, &b, sizeof(T)) == 0;
}

/// Topology, background and every value, active or not, at every voxel and tile, bit for bit.
template<typename GridT>
void expectSameTree(const GridT& a, const GridT& b, const std::string& what)
{
    ASSERT_TRUE(a.tree().hasSameTopology(b.tree())) << what;
    EXPECT_EQ(a.tree().leafCount(), b.tree().leafCount()) << what;
    EXPECT_TRUE(sameBits(a.background(), b.background())) << what;
    std::size_t values = 0, differ = 0;
    auto acc = b.getConstAccessor();
    for (auto it = a.tree().cbeginValueAll(); it; ++it, ++values) {
        const auto value = acc.getValue(it.getCoord());
        differ += !sameBits(*it, value) || it.isValueOn() != acc.isValueOn(it.getCoord());
    }
    if (!a.tree().empty()) EXPECT_GT(values, 0u) << what;
    EXPECT_EQ(differ, 0u) << what << ": values that differ, of " << values;
}

/// Leaves whose values are still in the file (OpenVDB's delayed loading), over all grids.
std::size_t leavesNotLoaded(const openvdb::GridPtrVec& grids)
{
    std::size_t n = 0;
    for (const auto& g : grids) {
        g->apply<ValueGrids>([&n](const auto& grid) {
            for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
                n += leaf->buffer().isOutOfCore();
            }
        });
    }
    return n;
}

class TestVdbReader: public ivdb::test::TempDirTest
{
protected:
    TestVdbReader(): TempDirTest("reader") {}

    /// Write @a grids with OpenVDB's io::File and the compression flags @a flags.
    std::string writeWithOpenVdb(const openvdb::GridCPtrVec& grids, std::uint32_t flags,
                                 const std::string& name) const
    {
        vio::File f(path(name));
        f.setCompression(flags);
        f.write(grids);
        f.close();
        return path(name);
    }

    /// OpenVDB's full load: every grid, every leaf read now.
    static openvdb::GridPtrVec readWithOpenVdb(const std::string& file)
    {
        vio::File f(file);
        f.open(/*delayLoad=*/false);
        openvdb::GridPtrVec grids = *f.getGrids();
        f.close();
        return grids;
    }

    /// ivdb's reader and OpenVDB's give the same grids.
    static void expectSameGrids(const openvdb::GridPtrVec& ours, const openvdb::GridPtrVec& theirs,
                                const std::string& what)
    {
        ASSERT_EQ(ours.size(), theirs.size()) << what;
        for (std::size_t i = 0; i < ours.size(); ++i) {
            const std::string where = what + ": grid " + std::to_string(i) + " '" +
                                      theirs[i]->getName() + "'";
            ASSERT_EQ(ours[i]->getName(), theirs[i]->getName()) << where << " (order)";
            ASSERT_EQ(ours[i]->type(), theirs[i]->type()) << where;
            EXPECT_EQ(ours[i]->saveFloatAsHalf(), theirs[i]->saveFloatAsHalf()) << where;
            EXPECT_EQ(ours[i]->transform(), theirs[i]->transform()) << where;
            // Metadata, the file_* statistics included (and no delayed-load table).
            EXPECT_EQ(ours[i]->metaCount(), theirs[i]->metaCount()) << where;
            for (auto m = theirs[i]->beginMeta(); m != theirs[i]->endMeta(); ++m) {
                const auto mine = (*ours[i])[m->first];
                ASSERT_TRUE(mine) << where << ": metadata " << m->first;
                EXPECT_EQ(mine->str(), m->second->str()) << where << ": metadata " << m->first;
            }
            EXPECT_FALSE((*ours[i])[openvdb::GridBase::META_FILE_DELAYED_LOAD]) << where;
            const bool typed = ours[i]->apply<ReadTypes>([&](const auto& a) {
                using GridT = std::decay_t<decltype(a)>;
                expectSameTree(a, static_cast<const GridT&>(*theirs[i]), where);
            });
            EXPECT_TRUE(typed) << where;
            // Grids that share a tree in the file share it in memory.
            for (std::size_t j = 0; j < i; ++j) {
                EXPECT_EQ(ours[i]->constBaseTreePtr() == ours[j]->constBaseTreePtr(),
                          theirs[i]->constBaseTreePtr() == theirs[j]->constBaseTreePtr())
                    << where << " and grid " << j;
            }
        }
    }

};

/// Copies of @a grids flagged to be written as half floats.
openvdb::GridCPtrVec halfCopies(const openvdb::GridCPtrVec& grids)
{
    openvdb::GridCPtrVec out;
    for (const auto& g : grids) {
        openvdb::GridBase::Ptr copy = g->deepCopyGrid();
        copy->setSaveFloatAsHalf(true);
        out.push_back(copy);
    }
    return out;
}

TEST_F(TestVdbReader, SameGridsAsOpenVdbForEachCompressionAndHalfFloats)
{
    const openvdb::GridCPtrVec grids = ivdb::test::everyKindOfGrid(/*bools=*/false);
    const std::pair<const char*, std::uint32_t> cases[] = {
        {"blosc", vio::COMPRESS_BLOSC | vio::COMPRESS_ACTIVE_MASK},
        {"zip", vio::COMPRESS_ZIP | vio::COMPRESS_ACTIVE_MASK},
        {"active mask only", vio::COMPRESS_ACTIVE_MASK},
        {"blosc without the active mask", vio::COMPRESS_BLOSC},
        {"no compression at all", vio::COMPRESS_NONE}};
    for (const auto& [what, flags] : cases) {
        const std::string file = writeWithOpenVdb(grids, flags, "f.vdb");
        const openvdb::GridPtrVec ours = ivdb::io::readVdb(file);
        expectSameGrids(ours, readWithOpenVdb(file), what);
        EXPECT_EQ(leavesNotLoaded(ours), 0u) << what << ": every leaf is read at once";
    }
    const openvdb::GridCPtrVec halves = halfCopies(grids);
    for (const auto& [what, flags] : cases) {
        const std::string file = writeWithOpenVdb(halves, flags, "h.vdb");
        expectSameGrids(ivdb::io::readVdb(file), readWithOpenVdb(file),
                        std::string(what) + ", half floats");
    }
}

TEST_F(TestVdbReader, SameGridsAsOpenVdbFromAStream)
{
    // io::Stream's layout: no grid offsets, each grid right after its descriptor.
    const openvdb::GridCPtrVec grids = ivdb::test::everyKindOfGrid(/*bools=*/false);
    {
        std::ofstream out(path("stream.vdb"), std::ios::binary);
        vio::Stream(out).write(grids);
    }
    const openvdb::GridPtrVec ours = ivdb::io::readVdb(path("stream.vdb"));
    expectSameGrids(ours, readWithOpenVdb(path("stream.vdb")), "stream");
    EXPECT_EQ(leavesNotLoaded(ours), 0u);
}

TEST_F(TestVdbReader, OneThreadReadsTheSame)
{
    const std::string file = writeWithOpenVdb(ivdb::test::everyKindOfGrid(false),
                                              vio::COMPRESS_BLOSC | vio::COMPRESS_ACTIVE_MASK,
                                              "f.vdb");
    const openvdb::GridPtrVec theirs = readWithOpenVdb(file);
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    expectSameGrids(ivdb::io::readVdb(file), theirs, "one thread");
}

TEST_F(TestVdbReader, OtherGridTypesAreReadByOpenVdb)
{
    // A bool grid's leaves are not walked by the layout check: the whole file goes to
    // OpenVDB's reader (delayed loading), with the same result.
    const std::string file = writeWithOpenVdb(ivdb::test::everyKindOfGrid(/*bools=*/true),
                                              vio::COMPRESS_BLOSC | vio::COMPRESS_ACTIVE_MASK,
                                              "b.vdb");
    const openvdb::GridPtrVec ours = ivdb::io::readVdb(file);
    EXPECT_GT(leavesNotLoaded(ours), 0u) << "read by io::File with delayed loading";
    expectSameGrids(ours, readWithOpenVdb(file), "with a bool grid");
}

TEST_F(TestVdbReader, OurWriterRoundTrips)
{
    const openvdb::GridCPtrVec grids = ivdb::test::everyKindOfGrid(/*bools=*/false);
    for (auto c : {ivdb::io::Compression::Blosc, ivdb::io::Compression::Zip,
                   ivdb::io::Compression::None}) {
        for (bool half : {false, true}) {
            ivdb::io::WriteOptions options;
            options.compression = c;
            options.half = half;
            ivdb::io::writeVdb(path("w.vdb"), grids, openvdb::MetaMap(), options);
            expectSameGrids(ivdb::io::readVdb(path("w.vdb")), readWithOpenVdb(path("w.vdb")),
                            ivdb::io::compressionNames()[std::size_t(c)] +
                                (half ? ", half" : ""));
        }
    }
}

} // namespace

TEST_F(TestVdbReader, PartialGridReadsTheTopologyAndOnlyTheLeavesAskedFor)
{
    // What each ivdb-mpi rank reads: the level set's nodes, tiles and value masks, and the values
    // of only the leaves it asks for, which equal a full read's.
    auto fog = ivdb::test::sphere(0.5f, 0.05f, "density");
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    auto ls = ivdb::test::sphere(1.0f, 0.01f, "surface");
    ivdb::io::writeVdb(path("two.vdb"), {fog, ls});
    const auto full = openvdb::gridPtrCast<openvdb::FloatGrid>(
        ivdb::io::selectGrid(ivdb::io::readVdb(path("two.vdb")), path("two.vdb"), ""));
    ivdb::io::PartialGrid part(path("two.vdb"), "");
    const auto& g = *part.grid();
    EXPECT_EQ(g.getName(), "surface");
    EXPECT_EQ(g.background(), full->background());
    std::vector<const openvdb::FloatTree::LeafNodeType*> want;
    for (auto it = full->tree().cbeginLeaf(); it; ++it) want.push_back(&*it);
    const auto& leaves = part.leaves();
    ASSERT_EQ(leaves.size(), want.size());
    for (const auto* leaf : leaves) EXPECT_TRUE(leaf->buffer().empty());
    std::vector<std::uint64_t> every3rd;
    for (std::uint64_t i = 0; i < leaves.size(); i += 3) every3rd.push_back(i);
    part.load(every3rd);
    part.checkValues(every3rd);
    std::size_t loaded = 0;
    for (std::size_t i = 0; i < leaves.size(); ++i) {
        EXPECT_EQ(leaves[i]->origin(), want[i]->origin());
        EXPECT_EQ(leaves[i]->getValueMask(), want[i]->getValueMask());
        if (i % 3 != 0) {
            EXPECT_TRUE(leaves[i]->buffer().empty()) << "leaf " << i << " was read";
            continue;
        }
        ++loaded;
        EXPECT_EQ(std::memcmp(leaves[i]->buffer().data(), want[i]->buffer().data(),
                              sizeof(float) * openvdb::FloatTree::LeafNodeType::SIZE), 0) << i;
    }
    EXPECT_EQ(loaded, every3rd.size());
    // The tiles (inside the sphere) are the full read's.
    std::size_t tiles = 0;
    for (auto it = full->tree().cbeginValueAll(); it; ++it) {
        if (it.getLevel() == 0) continue;
        ++tiles;
        EXPECT_EQ(g.tree().getValue(it.getCoord()), *it);
    }
    EXPECT_GT(tiles, 0u);
    // A grid by name; one that is not there, or not float values.
    EXPECT_EQ(ivdb::io::PartialGrid(path("two.vdb"), "density").grid()->getName(), "density");
    EXPECT_THROW(ivdb::io::PartialGrid(path("two.vdb"), "nope"), ivdb::ParamError);
    auto vec = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    vec->setName("v");
    vec->tree().setValue(openvdb::Coord(1, 2, 3), openvdb::Vec3s(1.0f));
    ivdb::io::writeVdb(path("vec.vdb"), {vec});
    EXPECT_THROW(ivdb::io::PartialGrid(path("vec.vdb"), "v"), ivdb::ParamError);
    EXPECT_THROW(ivdb::io::PartialGrid(path("missing.vdb"), ""), openvdb::IoError);
    // A value that is not finite in a leaf read is found there.
    auto bad = ivdb::test::sphere(0.5f, 0.05f, "surface");
    const openvdb::Coord at = bad->tree().cbeginLeaf()->origin();
    bad->tree().setValueOnly(at, std::numeric_limits<float>::quiet_NaN());
    ivdb::io::writeVdb(path("nan.vdb"), {bad});
    ivdb::io::PartialGrid damaged(path("nan.vdb"), "");
    damaged.load({0, 1});
    EXPECT_THROW(damaged.checkValues({0, 1}), openvdb::ValueError);
    damaged.load({2});
    EXPECT_NO_THROW(damaged.checkValues({2}));
    // Indices past the leaves, and loads after the file was let go, are the caller's mistakes.
    EXPECT_THROW(damaged.load({damaged.leaves().size()}), openvdb::ValueError);
    damaged.release();
    EXPECT_THROW(damaged.load({3}), openvdb::ValueError);
    EXPECT_NO_THROW(damaged.checkValues({2}));
}
