// SPDX-License-Identifier: Apache-2.0
// Differential operator tests: closed forms on spheres and on a rotated ellipsoid given as a raw
// quadric, OpenVDB's own operators where the stencil is the same, threaded against serial, and
// the errors for bad input.
#include <ivdb/diff/Differential.h>
#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/implicit/Quadric.h>
#include <ivdb/levelset/LevelSet.h>
#include <ivdb/raster/Rasterize.h>

#include <openvdb/tools/GridOperators.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

using namespace ivdb;
using implicit::Vec3d;
using openvdb::Coord;

class TestDifferential: public ::testing::Test
{
protected:
    void SetUp() override { openvdb::initialize(); }
};

namespace {

raster::RasterSettings settings(double dx, double w = 3.0)
{
    raster::RasterSettings r;
    r.voxelSize = dx;
    r.halfWidth = w;
    return r;
}

/// A level set of a sphere of @a radiusVoxels voxels (world radius 1, voxel size 1/radius),
/// centred off the voxel lattice; an exact SDF, so rasterize stores the distances as they are.
struct SphereLevelSet
{
    Vec3d center;
    double radius, dx;
    openvdb::FloatGrid::Ptr grid;
};

SphereLevelSet makeSphere(double radiusVoxels)
{
    SphereLevelSet s;
    s.radius = 1.0;
    s.dx = 1.0 / radiusVoxels;
    s.center = Vec3d(0.31, -0.27, 0.13) * s.dx;
    s.grid = raster::rasterize(std::make_shared<implicit::Sphere>(s.center, s.radius),
                               settings(s.dx));
    return s;
}

/// Sorted copy's worst, median and 95th percentile.
struct Summary
{
    double worst = 0.0, median = 0.0, p95 = 0.0;
    std::size_t count = 0;
};

Summary summarize(std::vector<double> v)
{
    Summary s;
    s.count = v.size();
    if (v.empty()) return s;
    std::sort(v.begin(), v.end());
    s.worst = v.back();
    s.median = v[v.size() / 2];
    s.p95 = v[std::min(v.size() - 1, std::size_t(0.95 * double(v.size())))];
    return s;
}

/// Both grids have the same active voxels (topology and count).
template<typename GridA, typename GridB>
void expectSameActiveVoxels(const GridA& a, const GridB& b, const std::string& what)
{
    EXPECT_EQ(a.activeVoxelCount(), b.activeVoxelCount()) << what;
    EXPECT_TRUE(a.tree().hasSameTopology(b.tree())) << what;
}

/// Every active value of @a a equals @a b's value at the same voxel within
/// @a tol * max(1, |b|); returns the largest scaled difference.
double compareFloatGrids(const openvdb::FloatGrid& a, const openvdb::FloatGrid& b, double tol,
                         const std::string& what)
{
    auto acc = b.getConstAccessor();
    std::size_t off = 0, missing = 0;
    double worst = 0.0;
    for (auto it = a.cbeginValueOn(); it; ++it) {
        float v;
        if (!acc.probeValue(it.getCoord(), v)) {
            ++missing;
            continue;
        }
        const double d = std::abs(double(*it) - double(v)) / std::max(1.0, std::abs(double(v)));
        worst = std::max(worst, d);
        if (!(d <= tol)) ++off;
    }
    EXPECT_EQ(missing, 0u) << what;
    EXPECT_EQ(off, 0u) << what << ": scaled differences up to " << worst;
    return worst;
}

/// Bit-for-bit equality of values and active topology.
template<typename GridT>
void expectIdentical(const GridT& a, const GridT& b, const std::string& what)
{
    expectSameActiveVoxels(a, b, what);
    auto acc = b.getConstAccessor();
    std::size_t off = 0;
    for (auto it = a.cbeginValueOn(); it; ++it) {
        const auto va = *it, vb = acc.getValue(it.getCoord());
        if (std::memcmp(&va, &vb, sizeof(va)) != 0) ++off;
    }
    EXPECT_EQ(off, 0u) << what << ": values differ between threaded and serial runs";
}

/// A raw quadric matrix for the ellipsoid with semi-axes @a radii, rotated by @a rotateDeg
/// (x, then y, then z, fixed axes) and translated by @a t, built by hand:
/// local q = R^T (p - t), f = q^T D q - 1, so A = R D R^T, b = -A t, c = t^T A t - 1.
struct RawEllipsoid
{
    implicit::Mat4 q{};
    double A[3][3];
    double b[3];
};

RawEllipsoid makeRawEllipsoid(const Vec3d& radii, const Vec3d& rotateDeg, const Vec3d& t)
{
    auto rot = [](int axis, double deg) {
        const double a = deg * M_PI / 180.0, c = std::cos(a), s = std::sin(a);
        std::array<std::array<double, 3>, 3> m{};
        const int i = (axis + 1) % 3, j = (axis + 2) % 3;
        m[axis][axis] = 1.0;
        m[i][i] = c;
        m[i][j] = -s;
        m[j][i] = s;
        m[j][j] = c;
        return m;
    };
    auto mul = [](const std::array<std::array<double, 3>, 3>& x,
                  const std::array<std::array<double, 3>, 3>& y) {
        std::array<std::array<double, 3>, 3> m{};
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                for (int k = 0; k < 3; ++k) m[i][j] += x[i][k] * y[k][j];
        return m;
    };
    const auto R = mul(rot(2, rotateDeg[2]), mul(rot(1, rotateDeg[1]), rot(0, rotateDeg[0])));
    RawEllipsoid e;
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
            e.A[i][j] = 0.0;
            for (int k = 0; k < 3; ++k) e.A[i][j] += R[i][k] * R[j][k] / (radii[k] * radii[k]);
        }
    }
    double c = -1.0;
    for (int i = 0; i < 3; ++i) {
        e.b[i] = 0.0;
        for (int j = 0; j < 3; ++j) {
            e.b[i] -= e.A[i][j] * t[j];
            c += t[i] * e.A[i][j] * t[j];
        }
    }
    for (int i = 0; i < 3; ++i) {
        for (int j = i; j < 3; ++j) e.q[i][j] = e.q[j][i] = 0.5 * (e.A[i][j] + e.A[j][i]);
        e.q[i][3] = e.q[3][i] = e.b[i];
    }
    e.q[3][3] = c;
    return e;
}

