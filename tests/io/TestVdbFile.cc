// SPDX-License-Identifier: Apache-2.0
// .vdb files: atomic writes, reads that refuse bad files with an IoError naming the path,
// and the grid description that `ivdb info` prints.
#include <ivdb/io/VdbFile.h>

#include <openvdb/io/File.h>
#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Diagnostics.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <gtest/gtest.h>

#include "../TempDirTest.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;

class TestVdbFile: public ivdb::test::TempDirTest
{
protected:
    TestVdbFile(): TempDirTest("io") {}

    static openvdb::FloatGrid::Ptr makeSphere(float radius = 1.0f, float voxel = 0.05f)
    {
        auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            radius, openvdb::Vec3f(0.1f, -0.2f, 0.3f), voxel, 3.0f);
        grid->setName("surface");
        grid->insertMeta("ivdb_scene", openvdb::StringMetadata("{\"shape\":{}}"));
        grid->insertMeta("answer", openvdb::Int32Metadata(42));
        return grid;
    }

    /// Names in the test folder that look like temporary files of writeVdb.
    std::vector<std::string> tempFiles() const
    {
        std::vector<std::string> out;
        for (const auto& e : fs::directory_iterator(mDir)) {
            const std::string name = e.path().filename().string();
            if (name.find(".tmp-") != std::string::npos) out.push_back(name);
        }
        return out;
    }

    static std::string readBytes(const std::string& p)
    {
        std::ifstream in(p, std::ios::binary);
        return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }

    static void writeBytes(const std::string& p, const std::string& bytes)
    {
        std::ofstream out(p, std::ios::binary | std::ios::trunc);
        out.write(bytes.data(), std::streamsize(bytes.size()));
    }

    /// Expect readVdb(@a p) to throw openvdb::IoError whose message names @a p, quickly and
    /// within bounded memory. The read runs in a child process (10 s alarm, address space
    /// limited to 1.5 GB more than now), so a crash, a hang or a runaway allocation on a
    /// corrupt file is reported as a failure instead of taking the test run down.
    static void expectReadFails(const std::string& p, const std::string& what,
                                const std::string& needle = std::string())
    {
        enum Outcome { kIoErrorWithPath = 10, kIoErrorWithoutPath, kOtherException, kNoThrow,
                       kOutOfMemory };
        int fds[2];
        ASSERT_EQ(::pipe(fds), 0);
        const pid_t pid = ::fork();
        ASSERT_GE(pid, 0);
        if (pid == 0) {
            ::close(fds[0]);
            long pages = 0, pageSize = ::sysconf(_SC_PAGESIZE);
            if (FILE* f = std::fopen("/proc/self/statm", "r")) {
                if (std::fscanf(f, "%ld", &pages) != 1) pages = 0;
                std::fclose(f);
            }
            struct rlimit lim;
            lim.rlim_cur = lim.rlim_max = rlim_t(pages) * rlim_t(pageSize) + (rlim_t(3) << 29);
            ::setrlimit(RLIMIT_AS, &lim);
            ::alarm(10);
            int outcome = kOtherException;
            std::string text;
            try {
                const openvdb::GridPtrVec grids = ivdb::io::readVdb(p);
                outcome = kNoThrow;
                text = std::to_string(grids.size()) + " grid(s) read";
            } catch (const openvdb::IoError& e) {
                text = e.what();
                outcome = text.find("bad_alloc") != std::string::npos ? kOutOfMemory
                        : text.find(p) != std::string::npos ? kIoErrorWithPath
                                                            : kIoErrorWithoutPath;
            } catch (const std::bad_alloc& e) {
                outcome = kOutOfMemory;
                text = e.what();
            } catch (const std::exception& e) {
                text = e.what();
            } catch (...) {
                text = "a non-std exception";
            }
            if (::write(fds[1], text.data(), text.size()) < 0) outcome = kOtherException;
            ::_exit(outcome);
        }
        ::close(fds[1]);
        std::string text;
        char buf[512];
        for (ssize_t n; (n = ::read(fds[0], buf, sizeof(buf))) > 0;) text.append(buf, size_t(n));
        ::close(fds[0]);
        int status = 0;
        ASSERT_EQ(::waitpid(pid, &status, 0), pid);
        if (WIFSIGNALED(status)) {
            ADD_FAILURE() << what << ": readVdb "
                          << (WTERMSIG(status) == SIGALRM ? std::string("did not finish in 10 s")
                                  : "crashed with signal " + std::to_string(WTERMSIG(status)));
            return;
        }
        ASSERT_TRUE(WIFEXITED(status));
        switch (WEXITSTATUS(status)) {
        case kIoErrorWithPath:
            EXPECT_NE(text.find(needle), std::string::npos)
                << what << ": the message does not say '" << needle << "': " << text;
            break;
        case kIoErrorWithoutPath:
            ADD_FAILURE() << what << ": message does not name the path: " << text;
            break;
        case kNoThrow: ADD_FAILURE() << what << ": readVdb did not throw (" << text << ")"; break;
        case kOutOfMemory:
            ADD_FAILURE() << what << ": readVdb ran out of memory (1.5 GB) instead of refusing "
                          << "the file: " << text;
            break;
        default:
            ADD_FAILURE() << what << ": expected openvdb::IoError, got: " << text;
        }
    }

    /// Expect writeVdb(@a p) to throw openvdb::IoError whose message names @a p.
    static void expectWriteFails(const std::string& p, const openvdb::GridCPtrVec& grids,
                                 const std::string& what)
    {
        try {
            ivdb::io::writeVdb(p, grids);
            ADD_FAILURE() << what << ": writeVdb did not throw";
        } catch (const openvdb::IoError& e) {
            EXPECT_NE(std::string(e.what()).find(p), std::string::npos)
                << what << ": message does not name the path: " << e.what();
        } catch (const std::exception& e) {
            ADD_FAILURE() << what << ": expected openvdb::IoError, got: " << e.what();
        }
    }

};

