// SPDX-License-Identifier: Apache-2.0
// Rasterizer tests: against OpenVDB's createLevelSetSphere, closed-form quadric surfaces, and the
// dense path (sparse must equal dense for the data scenes and for random CSG trees).
#include <ivdb/implicit/Blend.h>
#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/implicit/Quadric.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>

#include "DistanceChecks.h"

#include <openvdb/math/Operators.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <random>
#include <tuple>

using namespace ivdb;
using implicit::Implicit;
using implicit::Vec3d;
using openvdb::Coord;
using ivdb::test::unitGradientFraction;

class TestRasterize: public ::testing::Test
{
protected:
    void SetUp() override { openvdb::initialize(); }
};

namespace {

raster::RasterSettings settings(double dx, double w = 3.0,
                                raster::Sampling s = raster::Sampling::Sparse)
{
    raster::RasterSettings r;
    r.voxelSize = dx;
    r.halfWidth = w;
    r.sampling = s;
    return r;
}

/// Every active voxel of @a a is active in @a b with a value within @a tol, and the counts match.
void expectSameBand(const openvdb::FloatGrid& a, const openvdb::FloatGrid& b, float tol,
                    const std::string& what)
{
    EXPECT_EQ(a.activeVoxelCount(), b.activeVoxelCount()) << what;
    auto acc = b.getConstAccessor();
    size_t missing = 0, off = 0;
    float worst = 0.0f;
    for (auto it = a.cbeginValueOn(); it; ++it) {
        float v;
        if (!acc.probeValue(it.getCoord(), v)) {
            ++missing;
            continue;
        }
        worst = std::max(worst, std::abs(v - *it));
        if (std::abs(v - *it) > tol) ++off;
    }
    EXPECT_EQ(missing, 0u) << what << ": voxels active in one grid only";
    EXPECT_EQ(off, 0u) << what << ": values differ by up to " << worst;
}

/// Inactive values are +/-background with the sign of the shape at random points.
void expectSigns(const openvdb::FloatGrid& g, const Implicit& f, const implicit::BBoxd& box,
                 int samples, const std::string& what)
{
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    auto acc = g.getConstAccessor();
    const double dx = g.voxelSize()[0];
    int wrong = 0;
    for (int i = 0; i < samples; ++i) {
        const Vec3d p = box.min() + (box.max() - box.min()) * Vec3d(u(rng), u(rng), u(rng));
        const Coord ijk = Coord::round(p / dx);
        const Vec3d c = Vec3d(ijk.x(), ijk.y(), ijk.z()) * dx;
        const double fv = f.value(c);
        if (std::abs(fv) < 1e-9) continue;
        float v;
        if (!acc.probeValue(ijk, v)) {
            if (std::abs(std::abs(v) - g.background()) > 1e-6f) ++wrong;
        }
        if ((v < 0.0f) != (fv < 0.0)) ++wrong;
    }
    EXPECT_EQ(wrong, 0) << what;
}

/// Largest |phi| (in voxels), trilinearly interpolated, at the given exact surface points.
double worstSurfaceError(const openvdb::FloatGrid& g, const std::vector<Vec3d>& pts)
{
    openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> s(g);
    double worst = 0.0;
    for (const Vec3d& p : pts) worst = std::max(worst, std::abs(double(s.wsSample(p))));
    return worst / g.voxelSize()[0];
}

} // namespace

TEST_F(TestRasterize, SphereEqualsCreateLevelSetSphere)
{
    // Power-of-two voxel size: radius and centre are exact, so no voxel is a rounding tie.
    const double dx = 1.0 / 64.0;
    for (double w : {3.0, 1.5, 10.0}) {
        auto ours = raster::rasterize(std::make_shared<implicit::Sphere>(Vec3d(0.25, -0.5, 0.125),
                                                                         50.0 * dx),
                                      settings(dx, w));
        auto ref = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            float(50.0 * dx), openvdb::Vec3f(0.25f, -0.5f, 0.125f), float(dx), float(w));
        expectSameBand(*ours, *ref, 1e-6f, "half width " + std::to_string(w));
        expectSameBand(*ref, *ours, 1e-6f, "half width " + std::to_string(w));
        EXPECT_EQ(ours->getGridClass(), openvdb::GRID_LEVEL_SET);
        EXPECT_EQ(ours->getName(), "surface");
        EXPECT_FLOAT_EQ(ours->background(), float(w * dx));
        EXPECT_DOUBLE_EQ(ours->voxelSize()[0], dx);
        // Inside tiles are negative: the centre is deep inside.
        EXPECT_FLOAT_EQ(ours->tree().getValue(Coord(16, -32, 8)), -float(w * dx));
    }
}