/// The same rigid motion applied to a point of the axis-aligned ellipsoid (for sampling).
Vec3d rotateAndTranslate(const Vec3d& p, const Vec3d& rotateDeg, const Vec3d& t)
{
    Vec3d q = p;
    for (int axis = 0; axis < 3; ++axis) {
        const double a = rotateDeg[axis] * M_PI / 180.0, c = std::cos(a), s = std::sin(a);
        const int i = (axis + 1) % 3, j = (axis + 2) % 3;
        const double qi = c * q[i] - s * q[j], qj = s * q[i] + c * q[j];
        q[i] = qi;
        q[j] = qj;
    }
    return q + t;
}

/// Closed-form gradient, mean and Gaussian curvature of the quadric's level set at @a p
/// (mean positive for a sphere with the outward gradient).
void quadricCurvatures(const RawEllipsoid& e, const Vec3d& p, Vec3d& grad, double& mean,
                       double& gauss)
{
    double g[3], H[3][3];
    for (int i = 0; i < 3; ++i) {
        g[i] = 2.0 * e.b[i];
        for (int j = 0; j < 3; ++j) {
            g[i] += 2.0 * e.A[i][j] * p[j];
            H[i][j] = 2.0 * e.A[i][j];
        }
    }
    const double n2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2], n = std::sqrt(n2);
    double gHg = 0.0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) gHg += g[i] * H[i][j] * g[j];
    const double trace = H[0][0] + H[1][1] + H[2][2];
    mean = (n2 * trace - gHg) / (2.0 * n2 * n);
    // adjugate of the symmetric Hessian
    double adj[3][3];
    adj[0][0] = H[1][1] * H[2][2] - H[1][2] * H[2][1];
    adj[1][1] = H[0][0] * H[2][2] - H[0][2] * H[2][0];
    adj[2][2] = H[0][0] * H[1][1] - H[0][1] * H[1][0];
    adj[0][1] = adj[1][0] = H[0][2] * H[2][1] - H[0][1] * H[2][2];
    adj[0][2] = adj[2][0] = H[0][1] * H[1][2] - H[0][2] * H[1][1];
    adj[1][2] = adj[2][1] = H[0][2] * H[1][0] - H[0][0] * H[1][2];
    double gAg = 0.0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) gAg += g[i] * adj[i][j] * g[j];
    gauss = gAg / (n2 * n2);
    grad = Vec3d(g[0], g[1], g[2]);
}

const Vec3d kRadii(0.7, 0.45, 0.3), kRotate(30.0, -20.0, 50.0), kShift(0.11, -0.07, 0.05);

} // namespace

