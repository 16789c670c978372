// SPDX-License-Identifier: Apache-2.0
// The primitives and modifiers artists reach for (capsule, rounded box, capped cylinder and
// cone, offset, shell) and the smooth CSG, rasterized and checked against closed forms written
// here independently of the library's (another formula or a numerical minimization), and the
// shape contract: analytic gradients, conservative intervals, sparse equal to dense.
#include <ivdb/implicit/Blend.h>
#include <ivdb/implicit/Modifiers.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>

#include "DistanceChecks.h"

#include <openvdb/math/Operators.h>
#include <openvdb/tools/Interpolation.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

using namespace ivdb;
using implicit::Implicit;
using implicit::Vec3d;
using ivdb::test::expectDistances;
using ivdb::test::unitGradientFraction;

namespace {

class TestShapes: public ::testing::Test
{
protected:
    void SetUp() override { openvdb::initialize(); }
};

raster::RasterSettings settings(double dx, raster::Sampling sampling = raster::Sampling::Sparse)
{
    raster::RasterSettings s;
    s.voxelSize = dx;
    s.halfWidth = 3.0;
    s.sampling = sampling;
    return s;
}

/// Distance from @a p to the segment ab, by ternary search of the convex |p - (a + t (b - a))|
/// over t in [0, 1] (a numerical minimization, not the projection the library uses).
double segmentDistance(const Vec3d& p, const Vec3d& a, const Vec3d& b)
{
    double lo = 0.0, hi = 1.0;
    auto at = [&](double t) { return (p - (a + (b - a) * t)).length(); };
    // Ternary search down to 1e-12 of the segment (about 70 steps; the distance is flat at its
    // minimum, so its own error is far smaller).
    while (hi - lo > 1e-12) {
        const double m1 = lo + (hi - lo) / 3.0, m2 = hi - (hi - lo) / 3.0;
        if (at(m1) < at(m2)) hi = m2;
        else lo = m1;
    }
    return at(0.5 * (lo + hi));
}

/// Signed distance to the box [lo, hi] by clamping: outside the distance to the clamped
/// point, inside minus the distance to the nearest face.
double clampedBoxDistance(const Vec3d& p, const Vec3d& lo, const Vec3d& hi)
{
    Vec3d q;
    bool inside = true;
    double face = std::numeric_limits<double>::max();
    for (int i = 0; i < 3; ++i) {
        q[i] = std::min(hi[i], std::max(lo[i], p[i]));
        inside = inside && p[i] > lo[i] && p[i] < hi[i];
        face = std::min({face, p[i] - lo[i], hi[i] - p[i]});
    }
    return inside ? -face : (p - q).length();
}

/// Inigo Quilez's closed form of the capped cylinder between a and b (iquilezles.org,
/// "distance functions"): the radial and axial excesses scaled by |b - a|^2.
double capsuleCylinderReference(const Vec3d& p, const Vec3d& a, const Vec3d& b, double r)
{
    const Vec3d ba = b - a, pa = p - a;
    const double baba = ba.dot(ba), paba = pa.dot(ba);
    const double x = (pa * baba - ba * paba).length() - r * baba;
    const double y = std::abs(paba - baba * 0.5) - baba * 0.5;
    const double x2 = x * x, y2 = y * y * baba;
    const double d = std::max(x, y) < 0.0 ? -std::min(x2, y2)
                                          : (x > 0.0 ? x2 : 0.0) + (y > 0.0 ? y2 : 0.0);
    return (d < 0.0 ? -1.0 : 1.0) * std::sqrt(std::abs(d)) / baba;
}

/// Inigo Quilez's closed form of the capped cone between a (radius ra) and b (radius rb).
double cappedConeReference(const Vec3d& p, const Vec3d& a, const Vec3d& b, double ra, double rb)
{
    const double rba = rb - ra, baba = (b - a).dot(b - a), papa = (p - a).dot(p - a);
    const double paba = (p - a).dot(b - a) / baba;
    const double x = std::sqrt(std::max(0.0, papa - paba * paba * baba));
    const double cax = std::max(0.0, x - (paba < 0.5 ? ra : rb));
    const double cay = std::abs(paba - 0.5) - 0.5;
    const double k = rba * rba + baba;
    const double f = std::min(1.0, std::max(0.0, (rba * (x - ra) + paba * baba) / k));
    const double cbx = x - ra - f * rba, cby = paba - f;
    const double s = (cbx < 0.0 && cay < 0.0) ? -1.0 : 1.0;
    return s * std::sqrt(std::min(cax * cax + cay * cay * baba, cbx * cbx + cby * cby * baba));
}

/// The shape contract at random points of @a box: value() and values() the same bits, the
/// analytic gradient equal to central differences of value() (away from kinks: where the
/// differences of the two half steps agree), and interval() containing every value of random
/// sub-boxes.
void expectContract(const Implicit& f, const implicit::BBoxd& box, const std::string& what)
{
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const Vec3d ext = box.max() - box.min();
    double x[64], y[64], z[64], v[64];
    for (int i = 0; i < 64; ++i) {
        const Vec3d p = box.min() + ext * Vec3d(u(rng), u(rng), u(rng));
        x[i] = p[0], y[i] = p[1], z[i] = p[2];
    }
    f.values(x, y, z, v, 64);
    int compared = 0;
    for (int i = 0; i < 64; ++i) {
        const Vec3d p(x[i], y[i], z[i]);
        ASSERT_EQ(v[i], f.value(p)) << what << " values() at " << p;
        const double h = 1e-6;
        Vec3d fd, fd2;
        for (int a = 0; a < 3; ++a) {
            Vec3d e(0.0);
            e[a] = h;
            fd[a] = (f.value(p + e) - f.value(p - e)) / (2 * h);
            fd2[a] = (f.value(p + e * 2.0) - f.value(p - e * 2.0)) / (4 * h);
        }
        if ((fd - fd2).length() > 1e-6) continue; // a kink within the stencil
        ++compared;
        EXPECT_LT((f.gradient(p) - fd).length(), 1e-5) << what << " gradient at " << p;
    }
    EXPECT_GT(compared, 48) << what;
    for (int b = 0; b < 200; ++b) {
        const Vec3d c = box.min() + ext * Vec3d(u(rng), u(rng), u(rng));
        const Vec3d half = ext * (0.2 * u(rng));
        const implicit::BBoxd sub(c - half, c + half);
        const implicit::Interval iv = f.interval(sub);
        for (int s = 0; s < 20; ++s) {
            const Vec3d p = sub.min() + (sub.max() - sub.min()) * Vec3d(u(rng), u(rng), u(rng));
            const double val = f.value(p);
            ASSERT_TRUE(iv.lo <= val && val <= iv.hi)
                << what << ": interval [" << iv.lo << ", " << iv.hi << "] misses " << val;
        }
    }
}

/// Rasterize @a shape sparse and dense; every active voxel within 0.05 voxel of @a reference,
/// the band exactly where it should be, unit gradients at 97% of near-surface voxels, and
/// dense equal to sparse.
void expectShape(const Implicit::Ptr& shape, const std::function<double(const Vec3d&)>& reference,
                 double dx, const std::string& what)
{
    SCOPED_TRACE(what);
    const auto g = raster::rasterize(shape, settings(dx));
    ASSERT_GT(g->activeVoxelCount(), 1000u);
    const implicit::BBoxd b = shape->boundingBox();
    const implicit::BBoxd box(b.min() - Vec3d(4 * dx), b.max() + Vec3d(4 * dx));
    const double worst = expectDistances(*g, reference, dx, 3.0, 0.05, what, box);
    const double unit = unitGradientFraction(*g);
    std::printf("%s: %llu active voxels, worst error %.3g voxel, |grad phi| in [0.9, 1.1] at "
                "%.2f%%\n", what.c_str(), (unsigned long long)g->activeVoxelCount(), worst,
                100.0 * unit);
    EXPECT_GE(unit, 0.97);
#ifdef IVDB_SANITIZED
    // Sanitized builds run 10-20x slower. The shape's own code has run above; the dense path's
    // does not depend on the shape and runs under sanitizers in TestRasterize's sparse = dense
    // tests.
    return;
#endif
    // Dense equals sparse (at twice the voxel size: the dense path is the slow reference).
    const auto sparse = raster::rasterize(shape, settings(2.0 * dx));
    const auto dense = raster::rasterize(shape, settings(2.0 * dx, raster::Sampling::Dense));
    EXPECT_EQ(dense->activeVoxelCount(), sparse->activeVoxelCount());
    auto acc = dense->getConstAccessor();
    std::size_t differ = 0;
    for (auto it = sparse->cbeginValueOn(); it; ++it) {
        float v;
        if (!acc.probeValue(it.getCoord(), v) || v != *it) ++differ;
    }
    EXPECT_EQ(differ, 0u) << "sparse and dense differ";
}

} // namespace