TEST_F(TestRasterize, SphereAtArbitraryVoxelSizeMatchesOpenVdb)
{
    const double dx = 0.01, r = 0.37;
    const Vec3d c(0.013, -0.021, 0.007);
    auto ours = raster::rasterize(std::make_shared<implicit::Sphere>(c, r), settings(dx));
    auto ref = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        float(r), openvdb::Vec3f(c), float(dx), 3.0f);
    // OpenVDB computes in float voxel units, we in double world units: values agree to float
    // rounding and the band to all but exact ties, of which this geometry has none.
    expectSameBand(*ours, *ref, 1e-6f, "arbitrary voxel size");
}

TEST_F(TestRasterize, ExactBandHoldsTrueDistances)
{
    // Box and torus are exact SDFs: every active value is the closed form within float rounding
    // and the band is exactly |d| < half width.
    const double dx = 0.02;
    for (auto shape : std::vector<Implicit::Ptr>{
             std::make_shared<implicit::Box>(Vec3d(0.1, 0.0, -0.1), Vec3d(0.8, 0.5, 0.6)),
             std::make_shared<implicit::Torus>(Vec3d(0.0), 0.6, 0.2)}) {
        auto g = raster::rasterize(shape, settings(dx));
        size_t n = 0;
        for (auto it = g->cbeginValueOn(); it; ++it, ++n) {
            const Coord ijk = it.getCoord();
            const double d = shape->value(Vec3d(ijk.x(), ijk.y(), ijk.z()) * dx);
            ASSERT_NEAR(*it, d, 1e-7) << shape->typeName() << " at " << ijk;
            ASSERT_LT(std::abs(d), 3.0 * dx + 1e-9);
        }
        EXPECT_GT(n, 1000u);
        expectSigns(*g, *shape, implicit::BBoxd(Vec3d(-1.0), Vec3d(1.0)), 4000, shape->typeName());
        // Dense agrees exactly.
        auto dense = raster::rasterize(shape, settings(dx, 3.0, raster::Sampling::Dense));
        expectSameBand(*g, *dense, 0.0f, shape->typeName() + " dense");
    }
}

TEST_F(TestRasterize, RotatedEllipsoidFromRawQuadric)
{
    // Q = M^T diag(1/a^2, 1/b^2, 1/c^2, -1) M with M the inverse rigid motion.
    const Vec3d radii(0.7, 0.45, 0.3), t(0.11, -0.07, 0.05);
    implicit::Transform motion(std::make_shared<implicit::Sphere>(Vec3d(0.0), 1.0), t,
                               Vec3d(30.0, -20.0, 50.0), Vec3d(1.0));
    std::array<Vec3d, 3> frame;
    for (int i = 0; i < 3; ++i) {
        Vec3d e(0.0);
        e[i] = 1.0;
        frame[i] = motion.toWorld(e) - motion.toWorld(Vec3d(0.0));
    }
    implicit::Mat4 local{};
    local[0][0] = 1.0 / (radii[0] * radii[0]);
    local[1][1] = 1.0 / (radii[1] * radii[1]);
    local[2][2] = 1.0 / (radii[2] * radii[2]);
    local[3][3] = -1.0;
    auto shape = std::make_shared<implicit::Quadric>(implicit::placeQuadric(local, t, frame));
    ASSERT_TRUE(shape->isBounded());

    const double dx = 0.01;
    auto g = raster::rasterize(shape, settings(dx));
    ASSERT_GT(g->activeVoxelCount(), 10000u);

    std::mt19937 rng(3);
    std::normal_distribution<double> n(0.0, 1.0);
    std::vector<Vec3d> pts;
    for (int i = 0; i < 2000; ++i) {
        Vec3d u(n(rng), n(rng), n(rng));
        u.normalize();
        pts.push_back(motion.toWorld(Vec3d(u[0] * radii[0], u[1] * radii[1], u[2] * radii[2])));
        ASSERT_NEAR(shape->value(pts.back()), 0.0, 1e-9);
    }
    const double err = worstSurfaceError(*g, pts), frac = unitGradientFraction(*g);
    std::printf("rotated ellipsoid: worst |phi| at %zu surface points %.4f voxel, "
                "|grad phi| in [0.9, 1.1] at %.2f%% of near-surface voxels\n", pts.size(), err,
                100.0 * frac);
    EXPECT_LT(err, 0.1);
    EXPECT_GE(frac, 0.95);
    // Active values are distances: the centre of the band is within half a voxel of |d| < w.
    for (auto it = g->cbeginValueOn(); it; ++it) ASSERT_LT(std::abs(*it), 3.0 * dx);
    expectSigns(*g, *shape, implicit::BBoxd(Vec3d(-1.0), Vec3d(1.0)), 4000, "ellipsoid");
}

