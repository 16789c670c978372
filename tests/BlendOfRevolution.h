// SPDX-License-Identifier: Apache-2.0
// An independent reference for the distance to the blend of two spheres (shared by the grid
// blend's and the rasterizer's tests).
#pragma once

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <utility>
#include <vector>

namespace ivdb::test {

/// The signed distance to the blend of two spheres of radius @a radius centred at (+-@a c, 0, 0),
/// a surface of revolution about the x axis: the distance, in the meridian half-plane (x, r),
/// to the zero set of @a blend (of the two spheres' distances), sampled along 20,001 rays from
/// the origin (which lies inside) by bisection and taken as a polyline.
class BlendOfRevolution
{
public:
    BlendOfRevolution(std::function<double(double, double)> blend, double c, double radius)
        : mBlend(std::move(blend)), mC(c), mRadius(radius)
    {
        const int n = 20001;
        mX.resize(n);
        mR.resize(n);
        for (int i = 0; i < n; ++i) {
            const double t = M_PI * i / (n - 1), ct = std::cos(t), st = std::sin(t);
            double lo = 0.0, hi = 2.0 * (c + radius);
            for (int k = 0; k < 64; ++k) {
                const double mid = 0.5 * (lo + hi);
                (value(mid * ct, mid * st) < 0.0 ? lo : hi) = mid;
            }
            mX[i] = lo * ct;
            mR[i] = lo * st;
        }
    }

    double value(double x, double r) const
    {
        return mBlend(std::hypot(x + mC, r) - mRadius, std::hypot(x - mC, r) - mRadius);
    }

    /// The signed distance from (@a x, @a r), searching the polyline within @a window radians of
    /// the point's own angle.
    double distance(double x, double r, double window) const
    {
        const int n = int(mX.size());
        const double t = std::atan2(r, x);
        const int lo = std::max(0, int((t - window) / M_PI * (n - 1)));
        const int hi = std::min(n - 1, int((t + window) / M_PI * (n - 1)) + 1);
        double best = std::numeric_limits<double>::infinity();
        for (int i = lo; i < hi; ++i) {
            // Point to segment.
            const double ex = mX[i + 1] - mX[i], er = mR[i + 1] - mR[i];
            const double len2 = ex * ex + er * er;
            double u = len2 > 0.0 ? ((x - mX[i]) * ex + (r - mR[i]) * er) / len2 : 0.0;
            u = std::max(0.0, std::min(1.0, u));
            best = std::min(best, std::hypot(x - mX[i] - u * ex, r - mR[i] - u * er));
        }
        return value(x, r) < 0.0 ? -best : best;
    }

private:
    std::function<double(double, double)> mBlend;
    double mC, mRadius;
    std::vector<double> mX, mR;
};

} // namespace ivdb::test
