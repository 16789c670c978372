// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/Blend.h>

#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <openvdb/Exceptions.h>

#include "../util/Simd.h"
#include "Children.h"
#include "FastMath.h"
#include "Scratch.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace ivdb::implicit {

namespace {

using detail::Scratch;

/// exp(s p (t - e)) for a term t and the extreme term e: exactly 1 for e itself (exp(0)),
/// without the call.
inline double superEllipticTerm(double s, double p, double t, double e)
{
    return t == e ? 1.0 : detail::expNonPositive(s * p * (t - e));
}

/// The super-elliptic blend over a batch of @a n points: @a terms term-major (@a m rows of n).
/// Writes the values into @a out and the weights d f / d t into @a w (m rows of n), either null.
/// Points innermost (n <= MaxPoints), so the loops vectorize. The one definition of the
/// kernel's arithmetic: single points (value(), gradient(), the grid blend) are batches of one,
/// so every path gives the same bits.
template<std::size_t MaxPoints>
IVDB_CLONE_INLINE void superEllipticPoints(CsgOp op, double p, const double* terms, std::size_t m,
                                std::size_t n, double* out, double* w)
{
    // s = -1 for a union (a soft min), +1 for an intersection or difference (a soft max):
    // f = s (1/p) ln sum exp(s p t_i) = e + s (1/p) ln sum exp(s p (t_i - e)), e the extreme term,
    // so every exponent is <= 0 and the largest is exactly 0: no overflow, the sum is >= 1.
    const double s = op == CsgOp::Union ? -1.0 : 1.0, invP = 1.0 / p;
    double e[MaxPoints], sum[MaxPoints];
    if (m == 2) {
        // Two terms, the common case: one exponential, of the other term; the extreme's is
        // exactly 1 (as is exp(0) for equal terms), so these are the general loop's bits.
        const double* t1 = terms + n;
        double x[MaxPoints];
        for (std::size_t i = 0; i < n; ++i) {
            // Both terms loaded, then selected (a select of the two loads was compiled to a
            // gather from the chosen addresses, a sixth of this loop's time).
            const double a = terms[i], b = t1[i];
            const bool firstLeads = s < 0.0 ? a <= b : a >= b;
            e[i] = firstLeads ? a : b;
            const double other = firstLeads ? b : a;
            x[i] = detail::expNonPositive(s * p * (other - e[i]));
            sum[i] = 1.0 + x[i];
        }
        if (out) {
            for (std::size_t i = 0; i < n; ++i) out[i] = e[i] + s * detail::logPositive(sum[i]) * invP;
        }
        if (w) {
            for (std::size_t i = 0; i < n; ++i) {
                const bool firstLeads = e[i] == terms[i];
                const double inv = 1.0 / sum[i];
                w[i] = firstLeads ? inv : x[i] * inv;
                w[n + i] = firstLeads ? x[i] * inv : inv;
            }
        }
        return;
    }
    for (std::size_t i = 0; i < n; ++i) e[i] = terms[i];
    for (std::size_t c = 1; c < m; ++c) {
        const double* t = terms + c * n;
        if (s < 0.0) {
            for (std::size_t i = 0; i < n; ++i) e[i] = std::min(e[i], t[i]);
        } else {
            for (std::size_t i = 0; i < n; ++i) e[i] = std::max(e[i], t[i]);
        }
    }
    for (std::size_t i = 0; i < n; ++i) sum[i] = 0.0;
    for (std::size_t c = 0; c < m; ++c) {
        const double* t = terms + c * n;
        if (w) {
            double* wc = w + c * n;
            for (std::size_t i = 0; i < n; ++i) {
                wc[i] = superEllipticTerm(s, p, t[i], e[i]);
                sum[i] += wc[i];
            }
        } else {
            for (std::size_t i = 0; i < n; ++i) sum[i] += superEllipticTerm(s, p, t[i], e[i]);
        }
    }
    if (out) {
        for (std::size_t i = 0; i < n; ++i) out[i] = e[i] + s * detail::logPositive(sum[i]) * invP;
    }
    if (w) {
        double inv[MaxPoints];
        for (std::size_t i = 0; i < n; ++i) inv[i] = 1.0 / sum[i];
        for (std::size_t c = 0; c < m; ++c) {
            double* wc = w + c * n;
            for (std::size_t i = 0; i < n; ++i) wc[i] *= inv[i];
        }
    }
}

/// superEllipticPoints() for batches, compiled for SSE2 and AVX2 (single points call it inline,
/// as batches of one).
IVDB_VECTOR_CLONES
void superEllipticBatch(CsgOp op, double p, const double* terms, std::size_t m, std::size_t n,
                        double* out, double* w)
{
    superEllipticPoints<kMaxBatch>(op, p, terms, m, n, out, w);
}

/// The gradients sum_c (+/-) w_c grad f_c over a batch: @a cg holds each child's gradients
/// (3 rows of n per child), @a w the weights; the children a difference subtracts count negated.
/// Gradient()'s sums, in its order (the same bits from every vector width: no fused
/// multiply-adds, lib/src/util/Simd.h).
IVDB_VECTOR_CLONES
void weightedGradients(bool difference, const double* __restrict cg, const double* __restrict w,
                       std::size_t m, std::size_t n, double* __restrict gx,
                       double* __restrict gy, double* __restrict gz)
{
    for (std::size_t i = 0; i < n; ++i) gx[i] = gy[i] = gz[i] = 0.0;
    for (std::size_t c = 0; c < m; ++c) {
        const double* g = cg + 3 * c * n;
        const double* wc = w + c * n;
        const double sign = difference && c > 0 ? -1.0 : 1.0;
        for (std::size_t i = 0; i < n; ++i) {
            const double k = sign * wc[i];
            gx[i] += g[i] * k;
            gy[i] += g[n + i] * k;
            gz[i] += g[2 * n + i] * k;
        }
    }
}

/// One step of the smooth fold: the smooth min (union) or max (intersection, difference) of
/// @a a and @a b, with d/da in @a da and d/db in @a db.
double smoothStep(CsgOp op, double a, double b, double k, double& da, double& db)
{
    // max(a, b) = -min(-a, -b); the derivatives of min at (-a, -b) are those of max at (a, b).
    const double s = op == CsgOp::Union ? 1.0 : -1.0;
    const double sa = s * a, sb = s * b;
    const double h = std::max(k - std::abs(sa - sb), 0.0) / k;
    const bool aLeads = sa <= sb;
    da = aLeads ? 1.0 - 0.5 * h : 0.5 * h;
    db = 1.0 - da;
    return s * smoothMin(sa, sb, k);
}

} // namespace