TEST_F(TestRasterize, CylinderClippedByBounds)
{
    const double dx = 0.01, R = 0.4;
    auto cyl = implicit::makeCylinder(Vec3d(0.0), Vec3d(0.0, 0.0, 1.0), R);
    raster::RasterSettings s = settings(dx);
    s.bounds = implicit::BBoxd(Vec3d(-1.0, -1.0, -0.5), Vec3d(1.0, 1.0, 0.5));
    auto g = raster::rasterize(cyl, s);

    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<Vec3d> pts;
    for (int i = 0; i < 1000; ++i) {  // the side, away from the rims
        const double a = 2.0 * M_PI * u(rng), z = -0.45 + 0.9 * u(rng);
        pts.push_back(Vec3d(R * std::cos(a), R * std::sin(a), z));
    }
    for (int i = 0; i < 1000; ++i) {  // the caps made by the bounds
        const double a = 2.0 * M_PI * u(rng), r = (R - 0.05) * std::sqrt(u(rng));
        pts.push_back(Vec3d(r * std::cos(a), r * std::sin(a), i % 2 ? 0.5 : -0.5));
    }
    const double err = worstSurfaceError(*g, pts), frac = unitGradientFraction(*g);
    std::printf("clipped cylinder: worst |phi| at %zu surface points %.4f voxel, "
                "|grad phi| in [0.9, 1.1] at %.2f%% of near-surface voxels\n", pts.size(), err,
                100.0 * frac);
    EXPECT_LT(err, 0.1);
    EXPECT_GE(frac, 0.95);
    // Closed: the axis at the middle is inside, outside the bounds is outside.
    EXPECT_LT(g->tree().getValue(Coord(0, 0, 0)), 0.0f);
    EXPECT_GT(g->tree().getValue(Coord(0, 0, 80)), 0.0f);
}

TEST_F(TestRasterize, UnboundedShapeNeedsBounds)
{
    try {
        raster::rasterize(implicit::makePlane(Vec3d(0, 0, 1), 0.0), settings(0.05));
        FAIL() << "an unbounded plane must be refused";
    } catch (const openvdb::ValueError& e) {
        EXPECT_NE(std::string(e.what()).find("bounds"), std::string::npos) << e.what();
    }
}

TEST_F(TestRasterize, BadSettingsAreRefused)
{
    auto sphere = std::make_shared<implicit::Sphere>(Vec3d(0.0), 1.0);
    EXPECT_THROW(raster::rasterize(sphere, settings(0.0)), openvdb::ValueError);
    EXPECT_THROW(raster::rasterize(sphere, settings(-0.1)), openvdb::ValueError);
    EXPECT_THROW(raster::rasterize(sphere, settings(std::nan(""))), openvdb::ValueError);
    EXPECT_THROW(raster::rasterize(sphere, settings(0.1, 0.5)), openvdb::ValueError);
}

TEST_F(TestRasterize, DenseRefusesWhatDoesNotFit)
{
    auto sphere = std::make_shared<implicit::Sphere>(Vec3d(0.0), 1.0);
    raster::RasterSettings s = settings(0.01, 3.0, raster::Sampling::Dense);
    const std::uint64_t need = raster::denseMemoryEstimate(sphere, s);
    EXPECT_GE(need, 4ull * 200 * 200 * 200);  // at least the 200^3 voxels around the sphere
    s.memoryLimit = need - 1;
    try {
        raster::rasterize(sphere, s);
        FAIL() << "dense sampling over its memory limit must be refused";
    } catch (const openvdb::RuntimeError& e) {
        EXPECT_NE(std::string(e.what()).find("needs about"), std::string::npos) << e.what();
    }
    s.memoryLimit = need;
    EXPECT_GT(raster::rasterize(sphere, s)->activeVoxelCount(), 0u);
}