TEST_F(TestVdbFile, RoundTrip)
{
    const auto grid = makeSphere();
    const std::string out = path("sphere.vdb");
    openvdb::MetaMap fileMeta;
    fileMeta.insertMeta("creator", openvdb::StringMetadata("ivdb test"));
    ivdb::io::writeVdb(out, {grid}, fileMeta);
    ASSERT_TRUE(fs::is_regular_file(out));
    EXPECT_TRUE(tempFiles().empty());

    const openvdb::GridPtrVec grids = ivdb::io::readVdb(out);
    ASSERT_EQ(grids.size(), 1u);
    auto back = openvdb::gridPtrCast<openvdb::FloatGrid>(grids[0]);
    ASSERT_TRUE(back);
    EXPECT_EQ(back->getName(), "surface");
    EXPECT_EQ(back->getGridClass(), openvdb::GRID_LEVEL_SET);
    EXPECT_EQ(back->activeVoxelCount(), grid->activeVoxelCount());
    EXPECT_EQ(back->tree().leafCount(), grid->tree().leafCount());
    EXPECT_FLOAT_EQ(back->background(), grid->background());
    EXPECT_NEAR(back->voxelSize()[0], 0.05, 1e-7);
    EXPECT_EQ(back->evalActiveVoxelBoundingBox(), grid->evalActiveVoxelBoundingBox());
    // every active voxel has the same value and state (the default codec is lossless for floats)
    auto acc = back->getConstAccessor();
    std::size_t checked = 0;
    for (auto it = grid->cbeginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        ASSERT_TRUE(acc.isValueOn(c)) << c;
        ASSERT_EQ(acc.getValue(c), *it) << c;
        ++checked;
    }
    EXPECT_EQ(checked, grid->activeVoxelCount());
    // inactive values (interior and exterior background) survive too
    EXPECT_FLOAT_EQ(back->tree().getValue(back->transform().worldToIndexCellCentered(
                        openvdb::Vec3d(0.1, -0.2, 0.3))),
                    -grid->background());
    EXPECT_FLOAT_EQ(back->tree().getValue(openvdb::Coord(1000, 0, 0)), grid->background());
    // grid metadata
    ASSERT_TRUE(back->getMetadata<openvdb::StringMetadata>("ivdb_scene"));
    EXPECT_EQ(back->metaValue<std::string>("ivdb_scene"), "{\"shape\":{}}");
    EXPECT_EQ(back->metaValue<openvdb::Int32>("answer"), 42);
}