TEST_F(TestDifferential, SphereCurvaturesMatchClosedForms)
{
    for (double rv : {10.0, 25.0, 50.0, 100.0}) {
        const SphereLevelSet s = makeSphere(rv);
        const auto mean = diff::curvature(*s.grid, diff::Curvature::Mean);
        const auto lap = diff::curvature(*s.grid, diff::Curvature::Laplacian);
        const auto gauss = diff::curvature(*s.grid, diff::Curvature::Gaussian);
        const auto [k1, k2] = diff::principalCurvatures(*s.grid);
        for (const auto* g : {mean.get(), lap.get(), gauss.get(), k1.get(), k2.get()}) {
            expectSameActiveVoxels(*g, *s.grid, g->getName());
            EXPECT_EQ(g->transform(), s.grid->transform());
        }
        EXPECT_EQ(mean->getName(), "curvature");
        EXPECT_EQ(k1->getName(), "k1");
        EXPECT_EQ(k2->getName(), "k2");

        auto aMean = mean->getConstAccessor(), aLap = lap->getConstAccessor(),
             aGauss = gauss->getConstAccessor(), aK1 = k1->getConstAccessor(),
             aK2 = k2->getConstAccessor();
        std::vector<double> eMean, eLap, eGauss, eK1, eK2;
        std::size_t orderViolations = 0;
        for (auto it = s.grid->cbeginValueOn(); it; ++it) {
            if (!(std::abs(*it) < s.dx)) continue;
            const Coord ijk = it.getCoord();
            const double rho = (s.grid->transform().indexToWorld(ijk) - s.center).length();
            const double kappa = 1.0 / rho;
            eMean.push_back(std::abs(aMean.getValue(ijk) - kappa) / kappa);
            eLap.push_back(std::abs(aLap.getValue(ijk) - 2.0 * kappa) / (2.0 * kappa));
            eGauss.push_back(std::abs(aGauss.getValue(ijk) - kappa * kappa) / (kappa * kappa));
            eK1.push_back(std::abs(aK1.getValue(ijk) - kappa) / kappa);
            eK2.push_back(std::abs(aK2.getValue(ijk) - kappa) / kappa);
            if (aK1.getValue(ijk) < aK2.getValue(ijk)) ++orderViolations;
        }
        ASSERT_GT(eMean.size(), std::size_t(4.0 * M_PI * rv * rv)) << "radius " << rv;
        const Summary m = summarize(eMean), l = summarize(eLap), g = summarize(eGauss),
                      p1 = summarize(eK1), p2 = summarize(eK2);
        std::printf("sphere r=%3.0f voxels, %zu voxels with |phi| < dx: relative errors "
                    "worst/median: mean %.5f/%.5f, laplacian %.5f/%.5f, gaussian %.5f/%.5f, "
                    "k1 %.5f/%.5f, k2 %.5f/%.5f\n",
                    rv, m.count, m.worst, m.median, l.worst, l.median, g.worst, g.median,
                    p1.worst, p1.median, p2.worst, p2.median);
        const std::string at = "sphere of radius " + std::to_string(int(rv)) + " voxels";
        EXPECT_LE(m.worst, 0.01) << at << ": mean curvature";
        EXPECT_LE(m.median, 0.002) << at << ": mean curvature median";
        EXPECT_LE(l.worst, 0.01) << at << ": Laplacian";
        EXPECT_LE(g.worst, 0.02) << at << ": Gaussian curvature";
        EXPECT_LE(p1.worst, 0.01) << at << ": k1";
        EXPECT_LE(p2.worst, 0.01) << at << ": k2";
        EXPECT_EQ(orderViolations, 0u) << at << ": k1 < k2";
    }
}

TEST_F(TestDifferential, SphereGradientIsTheUnitNormal)
{
    for (double rv : {10.0, 25.0, 50.0, 100.0}) {
        const SphereLevelSet s = makeSphere(rv);
        const auto grad = diff::gradient(*s.grid, 1);
        auto acc = grad->getConstAccessor();
        std::vector<double> err;
        for (auto it = s.grid->cbeginValueOn(); it; ++it) {
            if (!(std::abs(*it) < s.dx)) continue;
            const Coord ijk = it.getCoord();
            const Vec3d d = s.grid->transform().indexToWorld(ijk) - s.center;
            err.push_back((Vec3d(acc.getValue(ijk)) - d / d.length()).length());
        }
        const Summary e = summarize(err);
        std::printf("sphere r=%3.0f voxels: |gradient - normal| worst %.6f median %.6f over %zu "
                    "voxels\n", rv, e.worst, e.median, e.count);
        EXPECT_LE(e.worst, 0.01) << "radius " << rv << " voxels";
    }
}