// The sparse path estimates its leaves before allocating: within a factor of 2 of the grid it
// builds (an exact sphere), and refused, naming the estimate, above its limit.
TEST_F(TestRasterize, SparseRefusesWhatDoesNotFit)
{
    auto sphere = std::make_shared<implicit::Sphere>(Vec3d(0.0), 1.0);
    raster::RasterSettings s = settings(0.005);
    const double used = double(raster::rasterize(sphere, s)->memUsage());
    s.memoryLimit = std::uint64_t(0.5 * used);
    try {
        raster::rasterize(sphere, s);
        FAIL() << "a sparse grid over its memory limit must be refused";
    } catch (const openvdb::RuntimeError& e) {
        EXPECT_NE(std::string(e.what()).find("would need about"), std::string::npos) << e.what();
    }
    s.memoryLimit = std::uint64_t(2.0 * used);
    EXPECT_GT(raster::rasterize(sphere, s)->activeVoxelCount(), 0u);
}

// The estimate behind the refusal: the leaves it expects (sampled interval tests) are within 20%
// of the leaves the rasterizer builds, for a sphere, a torus and a two-sphere union.
TEST_F(TestRasterize, SparseLeafEstimateIsWithinTwentyPercent)
{
    const std::vector<std::pair<std::string, implicit::Implicit::Ptr>> shapes = {
        {"sphere", std::make_shared<implicit::Sphere>(Vec3d(0.0), 1.0)},
        {"torus", std::make_shared<implicit::Torus>(Vec3d(0.1), 0.8, 0.25)},
        {"union", std::make_shared<implicit::Csg>(implicit::Csg::Op::Union, std::vector<implicit::Implicit::Ptr>{
            std::make_shared<implicit::Sphere>(Vec3d(-0.35, 0, 0), 0.6),
            std::make_shared<implicit::Sphere>(Vec3d(0.35, 0, 0), 0.6)})}};
    for (const auto& [name, shape] : shapes) {
        raster::RasterSettings s = settings(0.004);
        s.distance = raster::Distance::Bound;
        const double built = double(raster::rasterize(shape, s)->tree().leafCount());
        s.memoryLimit = 1;
        std::string message;
        try {
            raster::rasterize(shape, s);
        } catch (const openvdb::RuntimeError& e) {
            message = e.what();
        }
        const std::size_t at = message.find("(about ");
        ASSERT_NE(at, std::string::npos) << name << ": " << message;
        const double estimated = std::stod(message.substr(at + 7));
        std::printf("%s at voxel 0.004: %.0f leaves estimated, %.0f built (%+.1f%%)\n", name.c_str(),
                    estimated, built, 100.0 * (estimated / built - 1.0));
        EXPECT_NEAR(estimated / built, 1.0, 0.2) << name << ": " << message;
    }
}

TEST_F(TestRasterize, SparseEqualsDenseForDataScenes)
{
    // Coarser than the scenes' voxels: the dense path is the slow reference (sanitized builds
    // run 10-20x slower still).
#ifdef IVDB_SANITIZED
    const double kCoarser = 4.0;
#else
    const double kCoarser = 2.0;
#endif
    size_t scenes = 0;
    for (const auto& entry : std::filesystem::directory_iterator(IVDB_DATA_DIR)) {
        if (entry.path().extension() != ".json") continue;
        const scene::Scene sc = scene::loadScene(entry.path().string());
        raster::RasterSettings s = settings(kCoarser * sc.voxelSize.value(), sc.halfWidth);
        s.bounds = sc.bounds;
        auto sparse = raster::rasterize(sc.shape, s);
        s.sampling = raster::Sampling::Dense;
        auto dense = raster::rasterize(sc.shape, s);
        const std::string name = entry.path().filename().string();
        ASSERT_GT(sparse->activeVoxelCount(), 100u) << name;
        expectSameBand(*sparse, *dense, 0.0f, name);
        const auto shape = raster::clipToBounds(sc.shape, s);
        expectSigns(*sparse, *shape, shape->boundingBox(), 2000, name + " sparse");
        expectSigns(*dense, *shape, shape->boundingBox(), 2000, name + " dense");
        ++scenes;
    }
    EXPECT_GE(scenes, 9u);
}