TEST_F(TestVdbFile, ReadableByOpenVdb)
{
    const auto grid = makeSphere(0.5f, 0.02f);
    const std::string out = path("plain.vdb");
    openvdb::MetaMap fileMeta;
    fileMeta.insertMeta("creator", openvdb::StringMetadata("ivdb test"));
    ivdb::io::writeVdb(out, {grid}, fileMeta);

    openvdb::io::File file(out);
    ASSERT_NO_THROW(file.open());
    auto meta = file.getMetadata();
    ASSERT_TRUE(meta);
    EXPECT_EQ(meta->metaValue<std::string>("creator"), "ivdb test");
    EXPECT_TRUE(file.hasGrid("surface"));
    // delayed loading works through the stored grid offsets
    openvdb::GridBase::Ptr base = file.readGrid("surface");
    file.close();
    auto back = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
    ASSERT_TRUE(back);
    EXPECT_EQ(back->activeVoxelCount(), grid->activeVoxelCount());
    // the default compression is on: the file is smaller than the raw leaf values
    const auto bytes = fs::file_size(out);
    EXPECT_GT(bytes, 0u);
    EXPECT_LT(bytes, grid->activeVoxelCount() * sizeof(float) * 2);
}

TEST_F(TestVdbFile, SeveralGridsAndOverwrite)
{
    const auto a = makeSphere(1.0f, 0.1f);
    auto b = makeSphere(0.5f, 0.1f);
    b->setName("small");
    const std::string out = path("two.vdb");
    ivdb::io::writeVdb(out, {a, b});
    ASSERT_EQ(ivdb::io::readVdb(out).size(), 2u);
    // writing again replaces the file atomically
    ivdb::io::writeVdb(out, {b});
    const auto grids = ivdb::io::readVdb(out);
    ASSERT_EQ(grids.size(), 1u);
    EXPECT_EQ(grids[0]->getName(), "small");
    EXPECT_EQ(grids[0]->activeVoxelCount(), b->activeVoxelCount());
    EXPECT_TRUE(tempFiles().empty());
    // a path without a folder part writes into the current folder
    const fs::path cwd = fs::current_path();
    fs::current_path(mDir);
    EXPECT_NO_THROW(ivdb::io::writeVdb("bare.vdb", {a}));
    fs::current_path(cwd);
    EXPECT_TRUE(fs::is_regular_file(mDir / "bare.vdb"));
}

TEST_F(TestVdbFile, WriteFailures)
{
    const auto grid = makeSphere(1.0f, 0.1f);
    // into a missing folder
    const std::string missing = path("no/such/folder/out.vdb");
    expectWriteFails(missing, {grid}, "missing folder");
    EXPECT_FALSE(fs::exists(mDir / "no"));
    EXPECT_THROW(ivdb::io::checkOutputPath(missing), openvdb::IoError);
    // to a path that is a folder
    const std::string folder = path("folder.vdb");
    fs::create_directories(folder);
    expectWriteFails(folder, {grid}, "path is a folder");
    EXPECT_TRUE(fs::is_directory(folder));
    EXPECT_TRUE(fs::is_empty(folder));
    EXPECT_THROW(ivdb::io::checkOutputPath(folder), openvdb::IoError);
    // the empty path
    EXPECT_THROW(ivdb::io::checkOutputPath(""), openvdb::IoError);
    EXPECT_THROW(ivdb::io::writeVdb("", {grid}), openvdb::IoError);
    // a good path passes the check and creates nothing
    EXPECT_NO_THROW(ivdb::io::checkOutputPath(path("fine.vdb")));
    EXPECT_FALSE(fs::exists(path("fine.vdb")));
    EXPECT_TRUE(tempFiles().empty());
}