namespace {

struct EllipsoidErrors
{
    Summary angle, mean, gauss, k1, k2;
};

/// The closed-form principal curvatures H +/- sqrt(H^2 - K) of a quadric's level set at @a p.
std::pair<double, double> quadricPrincipal(const RawEllipsoid& e, const Vec3d& p)
{
    Vec3d g;
    double H, K;
    quadricCurvatures(e, p, g, H, K);
    const double root = std::sqrt(std::max(0.0, H * H - K));
    return {H + root, H - root};
}

/// Gradient direction, mean and Gaussian curvature of @a phi, trilinearly interpolated at 2000
/// analytic surface points of the ellipsoid @a e, against the closed forms.
EllipsoidErrors measureEllipsoid(const RawEllipsoid& e, const implicit::Quadric& shape,
                                 const openvdb::FloatGrid& phi)
{
    const auto grad = diff::gradient(phi, 1);
    const auto mean = diff::curvature(phi, diff::Curvature::Mean);
    const auto gauss = diff::curvature(phi, diff::Curvature::Gaussian);
    const auto [k1, k2] = diff::principalCurvatures(phi);
    openvdb::tools::GridSampler<openvdb::Vec3SGrid, openvdb::tools::BoxSampler> sGrad(*grad);
    openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> sMean(*mean),
        sGauss(*gauss), sK1(*k1), sK2(*k2);
    std::mt19937 rng(11);
    std::normal_distribution<double> n(0.0, 1.0);
    std::vector<double> angle, eMean, eGauss, eK1, eK2;
    for (int i = 0; i < 2000; ++i) {
        Vec3d u(n(rng), n(rng), n(rng));
        u.normalize();
        const Vec3d p = rotateAndTranslate(
            Vec3d(u[0] * kRadii[0], u[1] * kRadii[1], u[2] * kRadii[2]), kRotate, kShift);
        EXPECT_NEAR(shape.value(p), 0.0, 1e-9) << "sample " << i << " is not on the surface";
        Vec3d g;
        double H, K;
        quadricCurvatures(e, p, g, H, K);
        // the library's analytic gradient is the same 2 (A p + b)
        EXPECT_LT((shape.gradient(p) - g).length(), 1e-9 * g.length());
        const Vec3d d(sGrad.wsSample(p));
        const double c = std::clamp(d.dot(g) / (d.length() * g.length()), -1.0, 1.0);
        angle.push_back(std::acos(c) * 180.0 / M_PI);
        eMean.push_back(std::abs(sMean.wsSample(p) - H) / std::abs(H));
        eGauss.push_back(std::abs(sGauss.wsSample(p) - K) / std::abs(K));
        // Each principal curvature on its own (on this ellipsoid they differ but at 4 umbilics).
        const auto [c1, c2] = quadricPrincipal(e, p);
        eK1.push_back(std::abs(sK1.wsSample(p) - c1) / std::abs(c1));
        eK2.push_back(std::abs(sK2.wsSample(p) - c2) / std::abs(c2));
    }
    return {summarize(angle), summarize(eMean), summarize(eGauss), summarize(eK1), summarize(eK2)};
}

} // namespace

TEST_F(TestDifferential, RotatedEllipsoidFromRawQuadric)
{
    // The quadric is re-distanced by rasterize; the closed forms hold on the surface itself.
    const RawEllipsoid e = makeRawEllipsoid(kRadii, kRotate, kShift);
    auto shape = std::make_shared<implicit::Quadric>(e.q);
    ASSERT_TRUE(shape->isBounded());
    const double dx = 0.005;
    const auto phi = raster::rasterize(shape, settings(dx));
    const EllipsoidErrors r = measureEllipsoid(e, *shape, *phi);
    std::printf("rotated ellipsoid, rasterized (dx %.3f, %zu surface points): gradient angle "
                "worst %.4f p95 %.4f deg; mean curvature relative error p95 %.5f median %.5f "
                "worst %.5f; Gaussian p95 %.5f median %.5f worst %.5f; k1 p95 %.5f, k2 p95 "
                "%.5f\n", dx, r.angle.count, r.angle.worst, r.angle.p95, r.mean.p95,
                r.mean.median, r.mean.worst, r.gauss.p95, r.gauss.median, r.gauss.worst,
                r.k1.p95, r.k2.p95);
    EXPECT_LE(r.angle.worst, 0.5);
    EXPECT_LE(r.mean.p95, 0.003);
    EXPECT_LE(r.gauss.p95, 0.003);
    EXPECT_LE(r.k1.p95, 0.003);
    EXPECT_LE(r.k2.p95, 0.003);
}

