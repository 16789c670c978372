// SPDX-License-Identifier: Apache-2.0
// The parallel .vdb writer against OpenVDB's own: for the same grids and compression, the file
// io::File::write makes, byte for byte but for the random UUID; read back by OpenVDB.
#include <ivdb/io/VdbFile.h>

#include "Grids.h"

#include <ivdb/diff/Differential.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include "../TempDirTest.h"

#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <tbb/global_control.h>
#include <tbb/task_group.h>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;

class TestVdbWriter: public ivdb::test::TempDirTest
{
protected:
    TestVdbWriter(): TempDirTest("writer") {}

    static std::string bytes(const std::string& file)
    {
        std::ifstream in(file, std::ios::binary);
        return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }

    /// The same grids written by io::File and by ivdb: equal bytes but the UUID (36 bytes at
    /// offset 21, after the magic number, the format and library versions and the offsets flag).
    void expectSameFile(const openvdb::GridCPtrVec& grids, ivdb::io::Compression c,
                        const std::string& what, std::uint64_t bufferLimit = 0)
    {
        openvdb::MetaMap meta;
        meta.insertMeta("creator", openvdb::StringMetadata("test"));
        {
            openvdb::io::File f(path("openvdb.vdb"));
            f.setCompression(ivdb::io::compressionFlags(c));
            f.write(grids, meta);
            f.close();
        }
        ivdb::io::WriteOptions options;
        options.compression = c;
        options.bufferLimit = bufferLimit;
        ivdb::io::writeVdb(path("ivdb.vdb"), grids, meta, options);
        std::string a = bytes(path("openvdb.vdb")), b = bytes(path("ivdb.vdb"));
        ASSERT_EQ(a.size(), b.size()) << what;
        ASSERT_GT(a.size(), 57u);
        EXPECT_NE(a.substr(21, 36), b.substr(21, 36)) << what << ": the UUID is new per file";
        a.replace(21, 36, 36, '-');
        b.replace(21, 36, 36, '-');
        std::size_t first = 0;
        while (first < a.size() && a[first] == b[first]) ++first;
        EXPECT_EQ(first, a.size()) << what << ": first difference at byte " << first << " of "
                                   << a.size();
        // And OpenVDB reads ours.
        openvdb::io::File f(path("ivdb.vdb"));
        f.open();
        EXPECT_EQ(f.getGrids()->size(), grids.size()) << what;
        f.close();
    }

};

using ivdb::test::sphere;

TEST_F(TestVdbWriter, SameBytesAsOpenVdbForEveryKindOfGrid)
{
    const openvdb::GridCPtrVec all = ivdb::test::everyKindOfGrid(/*bools=*/true);
    const openvdb::GridCPtrVec pair{all[0], all[1]};
    for (auto c : {ivdb::io::Compression::Blosc, ivdb::io::Compression::Zip, ivdb::io::Compression::None}) {
        const std::string what = ivdb::io::compressionNames()[std::size_t(c)];
        expectSameFile(all, c, what);
        // The streaming path (every leaf compressed twice, as OpenVDB does) makes the same bytes.
        expectSameFile(pair, c, what + ", streamed", /*bufferLimit=*/1);
    }
}

TEST_F(TestVdbWriter, SameBytesForHalfFloatsAndOneThread)
{
    auto s = sphere(1.0f, 0.02f);
    auto half = s->deepCopy();
    half->setName("half");
    half->setSaveFloatAsHalf(true);
    auto gradient = ivdb::diff::gradient(*s, 1);
    gradient->setSaveFloatAsHalf(true);
    expectSameFile({s, half, gradient}, ivdb::io::Compression::Blosc, "half floats");
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    expectSameFile({s, half}, ivdb::io::Compression::Blosc, "one thread");
}

TEST_F(TestVdbWriter, HalfOptionFlagsFloatGrids)
{
    auto s = sphere(1.0f, 0.02f);
    ivdb::io::WriteOptions options;
    options.half = true;
    ivdb::io::writeVdb(path("h.vdb"), {s}, openvdb::MetaMap(), options);
    EXPECT_FALSE(s->saveFloatAsHalf()) << "the caller's grid is not changed";
    openvdb::io::File f(path("h.vdb"));
    f.open();
    auto back = openvdb::gridPtrCast<openvdb::FloatGrid>(f.readGrid("surface"));
    f.close();
    EXPECT_TRUE(back->saveFloatAsHalf());
    ASSERT_EQ(back->activeVoxelCount(), s->activeVoxelCount());
    auto acc = back->getConstAccessor();
    for (auto it = s->cbeginValueOn(); it; ++it) {
        // Half precision: 11 significant bits.
        ASSERT_NEAR(acc.getValue(it.getCoord()), *it, std::abs(*it) * 1e-3f + 1e-7f);
    }
}

// Called from a TBB task whose group was cancelled (another task of the caller's algorithm
// failed), the writer's parallel loops would skip work silently: it refuses instead of writing
// a short file, and the reader refuses instead of returning a half-read grid.
TEST_F(TestVdbWriter, CancelledTaskGroupWritesAndReadsNothing)
{
    auto s = sphere(1.0f, 0.01f);
    ivdb::io::writeVdb(path("whole.vdb"), {s});
    bool wrote = false, read = false;
    std::string writeError, readError;
    tbb::task_group_context context;
    tbb::task_group group(context);
    group.run([&] {
        context.cancel_group_execution();
        try {
            ivdb::io::writeVdb(path("cancelled.vdb"), {s});
            wrote = true;
        } catch (const openvdb::Exception& e) {
            writeError = e.what();
        }
        try {
            read = !ivdb::io::readVdb(path("whole.vdb")).empty();
        } catch (const openvdb::Exception& e) {
            readError = e.what();
        }
    });
    group.wait();
    EXPECT_FALSE(wrote);
    EXPECT_NE(writeError.find("cancelled"), std::string::npos) << writeError;
    EXPECT_FALSE(std::filesystem::exists(path("cancelled.vdb")));
    EXPECT_FALSE(read);
    EXPECT_NE(readError.find("cancelled"), std::string::npos) << readError;
    // Outside it, the same calls work.
    ivdb::io::writeVdb(path("after.vdb"), {s});
    EXPECT_EQ(ivdb::io::readVdb(path("after.vdb")).size(), 1u);
}

} // namespace