namespace {

Implicit::Ptr randomTree(std::mt19937& rng, int depth)
{
    std::uniform_real_distribution<double> u(-0.5, 0.5), r(0.15, 0.5);
    std::uniform_int_distribution<int> pick(0, depth > 0 ? 6 : 3);
    switch (pick(rng)) {
    case 0: return std::make_shared<implicit::Sphere>(Vec3d(u(rng), u(rng), u(rng)), r(rng));
    case 1:
        return std::make_shared<implicit::Box>(Vec3d(u(rng), u(rng), u(rng)),
                                               Vec3d(2 * r(rng), 2 * r(rng), 2 * r(rng)));
    case 2:
        return implicit::makeEllipsoid(Vec3d(u(rng), u(rng), u(rng)), Vec3d(r(rng), r(rng), r(rng)));
    case 3:
        return implicit::makeCylinder(Vec3d(u(rng), u(rng), u(rng)), Vec3d(u(rng), u(rng), 0.6),
                                      0.5 * r(rng));
    default: {
        const auto op = std::array<implicit::Csg::Op, 3>{implicit::Csg::Op::Union,
            implicit::Csg::Op::Intersection, implicit::Csg::Op::Difference}[pick(rng) % 3];
        std::vector<Implicit::Ptr> kids;
        const int n = 2 + int(rng() % 2);
        for (int i = 0; i < n; ++i) kids.push_back(randomTree(rng, depth - 1));
        Implicit::Ptr node = std::make_shared<implicit::Csg>(op, kids);
        if (rng() % 3 == 0) {
            node = std::make_shared<implicit::Transform>(node, Vec3d(0.1 * u(rng), 0.0, 0.0),
                Vec3d(90 * u(rng), 90 * u(rng), 0.0), Vec3d(1.0 + 0.3 * u(rng)));
        }
        return node;
    }
    }
}

} // namespace

TEST_F(TestRasterize, SparseEqualsDenseForRandomCsgTrees)
{
    std::mt19937 rng(2024);
    int compared = 0;
#ifdef IVDB_SANITIZED
    // Sanitized builds run 10-20x slower: the first 20 trees (the same trees, a prefix).
    const int trees = 20;
#else
    const int trees = 60;
#endif
    for (int t = 0; t < trees; ++t) {
        const Implicit::Ptr shape = randomTree(rng, 2);
        raster::RasterSettings s = settings(0.03);
        s.bounds = implicit::BBoxd(Vec3d(-0.8), Vec3d(0.8));
        auto sparse = raster::rasterize(shape, s);
        s.sampling = raster::Sampling::Dense;
        auto dense = raster::rasterize(shape, s);
        expectSameBand(*sparse, *dense, 0.0f, "tree " + std::to_string(t));
        const auto clipped = raster::clipToBounds(shape, s);
        expectSigns(*sparse, *clipped, *s.bounds, 500, "tree " + std::to_string(t));
        if (sparse->activeVoxelCount() > 0) ++compared;
    }
    EXPECT_GE(compared, trees * 5 / 6);
}

TEST_F(TestRasterize, ThreadedEqualsSerial)
{
    const auto sc = scene::loadScene(std::string(IVDB_DATA_DIR) + "/sphere_minus_cylinder.json");
    for (auto sampling : {raster::Sampling::Sparse, raster::Sampling::Dense}) {
        raster::RasterSettings s = settings(0.02, 3.0, sampling);
        s.bounds = sc.bounds;
        auto threaded = raster::rasterize(sc.shape, s);
        s.threaded = false;
        auto serial = raster::rasterize(sc.shape, s);
        expectSameBand(*threaded, *serial, 0.0f, "threaded vs serial");
    }
    auto sphere = std::make_shared<implicit::Sphere>(Vec3d(0.0), 0.8);
    raster::RasterSettings s = settings(0.01);
    auto a = raster::rasterize(sphere, s);
    s.threaded = false;
    expectSameBand(*a, *raster::rasterize(sphere, s), 0.0f, "sphere threaded vs serial");
}