BlendKernel BlendKernel::superElliptic(double p)
{
    check(limits::kBlendP, p);
    BlendKernel k;
    k.kind = Kind::SuperElliptic;
    k.p = p;
    return k;
}

BlendKernel BlendKernel::polynomial(double width)
{
    check(limits::kSmoothK, width);
    BlendKernel k;
    k.kind = Kind::Polynomial;
    k.k = width;
    return k;
}

double BlendKernel::combine(CsgOp op, const double* t, std::size_t n) const
{
    if (kind == Kind::SuperElliptic) return blendTerms(op, p, t, n);
    double s = t[0], da, db;
    for (std::size_t i = 1; i < n; ++i) s = smoothStep(op, s, t[i], k, da, db);
    return s;
}

void BlendKernel::weights(CsgOp op, const double* t, std::size_t n, double* w) const
{
    if (kind == Kind::SuperElliptic) return superEllipticPoints<1>(op, p, t, n, 1, nullptr, w);
    // Forward through the fold s_i = step(s_{i-1}, t_i), keeping d s_i / d t_i in w[i] and
    // d s_i / d s_{i-1} in a; then backward: d f / d t_i = w[i] times the later a's.
    Scratch a(n);
    double s = t[0];
    for (std::size_t i = 1; i < n; ++i) s = smoothStep(op, s, t[i], k, a.data()[i], w[i]);
    double chain = 1.0;
    for (std::size_t i = n; i-- > 1;) {
        w[i] *= chain;
        chain *= a.data()[i];
    }
    w[0] = chain;
}

double BlendKernel::swell(std::size_t n) const
{
    return kind == Kind::SuperElliptic ? std::log(double(n)) / p : double(n - 1) * k * 0.25;
}

double BlendKernel::reach(double toleranceWorld) const
{
    if (kind == Kind::Polynomial) return k;
    return std::max(0.0, std::log(1.0 / (p * toleranceWorld)) / p);
}

BlendKernel::Handover BlendKernel::handover(double toleranceWorld, std::size_t n) const
{
    if (kind == Kind::Polynomial) return {reach(toleranceWorld) + swell(n), 0.0};
    // At lead g the term's distance is within tol(g) = exp(-p (g - swell)) / p of the blend's
    // (reach() solved for the tolerance), so over the zone [edge - 1/p, edge] the ramped answer
    // is off by at most tol(edge) max_u ramp(u) e^(1 - u) = 1.1535 tol(edge): the edge is where
    // that is the tolerance. (A zone of 2/p, with its edge ln(1.54 / 1.16) / p farther out, bent
    // the answers no less: the mean curvature of a blend of two spheres, p = 20 at voxel
    // 0.0025, off by up to 0.35% either way, from the lead rule's kink at the surface.)
    constexpr double kRampGain = 1.16;
    return {reach(toleranceWorld / kRampGain) + swell(n), 1.0 / p};
}