TEST_F(TestShapes, PrimitivesAreTheirClosedForms)
{
    // At 0.006 the shapes are 50-150 voxels across: their sharp edges (a cylinder's rims, a
    // cone's apex), where central differences of a distance are not unit, hold under 3% of the
    // voxels near the surface.
    const double dx = 0.006;
    const Vec3d a(-0.31, -0.22, 0.13), b(0.27, 0.18, -0.24);
    auto capsule = std::make_shared<implicit::Capsule>(a, b, 0.17);
    expectContract(*capsule, implicit::BBoxd(Vec3d(-0.6), Vec3d(0.6)), "capsule");
    expectShape(capsule, [&](const Vec3d& p) { return segmentDistance(p, a, b) - 0.17; }, dx,
                "capsule");

    const Vec3d c(0.03, -0.02, 0.05), size(0.9, 0.6, 0.5);
    auto rounded = std::make_shared<implicit::RoundedBox>(c, size, 0.12);
    expectContract(*rounded, implicit::BBoxd(Vec3d(-0.6), Vec3d(0.6)), "rounded_box");
    const Vec3d inner = size * 0.5 - Vec3d(0.12);
    expectShape(rounded, [&](const Vec3d& p) {
        return clampedBoxDistance(p, c - inner, c + inner) - 0.12;
    }, dx, "rounded_box");

    auto cylinder = std::make_shared<implicit::CappedCone>(a, b, 0.2, 0.2, "capped_cylinder");
    expectContract(*cylinder, implicit::BBoxd(Vec3d(-0.6), Vec3d(0.6)), "capped_cylinder");
    expectShape(cylinder, [&](const Vec3d& p) { return capsuleCylinderReference(p, a, b, 0.2); },
                dx, "capped_cylinder");

#ifdef IVDB_SANITIZED
    // Sanitized builds run 10-20x slower: one cone.
    const std::vector<std::pair<double, double>> cones{{0.0, 0.3}};
#else
    const std::vector<std::pair<double, double>> cones{{0.25, 0.1}, {0.0, 0.3}, {0.15, 0.32}};
#endif
    for (const auto& radii : cones) {
        const double ra = radii.first, rb = radii.second; // (lambdas cannot capture bindings)
        auto cone = std::make_shared<implicit::CappedCone>(a, b, ra, rb);
        const std::string what = "capped_cone " + std::to_string(ra) + " " + std::to_string(rb);
        expectContract(*cone, implicit::BBoxd(Vec3d(-0.6), Vec3d(0.6)), what);
        expectShape(cone, [&](const Vec3d& p) { return cappedConeReference(p, a, b, ra, rb); },
                    dx, what);
    }
}

