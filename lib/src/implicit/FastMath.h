// SPDX-License-Identifier: Apache-2.0
// exp and log for the super-elliptic blend's loops (internal to lib/src/implicit): written out in
// plain arithmetic so that loops over points vectorize (libm's are calls), and the same function
// serves value() and the batches, so they agree bit for bit.
#pragma once

#include <cstdint>
#include <cstring>

namespace ivdb::implicit::detail {

inline double fromBits(std::int64_t b)
{
    double d;
    std::memcpy(&d, &b, sizeof(d));
    return d;
}

inline std::int64_t toBits(double d)
{
    std::int64_t b;
    std::memcpy(&b, &d, sizeof(b));
    return b;
}

// ln 2 in two parts: the high one has its low bits zero, so k * kLn2Hi is exact for |k| < 2^11.
inline constexpr double kLn2Hi = 6.93147180369123816490e-01;
inline constexpr double kLn2Lo = 1.90821492927058770002e-10;
inline constexpr double kLog2e = 1.44269504088896338700e+00;
/// Added to a double of magnitude below 2^51, rounds it to an integer held in the low bits.
inline constexpr double kRound = 6755399441055744.0; // 1.5 * 2^52

/// exp(x) for x <= 0 within 1 ulp (0 below -708, where exp leaves the normal doubles): x = k ln 2
/// + r with |r| <= ln(2)/2, exp(r) by its Taylor series to r^13 (the rest is below 1e-17
/// relative), times 2^k put into the exponent bits. The series is summed as 1 + (r + r^2 q(r)),
/// q's twelve terms in pairs (Estrin's scheme: c + c' r, then pairs of those times r^2, r^4):
/// six multiplies and adds deep instead of thirteen of each, for callers whose next step waits
/// on the result (the grid blend's iteration), and no slower in loops over points.
inline double expNonPositive(double x)
{
    const double xc = x < -708.0 ? -708.0 : x;
    const double shifted = xc * kLog2e + kRound;
    const double k = shifted - kRound;
    const std::int64_t ki = toBits(shifted) - toBits(kRound);
    const double r = (xc - k * kLn2Hi) - k * kLn2Lo;
    const double r2 = r * r, r4 = r2 * r2;
    // 1/n! for n = 2..13, in pairs.
    const double c23 = 0.5 + r * (1.0 / 6.0);
    const double c45 = 1.0 / 24.0 + r * (1.0 / 120.0);
    const double c67 = 1.0 / 720.0 + r * (1.0 / 5040.0);
    const double c89 = 1.0 / 40320.0 + r * (1.0 / 362880.0);
    const double c1011 = 1.0 / 3628800.0 + r * (1.0 / 39916800.0);
    const double c1213 = 1.0 / 479001600.0 + r * (1.0 / 6227020800.0);
    const double q = (c23 + r2 * c45) + r4 * ((c67 + r2 * c89) + r4 * (c1011 + r2 * c1213));
    const double e = 1.0 + (r + r2 * q);
    const double scale = fromBits(std::int64_t(std::uint64_t(ki + 1023) << 52));
    return x < -708.0 ? 0.0 : e * scale;
}

/// log(y) for a normal y > 0 within 2 ulp (NaN and +inf as they come): y = 2^k m with m in [sqrt(1/2), sqrt(2)), and
/// log(m) = 2 atanh(s), s = (m - 1) / (m + 1), |s| < 0.172, by its series to s^23 (the rest is
/// below 1e-18 relative).
inline double logPositive(double y)
{
    const std::int64_t bits = toBits(y);
    std::int64_t k = (bits >> 52) - 1023;
    double m = fromBits((bits & 0x000FFFFFFFFFFFFFLL) | 0x3FF0000000000000LL);
    const bool high = m > 1.4142135623730951;
    m = high ? 0.5 * m : m;
    k += high ? 1 : 0;
    const double s = (m - 1.0) / (m + 1.0), z = s * s;
    // t = sum of z^j / (2 j + 3), j = 0..10, in pairs as exp's series (Estrin's scheme).
    const double z2 = z * z, z4 = z2 * z2;
    const double t = ((1.0 / 3.0 + z * (1.0 / 5.0)) + z2 * (1.0 / 7.0 + z * (1.0 / 9.0))) +
                     z4 * (((1.0 / 11.0 + z * (1.0 / 13.0)) + z2 * (1.0 / 15.0 + z * (1.0 / 17.0))) +
                           z4 * ((1.0 / 19.0 + z * (1.0 / 21.0)) + z2 * (1.0 / 23.0)));
    // 2 s + 2 s^3 t': the leading term kept apart, so rounding the rest costs little.
    const double logm = 2.0 * s + 2.0 * s * (z * t);
    // k as a double through the same rounding constant (k is small).
    const double kd = fromBits(toBits(kRound) + k) - kRound;
    const double result = (kd * kLn2Hi + logm) + kd * kLn2Lo;
    return y - y == 0.0 ? result : y; // NaN stays NaN, +inf stays +inf
}

} // namespace ivdb::implicit::detail