std::string BlendKernel::describe() const
{
    return kind == Kind::SuperElliptic ? "p = " + util::formatNumber(p)
                                       : "k = " + util::formatNumber(k);
}

double blendTerms(Csg::Op op, double p, const double* t, std::size_t n)
{
    double f;
    superEllipticPoints<1>(op, p, t, n, 1, &f, nullptr); // one point: its n terms are a column
    return f;
}

Blend::Blend(Op op, double p, std::vector<Ptr> children)
    : Blend(op, BlendKernel::superElliptic(p), std::move(children))
{
}

Blend::Blend(Op op, const BlendKernel& kernel, std::vector<Ptr> children)
    : mOp(op), mKernel(kernel), mChildren(std::move(children))
{
    if (mKernel.kind == BlendKernel::Kind::SuperElliptic) check(limits::kBlendP, mKernel.p);
    else check(limits::kSmoothK, mKernel.k);
    if (mChildren.empty()) OPENVDB_THROW(openvdb::ValueError, "blend needs children");
    for (const auto& c : mChildren) {
        if (!c) OPENVDB_THROW(openvdb::ValueError, "blend has a null child");
    }
    // A term rho s_c f_c just above 0 lies on child c's positive side where rho s_c > 0.
    mChildLeadFactor = 1.0;
    for (std::size_t c = 0; c < mChildren.size(); ++c) {
        const bool flip = (mOp != Op::Union) != (mOp == Op::Difference && c > 0);
        mChildLeadFactor = mChildren[c]->isDistanceBound()
            ? std::max(mChildLeadFactor, mChildren[c]->distanceFactor(!flip))
            : std::numeric_limits<double>::infinity();
        if (!std::isfinite(mChildLeadFactor)) break;
    }
}

bool Blend::isDistanceBound() const { return detail::allDistanceBound(mChildren); }

double Blend::lipschitzBound() const { return detail::largestLipschitzBound(mChildren); }

std::string Blend::typeName() const
{
    return mKernel.kind == BlendKernel::Kind::SuperElliptic ? "blend" : "smooth";
}

void Blend::terms(const Vec3d& p, double* t) const
{
    for (std::size_t i = 0; i < mChildren.size(); ++i) {
        const double v = mChildren[i]->value(p);
        t[i] = (mOp == Op::Difference && i > 0) ? -v : v;
    }
}

double Blend::value(const Vec3d& p) const
{
    Scratch t(mChildren.size());
    terms(p, t.data());
    return mKernel.combine(mOp, t.data(), mChildren.size());
}

Vec3d Blend::gradient(const Vec3d& p) const
{
    // d f / d t_i = w_i: a combination of the terms' gradients.
    const std::size_t m = mChildren.size();
    Scratch t(m), w(m);
    terms(p, t.data());
    mKernel.weights(mOp, t.data(), m, w.data());
    Vec3d g(0.0);
    for (std::size_t i = 0; i < m; ++i) {
        const Vec3d gi = mChildren[i]->gradient(p);
        g += gi * ((mOp == Op::Difference && i > 0) ? -w.data()[i] : w.data()[i]);
    }
    return g;
}

void Blend::childRows(const double* x, const double* y, const double* z, std::size_t n,
                      double* terms, double* cg) const
{
    const bool difference = mOp == Op::Difference;
    for (std::size_t c = 0; c < mChildren.size(); ++c) {
        double* row = terms + c * n;
        if (cg) {
            double* g = cg + 3 * c * n;
            mChildren[c]->valuesAndGradients(x, y, z, row, g, g + n, g + 2 * n, n);
        } else {
            mChildren[c]->values(x, y, z, row, n);
        }
        if (difference && c > 0) {
            for (std::size_t i = 0; i < n; ++i) row[i] = -row[i];
        }
    }
}

void Blend::gradientsFromRows(const double* terms, const double* cg, std::size_t n, double* w,
                              bool haveWeights, double* gx, double* gy, double* gz) const
{
    const std::size_t m = mChildren.size();
    if (!haveWeights && mKernel.kind == BlendKernel::Kind::SuperElliptic) {
        superEllipticBatch(mOp, mKernel.p, terms, m, n, nullptr, w);
    } else if (!haveWeights) {
        std::vector<double> t(m), wp(m);
        for (std::size_t i = 0; i < n; ++i) {
            for (std::size_t c = 0; c < m; ++c) t[c] = terms[c * n + i];
            mKernel.weights(mOp, t.data(), m, wp.data());
            for (std::size_t c = 0; c < m; ++c) w[c * n + i] = wp[c];
        }
    }
    weightedGradients(mOp == Op::Difference, cg, w, m, n, gx, gy, gz);
}