TEST_F(TestShapes, OffsetAndShellAreDistances)
{
    const double dx = 0.01;
    // A box grown by d is the rounded box of size + 2d and radius d; shrunk, a smaller box.
    const Vec3d c(0.02, 0.01, -0.03), size(0.8, 0.5, 0.6);
    auto box = std::make_shared<implicit::Box>(c, size);
    auto grown = std::make_shared<implicit::Offset>(box, 0.1);
    expectContract(*grown, implicit::BBoxd(Vec3d(-0.7), Vec3d(0.7)), "offset");
    expectShape(grown, [&](const Vec3d& p) {
        return clampedBoxDistance(p, c - size * 0.5, c + size * 0.5) - 0.1;
    }, dx, "box offset by 0.1");
    // A rounded box shrunk by less than its radius: the rounded box of the smaller radius
    // (shrinking keeps sharp edges sharp, so a sharp box is left to docs/scene-format.md).
    auto rounded = std::make_shared<implicit::RoundedBox>(c, size, 0.12);
    auto shrunk = std::make_shared<implicit::Offset>(rounded, -0.05);
    const Vec3d inner = size * 0.5 - Vec3d(0.12);
    expectShape(shrunk, [&](const Vec3d& p) {
        return clampedBoxDistance(p, c - inner, c + inner) - 0.07;
    }, dx, "rounded box offset by -0.05");

    // A sphere's shell: two concentric spheres, the distance ||p - c| - R| - t/2.
    auto sphere = std::make_shared<implicit::Sphere>(c, 0.5);
    auto shell = std::make_shared<implicit::Shell>(sphere, 0.12);
    expectContract(*shell, implicit::BBoxd(Vec3d(-0.7), Vec3d(0.7)), "shell");
    expectShape(shell, [&](const Vec3d& p) {
        return std::abs((p - c).length() - 0.5) - 0.06;
    }, dx, "sphere shell 0.12");
}

