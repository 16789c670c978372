// SPDX-License-Identifier: Apache-2.0
// End-to-end runs of the ivdb binary: exit codes, stdout and stderr text, and the files left
// behind (none on failure; an existing output untouched).
#include "CliRun.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <nlohmann/json.hpp>

#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using RunResult = ivdb::test::CliResult;

class TestCli: public ivdb::test::CliTest
{
protected:
    /// Rasterize @a scene into @a output (in the run folder); asserts success.
    RunResult rasterize(const std::string& scene, const std::string& output,
                        std::vector<std::string> extra = {}) const
    {
        std::vector<std::string> args = {"rasterize", scene, "-o", output};
        args.insert(args.end(), extra.begin(), extra.end());
        RunResult r = run(args);
        EXPECT_EQ(r.exitCode, 0) << "stderr:\n" << r.err;
        return r;
    }

    /// `ivdb info --json FILE`, parsed.
    nlohmann::json infoJson(const std::string& file) const
    {
        const RunResult r = run({"info", file, "--json"});
        EXPECT_EQ(r.exitCode, 0) << r.err;
        EXPECT_EQ(r.err, "");
        try {
            return nlohmann::json::parse(r.out);
        } catch (const std::exception& e) {
            ADD_FAILURE() << "info --json printed invalid JSON (" << e.what() << "):\n" << r.out;
            return nlohmann::json();
        }
    }

    fs::path mDir;
};

TEST_F(TestCli, Help)
{
    RunResult r = run({"--help"});
    EXPECT_EQ(r.exitCode, 0) << r.err;
    expectMentions(r.out, {"rasterize", "info", "--help"}, "ivdb --help");

    r = run({"rasterize", "--help"});
    EXPECT_EQ(r.exitCode, 0) << r.err;
    expectMentions(r.out, {"--voxel-size", "--half-width", "--sampling", "sparse", "dense",
                           "--output"}, "ivdb rasterize --help");

    r = run({"info", "--help"});
    EXPECT_EQ(r.exitCode, 0) << r.err;
    expectMentions(r.out, {"--json"}, "ivdb info --help");
    EXPECT_TRUE(listing().empty());
}

// Every run's stderr is searched for sanitizer reports: the search finds each kind of report,
// also after ivdb's own error message, and passes ivdb's messages.
TEST_F(TestCli, SanitizerReportsInAChildFailTheTest)
{
    for (const char* report : {
             "ivdb: error: bad\n=================================================================\n"
             "==123==ERROR: AddressSanitizer: heap-use-after-free on address 0x602",
             "==123==ERROR: LeakSanitizer: detected memory leaks",
             "lib/src/x.cc:12:3: runtime error: signed integer overflow",
             "WARNING: ThreadSanitizer: data race (pid=1)"}) {
        EXPECT_NONFATAL_FAILURE(ivdb::test::expectNoSanitizerReport(report), "sanitizer report");
    }
    ivdb::test::expectNoSanitizerReport("ivdb: error: scene.json: shape.radius: must be > 0, got -1\n");
}

TEST_F(TestCli, UnknownSubcommandAndUsageErrors)
{
    RunResult r = run({"frobnicate", "x.json"});
    expectError(r, {"frobnicate"}, "unknown subcommand");
    r = run({});
    expectError(r, {}, "no subcommand");
    r = run({"rasterize", data("sphere.json")});
    expectError(r, {"--output"}, "missing -o");
    r = run({"rasterize", data("sphere.json"), "-o", "a.vdb", "--voxel-size", "abc"});
    expectError(r, {"--voxel-size", "abc"}, "non-numeric voxel size");
    r = run({"info"});
    expectError(r, {"file"}, "info without a file");
    EXPECT_TRUE(listing().empty());
}