TEST_F(TestVdbFile, FailedWriteLeavesExistingOutput)
{
    // /dev/full cannot be used to make the write fail: writeVdb writes a temporary file in the
    // target's folder (/dev) and renames it over the target, so it would replace the device node.
    // Instead, simulate a full disk: a file size limit makes write() fail with EFBIG part way.
    const auto grid = makeSphere(1.0f, 0.1f);
    const std::string out = path("keep.vdb");
    ivdb::io::writeVdb(out, {grid});
    const std::string before = readBytes(out);
    ASSERT_FALSE(before.empty());
    const auto big = makeSphere(1.0f, 0.02f);
    struct rlimit old {};
    ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old), 0);
    auto oldHandler = std::signal(SIGXFSZ, SIG_IGN);
    struct rlimit small = old;
    small.rlim_cur = 4096;
    ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
    bool threw = false;
    std::string message;
    try {
        ivdb::io::writeVdb(out, {big});
    } catch (const openvdb::IoError& e) {
        threw = true;
        message = e.what();
    } catch (const std::exception& e) {
        message = std::string("wrong exception type: ") + e.what();
    }
    ::setrlimit(RLIMIT_FSIZE, &old);
    std::signal(SIGXFSZ, oldHandler);
    EXPECT_TRUE(threw) << "writeVdb did not throw openvdb::IoError when the disk filled up; "
                       << message;
    EXPECT_NE(message.find(out), std::string::npos) << message;
    EXPECT_EQ(readBytes(out), before);
    EXPECT_EQ(ivdb::io::readVdb(out).at(0)->activeVoxelCount(), grid->activeVoxelCount());
    EXPECT_TRUE(tempFiles().empty());

    // a failed write into a missing folder does not touch an existing file of the same name
    expectWriteFails(path("missing/keep.vdb"), {grid}, "missing folder");
    EXPECT_EQ(readBytes(out), before);
    EXPECT_TRUE(tempFiles().empty());
}

TEST_F(TestVdbFile, ReadMissingFolderEmptyAndText)
{
    expectReadFails(path("missing.vdb"), "missing file");
    expectReadFails(mDir.string(), "a folder");
    const std::string empty = path("empty.vdb");
    writeBytes(empty, "");
    expectReadFails(empty, "empty file");
    const std::string text = path("text.vdb");
    writeBytes(text, "this is not a vdb file\nat all\n");
    expectReadFails(text, "text file");
    // a file with the right magic number and nothing else
    const std::string full = path("full.vdb");
    ivdb::io::writeVdb(full, {makeSphere(1.0f, 0.1f)});
    const std::string bytes = readBytes(full);
    const std::string magicOnly = path("magic.vdb");
    writeBytes(magicOnly, bytes.substr(0, 8));
    expectReadFails(magicOnly, "magic number only");
}

TEST_F(TestVdbFile, ReadTruncated)
{
    const std::string full = path("full.vdb");
    ivdb::io::writeVdb(full, {makeSphere(1.0f, 0.05f)});
    const std::string bytes = readBytes(full);
    ASSERT_GT(bytes.size(), 1000u);
    ASSERT_EQ(ivdb::io::readVdb(full).size(), 1u);

    // 10 offsets: inside the header, the file metadata, the grid descriptor and grid metadata
    // (a region where OpenVDB reads garbage lengths), the topology, the leaf values, and one
    // byte short of the end
    const std::vector<std::size_t> offsets = {
        4, 16, 64, 130, 180, 230, 400, bytes.size() / 3, bytes.size() / 2 + 7, bytes.size() - 1};
    for (std::size_t n : offsets) {
        const std::string cut = path("cut-" + std::to_string(n) + ".vdb");
        writeBytes(cut, bytes.substr(0, n));
        expectReadFails(cut, "truncated at " + std::to_string(n) + " of " +
                                 std::to_string(bytes.size()) + " bytes");
    }
}