void Blend::gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                      double* gz, std::size_t n) const
{
    // The children's values and gradients in term-major buffers, then as gradient() per point.
    const std::size_t m = mChildren.size();
    detail::BatchRows rows(5 * m * n);
    double *terms = rows.get(), *cg = terms + m * n, *w = cg + 3 * m * n;
    childRows(x, y, z, n, terms, cg);
    gradientsFromRows(terms, cg, n, w, false, gx, gy, gz);
}

void Blend::valuesAndGradients(const double* x, const double* y, const double* z, double* out,
                               double* gx, double* gy, double* gz, std::size_t n) const
{
    // values() and gradients() in one pass: the children once, and the super-elliptic kernel's
    // exponentials shared by the value and the weights (the same operations in the same order,
    // so the same bits).
    const std::size_t m = mChildren.size();
    detail::BatchRows rows(5 * m * n);
    double *terms = rows.get(), *cg = terms + m * n, *w = cg + 3 * m * n;
    childRows(x, y, z, n, terms, cg);
    const bool haveWeights = valuesFromRows(terms, n, out, w);
    gradientsFromRows(terms, cg, n, w, haveWeights, gx, gy, gz);
}

bool Blend::valuesFromRows(const double* terms, std::size_t n, double* values, double* w) const
{
    // Combined per point exactly as value() does.
    const std::size_t m = mChildren.size();
    if (mKernel.kind == BlendKernel::Kind::SuperElliptic) {
        superEllipticBatch(mOp, mKernel.p, terms, m, n, values, w);
        return w != nullptr;
    }
    std::vector<double> t(m);
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t c = 0; c < m; ++c) t[c] = terms[c * n + i];
        values[i] = mKernel.combine(mOp, t.data(), m);
    }
    return false;
}

void Blend::values(const double* x, const double* y, const double* z, double* out,
                   std::size_t n) const
{
    // Children into a term-major buffer, then combined per point.
    const detail::BatchRows terms(mChildren.size() * n);
    childRows(x, y, z, n, terms.get(), nullptr);
    valuesFromRows(terms.get(), n, out, nullptr);
}

Interval Blend::interval(const BBoxd& box) const
{
    const std::size_t m = mChildren.size();
    std::vector<double> lo(m), hi(m);
    for (std::size_t c = 0; c < m; ++c) {
        Interval iv = mChildren[c]->interval(box);
        if (mOp == Op::Difference && c > 0) iv = -iv;
        lo[c] = iv.lo;
        hi[c] = iv.hi;
    }
    return {mKernel.combine(mOp, lo.data(), m), mKernel.combine(mOp, hi.data(), m)};
}

void Blend::intervals(const double* cx, const double* cy, const double* cz, const Vec3d& half,
                      std::size_t n, double* lo, double* hi) const
{
    // interval() per box, the children's in batches and the blend of the bounds in one loop.
    const std::size_t m = mChildren.size();
    const detail::BatchRows rows(2 * m * n);
    double *tlo = rows.get(), *thi = tlo + m * n;
    for (std::size_t c = 0; c < m; ++c) {
        double* l = tlo + c * n;
        double* h = thi + c * n;
        mChildren[c]->intervals(cx, cy, cz, half, n, l, h);
        if (mOp == Op::Difference && c > 0) {
            for (std::size_t i = 0; i < n; ++i) {
                const double a = l[i];
                l[i] = -h[i];
                h[i] = -a;
            }
        }
    }
    if (mKernel.kind == BlendKernel::Kind::SuperElliptic) {
        superEllipticBatch(mOp, mKernel.p, tlo, m, n, lo, nullptr);
        superEllipticBatch(mOp, mKernel.p, thi, m, n, hi, nullptr);
        return;
    }
    std::vector<double> a(m), b(m);
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t c = 0; c < m; ++c) a[c] = tlo[c * n + i], b[c] = thi[c * n + i];
        lo[i] = mKernel.combine(mOp, a.data(), m);
        hi[i] = mKernel.combine(mOp, b.data(), m);
    }
}

BBoxd Blend::boundingBox() const { return boundingBoxBelow(0.0); }

BBoxd Blend::boundingBoxBelow(double level) const
{
    // A smooth max is at least the max: within the sharp operation's box.
    if (mOp != Op::Union) return Csg(mOp, mChildren).boundingBoxBelow(level);
    // A smooth min is at least the min less the swell: below the level only where some child
    // is below the level plus the swell.
    const double grow = mKernel.swell(mChildren.size());
    BBoxd b = mChildren[0]->boundingBoxBelow(level + grow);
    for (const auto& c : mChildren) b.expand(c->boundingBoxBelow(level + grow));
    return isFinite(b) ? b : infiniteBox();
}

} // namespace ivdb::implicit
