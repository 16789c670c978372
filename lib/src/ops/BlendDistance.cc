// SPDX-License-Identifier: Apache-2.0
#include "BlendDistance.h"

#include "../implicit/FastMath.h"

#include <algorithm>
#include <cmath>

namespace ivdb::ops::detail {

UnionKernel UnionKernel::inUnits(const implicit::BlendKernel& kernel, double unit)
{
    UnionKernel out;
    out.polynomial = kernel.kind == implicit::BlendKernel::Kind::Polynomial;
    out.p = kernel.p * unit;
    out.k = kernel.k / unit;
    return out;
}

namespace {

/// ln(1 + e) for e in [0, 1], to a few ulp, given u = 1 + e and @a r = 1 / u: the log of u,
/// corrected for the rounding of u (e - (u - 1) is exact), so small e keep their digits.
inline double log1p(double e, double u, double r)
{
    return implicit::detail::logPositive(u) + (e - (u - 1.0)) * r;
}

/// The super-elliptic iteration's range of logit w: e^-60 is far below any weight that
/// changes h.
constexpr double kTMax = 60.0;
/// A Newton step predicted to gain less than this (voxels, relative to 1 + |h|) is taken
/// without evaluating h where it lands.
constexpr double kAcceptGain = 1e-7;

/// h and its first two derivatives in the iteration's variable t (logit w for the
/// super-elliptic kernel, w for the smooth minimum).
struct Sample
{
    double t = 0.0, w = 0.5, h = 0.0, d1 = 0.0, d2 = 0.0, q = 1.0;
};


class SupportDistance
{
public:
    SupportDistance(const UnionKernel& kernel, double a, double b, double c)
        : mK(kernel), mInvP(kernel.polynomial ? 0.0 : 1.0 / kernel.p), mA(a), mB(b),
          mC(std::max(-1.0, std::min(1.0, c))) {}

    Sample at(double t) const
    {
        Sample s;
        s.t = t;
        double w, S, S1, S2, dw, d2w; // S(w), S'(w), S''(w); dw/dt, d2w/dt2
        if (mK.polynomial) {
            w = t;
            S = mK.k * w * (1.0 - w);
            S1 = mK.k * (1.0 - 2.0 * w);
            S2 = -2.0 * mK.k;
            dw = 1.0;
            d2w = 0.0;
        } else {
            // w = 1 / (1 + e^-t); ln w = -softplus(-t), ln(1 - w) = -softplus(t), all from
            // e = e^-|t| (the implicit blend's exp and log: no library calls), with one
            // division for w, 1 - w and the log's correction: r = 1 / (1 + e).
            const double e = implicit::detail::expNonPositive(-std::abs(t)), u = 1.0 + e;
            const double r = 1.0 / u, l = log1p(e, u, r);
            w = t >= 0.0 ? r : e * r;
            const double lnW = -(std::max(-t, 0.0) + l), ln1W = -(std::max(t, 0.0) + l);
            const double ww = w * (1.0 - w);
            S = -(w * lnW + (1.0 - w) * ln1W) * mInvP;
            S1 = -t * mInvP;
            S2 = -mInvP / std::max(ww, 1e-300);
            dw = ww;
            d2w = ww * (1.0 - 2.0 * w);
        }
        const double N = w * mA + (1.0 - w) * mB - S;
        const double N1 = mA - mB - S1, N2 = -S2;
        const double Q = 1.0 - 2.0 * (1.0 - mC) * w * (1.0 - w);
        const double Q1 = -2.0 * (1.0 - mC) * (1.0 - 2.0 * w), Q2 = 4.0 * (1.0 - mC);
        const double rq = 1.0 / std::sqrt(Q);
        const double G = N1 * Q - 0.5 * N * Q1;            // h' Q^(3/2)
        const double G1 = N2 * Q + 0.5 * N1 * Q1 - 0.5 * N * Q2;
        const double hw = G * rq * rq * rq;
        const double hww = G1 * rq * rq * rq - 1.5 * Q1 * G * rq * rq * rq * rq * rq;
        s.w = w;
        s.q = Q;
        s.h = N * rq;
        s.d1 = hw * dw;
        s.d2 = hww * dw * dw + hw * d2w;
        return s;
    }

    /// The least h from @a t0: Newton steps where h is convex, descent steps elsewhere, each
    /// halved until h decreases.
    Sample minimize(double t0) const
    {
        const double lo = mK.polynomial ? 0.0 : -kTMax, hi = mK.polynomial ? 1.0 : kTMax;
        const double maxStep = mK.polynomial ? 0.25 : 4.0;
        Sample s = at(std::max(lo, std::min(hi, t0)));
        for (int it = 0; it < 60; ++it) {
            double step = s.d2 > 0.0 ? -s.d1 / s.d2 : (s.d1 > 0.0 ? -maxStep : maxStep);
            // Where h is convex, Newton's step gains about d1^2 / (2 d2). Stop when that is
            // below 1e-10 voxel (a float distance of a few voxels holds about 2e-7).
            if (s.d2 > 0.0 && s.d1 * s.d1 < 2e-10 * s.d2 * (1.0 + std::abs(s.h))) break;
            // Below kAcceptGain, take the step's predicted least without evaluating h there:
            // h is quadratic that close (its error is third order in the step, ~1e-10 times
            // the gain), and the evaluation would only confirm it.
            if (s.d2 > 0.0 && s.d1 * s.d1 < 2.0 * kAcceptGain * s.d2 * (1.0 + std::abs(s.h))) {
                const double t = std::max(lo, std::min(hi, s.t + step));
                if (t == s.t + step) {
                    s.h += s.d1 * step + 0.5 * s.d2 * step * step;
                    s.t = t;
                    s.w = weightAt(t);
                    s.d1 = 0.0;
                    break;
                }
            }
            step = std::max(-maxStep, std::min(maxStep, step));
            bool moved = false;
            for (int half = 0; half < 30; ++half, step *= 0.5) {
                const double t = std::max(lo, std::min(hi, s.t + step));
                if (t == s.t) break;
                const Sample n = at(t);
                if (n.h <= s.h) {
                    moved = true;
                    s = n;
                    break;
                }
            }
            if (!moved) break;
        }
        return s;
    }

private:
    /// The weight w at the iteration's variable @a t.
    double weightAt(double t) const
    {
        if (mK.polynomial) return t;
        const double e = implicit::detail::expNonPositive(-std::abs(t)), r = 1.0 / (1.0 + e);
        return t >= 0.0 ? r : e * r;
    }

