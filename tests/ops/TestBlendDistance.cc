// SPDX-License-Identifier: Apache-2.0
// The distance to the blend of two planes (lib/src/ops/BlendDistance.h, internal) against a
// brute-force search: the nearest zero of the blend along rays from the point.
#include "../../lib/src/ops/BlendDistance.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

using namespace ivdb::ops::detail;

namespace {

constexpr double kPi = 3.14159265358979323846;

/// The union blend of two values, straight from its formula.
double unionBlend(const UnionKernel& k, double a, double b)
{
    if (k.polynomial) {
        const double h = std::max(k.k - std::abs(a - b), 0.0) / k.k;
        return std::min(a, b) - h * h * k.k * 0.25;
    }
    return std::min(a, b) - std::log1p(std::exp(-k.p * std::abs(a - b))) / k.p;
}

/// Two planes in the plane of their normals: a(y) = y.x + a0, b(y) = y . (cos t, sin t) + b0, so
/// that at y = 0 they are a0 and b0. The signed distance from the origin to the blend's zero set:
/// the nearest zero along rays (a fine scan, bisection), the rays' angle refined by golden section.
class BruteForce
{
public:
    BruteForce(const UnionKernel& k, double angle, double a0, double b0)
        : mK(k), mC(std::cos(angle)), mS(std::sin(angle)), mA(a0), mB(b0) {}

    double distance() const
    {
        const double sign = value(0.0, 0.0) < 0.0 ? -1.0 : 1.0;
        const int coarse = 720;
        double best = std::numeric_limits<double>::infinity(), bestAngle = 0.0;
        for (int i = 0; i < coarse; ++i) {
            const double t = 2.0 * kPi * i / coarse, r = rootAlong(t);
            if (r < best) best = r, bestAngle = t;
        }
        double lo = bestAngle - 4.0 * kPi / coarse, hi = bestAngle + 4.0 * kPi / coarse;
        const double g = (std::sqrt(5.0) - 1.0) / 2.0;
        for (int it = 0; it < 60; ++it) {
            const double m1 = hi - g * (hi - lo), m2 = lo + g * (hi - lo);
            if (rootAlong(m1) < rootAlong(m2)) hi = m2;
            else lo = m1;
        }
        return sign * std::min(best, rootAlong(0.5 * (lo + hi)));
    }

private:
    double value(double x, double y) const
    {
        return unionBlend(mK, x + mA, x * mC + y * mS + mB);
    }

    /// The first zero along the ray at angle @a t (infinity if none within 20).
    double rootAlong(double t) const
    {
        const double dx = std::cos(t), dy = std::sin(t);
        const double v0 = value(0.0, 0.0);
        double prev = 0.0;
        for (double r = 0.01; r <= 20.0; r += 0.01) {
            if ((value(r * dx, r * dy) < 0.0) != (v0 < 0.0)) {
                double lo = prev, hi = r;
                for (int it = 0; it < 60; ++it) {
                    const double mid = 0.5 * (lo + hi);
                    if ((value(mid * dx, mid * dy) < 0.0) != (v0 < 0.0)) hi = mid;
                    else lo = mid;
                }
                return 0.5 * (lo + hi);
            }
            prev = r;
        }
        return std::numeric_limits<double>::infinity();
    }

    UnionKernel mK;
    double mC, mS, mA, mB;
};

} // namespace