namespace {

/// The smooth CSG formula, written out: h = max(k - |a - b|, 0) / k; union min - h^2 k / 4,
/// intersection max + h^2 k / 4, difference the intersection with -b.
double smoothReference(implicit::CsgOp op, double a, double b, double k)
{
    if (op == implicit::CsgOp::Difference) b = -b;
    const double h = std::max(k - std::abs(a - b), 0.0) / k;
    return op == implicit::CsgOp::Union ? std::min(a, b) - h * h * k / 4.0
                                        : std::max(a, b) + h * h * k / 4.0;
}

/// Largest |phi| (voxels, trilinear) at points of the zero set of @a f found by bisection along
/// rays from @a from (inside), over rays that cross it once; returns it with the count used.
std::pair<double, int> zeroCrossingError(const openvdb::FloatGrid& g,
                                         const std::function<double(const Vec3d&)>& f,
                                         const Vec3d& from, int rays)
{
    openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> sampler(g);
    std::mt19937 rng(17);
    std::normal_distribution<double> n(0.0, 1.0);
    double worst = 0.0;
    int used = 0;
    for (int i = 0; i < 4 * rays && used < rays; ++i) {
        Vec3d d(n(rng), n(rng), n(rng));
        d.normalize();
        double lo = 0.0, hi = 2.0;
        if (f(from) >= 0.0 || f(from + d * hi) <= 0.0) continue;
        for (int k = 0; k < 60; ++k) {
            const double mid = 0.5 * (lo + hi);
            (f(from + d * mid) < 0.0 ? lo : hi) = mid;
        }
        // Star-shaped from `from` along this ray: inside all the way to the crossing.
        bool single = true;
        for (int k = 1; k < 80 && single; ++k) single = f(from + d * (lo * k / 80.0)) < 0.0;
        if (!single) continue;
        ++used;
        worst = std::max(worst, std::abs(double(sampler.wsSample(from + d * lo))));
    }
    return {worst / g.voxelSize()[0], used};
}

} // namespace