TEST_F(TestRasterize, ExtremeHalfWidths)
{
    auto sphere = std::make_shared<implicit::Sphere>(Vec3d(0.0), 0.5);
    auto g20 = raster::rasterize(sphere, settings(0.01, 20.0));
    auto ref = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.5f, openvdb::Vec3f(0.0f),
                                                                      0.01f, 20.0f);
    expectSameBand(*g20, *ref, 1e-6f, "half width 20");
    // OpenVDB refuses a half width of 1; check it against the closed form: the band is the
    // voxels with |d| < 1 voxel, a single shell.
    auto g1 = raster::rasterize(sphere, settings(0.01, 1.0));
    size_t expected = 0;
    for (int i = -52; i <= 52; ++i)
        for (int j = -52; j <= 52; ++j)
            for (int k = -52; k <= 52; ++k) {
                const double d = std::sqrt(double(i * i + j * j + k * k)) * 0.01 - 0.5;
                if (std::abs(float(d)) < 0.01f) ++expected;
            }
    EXPECT_EQ(g1->activeVoxelCount(), expected);
    for (auto it = g1->cbeginValueOn(); it; ++it) ASSERT_LT(std::abs(*it), 0.01f);
    // A re-distanced shape with a wide band: distances stay distances far from the surface.
    auto ell = implicit::makeEllipsoid(Vec3d(0.0), Vec3d(0.5, 0.4, 0.3));
    auto g = raster::rasterize(ell, settings(0.01, 20.0));
    ASSERT_GT(g->activeVoxelCount(), 0u);
    EXPECT_GE(unitGradientFraction(*g), 0.95);
    float lo = 0.0f, hi = 0.0f;
    for (auto it = g->cbeginValueOn(); it; ++it) {
        lo = std::min(lo, *it);
        hi = std::max(hi, *it);
    }
    EXPECT_GT(hi, 0.19f);
    EXPECT_LT(lo, -0.19f);
}

// "distance": "bound": a union of spheres stores min of the exact distances as it is, which is
// what OpenVDB's createLevelSetSphere + csgUnion give; sparse equals dense; a shape whose value
// can exceed its distance (a quadric) is refused.
TEST_F(TestRasterize, DistanceBoundStoresCsgOfDistances)
{
    const double dx = 1.0 / 64.0;
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> pos(-0.5, 0.5), rad(0.1, 0.3);
    std::vector<Implicit::Ptr> spheres;
    std::vector<std::pair<Vec3d, double>> params;
    for (int i = 0; i < 12; ++i) {
        // Centres and radii on the voxel lattice's binary fractions: no rounding ties.
        const Vec3d c(std::round(pos(rng) * 64) / 64, std::round(pos(rng) * 64) / 64,
                      std::round(pos(rng) * 64) / 64);
        const double r = std::round(rad(rng) * 64) / 64;
        spheres.push_back(std::make_shared<implicit::Sphere>(c, r));
        params.emplace_back(c, r);
    }
    auto u = std::make_shared<implicit::Csg>(implicit::Csg::Op::Union, spheres);
    raster::RasterSettings s = settings(dx);
    s.distance = raster::Distance::Bound;
    auto ours = raster::rasterize(u, s);

    // Closed form: every active voxel holds min of the distances; every voxel with |min| below
    // the band is active.
    size_t checked = 0;
    for (auto it = ours->cbeginValueOn(); it; ++it) {
        const Vec3d p = ours->indexToWorld(it.getCoord());
        double d = 1e9;
        for (const auto& [c, r] : params) d = std::min(d, (p - c).length() - r);
        ASSERT_NEAR(*it, d, 1e-6);
        ++checked;
    }
    EXPECT_GT(checked, 10000u);

    // OpenVDB's route: createLevelSetSphere per sphere, csgUnion; where both have a band voxel
    // the values agree.
    openvdb::FloatGrid::Ptr ref;
    for (const auto& [c, r] : params) {
        auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            float(r), openvdb::Vec3f(c), float(dx), 3.0f);
        if (!ref) ref = g;
        else openvdb::tools::csgUnion(*ref, *g);
    }
    auto refAcc = ref->getConstAccessor();
    size_t both = 0;
    for (auto it = ours->cbeginValueOn(); it; ++it) {
        float v;
        if (!refAcc.probeValue(it.getCoord(), v)) continue;
        ++both;
        ASSERT_NEAR(*it, v, 1e-6);
    }
    EXPECT_GT(double(both), 0.95 * double(ours->activeVoxelCount()));

    s.sampling = raster::Sampling::Dense;
    expectSameBand(*ours, *raster::rasterize(u, s), 0.0f, "bound: sparse vs dense");

    // A quadric is not a distance: refused, with the fix named.
    s.sampling = raster::Sampling::Sparse;
    auto withQuadric = std::make_shared<implicit::Csg>(implicit::Csg::Op::Union,
        std::vector<Implicit::Ptr>{spheres[0], implicit::makeEllipsoid(Vec3d(0.0), Vec3d(0.3, 0.2, 0.1))});
    try {
        raster::rasterize(withQuadric, s);
        FAIL() << "a quadric with distance bound must be refused";
    } catch (const openvdb::ValueError& e) {
        EXPECT_NE(std::string(e.what()).find("remove \"distance\""), std::string::npos) << e.what();
    }
}

