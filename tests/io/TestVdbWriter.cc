// SPDX-License-Identifier: Apache-2.0
// The parallel .vdb writer against OpenVDB's own: for the same grids and compression, the file
// io::File::write makes, byte for byte but for the random UUID; read back by OpenVDB.
#include <ivdb/io/VdbFile.h>
#include <ivdb/io/VdbPieces.h>

#include "Grids.h"

#include <ivdb/diff/Differential.h>
#include <ivdb/levelset/Fog.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>

#include <gtest/gtest.h>

#include "../TempDirTest.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
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

namespace {

/// @a grid's leaves in @a runs runs of file order, each a grid of its own.
template<typename GridT>
std::vector<typename GridT::Ptr> leafRuns(const GridT& grid, int runs)
{
    using LeafT = typename GridT::TreeType::LeafNodeType;
    std::vector<const LeafT*> leaves;
    for (auto it = grid.tree().cbeginLeaf(); it; ++it) leaves.push_back(&*it);
    std::vector<typename GridT::Ptr> out;
    for (int r = 0; r < runs; ++r) {
        auto part = GridT::create(grid.background());
        part->setGridClass(grid.getGridClass());
        for (std::size_t i = leaves.size() * r / runs; i < leaves.size() * (r + 1) / runs; ++i) {
            part->tree().addLeaf(new LeafT(*leaves[i]));
        }
        out.push_back(part);
    }
    return out;
}

/// The file @a head lays out with each grid's runs @a runs[g] (their masks and buffers), as the
/// ranks write it; fails the test if a byte is not written exactly once.
std::string assembled(const ivdb::io::FileHead& head,
                      const std::vector<std::vector<ivdb::io::LeafRun>>& runs,
                      const std::string& what)
{
    std::string file(head.fileBytes, '\0');
    std::vector<int> writes(file.size(), 0);
    const auto put = [&](std::uint64_t at, const char* data, std::uint64_t n) {
        EXPECT_LE(at + n, file.size()) << what;
        if (at + n > file.size()) return;
        file.replace(at, n, data, n);
        for (std::uint64_t i = at; i < at + n; ++i) ++writes[i];
    };
    for (const auto& p : head.nonMaskParts()) put(p.offset, p.data, p.size);
    for (std::size_t g = 0; g < runs.size(); ++g) {
        std::uint64_t leaf = 0, at = head.grids[g].buffersAt();
        for (const auto& run : runs[g]) {
            for (const auto& [o, data] : head.maskWrites(g, leaf, run.masks)) put(o, data.data(), data.size());
            leaf += run.masks.size();
            for (const auto& piece : run.pieces) {
                put(at, piece.data(), piece.size());
                at += piece.size();
            }
        }
    }
    EXPECT_EQ(std::count(writes.begin(), writes.end(), 1), std::ptrdiff_t(file.size())) << what;
    return file;
}

/// The first byte where two files differ but for the UUID (their size if none).
std::size_t firstDifference(std::string a, std::string b)
{
    if (a.size() != b.size()) return 0;
    a.replace(21, 36, 36, '-');
    b.replace(21, 36, 36, '-');
    std::size_t first = 0;
    while (first < a.size() && a[first] == b[first]) ++first;
    return first;
}

} // namespace

