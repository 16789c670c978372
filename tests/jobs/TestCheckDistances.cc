// SPDX-License-Identifier: Apache-2.0
// jobs::checkDistances and its brute-force search: the search against closed-form distances,
// the check against level sets whose errors are known (OpenVDB's own sphere, the same scaled,
// min / max of two spheres), its sampling, and its errors.
#include <ivdb/implicit/Primitives.h>
#include <ivdb/jobs/CheckDistances.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/util/Params.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <gtest/gtest.h>

#include "../TempDirTest.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

namespace {

using namespace ivdb;
using Vec3d = openvdb::Vec3d;

class TestCheckDistances: public ivdb::test::TempDirTest
{
protected:
    TestCheckDistances(): TempDirTest("check") {}

    static std::string data(const std::string& name) { return std::string(IVDB_DATA_DIR) + "/" + name; }

    void writeText(const std::string& name, const std::string& text) const
    {
        std::ofstream(path(name)) << text;
    }

    static void writeGrid(const std::string& file, openvdb::FloatGrid::Ptr grid)
    {
        openvdb::io::File(file).write({grid});
    }

    static std::set<std::tuple<int, int, int>> sampled(const jobs::CheckDistancesResult& r)
    {
        std::set<std::tuple<int, int, int>> coords;
        for (const auto& v : r.voxels) coords.emplace(v.ijk.x(), v.ijk.y(), v.ijk.z());
        return coords;
    }
};

TEST_F(TestCheckDistances, SearchFindsTheClosedFormDistances)
{
    // Points up to 3 voxels (dx = 0.01) from a sphere's and a box's surfaces, inside and out,
    // the box's edges and corners among them: the search is within 0.0001 voxel of the exact
    // distance, never nearer (it finds points of the surface).
    const double dx = 0.01;
    const Vec3d c(0.1, -0.2, 0.05), size(0.6, 0.4, 0.5);
    const implicit::Sphere sphere(c, 0.3);
    const implicit::Box box(c, size);
    const auto boxDistance = [&](const Vec3d& p) {
        const Vec3d q = Vec3d(std::abs(p[0] - c[0]), std::abs(p[1] - c[1]), std::abs(p[2] - c[2])) - size * 0.5;
        const Vec3d out(std::max(q[0], 0.0), std::max(q[1], 0.0), std::max(q[2], 0.0));
        return out.length() + std::min(std::max({q[0], q[1], q[2]}), 0.0);
    };
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-0.45, 0.45);
    for (const bool isBox : {false, true}) {
        const implicit::Implicit& shape = isBox ? static_cast<const implicit::Implicit&>(box) : sphere;
        const jobs::SurfaceSearch search(shape, 20000);
        int checked = 0;
        double worst = 0.0;
        while (checked < 150) {
            const Vec3d p = c + Vec3d(u(rng), u(rng), u(rng));
            const double exact = std::abs(isBox ? boxDistance(p) : (p - c).length() - 0.3);
            if (exact > 3.0 * dx) continue;
            ++checked;
            const double found = search.distance(p, 0.05 * dx, exact + dx);
            ASSERT_TRUE(std::isfinite(found)) << p;
            EXPECT_GE(found, exact - 1e-9) << p;
            worst = std::max(worst, (found - exact) / dx);
        }
        EXPECT_LT(worst, 1e-4) << (isBox ? "box" : "sphere");
        std::printf("%s: the search is at most %.2g voxel farther than the exact distance\n",
                    isBox ? "box" : "sphere", worst);
        // Nothing within reach: infinity; on the surface: 0.
        EXPECT_TRUE(std::isinf(search.distance(c + Vec3d(0.0, 0.0, 0.4), 0.05 * dx, 0.5 * dx)));
        EXPECT_NEAR(search.distance(c + Vec3d(0.3, 0.0, 0.0), 0.05 * dx, dx), 0.0, 1e-6 * dx);
    }
}