TEST_F(TestCli, RasterizeAndInfo)
{
    const RunResult r = rasterize(data("sphere.json"), "X.vdb");
    EXPECT_EQ(r.err, "");
    // exactly one summary line, naming the voxel count
    ASSERT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << r.out;
    expectMentions(r.out, {"active voxels", "sphere.json", "X.vdb"}, "summary");
    EXPECT_EQ(listing(), std::set<std::string>({"X.vdb"}));

    // what OpenVDB itself reads from the file
    openvdb::io::File file(path("X.vdb"));
    file.open();
    auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("surface"));
    file.close();
    ASSERT_TRUE(grid);
    const openvdb::Index64 active = grid->activeVoxelCount();
    EXPECT_GT(active, 0u);
    EXPECT_NE(r.out.find(" " + std::to_string(active) + " active voxels"), std::string::npos)
        << r.out;
    EXPECT_TRUE(grid->getMetadata<openvdb::StringMetadata>("ivdb_scene"));
    EXPECT_TRUE(grid->getMetadata<openvdb::StringMetadata>("ivdb_version"));
    // about 4 pi r^2 / h^2 * (2 * half width) voxels for a unit sphere at h = 0.01
    EXPECT_NEAR(double(active), 4 * M_PI * 1e4 * 6, 0.1 * 4 * M_PI * 1e4 * 6);

    // info, text
    RunResult t = run({"info", "X.vdb"});
    EXPECT_EQ(t.exitCode, 0) << t.err;
    expectMentions(t.out, {"surface", "level set", "float", "0.01", std::to_string(active)},
                   "info");

    // info, JSON
    const nlohmann::json j = infoJson("X.vdb");
    ASSERT_TRUE(j.contains("grids")) << j.dump();
    ASSERT_EQ(j["grids"].size(), 1u);
    const nlohmann::json& g = j["grids"][0];
    EXPECT_EQ(g.value("name", ""), "surface");
    EXPECT_EQ(g.value("class", ""), "level set");
    EXPECT_EQ(g.value("value_type", ""), "float");
    ASSERT_TRUE(g["voxel_size"].is_array());
    ASSERT_EQ(g["voxel_size"].size(), 3u);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(g["voxel_size"][i].get<double>(), 0.01, 1e-9);
    EXPECT_EQ(g["active_voxels"].get<openvdb::Index64>(), active);
    EXPECT_NEAR(g["background"].get<double>(), 0.03, 1e-6);
    const openvdb::CoordBBox box = grid->evalActiveVoxelBoundingBox();
    for (int i = 0; i < 3; ++i) {
        EXPECT_EQ(g["index_bbox"]["min"][i].get<int>(), box.min()[i]);
        EXPECT_EQ(g["index_bbox"]["max"][i].get<int>(), box.max()[i]);
        EXPECT_NEAR(g["world_bbox"]["min"][i].get<double>(), -1.03, 0.011);
        EXPECT_NEAR(g["world_bbox"]["max"][i].get<double>(), 1.03, 0.011);
    }
    EXPECT_EQ(listing(), std::set<std::string>({"X.vdb"}));
}

TEST_F(TestCli, OptionOverrides)
{
    rasterize(data("sphere.json"), "fine.vdb");
    rasterize(data("sphere.json"), "coarse.vdb", {"--voxel-size", "0.02"});
    const nlohmann::json fine = infoJson("fine.vdb"), coarse = infoJson("coarse.vdb");
    ASSERT_EQ(coarse["grids"].size(), 1u);
    for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(coarse["grids"][0]["voxel_size"][i].get<double>(), 0.02, 1e-9);
    }
    EXPECT_NEAR(coarse["grids"][0]["background"].get<double>(), 0.06, 1e-6);
    // band voxels scale with the area in voxels: a quarter at twice the voxel size
    const double ratio = coarse["grids"][0]["active_voxels"].get<double>() /
                         fine["grids"][0]["active_voxels"].get<double>();
    EXPECT_NEAR(ratio, 0.25, 0.03);

    // half width 2 instead of 3: background 0.02, about 2/3 of the voxels
    rasterize(data("sphere.json"), "thin.vdb", {"--half-width", "2"});
    const nlohmann::json thin = infoJson("thin.vdb");
    EXPECT_NEAR(thin["grids"][0]["background"].get<double>(), 0.02, 1e-6);
    EXPECT_NEAR(thin["grids"][0]["active_voxels"].get<double>() /
                    fine["grids"][0]["active_voxels"].get<double>(), 2.0 / 3.0, 0.05);

    // dense sampling gives the same voxels
    rasterize(data("sphere.json"), "dense.vdb", {"--voxel-size", "0.02", "--sampling", "dense"});
    const nlohmann::json dense = infoJson("dense.vdb");
    EXPECT_EQ(dense["grids"][0]["active_voxels"], coarse["grids"][0]["active_voxels"]);
    EXPECT_EQ(dense["grids"][0]["index_bbox"], coarse["grids"][0]["index_bbox"]);

    // a scene without voxel_size takes it from the command line
    writeText("novoxel.json", R"({"shape": {"type": "sphere", "radius": 0.5}})");
    rasterize("novoxel.json", "novoxel.vdb", {"--voxel-size", "0.05"});
    const nlohmann::json nv = infoJson("novoxel.vdb");
    EXPECT_NEAR(nv["grids"][0]["voxel_size"][0].get<double>(), 0.05, 1e-9);
    // and --quiet prints nothing
    const RunResult q = rasterize("novoxel.json", "quiet.vdb", {"--voxel-size", "0.05", "-q"});
    EXPECT_EQ(q.out, "");
}

