// SPDX-License-Identifier: Apache-2.0
// End-to-end runs of ivdb csg and ivdb blend: the level set written (read back with OpenVDB),
// and the errors for bad input (non-zero exit, `ivdb: error: ` message, no output file, an
// existing output untouched).
#include "CliRun.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using Result = ivdb::test::CliResult;

class TestCliOps: public ::testing::Test
{
protected:
    void SetUp() override
    {
        openvdb::initialize();
        static std::atomic<int> counter{0};
        mDir = fs::temp_directory_path() /
               ("ivdb-test-cli-ops-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
        fs::remove_all(mDir);
        fs::create_directories(mDir);
        // Two overlapping spheres (radius 0.6, voxel size 0.02), a fog grid and a text file.
        write("a.vdb", sphere(-0.35f, 0.02f));
        write("b.vdb", sphere(0.35f, 0.02f));
        write("coarse.vdb", sphere(0.35f, 0.04f));
        auto fog = sphere(0.0f, 0.02f);
        fog->setGridClass(openvdb::GRID_FOG_VOLUME);
        fog->setName("density");
        write("fog.vdb", fog);
        std::ofstream(mDir / "text.vdb") << "not a vdb file\n";
    }

    void TearDown() override
    {
        std::error_code ec;
        fs::remove_all(mDir, ec);
    }

    static openvdb::FloatGrid::Ptr sphere(float cx, float dx)
    {
        auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            0.6f, openvdb::Vec3f(cx, 0.0f, 0.0f), dx, 3.0f);
        g->setName("surface");
        return g;
    }

    void write(const std::string& name, openvdb::GridBase::Ptr grid) const
    {
        openvdb::io::File f((mDir / name).string());
        f.write({grid});
        f.close();
    }

    std::string path(const std::string& name) const { return (mDir / name).string(); }

    Result run(const std::vector<std::string>& args) const
    {
        return ivdb::test::runIvdb(mDir, args, 120);
    }

    openvdb::FloatGrid::Ptr readSurface(const std::string& name) const
    {
        openvdb::io::File f(path(name));
        f.open();
        auto g = openvdb::gridPtrCast<openvdb::FloatGrid>(f.readGrid("surface"));
        f.close();
        return g;
    }

    /// A failing run: non-zero, the message, and @a out neither created nor changed.
    void expectRefused(std::vector<std::string> args, const std::string& mention) const
    {
        for (bool existing : {false, true}) {
            const fs::path out = mDir / "out.vdb";
            fs::remove(out);
            if (existing) std::ofstream(out) << "previous output";
            std::vector<std::string> full = args;
            full.insert(full.end(), {"-o", out.string()});
            const Result r = run(full);
            EXPECT_NE(r.exitCode, 0) << mention;
            EXPECT_EQ(r.err.rfind("ivdb: error: ", 0), 0u) << r.err;
            EXPECT_NE(r.err.find(mention), std::string::npos) << "expected '" << mention << "' in: " << r.err;
            if (existing) {
                EXPECT_EQ(ivdb::test::slurpFile(out), "previous output") << mention;
            } else {
                EXPECT_FALSE(fs::exists(out)) << mention;
            }
            for (const auto& e : fs::directory_iterator(mDir)) {
                EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
            }
        }
    }

    fs::path mDir;
};

} // namespace

TEST_F(TestCliOps, CsgWritesTheCombinedLevelSet)
{
    for (const std::string op : {"union", "intersection", "difference"}) {
        ASSERT_EQ(run({"csg", op, "a.vdb", "b.vdb", "-o", "out_" + op + ".vdb", "-q"}).exitCode, 0);
        auto g = readSurface("out_" + op + ".vdb");
        ASSERT_TRUE(g);
        EXPECT_EQ(g->getGridClass(), openvdb::GRID_LEVEL_SET);
        EXPECT_GT(g->activeVoxelCount(), 1000u);
        // Origin: inside both spheres, so inside the union and intersection, outside A - B.
        const float v = g->tree().getValue(openvdb::Coord(0, 0, 0));
        EXPECT_EQ(v > 0.0f, op == "difference") << op << " " << v;
    }
    // A coarser input is resampled onto the finest one, with a note on stderr.
    const Result r = run({"csg", "union", "a.vdb", "coarse.vdb", "-o", "mixed.vdb", "-q"});
    EXPECT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.err.find("ivdb: note:"), std::string::npos) << r.err;
    EXPECT_NEAR(readSurface("mixed.vdb")->voxelSize()[0], 0.02, 1e-9);
}