TEST_F(TestCheckDistances, CheckFindsValuesFartherOrNearerThanTheSurface)
{
    // OpenVDB's own sphere (exact distances, off the origin), and the same with every value
    // scaled by 1.1: too far by a tenth of the distance, which the check measures per voxel.
    const double dx = 0.02, r = 0.5;
    const Vec3d c(0.11, 0.2, -0.05);
    writeText("sphere.json", "{\"voxel_size\": 0.02, \"shape\": {\"type\": \"sphere\", "
                             "\"center\": [0.11, 0.2, -0.05], \"radius\": 0.5}}");
    auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        float(r), openvdb::Vec3f(c), float(dx), 3.0f);
    writeGrid(path("exact.vdb"), grid);
    auto scaled = grid->deepCopy();
    for (auto it = scaled->tree().beginValueOn(); it; ++it) it.setValue(1.1f * *it);
    scaled->tree().root().setBackground(1.1f * grid->background(), true); // none clamped
    writeGrid(path("scaled.vdb"), scaled);

    jobs::CheckDistancesOptions o;
    o.raster.scene = path("sphere.json");
    o.input = path("exact.vdb");
    // Sanitized builds (20x slower) check a third of the sphere's voxels; every check below
    // holds voxel by voxel. The union's 400 stay: one of them is nearer by 0.1 voxel.
#ifdef IVDB_SANITIZED
    o.samples = 100;
#else
    o.samples = 300;
#endif
    const jobs::CheckDistancesResult exact = jobs::checkDistances(o);
    EXPECT_EQ(exact.voxels.size(), o.samples);
    EXPECT_EQ(exact.activeVoxels, grid->activeVoxelCount());
    EXPECT_NEAR(exact.voxelSize, dx, 1e-8);
    EXPECT_EQ(exact.fartherThan(1e-3), 0u);
    EXPECT_EQ(exact.nearerThan(1e-3), 0u);
    EXPECT_EQ(exact.signMismatches(), 0u);
    for (const auto& v : exact.voxels) {
        // The world position is the grid's (its transform), the search the closed form's.
        EXPECT_NEAR(v.searched, std::abs((v.world - c).length() - r), 1e-3 * dx) << v.ijk;
    }

    o.input = path("scaled.vdb");
    const jobs::CheckDistancesResult far = jobs::checkDistances(o);
    EXPECT_EQ(sampled(far), sampled(exact)); // the same seed, the same voxels
    double worst = 0.0;
    for (const auto& v : far.voxels) {
        EXPECT_NEAR(far.error(v), std::abs(v.value) / 11.0 / dx, 2e-3) << v.ijk;
        worst = std::max(worst, far.error(v));
    }
    EXPECT_EQ(far.error(far.voxels.front()), worst); // farthest first
    EXPECT_GT(worst, 0.25);
    EXPECT_EQ(far.nearerThan(1e-3), 0u);

    // min / max of two spheres (OpenVDB's CSG's values, "distance": "bound") are nearer than
    // the union's surface inside near the crease; the exact mode's are the distance.
    jobs::CheckDistancesOptions u;
    u.raster.scene = data("fig1_union.json");
    u.raster.voxelSize = 0.02;
    u.samples = 400;
    u.raster.distance = raster::Distance::Bound;
    const jobs::CheckDistancesResult bound = jobs::checkDistances(u);
    EXPECT_GT(bound.nearerThan(0.1), 0u);
    EXPECT_EQ(bound.fartherThan(1e-3), 0u);
    u.raster.distance = raster::Distance::Exact;
    const jobs::CheckDistancesResult union2 = jobs::checkDistances(u);
    EXPECT_EQ(union2.nearerThan(1e-3), 0u);
    EXPECT_EQ(union2.fartherThan(1e-3), 0u);
}