// "distance": "bound" for every shape whose value never exceeds its distance, not CSG alone: a
// blend of two spheres and a sphere scaled non-uniformly store their own values (closed forms),
// every voxel of the true band (the default mode's grid) is active with a value of its sign and
// no larger magnitude, and sparse equals dense.
TEST_F(TestRasterize, DistanceBoundStoresEveryDistanceBound)
{
    const double dx = 1.0 / 64.0, p = 20.0, r = 0.7;
    const Vec3d ca(-0.3, 0.0, 0.0), cb(0.3, 0.05, 0.0), squash(1.0, 0.8, 0.6);
    const double ra = 0.5, rb = 0.45;
    const auto blend = std::make_shared<implicit::Blend>(implicit::Csg::Op::Union, p,
        std::vector<Implicit::Ptr>{std::make_shared<implicit::Sphere>(ca, ra),
                                   std::make_shared<implicit::Sphere>(cb, rb)});
    const auto scaled = std::make_shared<implicit::Transform>(
        std::make_shared<implicit::Sphere>(Vec3d(0.0), r), Vec3d(0.0), Vec3d(0.0), squash);
    const std::vector<std::tuple<std::string, Implicit::Ptr, std::function<double(const Vec3d&)>>> cases = {
        {"blend", blend, [&](const Vec3d& x) {
             // -ln(e^(-p a) + e^(-p b)) / p, from the lesser term.
             const double a = (x - ca).length() - ra, b = (x - cb).length() - rb;
             return std::min(a, b) - std::log1p(std::exp(-p * std::abs(a - b))) / p;
         }},
        {"scaled sphere", scaled, [&](const Vec3d& x) {
             // min(scale) times the sphere's distance at the point scaled back.
             const Vec3d q(x[0] / squash[0], x[1] / squash[1], x[2] / squash[2]);
             return squash[2] * (q.length() - r);
         }}};
    for (const auto& [name, shape, closedForm] : cases) {
        raster::RasterSettings s = settings(dx);
        s.distance = raster::Distance::Bound;
        const auto bound = raster::rasterize(shape, s);
        size_t checked = 0;
        for (auto it = bound->cbeginValueOn(); it; ++it) {
            ASSERT_NEAR(*it, closedForm(bound->indexToWorld(it.getCoord())), 1e-6) << name;
            ++checked;
        }
        EXPECT_GT(checked, 10000u) << name;
        s.distance = raster::Distance::Exact;
        const auto exact = raster::rasterize(shape, s);
        auto acc = bound->getConstAccessor();
        size_t missing = 0, larger = 0;
        for (auto it = exact->cbeginValueOn(); it; ++it) {
            float v;
            if (!acc.probeValue(it.getCoord(), v)) {
                ++missing;
                continue;
            }
            // Within the default mode's tolerance (1e-3 voxel): where one sphere leads, it takes
            // that sphere's distance, which the blend's swell (e^(-p |a - b|) / p) moves by less.
            if (!(v * *it >= 0.0f && std::abs(v) <= std::abs(*it) + 1e-3 * dx)) ++larger;
        }
        EXPECT_EQ(missing, 0u) << name << ": true band voxels left inactive";
        EXPECT_EQ(larger, 0u) << name << ": bound values beyond the distance";
        // Not the distance: the blend's swell and the scale's min(scale) show.
        EXPECT_GT(bound->activeVoxelCount(), exact->activeVoxelCount()) << name;
        s.distance = raster::Distance::Bound;
        s.sampling = raster::Sampling::Dense;
        expectSameBand(*bound, *raster::rasterize(shape, s), 0.0f, name + " bound: sparse vs dense");
    }
}