TEST_F(TestDifferential, RotatedEllipsoidOperatorsOnSmoothDistance)
{
    // The same ellipsoid and band, with every active value set to f / |grad f| evaluated in
    // double precision (a smooth function whose zero set is the surface): this isolates the
    // operators from the rasterizer's re-distancing.
    const RawEllipsoid e = makeRawEllipsoid(kRadii, kRotate, kShift);
    auto shape = std::make_shared<implicit::Quadric>(e.q);
    const double dx = 0.005;
    const auto phi = raster::rasterize(shape, settings(dx));
    for (auto it = phi->beginValueOn(); it; ++it) {
        const Vec3d p = phi->transform().indexToWorld(it.getCoord());
        it.setValue(float(shape->value(p) / shape->gradient(p).length()));
    }
    const EllipsoidErrors r = measureEllipsoid(e, *shape, *phi);
    std::printf("rotated ellipsoid, f/|grad f| band (dx %.3f, %zu surface points): gradient "
                "angle worst %.4f p95 %.4f deg; mean curvature relative error p95 %.5f worst "
                "%.5f; Gaussian p95 %.5f worst %.5f; k1 p95 %.5f, k2 p95 %.5f\n", dx,
                r.angle.count, r.angle.worst, r.angle.p95, r.mean.p95, r.mean.worst, r.gauss.p95,
                r.gauss.worst, r.k1.p95, r.k2.p95);
    EXPECT_LE(r.angle.worst, 0.5);
    EXPECT_LE(r.mean.p95, 0.003);
    EXPECT_LE(r.gauss.p95, 0.003);
    EXPECT_LE(r.k1.p95, 0.003);
    EXPECT_LE(r.k2.p95, 0.003);
}

// A saddle, the hyperbolic paraboloid z = (x/a)^2 - (y/b)^2: principal curvatures of opposite
// signs, each against its closed form, and a Gaussian curvature that is negative everywhere.
TEST_F(TestDifferential, SaddlePrincipalCurvaturesHaveOppositeSigns)
{
    const double a = 0.8, b = 0.6, dx = 0.005;
    // f = p^T A p + 2 b.p + c with A = diag(1/a^2, -1/b^2, 0), b = (0, 0, -1/2), c = 0.
    RawEllipsoid s{};
    s.A[0][0] = 1.0 / (a * a);
    s.A[1][1] = -1.0 / (b * b);
    s.b[2] = -0.5;
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) s.q[i][j] = s.A[i][j];
        s.q[i][3] = s.q[3][i] = s.b[i];
    }
    auto shape = std::make_shared<implicit::Quadric>(s.q);
    raster::RasterSettings rs = settings(dx);
    rs.bounds = implicit::BBoxd(Vec3d(-0.45, -0.45, -0.7), Vec3d(0.45, 0.45, 0.45));
    const auto phi = raster::rasterize(shape, rs);
    const auto gauss = diff::curvature(*phi, diff::Curvature::Gaussian);
    const auto [k1, k2] = diff::principalCurvatures(*phi);
    openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> sGauss(*gauss),
        sK1(*k1), sK2(*k2);
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-0.3, 0.3); // 30 voxels inside the bounds
    std::vector<double> eK1, eK2, eGauss;
    std::size_t wrongSign = 0;
    for (int i = 0; i < 2000; ++i) {
        const double x = u(rng), y = u(rng);
        const Vec3d p(x, y, x * x / (a * a) - y * y / (b * b));
        ASSERT_NEAR(shape->value(p), 0.0, 1e-12);
        Vec3d g;
        double H, K;
        quadricCurvatures(s, p, g, H, K);
        ASSERT_LT(K, 0.0) << "the closed form: a saddle everywhere";
        const auto [c1, c2] = quadricPrincipal(s, p);
        const double d1 = sK1.wsSample(p), d2 = sK2.wsSample(p), dK = sGauss.wsSample(p);
        if (!(d1 > 0.0 && d2 < 0.0 && dK < 0.0)) ++wrongSign;
        eK1.push_back(std::abs(d1 - c1) / std::abs(c1));
        eK2.push_back(std::abs(d2 - c2) / std::abs(c2));
        eGauss.push_back(std::abs(dK - K) / std::abs(K));
    }
    const Summary r1 = summarize(eK1), r2 = summarize(eK2), rg = summarize(eGauss);
    std::printf("saddle z = (x/%.1f)^2 - (y/%.1f)^2 (dx %.3f, 2000 surface points): relative "
                "error p95/worst: k1 %.5f/%.5f, k2 %.5f/%.5f, Gaussian %.5f/%.5f\n", a, b, dx,
                r1.p95, r1.worst, r2.p95, r2.worst, rg.p95, rg.worst);
    EXPECT_EQ(wrongSign, 0u) << "k1 > 0 > k2 and K < 0 at every point";
    EXPECT_LE(r1.p95, 0.003);
    EXPECT_LE(r2.p95, 0.003);
    EXPECT_LE(rg.p95, 0.003);
}