TEST_F(TestCli, OutputOptions)
{
    // What OpenVDB's own reader gets from each kind of file the writer makes.
    const auto load = [&](const std::string& name) {
        openvdb::io::File file(path(name));
        file.open();
        auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("surface"));
        file.close();
        return grid;
    };
    const std::string scene = data("sphere.json");
    rasterize(scene, "blosc.vdb", {"--voxel-size", "0.02"});
    rasterize(scene, "zip.vdb", {"--voxel-size", "0.02", "--compression", "zip"});
    rasterize(scene, "none.vdb", {"--voxel-size", "0.02", "--compression", "none"});
    rasterize(scene, "half.vdb", {"--voxel-size", "0.02", "--half"});
    const auto blosc = load("blosc.vdb");
    ASSERT_TRUE(blosc);
    EXPECT_FALSE(blosc->saveFloatAsHalf());
    for (const char* name: {"zip.vdb", "none.vdb"}) {
        const auto grid = load(name);
        ASSERT_TRUE(grid) << name;
        EXPECT_EQ(grid->activeVoxelCount(), blosc->activeVoxelCount()) << name;
        std::size_t differ = 0;
        for (auto it = blosc->cbeginValueOn(); it; ++it) {
            differ += grid->tree().getValue(it.getCoord()) != *it;
        }
        EXPECT_EQ(differ, 0u) << name;
    }
    // Blosc stores less than the raw values; OpenVDB never zips a level set, so zip stores its
    // values as none does (its delayed-load table, which records block sizes, is a little larger)
    const auto bloscSize = fs::file_size(path("blosc.vdb")), noneSize = fs::file_size(path("none.vdb"));
    EXPECT_LT(bloscSize, 0.97 * noneSize);
    EXPECT_LT(fs::file_size(path("zip.vdb")), 1.01 * noneSize);

    // half floats: flagged as such, about half the uncompressed payload, within half precision
    const auto half = load("half.vdb");
    ASSERT_TRUE(half);
    EXPECT_TRUE(half->saveFloatAsHalf());
    EXPECT_EQ(half->activeVoxelCount(), blosc->activeVoxelCount());
    double worst = 0;
    for (auto it = blosc->cbeginValueOn(); it; ++it) {
        const double a = *it, b = half->tree().getValue(it.getCoord());
        worst = std::max(worst, std::abs(a - b) / std::max(std::abs(a), 6.2e-5));
    }
    EXPECT_LE(worst, std::ldexp(1.0, -11));
    EXPECT_LT(fs::file_size(path("half.vdb")), bloscSize);

    expectFails({"rasterize", scene, "--compression", "lz4"}, "out.vdb",
                {"--compression", "lz4", "blosc", "zip", "none"}, "--compression lz4");
}

