// SPDX-License-Identifier: Apache-2.0
// `ivdb convert`: .vdb re-saved with another compression or half floats (read back by OpenVDB),
// NanoVDB files accepted by NanoVDB's own nanovdb_validate and nanovdb_print, and bad requests
// refused with nothing written.
#include "CliRun.h"

#include <ivdb/util/Process.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

/// @a name's path on PATH; fails the test (never skips) when it is missing: scripts/deps.sh
/// installs NanoVDB's tools (libnanovdb-tools).
std::string onPath(const std::string& name)
{
    std::istringstream dirs(std::getenv("PATH") ? std::getenv("PATH") : "");
    for (std::string dir; std::getline(dirs, dir, ':');) {
        const fs::path p = fs::path(dir) / name;
        if (::access(p.c_str(), X_OK) == 0) return p.string();
    }
    ADD_FAILURE() << name << " not found on PATH: install libnanovdb-tools (scripts/deps.sh does)";
    return name;
}

std::map<std::string, openvdb::GridBase::Ptr> readGrids(const std::string& file)
{
    openvdb::io::File f(file);
    f.open();
    std::map<std::string, openvdb::GridBase::Ptr> grids;
    const openvdb::GridPtrVecPtr all = f.getGrids();
    for (const auto& g : *all) grids[g->getName()] = g;
    f.close();
    return grids;
}

class TestCliConvert: public ivdb::test::CliTest
{
protected:
    void SetUp() override
    {
        CliTest::SetUp();
        openvdb::initialize();
        ASSERT_EQ(run({"rasterize", data("sphere.json"), "-o", "s.vdb", "--voxel-size", "0.05", "-q"}).exitCode, 0);
        ASSERT_EQ(run({"gradient", "s.vdb", "-o", "g.vdb", "--magnitude", "--with-input", "-q"}).exitCode, 0);
    }
};

TEST_F(TestCliConvert, VdbWithOtherCompressionAndHalfFloats)
{
    const auto source = readGrids(path("g.vdb"));
    ASSERT_EQ(source.size(), 3u);
    const ivdb::test::CliResult r = run({"convert", "g.vdb", "-o", "z.vdb", "--compression", "none"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    expectMentions(r.out, {"3 grids", "OpenVDB", "z.vdb"}, "summary");
    for (const auto& [name, grid] : readGrids(path("z.vdb"))) {
        ASSERT_TRUE(source.count(name)) << name;
        EXPECT_EQ(grid->activeVoxelCount(), source.at(name)->activeVoxelCount()) << name;
        EXPECT_EQ(grid->getMetadata<openvdb::StringMetadata>("ivdb_source")->value(),
                  source.at(name)->getMetadata<openvdb::StringMetadata>("ivdb_source")->value());
    }
    auto plain = openvdb::gridPtrCast<openvdb::Vec3SGrid>(readGrids(path("z.vdb"))["gradient"]);
    auto original = openvdb::gridPtrCast<openvdb::Vec3SGrid>(source.at("gradient"));
    std::size_t differ = 0;
    for (auto it = original->cbeginValueOn(); it; ++it) {
        differ += plain->tree().getValue(it.getCoord()) != *it;
    }
    EXPECT_EQ(differ, 0u);

    // one grid, half floats: within 11 significant bits
    ASSERT_EQ(run({"convert", "g.vdb", "-o", "h.vdb", "--grid", "surface", "--half", "-q"}).exitCode, 0);
    const auto half = readGrids(path("h.vdb"));
    ASSERT_EQ(half.size(), 1u);
    auto h = openvdb::gridPtrCast<openvdb::FloatGrid>(half.at("surface"));
    auto s = openvdb::gridPtrCast<openvdb::FloatGrid>(source.at("surface"));
    ASSERT_TRUE(h && s);
    EXPECT_TRUE(h->saveFloatAsHalf());
    double worst = 0;
    for (auto it = s->cbeginValueOn(); it; ++it) {
        const double a = *it, b = h->tree().getValue(it.getCoord());
        worst = std::max(worst, std::abs(a - b) / std::max(std::abs(a), 6.2e-5));
    }
    EXPECT_LE(worst, std::ldexp(1.0, -11));
}

TEST_F(TestCliConvert, NanoVdbFilesPassNanoVdbsOwnTools)
{
    const ivdb::test::CliResult r = run({"convert", "g.vdb", "-o", "g.nvdb"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    expectMentions(r.out, {"3 grids", "NanoVDB", "g.nvdb"}, "summary");
    const auto validate = ivdb::util::runProcess({onPath("nanovdb_validate"), "-v", path("g.nvdb")});
    EXPECT_EQ(validate.status, 0) << validate.err;
    const auto source = readGrids(path("g.vdb"));
    for (const auto& [name, grid] : source) {
        EXPECT_NE(validate.out.find("Grid named \"" + name + "\": passed"), std::string::npos)
            << validate.out;
    }
    const auto print = ivdb::util::runProcess({onPath("nanovdb_print"), path("g.nvdb")});
    EXPECT_EQ(print.status, 0) << print.err;
    for (const auto& [name, grid] : source) {
        expectMentions(print.out, {name, std::to_string(grid->activeVoxelCount())}, "nanovdb_print");
    }

    ASSERT_EQ(run({"convert", "g.vdb", "-o", "one.nvdb", "--grid", "surface", "-q"}).exitCode, 0);
    const auto one = ivdb::util::runProcess({onPath("nanovdb_print"), path("one.nvdb")});
    expectMentions(one.out, {"surface", "float", "SDF"}, "nanovdb_print, one grid");
    EXPECT_EQ(one.out.find("gradient"), std::string::npos) << one.out;
}

TEST_F(TestCliConvert, BadRequests)
{
    expectFails({"convert", "g.vdb"}, "g.txt", {"--output", "g.txt", ".vdb", ".nvdb"},
                "unknown output extension");
    expectFails({"convert", "g.vdb", "--half"}, "g.nvdb", {"--half", ".vdb"}, "--half to NanoVDB");
    expectFails({"convert", "g.vdb", "--compression", "zip"}, "g.nvdb", {"--compression", "NanoVDB"},
                "--compression to NanoVDB");
    expectFails({"convert", "g.vdb", "--compression", "lz4"}, "g2.vdb", {"--compression", "lz4"},
                "--compression lz4");
    expectFails({"convert", "g.vdb", "--grid", "nope"}, "g2.vdb", {"--grid", "nope", "gradient"},
                "missing grid");
    expectFails({"convert", "missing.vdb"}, "g2.vdb", {"missing.vdb"}, "missing input");
    // a grid type NanoVDB cannot hold
    auto v = openvdb::Vec3DGrid::create();
    v->setName("velocity");
    v->tree().setValue(openvdb::Coord(1), openvdb::Vec3d(1, 2, 3));
    openvdb::io::File(path("v.vdb")).write({v});
    expectFails({"convert", "v.vdb"}, "v.nvdb", {"v.vdb", "velocity", "vec3d", "--grid"},
                "vec3d to NanoVDB");
}

} // namespace