TEST_F(TestDifferential, EqualsOpenVdbOperators)
{
    const SphereLevelSet s = makeSphere(40.0);
    auto csg = std::make_shared<implicit::Csg>(
        implicit::Csg::Op::Difference,
        std::vector<implicit::Implicit::Ptr>{
            std::make_shared<implicit::Sphere>(Vec3d(0.01, -0.02, 0.03), 0.5),
            std::make_shared<implicit::Sphere>(Vec3d(0.35, 0.1, -0.05), 0.3)});
    const auto scene = raster::rasterize(csg, settings(0.01));
    for (const auto& [name, phi] : {std::pair<std::string, openvdb::FloatGrid::Ptr>{"sphere", s.grid},
                                    {"difference of spheres", scene}}) {
        SCOPED_TRACE(name);
        const auto ours = diff::gradient(*phi, 1);
        const auto ref = openvdb::tools::gradient(*phi);
        expectSameActiveVoxels(*ours, *ref, name + ": gradient");
        auto acc = ref->getConstAccessor();
        std::size_t off = 0;
        double worst = 0.0;
        for (auto it = ours->cbeginValueOn(); it; ++it) {
            const openvdb::Vec3s r = acc.getValue(it.getCoord());
            for (int i = 0; i < 3; ++i) worst = std::max(worst, double(std::abs((*it)[i] - r[i])));
            if (!((*it - r).length() <= 1e-5f)) ++off;
        }
        EXPECT_EQ(off, 0u) << name << ": gradient differs from tools::gradient by up to " << worst;

        const auto mean = diff::curvature(*phi, diff::Curvature::Mean);
        const auto refMean = openvdb::tools::meanCurvature(*phi);
        expectSameActiveVoxels(*mean, *refMean, name + ": mean curvature");
        const double wm = compareFloatGrids(*mean, *refMean, 1e-5, name + ": mean curvature");

        // tools::laplacian uses the same 7-point CD_SECOND stencil
        const auto lap = diff::curvature(*phi, diff::Curvature::Laplacian);
        const auto refLap = openvdb::tools::laplacian(*phi);
        expectSameActiveVoxels(*lap, *refLap, name + ": Laplacian");
        const double wl = compareFloatGrids(*lap, *refLap, 1e-5, name + ": Laplacian");
        std::printf("%s: max difference to OpenVDB: gradient %.3g, mean curvature %.3g, "
                    "Laplacian %.3g (relative where > 1)\n", name.c_str(), worst, wm, wl);
    }
}

TEST_F(TestDifferential, ThreadedEqualsSerial)
{
    auto csg = std::make_shared<implicit::Csg>(
        implicit::Csg::Op::Difference,
        std::vector<implicit::Implicit::Ptr>{
            std::make_shared<implicit::Sphere>(Vec3d(0.0), 0.5),
            std::make_shared<implicit::Sphere>(Vec3d(0.3, 0.1, 0.0), 0.3)});
    const auto phi = raster::rasterize(csg, settings(0.01));
    for (int step : {1, 3}) {
        expectIdentical(*diff::gradient(*phi, step, true), *diff::gradient(*phi, step, false),
                        "gradient step " + std::to_string(step));
    }
    for (auto kind : {diff::Curvature::Mean, diff::Curvature::Gaussian, diff::Curvature::Laplacian}) {
        expectIdentical(*diff::curvature(*phi, kind, true), *diff::curvature(*phi, kind, false),
                        "curvature kind " + std::to_string(int(kind)));
    }
    const auto [t1, t2] = diff::principalCurvatures(*phi, true);
    const auto [s1, s2] = diff::principalCurvatures(*phi, false);
    expectIdentical(*t1, *s1, "k1");
    expectIdentical(*t2, *s2, "k2");
}

TEST_F(TestDifferential, RunsOfLeavesMakeTheWholeGrid)
{
    // What ivdb-mpi's ranks compute: each operator on runs of the leaves (the others only read)
    // gives, joined, the operator on the whole grid, bitwise.
    auto csg = std::make_shared<implicit::Csg>(
        implicit::Csg::Op::Union,
        std::vector<implicit::Implicit::Ptr>{
            std::make_shared<implicit::Sphere>(Vec3d(0.0), 0.5),
            std::make_shared<implicit::Sphere>(Vec3d(0.5, 0.1, 0.0), 0.3)});
    const auto phi = raster::rasterize(csg, settings(0.01));
    std::vector<const openvdb::FloatTree::LeafNodeType*> all;
    for (auto it = phi->tree().cbeginLeaf(); it; ++it) all.push_back(&*it);
    // Joins the runs' output grids, which must each hold only their run's leaves.
    auto joined = [&](auto&& op) {
        auto out = op(nullptr);
        out->clear();
        const std::size_t runs = 5;
        for (std::size_t r = 0; r < runs; ++r) {
            const diff::LeafList only(all.begin() + std::ptrdiff_t(all.size() * r / runs),
                                      all.begin() + std::ptrdiff_t(all.size() * (r + 1) / runs));
            auto part = op(&only);
            EXPECT_LE(part->tree().leafCount(), only.size());
            for (auto it = part->tree().cbeginLeaf(); it; ++it) {
                EXPECT_TRUE(std::find_if(only.begin(), only.end(), [&](const auto* l) {
                    return l->origin() == it->origin(); }) != only.end());
            }
            out->tree().merge(part->tree());
        }
        return out;
    };
    for (int step : {1, 12}) {
        expectIdentical(*joined([&](const diff::LeafList* o) { return diff::gradient(*phi, step, true, o); }),
                        *diff::gradient(*phi, step), "gradient step " + std::to_string(step));
    }
    for (auto kind : {diff::Curvature::Mean, diff::Curvature::Gaussian, diff::Curvature::Laplacian}) {
        expectIdentical(*joined([&](const diff::LeafList* o) { return diff::curvature(*phi, kind, true, o); }),
                        *diff::curvature(*phi, kind), "curvature kind " + std::to_string(int(kind)));
    }
    expectIdentical(*joined([&](const diff::LeafList* o) { return diff::principalCurvatures(*phi, true, o).second; }),
                    *diff::principalCurvatures(*phi).second, "k2");
}