TEST(TestBlendDistance, EqualsTheNearestZeroOfTheBlendOfTwoPlanes)
{
    UnionKernel kernels[6];
    const double ps[3] = {0.4, 1.5, 6.0};
    const double ks[3] = {1.0, 4.0, 12.0};
    for (int i = 0; i < 3; ++i) {
        kernels[i].p = ps[i];
        kernels[3 + i].polynomial = true;
        kernels[3 + i].k = ks[i];
    }
    int checked = 0, refused = 0;
    double worst = 0.0;
#ifdef IVDB_SANITIZED
    // Sanitized builds run 10-20x slower: every kernel, three angles.
    const std::vector<double> kAngles{15.0, 90.0, 165.0};
#else
    const std::vector<double> kAngles{15.0, 50.0, 90.0, 130.0, 165.0};
#endif
    for (const UnionKernel& k : kernels) {
        for (const double degrees : kAngles) {
            const double angle = degrees * kPi / 180.0;
            for (double a = -3.0; a <= 3.01; a += 1.5) {
                for (double b = -3.0; b <= 3.01; b += 1.25) {
                    const PlaneBlendDistance d = planeBlendDistance(k, a, b, std::cos(angle));
                    if (!d.ok) {
                        // Only planes that nearly face each other (165 degrees apart) are refused.
                        EXPECT_GT(degrees, 150.0) << a << " " << b;
                        ++refused;
                        continue;
                    }
                    const double ref = BruteForce(k, angle, a, b).distance();
                    worst = std::max(worst, std::abs(d.distance - ref));
                    ASSERT_NEAR(d.distance, ref, 1e-6)
                        << (k.polynomial ? "k " : "p ") << (k.polynomial ? k.k : k.p) << ", "
                        << degrees << " degrees, a " << a << ", b " << b;
                    ++checked;
                }
            }
        }
    }
#ifdef IVDB_SANITIZED
    EXPECT_GT(checked, 300);
#else
    EXPECT_GT(checked, 600);
#endif
    std::printf("worst difference %.2e over %d points, %d refused\n", worst, checked, refused);
}

// The first-order estimate, which the grid blend uses to pick the planes of the voxel near the
// nearest point before solving: the blend at x over the length of its gradient, with the
// gradient's weight, from the formulas above.
TEST(TestBlendDistance, FirstOrderEstimateIsTheBlendOverItsGradient)
{
    UnionKernel kernels[6];
    const double ps[3] = {0.4, 1.5, 6.0};
    const double ks[3] = {1.0, 4.0, 12.0};
    for (int i = 0; i < 3; ++i) {
        kernels[i].p = ps[i];
        kernels[3 + i].polynomial = true;
        kernels[3 + i].k = ks[i];
    }
    int checked = 0;
    double worstFoot = 0.0, worstRestart = 0.0;
    for (const UnionKernel& k : kernels) {
        for (const double degrees : {15.0, 50.0, 90.0, 130.0}) {
            const double c = std::cos(degrees * kPi / 180.0), sn = std::sin(degrees * kPi / 180.0);
            for (double a = -3.0; a <= 3.01; a += 0.25) {
                for (double b = -3.0; b <= 3.01; b += 0.25) {
                    // The weight of a in the blend's gradient: dU/da.
                    const double w = k.polynomial
                        ? std::clamp(0.5 + (b - a) / (2.0 * k.k), 0.0, 1.0)
                        : 1.0 / (1.0 + std::exp(-k.p * (b - a)));
                    const double g = std::sqrt(1.0 - 2.0 * (1.0 - c) * w * (1.0 - w));
                    const PlaneBlendDistance e = planeBlendEstimate(k, a, b, c);
                    ASSERT_TRUE(e.ok);
                    ASSERT_NEAR(e.weight, w, 1e-12) << degrees << " " << a << " " << b;
                    ASSERT_NEAR(e.distance, unionBlend(k, a, b) / g, 1e-12)
                        << (k.polynomial ? "k " : "p ") << (k.polynomial ? k.k : k.p) << ", "
                        << degrees << " degrees, a " << a << ", b " << b;
                    // How far its foot point x - (distance / |g|) g is from the exact one (for
                    // the record: it costs only steps).
                    const PlaneBlendDistance d = planeBlendDistance(k, a, b, c);
                    // The estimate's start is the default one, so starting there is the same
                    // iteration. The answer's start is its weight as the iteration's variable,
                    // and from there the iteration stays at the least, within the 1e-6 it is
                    // held to against the rays (above).
                    const PlaneBlendDistance again = planeBlendDistance(k, a, b, c, e.start);
                    ASSERT_EQ(again.distance, d.distance) << degrees << " " << a << " " << b;
                    ASSERT_EQ(again.weight, d.weight);
                    const double atStart =
                        k.polynomial ? d.start : 1.0 / (1.0 + std::exp(-d.start));
                    ASSERT_NEAR(atStart, d.weight, 1e-12) << degrees << " " << a << " " << b;
                    const double restart = planeBlendDistance(k, a, b, c, d.start).distance;
                    ASSERT_NEAR(restart, d.distance, 1e-6) << degrees << " " << a << " " << b;
                    worstRestart = std::max(worstRestart, std::abs(restart - d.distance));
                    auto foot = [&](const PlaneBlendDistance& r, double out[2]) {
                        const double gx = r.weight + (1.0 - r.weight) * c, gy = (1.0 - r.weight) * sn;
                        const double len = std::hypot(gx, gy);
                        out[0] = -r.distance / len * gx;
                        out[1] = -r.distance / len * gy;
                    };
                    double fd[2], fe[2];
                    foot(d, fd);
                    foot(e, fe);
                    if (std::abs(d.distance) <= 1.0) {
                        worstFoot = std::max(worstFoot, std::hypot(fd[0] - fe[0], fd[1] - fe[1]));
                    }
                    ++checked;
                }
            }
        }
    }
    EXPECT_EQ(checked, 6 * 4 * 25 * 25);
    std::printf("%d points; within 1 of the surface the first-order foot point is up to %.3f "
                "from the nearest point; restarted at its answer, the iteration moves by up to "
                "%.1e\n", checked, worstFoot, worstRestart);
}