TEST_F(TestShapes, SmoothCsgMatchesItsFormula)
{
    const double dx = 0.01;
    const Vec3d ca(-0.3, 0.01, -0.02), cb(0.32, -0.02, 0.01);
    const double ra = 0.45, rb = 0.4;
    auto sa = std::make_shared<implicit::Sphere>(ca, ra);
    auto sb = std::make_shared<implicit::Sphere>(cb, rb);
    for (implicit::CsgOp op : {implicit::CsgOp::Union, implicit::CsgOp::Intersection,
                               implicit::CsgOp::Difference}) {
#ifdef IVDB_SANITIZED
        const std::vector<double> widths{10.0}; // sanitized builds run 10-20x slower
#else
        const std::vector<double> widths{2.0, 10.0, 40.0};
#endif
        for (double kVox : widths) {
            const double k = kVox * dx;
            auto shape = std::make_shared<implicit::Blend>(op, implicit::BlendKernel::polynomial(k),
                                                           std::vector<Implicit::Ptr>{sa, sb});
            const std::string what = std::string("smooth ") + implicit::toString(op) + " k = " +
                                     std::to_string(int(kVox)) + " voxels";
            SCOPED_TRACE(what);
            EXPECT_EQ(shape->typeName(), "smooth");
            auto formula = [&](const Vec3d& p) {
                return smoothReference(op, (p - ca).length() - ra, (p - cb).length() - rb, k);
            };
            // The node is the formula.
            std::mt19937 rng(3);
            std::uniform_real_distribution<double> u(-0.8, 0.8);
            for (int i = 0; i < 1000; ++i) {
                const Vec3d p(u(rng), u(rng), u(rng));
                ASSERT_NEAR(shape->value(p), formula(p), 1e-12) << p;
            }
            expectContract(*shape, implicit::BBoxd(Vec3d(-0.8), Vec3d(0.8)), what);
            const auto g = raster::rasterize(shape, settings(dx));
            const Vec3d from = op == implicit::CsgOp::Union        ? Vec3d(0.0)
                             : op == implicit::CsgOp::Intersection ? (ca + cb) * 0.5
                                                                   : ca - Vec3d(0.2, 0.0, 0.0);
            const auto [worst, used] = zeroCrossingError(*g, formula, from, 800);
            const double unit = unitGradientFraction(*g);
            std::printf("%s: worst |phi| at %d zero crossings of the formula %.3f voxel, |grad "
                        "phi| in [0.9, 1.1] at %.2f%%\n", what.c_str(), used, worst, 100.0 * unit);
            EXPECT_GE(used, 400);
            // The intersection's rim at k = 2 voxels is rounded over about two voxels, where
            // trilinear interpolation of exact distances is off by 0.107 voxel.
            EXPECT_LE(worst, op == implicit::CsgOp::Intersection && kVox == 2.0 ? 0.11 : 0.1);
            EXPECT_GE(unit, 0.97);
        }
    }
    // Three children fold from the left; a union swells at most (n - 1) k / 4 beyond the
    // sharp one, which the bounding box allows for.
    const double k = 0.2;
    auto sc = std::make_shared<implicit::Sphere>(Vec3d(0.0, 0.45, 0.0), 0.3);
    implicit::Blend three(implicit::CsgOp::Union, implicit::BlendKernel::polynomial(k), {sa, sb, sc});
    const Vec3d p(0.01, 0.2, 0.03);
    const double ab = smoothReference(implicit::CsgOp::Union, sa->value(p), sb->value(p), k);
    EXPECT_NEAR(three.value(p), smoothReference(implicit::CsgOp::Union, ab, sc->value(p), k), 1e-12);
    const implicit::BBoxd bb = three.boundingBox();
    EXPECT_NEAR(bb.min()[0], ca[0] - ra - 2 * k / 4, 1e-12);
    EXPECT_NEAR(bb.max()[1], 0.45 + 0.3 + 2 * k / 4, 1e-12);
}