TEST_F(TestVdbFile, ReadRefusesDamagedTransformAndRootRecords)
{
    // A sphere (root children) and two root-level tiles, one active, one inactive.
    auto grid = makeSphere(1.0f, 0.1f);
    grid->tree().addTile(/*level=*/3, openvdb::Coord(8192, 0, -4096), 2.5f, /*active=*/true);
    grid->tree().addTile(3, openvdb::Coord(-8192, 4096, 0), -1.5f, /*active=*/false);
    grid->insertMeta("flag", openvdb::BoolMetadata(true));
    const std::string full = path("tiles.vdb");
    ivdb::io::writeVdb(full, {grid});
    const std::string bytes = readBytes(full);
    const auto read = ivdb::io::readVdb(full);
    ASSERT_EQ(read.size(), 1u);
    auto back = openvdb::gridPtrCast<openvdb::FloatGrid>(read[0]);
    ASSERT_TRUE(back);
    EXPECT_EQ(back->tree().getValue(openvdb::Coord(8192 + 5, 7, -4096 + 9)), 2.5f);
    EXPECT_TRUE(back->tree().isValueOn(openvdb::Coord(8192, 0, -4096)));

    // Each root tile record is: origin (3 x int32), value (float), active (1 byte).
    const auto record = [&](std::int32_t x, std::int32_t y, std::int32_t z, float v) {
        std::string key(16, '\0');
        const std::int32_t xyz[3] = {x, y, z};
        std::memcpy(&key[0], xyz, 12);
        std::memcpy(&key[12], &v, 4);
        const std::size_t at = bytes.find(key);
        EXPECT_NE(at, std::string::npos);
        EXPECT_EQ(bytes.find(key, at + 1), std::string::npos) << "the record is not unique";
        return at;
    };
    const std::size_t active = record(8192, 0, -4096, 2.5f);
    const std::size_t inactive = record(-8192, 4096, 0, -1.5f);
    ASSERT_NE(active, std::string::npos);
    ASSERT_NE(inactive, std::string::npos);
    ASSERT_EQ(bytes[active + 16], '\1');
    ASSERT_EQ(bytes[inactive + 16], '\0');

    const auto damaged = [&](const std::string& name, std::size_t at, const std::string& with) {
        std::string copy = bytes;
        copy.replace(at, with.size(), with);
        const std::string out = path(name + ".vdb");
        writeBytes(out, copy);
        return out;
    };
    // An "active" flag that is not a bool: OpenVDB would read it into a bool (undefined).
    expectReadFails(damaged("flag", active + 16, "\x02"), "active flag 2", "root tile");
    expectReadFails(damaged("flag2", inactive + 16, "\xff"), "active flag 255", "root tile");
    // A tile origin off the root's 4096-voxel grid.
    expectReadFails(damaged("origin", active, "\x01\x20"), "origin 8193", "root tile");
    // A tile count the file cannot hold: 12 bytes before the first record (tiles, children).
    const std::size_t first = std::min(active, inactive);
    // A root child origin off the grid, in each coordinate: the first child's record follows
    // the two tile records (17 bytes each) and starts with its origin.
    const std::size_t child = first + 2 * 17;
    std::int32_t childOrigin[3];
    std::memcpy(childOrigin, &bytes[child], 12);
    for (int a = 0; a < 3; ++a) ASSERT_EQ(childOrigin[a] % 4096, 0) << "not a child record";
    for (int a = 0; a < 3; ++a) {
        expectReadFails(damaged("child" + std::to_string(a), child + 4 * a, "\x01"),
                        "child origin off the grid in coordinate " + std::to_string(a),
                        "root child at an invalid origin");
    }
    expectReadFails(damaged("count", first - 8, std::string("\xff\xff\xff\x7f", 4)),
                    "2^31 tiles", "root tiles");
    // Metadata whose byte count is not its type's size: OpenVDB would read the type's size and
    // then everything after it from the wrong place.
    const std::string int32Key = std::string("answer") + std::string("\x05\0\0\0int32", 9);
    const std::size_t answer = bytes.find(int32Key);
    ASSERT_NE(answer, std::string::npos);
    expectReadFails(damaged("metasize", answer + int32Key.size(), std::string("\x05", 1)),
                    "int32 metadata of 5 bytes", "holds 5 bytes instead of 4");
    // A bool metadata value that is not 0 or 1 (OpenVDB reads it straight into a bool).
    const std::string boolKey = std::string("flag") + std::string("\x04\0\0\0bool\x01\0\0\0", 12);
    const std::size_t flag = bytes.find(boolKey);
    ASSERT_NE(flag, std::string::npos);
    ASSERT_EQ(bytes[flag + boolKey.size()], '\1');
    expectReadFails(damaged("metabool", flag + boolKey.size(), "\x07"), "bool metadata 7",
                    "not a bool");
    // A transform of a type OpenVDB does not know.
    const std::size_t map = bytes.find("UniformScaleMap");
    ASSERT_NE(map, std::string::npos);
    expectReadFails(damaged("map", map, "UniformScaleMaq"), "unknown map", "unknown type");
}