// Three and four inputs through the CLI, each voxel against the inputs (min for a union, A
// minus the others for a difference), and --grid choosing a grid that is not the first.
TEST_F(TestCliOps, ThreeAndFourInputsAndANamedGrid)
{
    // c.vdb holds a decoy level set first, then the sphere as "ball".
    auto decoy = sphere(5.0f, 0.02f), ball = sphere(0.0f, 0.02f);
    decoy->setName("decoy");
    ball->setName("ball");
    {
        openvdb::io::File f(path("c.vdb"));
        f.write({decoy, ball});
    }
    auto named = sphere(0.1f, 0.02f);
    named->setName("ball");
    write("d.vdb", named);
    for (auto& [from, to] : std::vector<std::pair<std::string, std::string>>{{"a.vdb", "a2.vdb"}, {"b.vdb", "b2.vdb"}}) {
        auto g = readSurface(from);
        g->setName("ball");
        write(to, g);
    }
    const std::vector<std::string> inputs = {"a2.vdb", "b2.vdb", "c.vdb", "d.vdb"};
    for (const std::string op : {"union", "difference"}) {
        for (std::size_t n : {3u, 4u}) {
            std::vector<std::string> args = {"csg", op};
            args.insert(args.end(), inputs.begin(), inputs.begin() + long(n));
            args.insert(args.end(), {"--grid", "ball", "-o", "out.vdb", "-q"});
            const Result r = run(args);
            ASSERT_EQ(r.exitCode, 0) << r.err;
            auto out = readSurface("out.vdb");
            std::vector<openvdb::FloatGrid::Ptr> in = {readSurface("a.vdb"), readSurface("b.vdb"), ball, named};
            // Voxels where every input is active (within their bands): the exact min / max.
            std::size_t checked = 0, off = 0;
            for (auto it = out->cbeginValueOn(); it; ++it) {
                float v[4];
                bool all = true;
                for (std::size_t k = 0; k < n; ++k) all &= in[k]->tree().probeValue(it.getCoord(), v[k]);
                if (!all) continue;
                float expected = v[0];
                for (std::size_t k = 1; k < n; ++k) {
                    expected = op == "union" ? std::min(expected, v[k]) : std::max(expected, -v[k]);
                }
                ++checked;
                if (*it != expected) ++off;
            }
            EXPECT_GT(checked, 50u) << op << " of " << n; // a thin ring for four inputs
            EXPECT_EQ(off, 0u) << op << " of " << n;
            // The decoy (5 units away) is not in the result: nothing active beyond x = 2.
            EXPECT_LT(out->evalActiveVoxelBoundingBox().max().x(), 100) << op << " of " << n;
        }
    }
    const Result blend = run({"blend", "union", "a2.vdb", "b2.vdb", "c.vdb", "--grid", "ball", "-p", "20", "-o", "blend3.vdb"});
    ASSERT_EQ(blend.exitCode, 0) << blend.err;
    EXPECT_NE(blend.out.find("of 3 level sets"), std::string::npos) << blend.out;
    // At (0, 0.62, 0) the three spheres' distances are 0.11197, 0.11197 and 0.02: the blended
    // union -(1/p) ln(sum exp(-p d)) is 0.0062 there (the sharp union 0.02) with a gradient of
    // length 0.97, so the re-distanced value, 0.0064, is within a quarter voxel of it.
    const float v = readSurface("blend3.vdb")->tree().getValue(openvdb::Coord(0, 31, 0));
    EXPECT_NEAR(v, 0.0062f, 0.005f);
}

