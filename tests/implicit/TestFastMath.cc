// SPDX-License-Identifier: Apache-2.0
// The blend's own exp and log (lib/src/implicit/FastMath.h, internal: loops over points with them
// vectorize) against libm's, in units in the last place.
#include "../../lib/src/implicit/FastMath.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

using namespace ivdb::implicit::detail;

namespace {

/// |a - b| in units of b's last place.
double ulps(double a, double b)
{
    if (a == b) return 0.0;
    const double ulp = std::nextafter(std::abs(b), std::numeric_limits<double>::infinity()) - std::abs(b);
    return std::abs(a - b) / ulp;
}

} // namespace

TEST(TestFastMath, ExpIsWithinOneUlpOfLibm)
{
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> wide(-708.0, 0.0), near(-1.0, 0.0);
    double worst = 0.0;
    for (int i = 0; i < 2000000; ++i) {
        const double x = i % 2 ? wide(rng) : near(rng);
        worst = std::max(worst, ulps(expNonPositive(x), std::exp(x)));
    }
    for (double x : {0.0, -0.0, -1e-300, -0.5 * std::log(2.0), -std::log(2.0), -707.9, -708.0}) {
        worst = std::max(worst, ulps(expNonPositive(x), std::exp(x)));
    }
    EXPECT_LE(worst, 1.0);
    EXPECT_EQ(expNonPositive(0.0), 1.0);
    // Below -708 the result leaves the normal doubles: 0 (next to a sum of at least 1).
    EXPECT_EQ(expNonPositive(-708.5), 0.0);
    EXPECT_EQ(expNonPositive(-1e6), 0.0);
    EXPECT_TRUE(std::isnan(expNonPositive(std::numeric_limits<double>::quiet_NaN())));
}

TEST(TestFastMath, LogIsWithinTwoUlpOfLibm)
{
    std::mt19937_64 rng(6);
    std::uniform_real_distribution<double> sums(1.0, 64.0), exponent(-300.0, 300.0);
    double worst = 0.0;
    for (int i = 0; i < 2000000; ++i) {
        const double y = i % 2 ? sums(rng) : std::pow(10.0, exponent(rng));
        worst = std::max(worst, ulps(logPositive(y), std::log(y)));
    }
    for (double y : {1.0, 2.0, std::sqrt(2.0), std::nextafter(std::sqrt(2.0), 2.0), 64.0,
                     1.0 + 1e-15, std::numeric_limits<double>::min(), 1e308}) {
        worst = std::max(worst, ulps(logPositive(y), std::log(y)));
    }
    EXPECT_LE(worst, 2.0);
    EXPECT_EQ(logPositive(1.0), 0.0);
    EXPECT_TRUE(std::isnan(logPositive(std::numeric_limits<double>::quiet_NaN())));
    EXPECT_EQ(logPositive(std::numeric_limits<double>::infinity()),
              std::numeric_limits<double>::infinity());
}