// The grid blend's short cut inside (lib/src/ops/Blend.cc, localBlend()): from a point s inside
// the deciding plane a, where the other term at a's nearest point, b*, still leads by the lead
// rule's margin (the reach at the default tolerance of 0.05 voxel, the swell and a voxel), the
// distance is -s less blendOffset(b*). Against the distance to the blend of the two planes
// (above: within 1e-6 of the rays' search), and blendOffset() against the blend's formula.
TEST(TestBlendDistance, InsideWhereOneTermWeighsAllTheOffsetIsTheDistance)
{
    UnionKernel kernels[5];
    const double ps[3] = {0.8, 2.5, 6.0}; // p = 320 and 1000 on the benchmarks' voxel, and sharper
    const double ks[2] = {1.0, 4.0};
    for (int i = 0; i < 3; ++i) kernels[i].p = ps[i];
    for (int i = 0; i < 2; ++i) {
        kernels[3 + i].polynomial = true;
        kernels[3 + i].k = ks[i];
    }
    int checked = 0;
    double worst = 0.0;
    for (const UnionKernel& k : kernels) {
        const double lead = k.polynomial
            ? k.k + k.k / 4.0 + 1.0
            : std::log(1.0 / (k.p * 0.05)) / k.p + std::log(2.0) / k.p + 1.0;
        for (const double degrees : {15.0, 50.0, 90.0, 130.0}) {
            const double c = std::cos(degrees * kPi / 180.0);
            for (double s = 0.25; s <= 3.01; s += 0.25) {
                for (double bStar = lead; bStar <= lead + 3.01; bStar += 0.5) {
                    const double offset = blendOffset(k, bStar);
                    // The blend's surface: U(offset, b*) = 0.
                    ASSERT_NEAR(unionBlend(k, offset, bStar), 0.0, 1e-14) << bStar;
                    const double b = bStar - s * c; // b at x, s from a's surface
                    const PlaneBlendDistance d = planeBlendDistance(k, -s, b, c);
                    ASSERT_TRUE(d.ok);
                    const double shortCut = -s - offset;
                    worst = std::max(worst, std::abs(shortCut - d.distance));
                    ASSERT_NEAR(shortCut, d.distance, 2e-4)
                        << (k.polynomial ? "k " : "p ") << (k.polynomial ? k.k : k.p) << ", "
                        << degrees << " degrees, s " << s << ", b* " << bStar;
                    ++checked;
                }
            }
        }
        // A spot check against the rays themselves, at the rule's edge: s = 2, 60 degrees.
        const double rays = BruteForce(k, kPi / 3.0, -2.0, lead - 2.0 * 0.5).distance();
        EXPECT_NEAR(-2.0 - blendOffset(k, lead), rays, 2e-4);
    }
    EXPECT_EQ(checked, 5 * 4 * 12 * 7);
    std::printf("%d points; the short cut is within %.1e of the distance\n", checked, worst);
}