TEST_F(TestDifferential, GradientStepAndGridProperties)
{
    const SphereLevelSet s = makeSphere(25.0);
    for (int step : {1, 2}) {
        const auto grad = diff::gradient(*s.grid, step);
        EXPECT_TRUE(grad->tree().hasSameTopology(s.grid->tree())) << "step " << step;
        EXPECT_EQ(grad->activeVoxelCount(), s.grid->activeVoxelCount());
        EXPECT_EQ(grad->transform(), s.grid->transform());
        EXPECT_EQ(grad->getName(), "gradient");
        EXPECT_EQ(grad->getVectorType(), openvdb::VEC_COVARIANT);
        EXPECT_TRUE(grad->isInWorldSpace());

        // voxels whose +/- step neighbours along each axis are all in the band
        auto in = s.grid->getConstAccessor();
        auto acc = grad->getConstAccessor();
        std::vector<double> err;
        for (auto it = s.grid->cbeginValueOn(); it; ++it) {
            const Coord ijk = it.getCoord();
            bool inside = true;
            for (int a = 0; a < 3 && inside; ++a) {
                Coord o(0);
                o[a] = step;
                inside = in.isValueOn(ijk + o) && in.isValueOn(ijk - o);
            }
            if (!inside) continue;
            const Vec3d d = s.grid->transform().indexToWorld(ijk) - s.center;
            err.push_back((Vec3d(acc.getValue(ijk)) - d / d.length()).length());
        }
        const Summary e = summarize(err);
        std::printf("sphere r=25 voxels, step %d: |gradient - normal| worst %.6f median %.6f over "
                    "%zu voxels with the stencil in the band\n", step, e.worst, e.median, e.count);
        EXPECT_GT(e.count, s.grid->activeVoxelCount() / 4);
        EXPECT_LE(e.worst, 0.01) << "step " << step;
    }
    // the magnitude grid: |gradient| on the same voxels
    const auto grad = diff::gradient(*s.grid, 1);
    const auto mag = diff::magnitude(*grad);
    EXPECT_EQ(mag->getName(), "gradient_magnitude");
    EXPECT_TRUE(mag->tree().hasSameTopology(grad->tree()));
    EXPECT_EQ(mag->transform(), grad->transform());
    auto gacc = grad->getConstAccessor();
    for (auto it = mag->cbeginValueOn(); it; ++it) {
        ASSERT_NEAR(*it, gacc.getValue(it.getCoord()).length(), 1e-6);
    }
}

