// SPDX-License-Identifier: Apache-2.0
// ivdb bench end to end: the CSV (checked against the dense path and OpenVDB's route, which it
// measures side by side), the plot, skipped runs, and bad arguments.
#include "CliRun.h"
#include "ReadCsv.h"

#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using ivdb::test::runIvdb;
using ivdb::test::slurpFile;

using ivdb::test::CsvRow;
using ivdb::test::readCsv;

class TestCliBench: public ::testing::Test
{
protected:
    void SetUp() override
    {
        static std::atomic<int> counter{0};
        mDir = fs::temp_directory_path() /
               ("ivdb-test-cli-bench-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
        fs::remove_all(mDir);
        fs::create_directories(mDir);
    }
    void TearDown() override
    {
        std::error_code ec;
        fs::remove_all(mDir, ec);
    }
    fs::path mDir;
};

TEST_F(TestCliBench, DefaultScenesCsvPlotAndTable)
{
    const auto r = runIvdb(mDir, {"bench", "--resolutions", "24,40", "--reps", "1", "--out", "b"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const auto rows = readCsv(mDir / "b" / "bench.csv");
    // Five scenes (the sphere, and two unions in both distance modes), two resolutions, three
    // methods each (all are unions of spheres).
    ASSERT_EQ(rows.size(), 30u);
    std::map<std::string, const CsvRow*> byKey;
    for (const auto& row : rows) {
        EXPECT_EQ(row.at("status"), "ok") << row.at("scene") << " " << row.at("method");
        byKey[row.at("scene") + "/" + row.at("method") + "/" + row.at("resolution")] = &row;
        EXPECT_GT(std::stod(row.at("time_s")), 0.0);
        EXPECT_LE(std::stod(row.at("time_min_s")), std::stod(row.at("time_s")));
        if (row.at("scene").rfind("spheres_1000", 0) != 0 || row.at("method") != "openvdb") { // see below
            EXPECT_GT(std::stoull(row.at("active_voxels")), 0u);
        }
        EXPECT_GT(std::stoull(row.at("file_bytes")), 0u);
        EXPECT_GT(std::stoull(row.at("peak_memory_bytes")), std::stoull(row.at("work_memory_bytes")));
    }
    for (const std::string scene : {"sphere", "two_spheres", "spheres_1000", "two_spheres_exact",
                                    "spheres_1000_exact"}) {
        for (const std::string res : {"24", "40"}) {
            const CsvRow* s = byKey.at(scene + "/sparse/" + res);
            const CsvRow* d = byKey.at(scene + "/dense/" + res);
            const CsvRow* o = byKey.at(scene + "/openvdb/" + res);
            // Sparse and dense build the same grid; the dense box holds more voxels than the band.
            EXPECT_EQ(s->at("active_voxels"), d->at("active_voxels")) << scene << " " << res;
            EXPECT_EQ(s->at("file_bytes"), d->at("file_bytes")) << scene << " " << res;
            EXPECT_GT(std::stoull(s->at("dense_voxels")), std::stoull(s->at("active_voxels")));
            // createLevelSetSphere (+ csgUnion) builds the same band of min distances, up to
            // voxels whose distance rounds differently at the band's edge. (It drops spheres
            // under 1.5 voxels in radius, as many of the 1000 are at these sizes: not compared.)
            const double a = std::stod(s->at("active_voxels")), b = std::stod(o->at("active_voxels"));
            if (scene == "sphere" || scene == "two_spheres") EXPECT_NEAR(a, b, 0.01 * a) << scene << " " << res;
        }
    }
    // Voxels across the shape: the sphere (2 units across) at 40 voxels has voxel size 0.05.
    EXPECT_DOUBLE_EQ(std::stod(byKey.at("sphere/sparse/40")->at("voxel_size")), 0.05);

    const std::string png = slurpFile(mDir / "b" / "bench.png");
    ASSERT_GT(png.size(), 10000u);
    EXPECT_EQ(png.substr(1, 3), "PNG");
    EXPECT_NE(r.out.find("| sphere | 40 |"), std::string::npos) << r.out;
    // The machine it ran on, first (TestMachine checks what it says).
    EXPECT_EQ(r.out.rfind("Machine: ", 0), 0u) << r.out;
    EXPECT_NE(r.out.find(" cores, vector code "), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("sphere sparse: time slope"), std::string::npos) << r.out;
    for (const char* s : {"sphere", "two_spheres", "spheres_1000", "two_spheres_exact",
                          "spheres_1000_exact"}) {
        EXPECT_TRUE(fs::exists(mDir / "b" / "scenes" / (std::string(s) + ".json"))) << s;
    }
    // No temporary files left behind.
    for (const auto& e : fs::directory_iterator(mDir / "b")) {
        EXPECT_NE(e.path().filename().string()[0], '.') << e.path();
    }
}

TEST_F(TestCliBench, SkipsDenseRunsThatWouldTakeTooLong)
{
    // The 1000-sphere scene at 128 voxels across: 2.1e9 primitive evaluations, over --quick's
    // budget, so dense is skipped and marked; sparse runs; no plot asked for.
    ASSERT_EQ(runIvdb(mDir, {"bench", "--resolutions", "8", "--reps", "1", "--out", "s",
                             "--no-plot"}).exitCode, 0);
    const auto r = runIvdb(mDir, {"bench", "--scene", "s/scenes/spheres_1000.json", "--resolutions",
                                  "128", "--reps", "1", "--quick", "--no-plot", "--out", "q"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const auto rows = readCsv(mDir / "q" / "bench.csv");
    ASSERT_EQ(rows.size(), 3u);
    for (const auto& row : rows) {
        if (row.at("method") == "dense") {
            EXPECT_EQ(row.at("status").rfind("skipped: ", 0), 0u) << row.at("status");
        } else {
            EXPECT_EQ(row.at("status"), "ok") << row.at("method");
        }
    }
    EXPECT_FALSE(fs::exists(mDir / "q" / "bench.png"));
}

TEST_F(TestCliBench, BadArguments)
{
    const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
        {{"bench", "--resolutions", "4", "--out", "x"}, "--resolutions"},
        {{"bench", "--reps", "0", "--out", "x"}, "--reps"},
        {{"bench", "--scene", "missing.json", "--resolutions", "16", "--out", "x"}, "missing.json"},
    };
    for (const auto& [args, mention] : cases) {
        const auto r = runIvdb(mDir, args);
        EXPECT_NE(r.exitCode, 0) << mention;
        EXPECT_EQ(r.err.rfind("ivdb: error: ", 0), 0u) << r.err;
        EXPECT_NE(r.err.find(mention), std::string::npos) << r.err;
        EXPECT_FALSE(fs::exists(mDir / "x" / "bench.csv")) << mention;
    }
}

} // namespace