TEST_F(TestCheckDistances, WrongSignsAreCountedBeyondAThousandthOfAVoxel)
{
    // A small sphere whose surface passes a millionth from voxel (5, 0, 0)'s centre: there the
    // wrong sign is a 1e-4 voxel error and is taken; at (3, 0, 0), two voxels inside, it is not.
    const double dx = 0.02;
    writeText("small.json", "{\"voxel_size\": 0.02, \"shape\": {\"type\": \"sphere\", "
                            "\"center\": [0, 0, 0], \"radius\": 0.100001}}");
    auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.100001f, openvdb::Vec3f(0.0f),
                                                                         float(dx), 3.0f);
    auto acc = grid->getAccessor();
    ASSERT_TRUE(acc.isValueOn(openvdb::Coord(5, 0, 0)));
    acc.setValue(openvdb::Coord(5, 0, 0), 1e-6f);
    acc.setValue(openvdb::Coord(3, 0, 0), 0.04f);
    writeGrid(path("small.vdb"), grid);
    jobs::CheckDistancesOptions o;
    o.raster.scene = path("small.json");
    o.input = path("small.vdb");
    o.samples = 100000;
    o.directions = 2000;
    const auto r = jobs::checkDistances(o);
    EXPECT_EQ(r.voxels.size(), grid->activeVoxelCount());
    EXPECT_EQ(r.signMismatches(), 1u);
    for (const auto& v : r.voxels) {
        if (!v.signAgrees) EXPECT_EQ(v.ijk, openvdb::Coord(3, 0, 0));
    }
}

TEST_F(TestCheckDistances, SamplesAreChosenBySeedFromTheBandOrNearKinks)
{
    jobs::CheckDistancesOptions o;
    o.raster.scene = data("sphere.json");
    o.raster.voxelSize = 0.1;
    o.samples = 50;
    o.directions = 500;
    const auto a = jobs::checkDistances(o);
    const auto again = jobs::checkDistances(o);
    o.seed = 2;
    const auto b = jobs::checkDistances(o);
    EXPECT_EQ(sampled(a), sampled(again));
    EXPECT_NE(sampled(a), sampled(b));
    EXPECT_EQ(a.voxels.size(), 50u);
    EXPECT_EQ(a.candidates, a.activeVoxels); // a band has no clamped voxel

    o.samples = 1000000; // more than the band: every voxel once
    const auto all = jobs::checkDistances(o);
    EXPECT_EQ(all.voxels.size(), all.candidates);
    EXPECT_EQ(sampled(all).size(), all.candidates);

    // A sphere never kinks; a blend of a box does, inside the box near its edges only.
    o.nearKinks = true;
    EXPECT_EQ(jobs::checkDistances(o).candidates, 0u);
    writeText("blend.json", R"({"voxel_size": 0.02, "shape": {"type": "blend", "op": "union",
        "p": 30, "children": [{"type": "box", "center": [0, 0, 0], "size": [0.6, 0.6, 0.6]},
        {"type": "sphere", "center": [0.3, 0.3, 0], "radius": 0.2}]}})");
    o.raster.scene = path("blend.json");
    o.raster.voxelSize.reset();
    o.samples = 30;
    const auto kinks = jobs::checkDistances(o);
    EXPECT_GT(kinks.candidates, 0u);
    EXPECT_LT(kinks.candidates, kinks.activeVoxels / 2);
    EXPECT_EQ(kinks.voxels.size(), 30u);
}

TEST_F(TestCheckDistances, BadSettingsNameTheirParameter)
{
    auto expectParam = [](const jobs::CheckDistancesOptions& o, const std::string& param) {
        try {
            jobs::checkDistances(o);
            ADD_FAILURE() << "no error for " << param;
        } catch (const ParamError& e) {
            EXPECT_EQ(e.param(), param) << e.what();
            EXPECT_EQ(std::string(e.what()).find("--"), std::string::npos) << e.what();
        }
    };
    jobs::CheckDistancesOptions o;
    o.raster.scene = data("sphere.json");
    o.raster.voxelSize = 0.1;
    o.samples = 0;
    expectParam(o, "samples");
    o.samples = 10;
    o.directions = 0;
    expectParam(o, "directions");
    o.directions = 100;
    o.input = path("sphere.vdb");
    expectParam(o, "voxel_size"); // the input's own
    o.raster.voxelSize.reset();
    EXPECT_THROW(jobs::checkDistances(o), openvdb::IoError); // no such file

    // A keyed scene is checked at its start frame, as compare-gradient takes it.
    o.input.clear();
    o.raster.scene = data("anim_metaballs.json");
    o.raster.voxelSize = 0.05;
    const auto keyed = jobs::checkDistances(o);
    EXPECT_EQ(keyed.voxels.size(), 10u);
    EXPECT_EQ(keyed.fartherThan(0.01), 0u);
    EXPECT_EQ(keyed.signMismatches(), 0u);
}

} // namespace