TEST_F(TestShapes, SceneTypesAndTheirErrors)
{
    const scene::Scene s = scene::parseScene(R"({"voxel_size": 0.01, "shape": {"type": "smooth",
        "op": "union", "k": 0.1, "children": [
          {"type": "capsule", "a": [0, 0, 0], "b": [0.5, 0, 0], "radius": 0.1},
          {"type": "rounded_box", "size": [0.4, 0.3, 0.2], "radius": 0.05},
          {"type": "capped_cylinder", "a": [0, 0, 0], "b": [0, 0.4, 0], "radius": 0.1},
          {"type": "capped_cone", "a": [0, 0, 0], "b": [0, 0, 0.4], "radius_a": 0.2, "radius_b": 0},
          {"type": "offset", "distance": 0.02, "child": {"type": "sphere", "radius": 0.2}},
          {"type": "shell", "thickness": 0.04, "child": {"type": "sphere", "radius": 0.3}}]}})",
                                             "s.json");
    EXPECT_EQ(s.shape->typeName(), "smooth");
    EXPECT_TRUE(s.shape->isBounded());

    auto refused = [](const std::string& shape, const std::string& message) {
        try {
            scene::parseScene(R"({"voxel_size": 0.01, "shape": )" + shape + "}", "bad.json");
            ADD_FAILURE() << "accepted: " << shape;
        } catch (const scene::SceneError& e) {
            EXPECT_NE(std::string(e.what()).find(message), std::string::npos)
                << e.what() << "\n  expected: " << message;
        }
    };
    refused(R"({"type": "capsule", "a": [0, 0, 0], "b": [1, 0, 0], "radius": 0})",
            "bad.json: shape.radius: must be > 0, got 0");
    refused(R"({"type": "capsule", "a": [0, 0, 0], "radius": 1})", "shape.b: is missing");
    refused(R"({"type": "rounded_box", "size": [1, 1, 0.2], "radius": 0.2})",
            "shape.radius: must be <= half the smallest size (0.1), got 0.2");
    refused(R"({"type": "rounded_box", "size": [1, 1, 0], "radius": 0.1})", "shape.size[2]: must be > 0");
    refused(R"({"type": "capped_cylinder", "a": [1, 2, 3], "b": [1, 2, 3], "radius": 1})",
            "shape.b: must differ from a");
    refused(R"({"type": "capped_cone", "a": [0, 0, 0], "b": [0, 0, 1], "radius_a": -1, "radius_b": 1})",
            "shape.radius_a: must be >= 0, got -1");
    refused(R"({"type": "capped_cone", "a": [0, 0, 0], "b": [0, 0, 1], "radius_a": 0, "radius_b": 0})",
            "shape.radius_b: must be > 0 when radius_a is 0");
    refused(R"({"type": "shell", "thickness": 0, "child": {"type": "sphere", "radius": 1}})",
            "shape.thickness: must be > 0, got 0");
    refused(R"({"type": "offset", "child": {"type": "sphere", "radius": 1}})", "shape.distance: is missing");
    refused(R"({"type": "offset", "distance": 0.1, "child": {"type": "sphere", "radius": -1}})",
            "shape.child.radius: must be > 0");
    refused(R"({"type": "smooth", "op": "union", "k": 0, "children": [{"type": "sphere", "radius": 1},
            {"type": "sphere", "radius": 1}]})", "shape.k: must be > 0");
    refused(R"({"type": "smooth", "op": "union", "k": 0.1, "children": [{"type": "sphere", "radius": 1}]})",
            "shape.children: needs at least 2 shapes");
    refused(R"({"type": "smooth", "op": "xor", "k": 0.1, "children": []})", "shape.op: must be one of");
    refused(R"({"type": "capsule", "a": [0, 0, 0], "b": [1, 0, 0], "radius": 1, "r": 2})",
            "shape.r: unknown key; allowed here: type, a, b, radius");
}