TEST_F(TestVdbFile, ReadsStreamsSharedTreesAndEmptyGridsAndRefusesOtherFormats)
{
    auto sphere = makeSphere(1.0f, 0.1f);
    auto shared = sphere->copyGrid(); // shares the tree: written as an instance
    shared->setName("shared");
    auto vectors = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    vectors->setName("vectors");
    vectors->fill(openvdb::CoordBBox(openvdb::Coord(-20), openvdb::Coord(20)),
                  openvdb::Vec3s(1.0f, 2.0f, 3.0f));
    // A grid without leaves: OpenVDB writes its delayed-load table with 0 bytes.
    auto empty = openvdb::FloatGrid::create(0.5f);
    empty->setName("empty");
    const openvdb::GridCPtrVec grids = {sphere, shared, vectors, empty};

    // io::File's layout (with grid offsets), through ivdb's writer
    const std::string file = path("file.vdb");
    ivdb::io::writeVdb(file, grids);
    // io::Stream's layout (no offsets: each grid follows its record), saved to a file
    const std::string stream = path("stream.vdb");
    {
        std::ofstream out(stream, std::ios::binary);
        openvdb::io::Stream(out).write(grids);
    }
    for (const std::string& p : {file, stream}) {
        SCOPED_TRACE(p);
        const auto read = ivdb::io::readVdb(p);
        ASSERT_EQ(read.size(), 4u);
        const auto named = [&read](const std::string& name) {
            for (const auto& g : read) {
                if (g->getName() == name) return g;
            }
            return openvdb::GridBase::Ptr();
        };
        auto a = openvdb::gridPtrCast<openvdb::FloatGrid>(named("surface"));
        auto b = openvdb::gridPtrCast<openvdb::FloatGrid>(named("shared"));
        auto v = openvdb::gridPtrCast<openvdb::Vec3SGrid>(named("vectors"));
        auto e = openvdb::gridPtrCast<openvdb::FloatGrid>(named("empty"));
        ASSERT_TRUE(a && b && v && e);
        EXPECT_EQ(e->activeVoxelCount(), 0u);
        EXPECT_EQ(e->background(), 0.5f);
        EXPECT_EQ(a->activeVoxelCount(), sphere->activeVoxelCount());
        EXPECT_EQ(b->activeVoxelCount(), sphere->activeVoxelCount());
        EXPECT_EQ(v->activeVoxelCount(), vectors->activeVoxelCount());
        EXPECT_EQ(v->tree().getValue(openvdb::Coord(3, -4, 5)), openvdb::Vec3s(1.0f, 2.0f, 3.0f));
        const openvdb::Coord ijk(0, 0, 10);
        EXPECT_EQ(a->tree().getValue(ijk), sphere->tree().getValue(ijk));
    }
    // Truncated streams: the grids' own bytes are all that says where each ends.
    const std::string bytes = readBytes(stream);
    for (std::size_t n : {bytes.size() / 4, bytes.size() / 2, bytes.size() - 9}) {
        const std::string cut = path("stream-cut-" + std::to_string(n) + ".vdb");
        writeBytes(cut, bytes.substr(0, n));
        expectReadFails(cut, "stream truncated at " + std::to_string(n));
    }
    // A stream with a grid type whose layout ivdb does not walk is refused, with what to do.
    auto mask = openvdb::BoolGrid::create(false);
    mask->setName("mask");
    mask->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(9)), true);
    const std::string boolStream = path("bool-stream.vdb");
    {
        std::ofstream out(boolStream, std::ios::binary);
        openvdb::io::Stream(out).write(openvdb::GridCPtrVec{mask});
    }
    expectReadFails(boolStream, "bool grid in a stream", "vdb_tool");
    // ... and read from a file with offsets.
    const std::string boolFile = path("bool-file.vdb");
    ivdb::io::writeVdb(boolFile, {mask});
    EXPECT_EQ(ivdb::io::readVdb(boolFile).size(), 1u);

    // File format versions outside 222 (OpenVDB 1.0) to 224 (this OpenVDB's).
    for (std::uint32_t version : {213u, 221u, 225u, 0x7fffffffu}) {
        std::string copy = readBytes(file);
        std::memcpy(&copy[8], &version, 4);
        const std::string out = path("version-" + std::to_string(version) + ".vdb");
        writeBytes(out, copy);
        expectReadFails(out, "file format " + std::to_string(version), "file format");
    }
}