TEST_F(TestVdbWriter, PiecesMakeTheSameFile)
{
    // The pieces ivdb-mpi writes (a head from the skeleton and the runs' entries, then each run's
    // buffers) are the file writeVdb writes, for level sets with inside tiles, leaf runs that
    // split 128^3 nodes, every compression and half floats.
    auto big = sphere(1.0f, 0.005f, "surface");
    openvdb::tools::signedFloodFill(big->tree());
    openvdb::tools::pruneLevelSet(big->tree());
    auto small = sphere(0.3f, 0.02f, "small");
    small->insertMeta("note", openvdb::StringMetadata("kept"));
    openvdb::MetaMap meta;
    meta.insertMeta("creator", openvdb::StringMetadata("test"));
    for (const auto& grid : {big, small}) {
        ASSERT_GT(grid->tree().activeTileCount() + grid->tree().leafCount(), 0u);
        const auto skeleton = ivdb::io::skeletonOf(*grid);
        // Every compression on the small grid; the large one (every kind of tile) with Blosc.
        const bool large = grid == big;
        for (auto c : {ivdb::io::Compression::Blosc, ivdb::io::Compression::Zip, ivdb::io::Compression::None}) {
            if (large && c != ivdb::io::Compression::Blosc) continue;
            for (bool half : {false, true}) {
                ivdb::io::WriteOptions options;
                options.compression = c;
                options.half = half;
                ivdb::io::writeVdb(path("whole.vdb"), {grid}, meta, options);
                for (int runs : {1, 3, 7}) {
                    if (large && runs == 3) continue;
                    const std::string what = grid->getName() + ", " +
                        ivdb::io::compressionNames()[std::size_t(c)] + (half ? ", half" : "") +
                        ", " + std::to_string(runs) + " runs";
                    ivdb::io::LeafRun all;
                    std::string body;
                    std::vector<ivdb::io::LeafRun> parts;
                    for (const auto& part : leafRuns(*grid, runs)) {
                        parts.push_back(ivdb::io::encodeLeafRun(*part, options));
                        const ivdb::io::LeafRun& run = parts.back();
                        const std::size_t before = body.size();
                        all.appendEntries(run);
                        for (const auto& piece : run.pieces) body += piece;
                        EXPECT_EQ(run.byteCount(), body.size() - before) << what;
                    }
                    ASSERT_EQ(all.masks.size(), grid->tree().leafCount()) << what;
                    EXPECT_EQ(all.activeVoxels, grid->activeVoxelCount()) << what;
                    const ivdb::io::FileHead fileHead =
                        ivdb::io::vdbFileHead(*skeleton, all, body.size(), meta, options);
                    // The head's own parts and each run's masks, as the ranks write them: every
                    // byte of the head written exactly once.
                    ASSERT_EQ(fileHead.grids.size(), 1u) << what;
                    const std::string& headBytes = fileHead.grids[0].bytes;
                    EXPECT_EQ(fileHead.fileBytes, headBytes.size() + body.size()) << what;
                    EXPECT_EQ(fileHead.grids[0].size, headBytes.size()) << what;
                    std::string head(headBytes.size(), '\0');
                    std::vector<int> writes(head.size(), 0);
                    const auto put = [&](std::uint64_t at, const char* data, std::uint64_t n) {
                        ASSERT_LE(at + n, head.size()) << what;
                        head.replace(at, n, data, n);
                        for (std::uint64_t i = at; i < at + n; ++i) ++writes[i];
                    };
                    for (const auto& p : fileHead.nonMaskParts()) put(p.offset, p.data, p.size);
                    std::uint64_t leaf = 0;
                    for (const auto& run : parts) {
                        for (const auto& [at, data] : fileHead.maskWrites(0, leaf, run.masks)) {
                            put(at, data.data(), data.size());
                        }
                        leaf += run.masks.size();
                    }
                    EXPECT_EQ(std::count(writes.begin(), writes.end(), 1), std::ptrdiff_t(head.size())) << what;
                    std::string a = bytes(path("whole.vdb")), b = head + body;
                    ASSERT_EQ(a.size(), b.size()) << what;
                    a.replace(21, 36, 36, '-');
                    b.replace(21, 36, 36, '-');
                    std::size_t first = 0;
                    while (first < a.size() && a[first] == b[first]) ++first;
                    EXPECT_EQ(first, a.size()) << what << ": first difference at byte " << first
                                               << " of " << a.size() << " (head " << head.size() << ")";
                }
            }
        }
    }
    // A skeleton and entries that disagree are refused.
    auto skeleton = ivdb::io::skeletonOf(*small);
    ivdb::io::LeafRun none;
    EXPECT_THROW(ivdb::io::vdbFileHead(*skeleton, none, 0, meta, {}), openvdb::ValueError);
    // Masks of leaves the head does not hold are refused.
    ivdb::io::LeafRun entries;
    for (const auto& part : leafRuns(*small, 1)) entries = ivdb::io::encodeLeafRun(*part, {});
    const ivdb::io::FileHead head = ivdb::io::vdbFileHead(*skeleton, entries, 0, meta, {});
    EXPECT_THROW(head.maskWrites(0, 1, entries.masks), openvdb::ValueError);
    EXPECT_THROW(head.maskWrites(1, 0, entries.masks), openvdb::ValueError);
}

