// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <algorithm>
#include <cmath>

namespace ivdb::implicit {

/// @brief A closed interval [lo, hi] of reals, for conservative bounds of a function over a box.
/// @details Every operation returns an interval that contains every value the exact operation can
/// take on its arguments (no outward rounding: the rasterizer adds a safety margin instead).
struct Interval
{
    double lo = 0.0, hi = 0.0;

    Interval() = default;
    Interval(double l, double h): lo(l), hi(h) {}
    explicit Interval(double v): lo(v), hi(v) {}

    bool contains(double v) const { return lo <= v && v <= hi; }
    double width() const { return hi - lo; }
};

inline Interval operator+(const Interval& a, const Interval& b) { return {a.lo + b.lo, a.hi + b.hi}; }
inline Interval operator-(const Interval& a, const Interval& b) { return {a.lo - b.hi, a.hi - b.lo}; }
inline Interval operator-(const Interval& a) { return {-a.hi, -a.lo}; }
inline Interval operator+(const Interval& a, double s) { return {a.lo + s, a.hi + s}; }
inline Interval operator*(const Interval& a, double s)
{
    return s >= 0.0 ? Interval{a.lo * s, a.hi * s} : Interval{a.hi * s, a.lo * s};
}
inline Interval operator*(const Interval& a, const Interval& b)
{
    const double p[4] = {a.lo * b.lo, a.lo * b.hi, a.hi * b.lo, a.hi * b.hi};
    return {std::min(std::min(p[0], p[1]), std::min(p[2], p[3])),
            std::max(std::max(p[0], p[1]), std::max(p[2], p[3]))};
}
/// Tight square: [0, max^2] when the interval straddles zero.
inline Interval sqr(const Interval& a)
{
    if (a.lo >= 0.0) return {a.lo * a.lo, a.hi * a.hi};
    if (a.hi <= 0.0) return {a.hi * a.hi, a.lo * a.lo};
    return {0.0, std::max(a.lo * a.lo, a.hi * a.hi)};
}
/// Square root of the non-negative part.
inline Interval sqrt(const Interval& a)
{
    return {std::sqrt(std::max(a.lo, 0.0)), std::sqrt(std::max(a.hi, 0.0))};
}
inline Interval min(const Interval& a, const Interval& b)
{
    return {std::min(a.lo, b.lo), std::min(a.hi, b.hi)};
}
inline Interval max(const Interval& a, const Interval& b)
{
    return {std::max(a.lo, b.lo), std::max(a.hi, b.hi)};
}

} // namespace ivdb::implicit