TEST_F(TestVdbFile, DescribeGrid)
{
    const auto grid = makeSphere(1.0f, 0.05f);
    const ivdb::io::GridInfo info = ivdb::io::describeGrid(*grid);
    EXPECT_EQ(info.name, "surface");
    EXPECT_EQ(info.gridClass, "level set");
    EXPECT_TRUE(info.isLevelSet);
    EXPECT_EQ(info.valueType, "float");
    EXPECT_NEAR(info.voxelSize[0], 0.05, 1e-7);
    EXPECT_NEAR(info.voxelSize[1], 0.05, 1e-7);
    EXPECT_NEAR(info.voxelSize[2], 0.05, 1e-7);
    EXPECT_EQ(info.activeVoxels, grid->activeVoxelCount());
    EXPECT_GT(info.activeVoxels, 0u);
    EXPECT_EQ(info.leafNodes, grid->tree().leafCount());
    EXPECT_EQ(info.indexBox, grid->evalActiveVoxelBoundingBox());
    ASSERT_EQ(info.background.size(), 1u);
    EXPECT_NEAR(info.background[0], 3 * 0.05, 1e-6);
    EXPECT_GT(info.memoryBytes, 0u);
    // world box: the index box in world units; the sphere (r 1 at (0.1, -0.2, 0.3)) plus the band
    const openvdb::Vec3d c(0.1, -0.2, 0.3);
    for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(info.worldBox.min()[i], c[i] - 1.0, 3 * 0.05 + 0.05) << i;
        EXPECT_NEAR(info.worldBox.max()[i], c[i] + 1.0, 3 * 0.05 + 0.05) << i;
        const double h = grid->voxelSize()[0];
        EXPECT_NEAR(info.worldBox.min()[i], info.indexBox.min()[i] * h, 1e-9) << i;
        EXPECT_NEAR(info.worldBox.max()[i], info.indexBox.max()[i] * h, 1e-9) << i;
    }
    // an empty fog grid
    auto fog = openvdb::FloatGrid::create(0.0f);
    fog->setName("density");
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    const ivdb::io::GridInfo f = ivdb::io::describeGrid(*fog);
    EXPECT_EQ(f.name, "density");
    EXPECT_EQ(f.gridClass, "fog volume");
    EXPECT_FALSE(f.isLevelSet);
    EXPECT_EQ(f.activeVoxels, 0u);
    EXPECT_TRUE(f.indexBox.empty());
    // after a round trip the description is the same
    const std::string out = path("d.vdb");
    ivdb::io::writeVdb(out, {grid});
    const ivdb::io::GridInfo r = ivdb::io::describeGrid(*ivdb::io::readVdb(out).at(0));
    EXPECT_EQ(r.activeVoxels, info.activeVoxels);
    EXPECT_EQ(r.indexBox, info.indexBox);
    EXPECT_EQ(r.gridClass, "level set");
}