    UnionKernel mK;
    double mInvP; // 1 / p (super-elliptic)
    double mA, mB, mC;
};

/// The kernel's weight of a (as the iteration's variable: logit w, or w) at x, from the
/// difference of the terms @a bMinusA.
double kernelWeight(const UnionKernel& kernel, double bMinusA)
{
    return kernel.polynomial ? std::max(0.0, std::min(1.0, 0.5 + bMinusA / (2.0 * kernel.k)))
                             : kernel.p * bMinusA;
}

/// The blend at x, f, and its gradient g = w n_a + (1 - w) n_b: the weight (also as the
/// iteration's variable t) and q = |g|^2 = 1 - 2 (1 - c) w (1 - w).
struct AtX
{
    double t = 0.0, w = 0.5, f = 0.0, q = 1.0;
};

AtX blendAtX(const UnionKernel& kernel, double a, double b, double c)
{
    AtX x;
    x.t = kernelWeight(kernel, b - a);
    if (kernel.polynomial) {
        x.w = x.t;
        const double h = std::max(kernel.k - std::abs(a - b), 0.0) / kernel.k;
        x.f = std::min(a, b) - h * h * kernel.k * 0.25;
    } else {
        const double e = implicit::detail::expNonPositive(-std::abs(x.t)), u = 1.0 + e;
        const double r = 1.0 / u;
        x.w = x.t >= 0.0 ? r : e * r;
        x.f = std::min(a, b) - log1p(e, u, r) / kernel.p;
    }
    const double cc = std::max(-1.0, std::min(1.0, c));
    x.q = 1.0 - 2.0 * (1.0 - cc) * x.w * (1.0 - x.w);
    return x;
}

/// Where the iteration starts: the kernel's weight at the first-order foot point of x (@a x
/// the blend there), x - f g / q. That point changes b - a by -f (1 - c) (1 - 2 w) / q. The
/// least h is attained at the weight of the true foot point (the tangent plane there), so this
/// is near it. On the radius-400 pair it took the iteration's evaluations of h from 1.27 M to
/// 0.77 M (p = 1000) and from 2.08 M to 1.51 M (p = 320) against x's own weight, for the same
/// distances.
double startAtFoot(const UnionKernel& kernel, const AtX& x, double a, double b, double c)
{
    if (!(x.q > 0.05)) return x.t; // planes facing each other: no first-order foot point
    const double cc = std::max(-1.0, std::min(1.0, c));
    return kernelWeight(kernel, (b - a) - x.f * (1.0 - cc) * (1.0 - 2.0 * x.w) / x.q);
}

/// The answer from sample @a s of h: the distance, its weight, whether the planes could tell.
PlaneBlendDistance answer(const UnionKernel& kernel, const Sample& s, double a, double b)
{
    PlaneBlendDistance out;
    out.distance = s.h;
    out.weight = s.w;
    out.start = s.t;
    // Planes facing each other (c near -1) leave Q near 0 where both weigh alike: the
    // linearization says nothing there.
    out.ok = std::isfinite(s.h) && s.q > 0.05;
    // The ends are tangent planes too (the smooth minimum's flat parts; the super-elliptic
    // blend's asymptotes): a descent that stopped in another valley is not the least.
    const double aEnd = kernel.polynomial ? 1.0 : kTMax, bEnd = kernel.polynomial ? 0.0 : -kTMax;
    if (a < out.distance) out.distance = a, out.weight = 1.0, out.start = aEnd;
    if (b < out.distance) out.distance = b, out.weight = 0.0, out.start = bEnd;
    return out;
}

} // namespace

PlaneBlendDistance planeBlendEstimate(const UnionKernel& kernel, double a, double b, double c)
{
    const AtX x = blendAtX(kernel, a, b, c);
    PlaneBlendDistance out;
    out.distance = x.f / std::sqrt(std::max(x.q, 0.0));
    out.weight = x.w;
    out.blend = x.f;
    out.start = startAtFoot(kernel, x, a, b, c);
    out.ok = std::isfinite(out.distance) && x.q > 0.05;
    return out;
}

PlaneBlendDistance planeBlendDistance(const UnionKernel& kernel, double a, double b, double c,
                                      double start)
{
    const SupportDistance support(kernel, a, b, c);
    // Start at @a start, else at the kernel's weight at x's first-order foot point.
    const double t0 = std::isnan(start) ? startAtFoot(kernel, blendAtX(kernel, a, b, c), a, b, c)
                                        : start;
    return answer(kernel, support.minimize(t0), a, b);
}

double blendOffset(const UnionKernel& kernel, double b)
{
    if (kernel.polynomial) return 0.0;
    return -std::log1p(-implicit::detail::expNonPositive(-kernel.p * std::max(b, 0.0))) / kernel.p;
}

} // namespace ivdb::ops::detail