TEST_F(TestCli, BadScenes)
{
    writeText("neg.json", R"({"voxel_size": 0.01, "shape": {"type": "union", "children": [
        {"type": "sphere", "radius": 1},
        {"type": "sphere", "center": [1, 0, 0], "radius": 1},
        {"type": "sphere", "center": [2, 0, 0], "radius": -1}]}})");
    expectFails({"rasterize", "neg.json"}, "out.vdb", {"neg.json", "shape.children[2].radius", "-1"},
                         "negative radius");

    writeText("key.json", R"({"voxel_size": 0.01,
        "shape": {"type": "sphere", "radius": 1, "radus": 1}})");
    expectFails({"rasterize", "key.json"}, "out.vdb", {"key.json", "shape.radus", "unknown"},
                         "unknown key");

    writeText("bad.json", R"({"voxel_size": 0.01, "shape": {"type": "sphere", "radius": 1})");
    expectFails({"rasterize", "bad.json"}, "out.vdb", {"bad.json", "JSON"}, "invalid JSON");

    expectFails({"rasterize", "missing.json"}, "out.vdb", {"missing.json"}, "missing scene file");

    writeText("plane.json", R"({"voxel_size": 0.05,
        "shape": {"type": "plane", "normal": [0, 0, 1], "offset": 0}})");
    expectFails({"rasterize", "plane.json"}, "out.vdb", {"plane.json", "bounds"}, "unbounded plane");

    writeText("novoxel.json", R"({"shape": {"type": "sphere", "radius": 1}})");
    writeText("huge.json", R"({"voxel_size": 0.01, "shape": {"type": "sphere", "radius": 1e999}})");
    expectFails({"rasterize", "huge.json"}, "out.vdb", {"huge.json", "1e999"}, "radius 1e999");

    expectFails({"rasterize", "novoxel.json"}, "out.vdb",
                         {"novoxel.json", "voxel_size", "--voxel-size"},
                         "no voxel size anywhere");
}

TEST_F(TestCli, BadOptions)
{
    const std::string scene = data("sphere.json");
    expectFails({"rasterize", scene, "--voxel-size", "0"}, "out.vdb", {"--voxel-size", "0"},
                         "--voxel-size 0");
    expectFails({"rasterize", scene, "--voxel-size", "-1"}, "out.vdb", {"--voxel-size", "-1"},
                         "--voxel-size -1");
    expectFails({"rasterize", scene, "--half-width", "0.5"}, "out.vdb", {"--half-width", "0.5"},
                         "--half-width 0.5");
    expectFails({"rasterize", scene, "--sampling", "foo"}, "out.vdb", {"--sampling", "foo"},
                         "--sampling foo");
    expectFails({"rasterize", scene}, "nodir/out.vdb", {"nodir/out.vdb", "nodir"},
                         "output into a missing folder");
    EXPECT_FALSE(fs::exists(path("nodir")));
    fs::create_directories(path("outdir"));
    expectFails({"rasterize", scene}, "outdir", {"outdir", "folder"}, "output is a folder");
    EXPECT_TRUE(fs::is_empty(path("outdir")));
}

TEST_F(TestCli, InfoBadFiles)
{
    RunResult r = run({"info", "missing.vdb"});
    expectError(r, {"missing.vdb"}, "info on a missing file");

    writeText("text.vdb", "hello, this is text\n");
    r = run({"info", "text.vdb"});
    expectError(r, {"text.vdb"}, "info on a text file");
    // the CLI drops OpenVDB's exception-type prefix ("IoError: ...") from messages
    EXPECT_EQ(r.err.find("IoError"), std::string::npos) << r.err;

    ASSERT_EQ(rasterize(data("sphere.json"), "good.vdb", {"--voxel-size", "0.05"}).exitCode, 0);
    const std::string bytes = ivdb::test::slurpFile(path("good.vdb"));
    ASSERT_GT(bytes.size(), 1000u);
    // 20: in the header; 200: in the grid metadata, where OpenVDB reads garbage lengths
    for (std::size_t n : {std::size_t(20), std::size_t(200), bytes.size() / 2, bytes.size() - 1}) {
        const std::string name = "cut" + std::to_string(n) + ".vdb";
        writeText(name, bytes.substr(0, n));
        r = run({"info", name});
        expectError(r, {name}, "info on a file truncated at " + std::to_string(n));
        r = run({"info", name, "--json"});
        expectError(r, {name}, "info --json on a file truncated at " + std::to_string(n));
    }
    fs::create_directories(path("folder.vdb"));
    r = run({"info", "folder.vdb"});
    expectError(r, {"folder.vdb", "folder"}, "info on a folder");
}

} // namespace