// Every value a command reads is checked finite wherever it lies: an inactive voxel, an active
// one, a tile of a 128^3 node, of a 4096^3 node and of the root, the background; in float,
// double and vector grids (one component). OpenVDB's Diagnose (a reference that walks every
// value through its iterators) agrees on each.
TEST_F(TestVdbFile, ValuesThatAreNotFiniteAreFoundWhereverTheyLie)
{
    const float kBad[] = {std::numeric_limits<float>::quiet_NaN(),
                          std::numeric_limits<float>::infinity(),
                          -std::numeric_limits<float>::infinity()};
    const auto refused = [](const openvdb::GridBase& g) {
        try {
            ivdb::io::checkGridValues(g, "x.vdb");
        } catch (const openvdb::ValueError& e) {
            EXPECT_NE(std::string(e.what()).find("not finite"), std::string::npos) << e.what();
            return true;
        }
        return false;
    };
    const auto sphere = [] {
        return openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(1.0f, openvdb::Vec3f(0.0f),
                                                                        0.05f);
    };
    ASSERT_FALSE(refused(*sphere()));
    for (float bad : kBad) {
        using Setter = std::function<void(openvdb::FloatGrid&)>;
        const std::vector<std::pair<const char*, Setter>> places{
            {"an inactive voxel", [&](openvdb::FloatGrid& g) {
                 auto* leaf = g.tree().probeLeaf(openvdb::Coord(20, 0, 0));
                 ASSERT_NE(leaf, nullptr);
                 const openvdb::Index m = leaf->beginValueOff().pos();
                 leaf->setValueOnly(m, bad);
             }},
            {"an active voxel", [&](openvdb::FloatGrid& g) {
                 g.tree().setValueOn(openvdb::Coord(20, 0, 0), bad);
             }},
            {"a tile of a 128^3 node", [&](openvdb::FloatGrid& g) {
                 g.tree().addTile(1, openvdb::Coord(0, 0, 0), bad, false);
             }},
            {"a tile of a 4096^3 node", [&](openvdb::FloatGrid& g) {
                 g.tree().addTile(2, openvdb::Coord(128, 128, 128), bad, false);
             }},
            {"a root tile", [&](openvdb::FloatGrid& g) {
                 g.tree().addTile(3, openvdb::Coord(8192, 0, 0), bad, true);
             }},
            {"the background", [&](openvdb::FloatGrid& g) {
                 g.tree().root().setBackground(bad, /*updateChildNodes=*/false);
             }}};
        for (const auto& [where, set] : places) {
            auto g = sphere();
            set(*g);
            EXPECT_TRUE(refused(*g)) << where << " " << bad;
            // The reference: OpenVDB's own check over every value.
            openvdb::tools::Diagnose<openvdb::FloatGrid> diagnose(*g);
            openvdb::tools::CheckFinite<openvdb::FloatGrid, openvdb::FloatGrid::ValueAllCIter> finite;
            EXPECT_FALSE(diagnose.check(finite, false, true, true, true).empty()) << where;
        }
        auto d = openvdb::DoubleGrid::create(0.0);
        d->tree().setValueOn(openvdb::Coord(3, 4, 5), 1.0);
        ASSERT_FALSE(refused(*d));
        d->tree().setValueOff(openvdb::Coord(3, 4, 6), double(bad));
        EXPECT_TRUE(refused(*d)) << bad;
        for (int c = 0; c < 3; ++c) {
            auto v = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
            v->tree().setValueOn(openvdb::Coord(-9, 1, 2), openvdb::Vec3s(1.0f, 2.0f, 3.0f));
            ASSERT_FALSE(refused(*v));
            openvdb::Vec3s value(1.0f, 2.0f, 3.0f);
            value[c] = bad;
            v->tree().setValueOn(openvdb::Coord(-9, 1, 7), value);
            EXPECT_TRUE(refused(*v)) << "component " << c << " " << bad;
        }
    }
}

} // namespace