TEST_F(TestVdbWriter, PiecesMakeTheSameFileOfSeveralGrids)
{
    // What ivdb-mpi gradient writes: a vec3s grid, a float grid on its leaves and the input
    // level set (with inside tiles), each from runs of its leaves, laid out one after another.
    auto input = sphere(1.0f, 0.02f, "surface");
    openvdb::tools::signedFloodFill(input->tree());
    openvdb::tools::pruneLevelSet(input->tree());
    const auto gradient = ivdb::diff::gradient(*input, 1);
    const auto magnitude = ivdb::diff::magnitude(*gradient);
    const openvdb::GridBase::ConstPtr grids[] = {gradient, magnitude, input};
    // The skeletons the library makes from the input's topology alone, with each grid's metadata.
    auto gradSkeleton = ivdb::io::leafSkeleton<openvdb::Vec3SGrid>(input->tree(), input->transform(),
                                                                  openvdb::Vec3s(0.0f));
    auto magSkeleton = ivdb::io::leafSkeleton<openvdb::FloatGrid>(input->tree(), input->transform(), 0.0f);
    static_cast<openvdb::MetaMap&>(*gradSkeleton) = static_cast<const openvdb::MetaMap&>(*gradient);
    static_cast<openvdb::MetaMap&>(*magSkeleton) = static_cast<const openvdb::MetaMap&>(*magnitude);
    const openvdb::GridBase::ConstPtr skeletons[] = {gradSkeleton, magSkeleton, ivdb::io::skeletonOf(*input)};
    openvdb::MetaMap meta;
    meta.insertMeta("creator", openvdb::StringMetadata("test"));
    for (auto c : {ivdb::io::Compression::Blosc, ivdb::io::Compression::Zip}) {
        for (bool half : {false, true}) {
            ivdb::io::WriteOptions options;
            options.compression = c;
            options.half = half;
            const std::string what = ivdb::io::compressionNames()[std::size_t(c)] + (half ? ", half" : "");
            ivdb::io::writeVdb(path("whole.vdb"), {gradient, magnitude, input}, meta, options);
            // Per grid: its runs (3 of them) and their entries joined.
            std::vector<std::vector<ivdb::io::LeafRun>> runs(3);
            std::vector<ivdb::io::LeafRun> all(3);
            std::vector<ivdb::io::HeadGrid> heads;
            for (std::size_t g = 0; g < 3; ++g) {
                grids[g]->apply<openvdb::TypeList<openvdb::FloatGrid, openvdb::Vec3SGrid>>([&](const auto& grid) {
                    for (const auto& part : leafRuns(grid, 3)) {
                        runs[g].push_back(ivdb::io::encodeLeafRun(*part, options));
                        all[g].appendEntries(runs[g].back());
                    }
                });
                std::uint64_t bytes = 0;
                for (const auto& r : runs[g]) bytes += r.byteCount();
                heads.push_back({skeletons[g], &all[g], bytes});
            }
            const ivdb::io::FileHead head = ivdb::io::vdbFileHead(heads, meta, options);
            ASSERT_EQ(head.grids.size(), 3u);
            const std::string file = assembled(head, runs, what);
            const std::string a = bytes(path("whole.vdb"));
            ASSERT_EQ(a.size(), file.size()) << what;
            const std::size_t first = firstDifference(a, file);
            EXPECT_EQ(first, a.size()) << what << ": first difference at byte " << first;
        }
    }
}