TEST_F(TestCli, MeshScenes)
{
    // The knot of data/ smooth-unioned with a sphere: written, and read back as a level set.
    const auto ok = run({"rasterize", data("knot_smooth.json"), "-o", "knot.vdb", "--voxel-size", "0.02"});
    ASSERT_EQ(ok.exitCode, 0) << ok.err;
    expectMentions(ok.out, {"knot_smooth.json:", "active voxels"}, "knot");
    EXPECT_TRUE(std::filesystem::exists(path("knot.vdb")));

    // An open mesh: a note on stderr, and a level set all the same.
    writeText("open.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\n");
    writeText("open.json", R"({"voxel_size": 0.05, "shape": {"type": "mesh", "file": "open.obj"}})");
    const auto opened = run({"rasterize", "open.json", "-o", "open.vdb"});
    ASSERT_EQ(opened.exitCode, 0) << opened.err;
    expectMentions(opened.err, {"ivdb: note: ", "open.obj: the mesh is not closed (3 edges"}, "open");

    // A missing mesh: the JSON path and the file named, nothing written.
    writeText("missing.json", R"({"voxel_size": 0.05, "shape": {"type": "union", "children": [
        {"type": "sphere", "radius": 1}, {"type": "mesh", "file": "nosuch.obj"}]}})");
    const auto before = listing();
    const auto bad = run({"rasterize", "missing.json", "-o", "bad.vdb"});
    expectError(bad, {"missing.json: shape.children[1].file: ", "nosuch.obj: cannot open the mesh file"},
                "missing mesh");
    EXPECT_EQ(listing(), before);
}

// `ivdb plan`: the partition as JSON and as text, against the grid `ivdb rasterize` makes.
TEST_F(TestCli, PlanSplitsASceneOverRanks)
{
    const std::string scene = data("fig1_union.json");
    RunResult r = run({"plan", scene, "--ranks", "3", "--json", "--voxel-size", "0.02"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    nlohmann::json j;
    ASSERT_NO_THROW(j = nlohmann::json::parse(r.out)) << r.out;
    EXPECT_EQ(j["ranks"], 3);
    EXPECT_DOUBLE_EQ(j["voxel_size"].get<double>(), 0.02);
    ASSERT_EQ(j["per_rank"].size(), 3u);
    const std::uint64_t leaves = j["leaves"].get<std::uint64_t>();
    std::uint64_t next = 0;
    for (const auto& rank : j["per_rank"]) {
        EXPECT_EQ(rank["first_leaf"].get<std::uint64_t>(), next);
        next += rank["leaves"].get<std::uint64_t>();
        EXPECT_EQ(rank["first_origin"].size(), 3u);
        EXPECT_GT(rank["memory_bytes"].get<double>(), 0.0);
    }
    EXPECT_EQ(next, leaves);
    EXPECT_GE(j["balance"].get<double>(), 1.0);
    EXPECT_LE(j["balance"].get<double>(), 1.0 + 3.0 / double(leaves));

    rasterize(scene, "union.vdb", {"--voxel-size", "0.02"});
    const nlohmann::json grid = infoJson("union.vdb")["grids"][0];
    const double active = grid["active_voxels"].get<double>();
    EXPECT_GE(leaves, grid["leaf_nodes"].get<std::uint64_t>());
    const double gridLeaves = grid["leaf_nodes"].get<double>();
    EXPECT_NEAR(j["grid_leaves"].get<double>(), gridLeaves, 0.05 * gridLeaves);
    EXPECT_NEAR(j["active_voxels"].get<double>(), active, 0.05 * active);

    r = run({"plan", scene, "--ranks", "2"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    expectMentions(r.out, {"2 ranks", "balance", "leaves the band may cross", "active voxels"},
                   "plan as text");

    r = run({"plan", scene, "--ranks", "0"});
    expectError(r, {"--ranks", "0"}, "plan with 0 ranks");
    r = run({"plan", "missing.json", "--ranks", "2"});
    expectError(r, {"missing.json"}, "plan of a missing scene");
    r = run({"plan", scene});
    EXPECT_EQ(r.exitCode, 2) << "plan without --ranks: " << r.err;
    expectMentions(r.err, {"--ranks"}, "plan without --ranks");
}
