// Grid blend (ops::blend): against the analytic blended surface of two exact spheres.
#include <ivdb/implicit/Blend.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/ops/Blend.h>
#include <ivdb/raster/Rasterize.h>

#include <openvdb/math/Operators.h>
#include <openvdb/tools/Interpolation.h>

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using namespace ivdb;
using implicit::Vec3d;

class TestBlendGrid: public ::testing::Test
{
protected:
    void SetUp() override { openvdb::initialize(); }

    static openvdb::FloatGrid::ConstPtr sphere(const Vec3d& c, double dx)
    {
        raster::RasterSettings s;
        s.voxelSize = dx;
        return raster::rasterize(std::make_shared<implicit::Sphere>(c, 0.6), s);
    }
};

TEST_F(TestBlendGrid, MatchesAnalyticBlendedSurface)
{
    const Vec3d ca(-0.3437, 0.0123, -0.0071), cb(0.3512, -0.0089, 0.0043);
    // Coarser voxels for smaller p keep the extended bands (ln(1/(p tol))/p) small.
    for (auto [p, dx] : {std::pair<double, double>{50.0, 0.01}, {10.0, 0.02}, {4.0, 0.04}}) {
        auto a = sphere(ca, dx), b = sphere(cb, dx);
        ops::BlendSettings s;
        s.p = p;
        std::vector<std::string> notes;
        auto g = ops::blend(ops::CsgOp::Union, {a, b}, s, &notes);
        ASSERT_EQ(notes.size(), 1u);
        EXPECT_EQ(g->getName(), "surface");
        EXPECT_EQ(g->getGridClass(), openvdb::GRID_LEVEL_SET);
        EXPECT_FLOAT_EQ(g->background(), a->background());

        const implicit::Blend exact(implicit::Csg::Op::Union, p,
            {std::make_shared<implicit::Sphere>(ca, 0.6), std::make_shared<implicit::Sphere>(cb, 0.6)});
        openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> sampler(*g);
        std::mt19937 rng(11);
        std::normal_distribution<double> n(0.0, 1.0);
        double worst = 0.0;
        for (int i = 0; i < 1000; ++i) {
            Vec3d d(n(rng), n(rng), n(rng));
            d.normalize();
            double lo = 0.0, hi = 2.0; // bisection for the surface along the ray from the origin
            for (int k = 0; k < 60; ++k) {
                const double mid = 0.5 * (lo + hi);
                (exact.value(d * mid) < 0.0 ? lo : hi) = mid;
            }
            worst = std::max(worst, std::abs(double(sampler.wsSample(d * lo))) / dx);
        }
        size_t near = 0, unit = 0;
        auto acc = g->getConstAccessor();
        for (auto it = g->cbeginValueOn(); it; ++it) {
            if (std::abs(*it) >= 1.5 * dx) continue;
            ++near;
            const double len = openvdb::math::ISGradient<openvdb::math::CD_2ND>::result(
                                   acc, it.getCoord()).length() / dx;
            if (len >= 0.9 && len <= 1.1) ++unit;
        }
        std::printf("grid blend p = %g (voxel %g): worst |phi| at 1000 analytic surface points "
                    "%.4f voxel, |grad phi| in [0.9, 1.1] at %.2f%%\n",
                    p, dx, worst, 100.0 * double(unit) / double(near));
        EXPECT_LT(worst, 0.25) << "p = " << p;
        EXPECT_GE(double(unit) / double(near), 0.95) << "p = " << p;
    }
}

TEST_F(TestBlendGrid, RefusesWhatDoesNotFitAndBadSettings)
{
    auto a = sphere(Vec3d(-0.35, 0, 0), 0.02), b = sphere(Vec3d(0.35, 0, 0), 0.02);
    ops::BlendSettings s;
    s.p = 0.5;
    s.memoryLimit = 100u << 20;
    try {
        ops::blend(ops::CsgOp::Union, {a, b}, s);
        FAIL() << "a blend whose extension does not fit must be refused";
    } catch (const openvdb::RuntimeError& e) {
        EXPECT_NE(std::string(e.what()).find("scene-level blend"), std::string::npos) << e.what();
    }
    s.memoryLimit = 0;
    for (double p : {0.0, -1.0, 0.05, 2000.0, std::nan("")}) {
        s.p = p;
        EXPECT_THROW(ops::blend(ops::CsgOp::Union, {a, b}, s), openvdb::ValueError) << p;
    }
    s.p = 50.0;
    EXPECT_THROW(ops::blend(ops::CsgOp::Union, {a}, s), openvdb::ValueError);
}

TEST_F(TestBlendGrid, HighPApproachesSharpUnion)
{
    const double dx = 0.01;
    auto a = sphere(Vec3d(-0.3437, 0.0123, 0), dx), b = sphere(Vec3d(0.3512, 0, 0.0043), dx);
    ops::BlendSettings s;
    s.p = 1000.0;
    auto g = ops::blend(ops::CsgOp::Union, {a, b}, s);
    openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> sampler(*g);
    std::mt19937 rng(5);
    std::normal_distribution<double> n(0.0, 1.0);
    double worst = 0.0;
    int used = 0;
    for (int i = 0; i < 3000 && used < 1000; ++i) {
        Vec3d d(n(rng), n(rng), n(rng));
        d.normalize();
        const Vec3d c = i % 2 ? Vec3d(-0.3437, 0.0123, 0) : Vec3d(0.3512, 0, 0.0043);
        const Vec3d o = i % 2 ? Vec3d(0.3512, 0, 0.0043) : Vec3d(-0.3437, 0.0123, 0);
        const Vec3d q = c + d * 0.6;
        if ((q - o).length() < 0.6 + 3 * dx) continue; // away from the crease (sharp there)
        ++used;
        worst = std::max(worst, std::abs(double(sampler.wsSample(q))) / dx);
    }
    std::printf("grid blend p = 1000: worst |phi| at %d sharp-union surface points %.4f voxel\n",
                used, worst);
    EXPECT_GE(used, 1000);
    EXPECT_LT(worst, 0.1);
}