TEST_F(TestDifferential, BadInputThrows)
{
    const SphereLevelSet s = makeSphere(10.0);
    EXPECT_THROW(diff::gradient(*s.grid, 0), openvdb::ValueError);
    EXPECT_THROW(diff::gradient(*s.grid, -1), openvdb::ValueError);
    EXPECT_NO_THROW(levelset::checkLevelSet(*s.grid, "sphere"));

    auto vec = openvdb::Vec3SGrid::create();
    vec->setGridClass(openvdb::GRID_LEVEL_SET);
    EXPECT_THROW(levelset::checkLevelSet(*vec, "vector"), ParamError);

    auto fog = s.grid->deepCopy();
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    EXPECT_THROW(levelset::checkLevelSet(*fog, "fog"), ParamError);

    auto unknown = s.grid->deepCopy();
    unknown->setGridClass(openvdb::GRID_UNKNOWN);
    EXPECT_THROW(levelset::checkLevelSet(*unknown, "unknown"), ParamError);

    auto stretched = s.grid->deepCopy();
    auto xform = openvdb::math::Transform::createLinearTransform(s.dx);
    xform->postScale(openvdb::Vec3d(1.0, 2.0, 1.0));
    stretched->setTransform(xform);
    EXPECT_THROW(levelset::checkLevelSet(*stretched, "stretched"), openvdb::ValueError);
    EXPECT_THROW(diff::gradient(*stretched, 1), openvdb::ValueError);
    EXPECT_THROW(diff::curvature(*stretched, diff::Curvature::Mean), openvdb::ValueError);
    EXPECT_THROW(diff::principalCurvatures(*stretched), openvdb::ValueError);

    // the messages name the grid and the fix
    try {
        levelset::checkLevelSet(*vec, "in.vdb: grid 'v'");
        ADD_FAILURE() << "no throw";
    } catch (const ParamError& e) {
        // The message names the grid and the fix; the parameter to change is the grid, which
        // the CLI names as --grid (tests/cli), never the library.
        const std::string what = e.what();
        EXPECT_NE(what.find("in.vdb: grid 'v'"), std::string::npos) << what;
        EXPECT_NE(what.find("choose"), std::string::npos) << what;
        EXPECT_EQ(what.find("--"), std::string::npos) << what;
        EXPECT_EQ(e.param(), "grid");
    }
}

TEST_F(TestDifferential, CompareGradientStatistics)
{
    {
        const double dx = 0.02;
        auto sphere = std::make_shared<implicit::Sphere>(Vec3d(0.013, -0.007, 0.021), 1.0);
        const auto phi = raster::rasterize(sphere, settings(dx));
        const auto c = diff::compareGradient(*sphere, *phi, *diff::gradient(*phi, 1), 1);
        for (const auto& [name, e] : {std::pair<std::string, diff::GradientErrors>{"band", c.band},
                                      {"interior", c.interior}}) {
            std::printf("sphere r=50 voxels, step 1, %s: angle mean %.4f median %.4f p95 %.4f "
                        "max %.4f deg; mean |grad| %.5f, magnitude error mean %.5f median %.5f "
                        "(%zu voxels, %zu skipped)\n", name.c_str(), e.angleDeg.mean,
                        e.angleDeg.median, e.angleDeg.p95, e.angleDeg.max, e.meanMagnitude,
                        e.magnitudeError.mean, e.magnitudeError.median, e.angleDeg.count,
                        e.skipped);
            EXPECT_EQ(e.skipped, 0u) << name;
            EXPECT_LT(e.angleDeg.median, 0.5) << name;
            EXPECT_LE(e.angleDeg.median, e.angleDeg.p95) << name;
            EXPECT_LE(e.angleDeg.p95, e.angleDeg.max) << name;
        }
        EXPECT_EQ(c.band.angleDeg.count, phi->activeVoxelCount());
        EXPECT_GT(c.interior.angleDeg.count, phi->activeVoxelCount() / 4);
        EXPECT_LT(c.interior.angleDeg.count, c.band.angleDeg.count);
        // where the stencil stays in the band; over the whole band the outer voxels read the
        // clamped background, which tilts their gradient by several degrees
        EXPECT_LT(c.interior.angleDeg.mean, 0.5);
        EXPECT_LT(c.band.angleDeg.mean, 2.0);
        // inside the stencil-safe voxels the gradient of a distance field has unit length
        EXPECT_NEAR(c.interior.meanMagnitude, 1.0, 0.001);
        EXPECT_LT(c.interior.magnitudeError.max, 0.01);
        EXPECT_NEAR(c.band.meanMagnitude, 1.0, 0.1);
    }
    {
        const RawEllipsoid e = makeRawEllipsoid(kRadii, kRotate, kShift);
        auto shape = std::make_shared<implicit::Quadric>(e.q);
        const auto phi = raster::rasterize(shape, settings(0.01));
        const auto c1 = diff::compareGradient(*shape, *phi, *diff::gradient(*phi, 1), 1);
        const auto c4 = diff::compareGradient(*shape, *phi, *diff::gradient(*phi, 4), 4);
        std::printf("ellipsoid dx 0.01, band: step 1 angle mean %.4f deg, magnitude error mean "
                    "%.5f; step 4 angle mean %.4f deg, magnitude error mean %.5f\n",
                    c1.band.angleDeg.mean, c1.band.magnitudeError.mean, c4.band.angleDeg.mean,
                    c4.band.magnitudeError.mean);
        EXPECT_GT(c4.band.angleDeg.mean, c1.band.angleDeg.mean);
        EXPECT_GT(c4.band.magnitudeError.mean, c1.band.magnitudeError.mean);
        // fewer voxels keep a +/- 4 stencil inside a band of half width 3 than a +/- 1 stencil
        EXPECT_LT(c4.interior.angleDeg.count, c1.interior.angleDeg.count);
    }
}