TEST_F(TestVdbWriter, PiecesMakeTheSameFileWithAFogVolume)
{
    // What ivdb-mpi rasterize --fog writes: the level set and its fog volume (fogFromLevelSet),
    // the fog made leaf by leaf in runs (levelset::fogLeaf), its ramp's end from the whole grid
    // (fogCutoff) and its nodes and tiles from the level set's skeleton (fogSkeleton): inside
    // tiles active in 128^3 and 4096^3 nodes (a sphere of radius 333 voxels), a sphere with no
    // inside tile at the leaves' level, and one whose voxels never reach -background (the ramp
    // ends at its lowest value).
    auto big = sphere(1.0f, 0.003f, "surface");
    auto small = sphere(0.3f, 0.02f, "surface");
    auto tiny = sphere(0.04f, 0.02f, "surface");
    openvdb::MetaMap meta;
    meta.insertMeta("creator", openvdb::StringMetadata("test"));
    for (const auto& grid : {big, small, tiny}) {
        openvdb::tools::signedFloodFill(grid->tree());
        openvdb::tools::pruneLevelSet(grid->tree());
        grid->insertMeta("ivdb_source", openvdb::StringMetadata("a test"));
        const auto fog = ivdb::levelset::fogFromLevelSet(*grid);
        const auto skeleton = ivdb::io::skeletonOf(*grid);
        const std::string name = grid == big ? "big" : grid == small ? "small" : "tiny";
        for (bool half : {false, true}) {
            if (grid == big && half) continue;
            ivdb::io::WriteOptions options;
            options.half = half;
            const std::string what = name + (half ? ", half" : "");
            ivdb::io::writeVdb(path("whole.vdb"), {grid, fog}, meta, options);
            const auto parts = leafRuns(*grid, 3);
            float lowest = std::numeric_limits<float>::max();
            for (const auto& part : parts) lowest = std::min(lowest, ivdb::levelset::lowestValue(part->tree()));
            const float cutoff = ivdb::levelset::fogCutoff(*skeleton, lowest);
            if (grid == tiny) EXPECT_GT(cutoff, -grid->background()) << what;
            else EXPECT_EQ(cutoff, -grid->background()) << what;
            std::vector<std::vector<ivdb::io::LeafRun>> runs(2);
            std::vector<ivdb::io::LeafRun> all(2);
            std::vector<std::uint8_t> kept;
            for (const auto& part : parts) {
                runs[0].push_back(ivdb::io::encodeLeafRun(*part, options));
                all[0].appendEntries(runs[0].back());
                auto fogPart = openvdb::FloatGrid::create(0.0f);
                fogPart->setGridClass(openvdb::GRID_FOG_VOLUME);
                for (auto it = part->tree().cbeginLeaf(); it; ++it) {
                    auto leaf = std::make_unique<openvdb::FloatTree::LeafNodeType>(*it);
                    kept.push_back(ivdb::levelset::fogLeaf(*leaf, cutoff) ? 1 : 0);
                    if (kept.back()) fogPart->tree().addLeaf(leaf.release());
                }
                runs[1].push_back(ivdb::io::encodeLeafRun(*fogPart, options));
                all[1].appendEntries(runs[1].back());
            }
            EXPECT_EQ(all[1].masks.size(), fog->tree().leafCount()) << what;
            EXPECT_LT(all[1].masks.size(), all[0].masks.size()) << what;
            ivdb::io::ActiveTiles tiles;
            const auto fogSkeleton = ivdb::levelset::fogSkeleton(*skeleton, kept, tiles);
            if (grid == big) {
                EXPECT_FALSE(tiles.empty()) << what;
                openvdb::FloatTree::ValueOnCIter above = fogSkeleton->tree().cbeginValueOn();
                above.setMaxDepth(openvdb::FloatTree::ValueOnCIter::LEAF_DEPTH - 2);
                EXPECT_TRUE(bool(above)) << what << ": an inside tile above the 128^3 nodes";
            }
            std::vector<ivdb::io::HeadGrid> heads;
            for (std::size_t g = 0; g < 2; ++g) {
                std::uint64_t n = 0;
                for (const auto& r : runs[g]) n += r.byteCount();
                heads.push_back({g == 0 ? openvdb::GridBase::ConstPtr(skeleton) : fogSkeleton,
                                 &all[g], n, g == 0 ? nullptr : &tiles});
            }
            const ivdb::io::FileHead head = ivdb::io::vdbFileHead(heads, meta, options);
            const std::string file = assembled(head, runs, what);
            const std::string a = bytes(path("whole.vdb"));
            ASSERT_EQ(a.size(), file.size()) << what;
            const std::size_t first = firstDifference(a, file);
            EXPECT_EQ(first, a.size()) << what << ": first difference at byte " << first;
        }
        // A skeleton and a list of kept leaves that do not match are refused.
        ivdb::io::ActiveTiles tiles;
        EXPECT_THROW(ivdb::levelset::fogSkeleton(*skeleton, {1}, tiles), openvdb::ValueError);
    }
}