TEST_F(TestCliOps, BlendWritesTheBlendedLevelSet)
{
    const Result r = run({"blend", "union", "a.vdb", "b.vdb", "-p", "50", "-o", "blend.vdb", "-q"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.err.find("bands extended"), std::string::npos) << r.err;
    auto g = readSurface("blend.vdb");
    EXPECT_EQ(g->getGridClass(), openvdb::GRID_LEVEL_SET);
    // At (0, 0.5, 0), over the neck, both spheres are 0.0103 away: outside the sharp union, but
    // inside the blend, whose value there is 0.0103 - ln(2)/50 = -0.0035.
    ASSERT_EQ(run({"csg", "union", "a.vdb", "b.vdb", "-o", "sharp.vdb", "-q"}).exitCode, 0);
    const openvdb::Coord neck(0, 25, 0);
    const float sharp = readSurface("sharp.vdb")->tree().getValue(neck);
    const float blended = g->tree().getValue(neck);
    EXPECT_NEAR(sharp, 0.0103f, 0.002f);
    EXPECT_LT(blended, 0.0f) << blended;
    EXPECT_GT(blended, -0.02f) << blended;
}

TEST_F(TestCliOps, SmoothBlendWritesTheSmoothLevelSet)
{
    const Result r = run({"blend", "union", "a.vdb", "b.vdb", "-k", "0.05", "-o", "smooth.vdb"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("smooth union k=0.05 of 2 level sets"), std::string::npos) << r.out;
    auto g = readSurface("smooth.vdb");
    EXPECT_EQ(g->getGridClass(), openvdb::GRID_LEVEL_SET);
    // Over the neck both spheres are 0.0103 away (|a - b| = 0, h = 1): the formula gives
    // 0.0103 - k/4 = -0.0022, inside; the voxel holds the distance to that surface.
    const float neck = g->tree().getValue(openvdb::Coord(0, 25, 0));
    EXPECT_LT(neck, 0.0f) << neck;
    EXPECT_GT(neck, -0.01f) << neck;
    // Far from the crease (beyond k) the sharp union's values are kept.
    ASSERT_EQ(run({"csg", "union", "a.vdb", "b.vdb", "-o", "sharp.vdb", "-q"}).exitCode, 0);
    const openvdb::Coord far(-47, 0, 0);
    EXPECT_EQ(g->tree().getValue(far), readSurface("sharp.vdb")->tree().getValue(far));
    // -p and -k are one or the other: a usage error (exit 2) for both or neither.
    for (const auto& args : std::vector<std::vector<std::string>>{
             {"blend", "union", "a.vdb", "b.vdb", "-p", "10", "-k", "0.1", "-o", "x.vdb"},
             {"blend", "union", "a.vdb", "b.vdb", "-o", "x.vdb"}}) {
        const Result u = run(args);
        EXPECT_EQ(u.exitCode, 2) << u.err;
        EXPECT_NE(u.err.find("smooth"), std::string::npos) << u.err;
        EXPECT_FALSE(fs::exists(path("x.vdb")));
    }
}

TEST_F(TestCliOps, BadInputsAreRefused)
{
    expectRefused({"csg", "union", "a.vdb", "fog.vdb"}, "fog volume");
    expectRefused({"csg", "union", "a.vdb", "missing.vdb"}, "missing.vdb");
    expectRefused({"csg", "union", "a.vdb", "text.vdb"}, "text.vdb");
    expectRefused({"csg", "union", "a.vdb", "b.vdb", "--grid", "nosuch"}, "nosuch");
    expectRefused({"csg", "union", "a.vdb"}, "at least two");
    expectRefused({"blend", "union", "a.vdb", "b.vdb", "-p", "0"}, "-p must be in [0.1, 1000]");
    expectRefused({"blend", "union", "a.vdb", "b.vdb", "-p", "-1"}, "-p must be in [0.1, 1000]");
    expectRefused({"blend", "union", "a.vdb", "fog.vdb", "-p", "10"}, "fog volume");
    expectRefused({"blend", "union", "a.vdb", "b.vdb", "-k", "0"}, "-k must be > 0");
    expectRefused({"blend", "union", "a.vdb", "b.vdb", "-k", "-0.1"}, "-k must be > 0");
    expectRefused({"blend", "union", "a.vdb", "b.vdb", "-k", "nan"}, "-k");
    expectRefused({"blend", "union", "a.vdb", "b.vdb", "-p", "10", "--tolerance", "0"},
                  "--tolerance");
    // An extension that cannot fit is refused with a pointer to the scene-level blend.
    expectRefused({"blend", "union", "a.vdb", "b.vdb", "-p", "0.1", "--tolerance", "1e-9"},
                  "scene-level blend");
}
