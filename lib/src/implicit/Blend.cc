// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/Blend.h>

#include <ivdb/util/Params.h>

#include <openvdb/Exceptions.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace ivdb::implicit {

Blend::Blend(Op op, double p, std::vector<Ptr> children)
    : mOp(op), mP(p), mChildren(std::move(children))
{
    check(limits::kBlendP, p);
    if (mChildren.empty()) OPENVDB_THROW(openvdb::ValueError, "blend needs children");
    for (const auto& c : mChildren) {
        if (!c) OPENVDB_THROW(openvdb::ValueError, "blend has a null child");
    }
}

std::string Blend::typeName() const { return "blend"; }

double blendTerms(Csg::Op op, double p, const double* t, std::size_t n)
{
    // s = -1 for a union (a soft min), +1 for an intersection or difference (a soft max):
    // f = s (1/p) ln sum exp(s p t_i) = e + s (1/p) ln sum exp(s p (t_i - e)), e the extreme term,
    // so every exponent is <= 0 and the largest is exactly 0: no overflow, the sum is >= 1.
    const double s = op == Csg::Op::Union ? -1.0 : 1.0;
    double e = t[0];
    for (std::size_t i = 1; i < n; ++i) e = s < 0.0 ? std::min(e, t[i]) : std::max(e, t[i]);
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) sum += std::exp(s * p * (t[i] - e));
    return e + s * std::log(sum) / p;
}

double Blend::value(const Vec3d& p) const
{
    double t[64];
    std::vector<double> big;
    double* terms = t;
    if (mChildren.size() > 64) {
        big.resize(mChildren.size());
        terms = big.data();
    }
    for (std::size_t i = 0; i < mChildren.size(); ++i) {
        const double v = mChildren[i]->value(p);
        terms[i] = (mOp == Op::Difference && i > 0) ? -v : v;
    }
    return combine(terms, mChildren.size());
}

namespace {

/// The weights d f / d t_i = exp(s p (t_i - e)) / sum of a blend's terms @a t (in place), in
/// the order value() sums them; returns the sum.
double blendWeights(Csg::Op op, double p, double* t, std::size_t n)
{
    const double s = op == Csg::Op::Union ? -1.0 : 1.0;
    double e = t[0];
    for (std::size_t i = 0; i < n; ++i) e = s < 0.0 ? std::min(e, t[i]) : std::max(e, t[i]);
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        t[i] = std::exp(s * p * (t[i] - e));
        sum += t[i];
    }
    return sum;
}

} // namespace

Vec3d Blend::gradient(const Vec3d& p) const
{
    // d f / d t_i = w_i: a convex combination of the terms' gradients.
    double small[64];
    std::vector<double> big;
    double* t = small;
    if (mChildren.size() > 64) {
        big.resize(mChildren.size());
        t = big.data();
    }
    for (std::size_t i = 0; i < mChildren.size(); ++i) {
        const double v = mChildren[i]->value(p);
        t[i] = (mOp == Op::Difference && i > 0) ? -v : v;
    }
    const double sum = blendWeights(mOp, mP, t, mChildren.size());
    Vec3d g(0.0);
    for (std::size_t i = 0; i < mChildren.size(); ++i) {
        const Vec3d gi = mChildren[i]->gradient(p);
        g += gi * ((mOp == Op::Difference && i > 0) ? -t[i] / sum : t[i] / sum);
    }
    return g;
}

void Blend::gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                      double* gz, std::size_t n) const
{
    // The children's values and gradients in term-major buffers, then per point as gradient().
    const std::size_t m = mChildren.size();
    std::vector<double> terms(m * n), cg(3 * m * n);
    for (std::size_t c = 0; c < m; ++c) {
        double* row = terms.data() + c * n;
        mChildren[c]->values(x, y, z, row, n);
        if (mOp == Op::Difference && c > 0) {
            for (std::size_t i = 0; i < n; ++i) row[i] = -row[i];
        }
        double* g = cg.data() + 3 * c * n;
        mChildren[c]->gradients(x, y, z, g, g + n, g + 2 * n, n);
    }
    std::vector<double> t(m);
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t c = 0; c < m; ++c) t[c] = terms[c * n + i];
        const double sum = blendWeights(mOp, mP, t.data(), m);
        Vec3d g(0.0);
        for (std::size_t c = 0; c < m; ++c) {
            const double* cgc = cg.data() + 3 * c * n;
            const Vec3d gi(cgc[i], cgc[n + i], cgc[2 * n + i]);
            g += gi * ((mOp == Op::Difference && c > 0) ? -t[c] / sum : t[c] / sum);
        }
        gx[i] = g[0];
        gy[i] = g[1];
        gz[i] = g[2];
    }
}

void Blend::values(const double* x, const double* y, const double* z, double* out,
                   std::size_t n) const
{
    // Children into a term-major buffer, then combine per point exactly as value() does.
    const std::size_t m = mChildren.size();
    std::vector<double> terms(m * n);
    for (std::size_t c = 0; c < m; ++c) {
        double* row = terms.data() + c * n;
        mChildren[c]->values(x, y, z, row, n);
        if (mOp == Op::Difference && c > 0) {
            for (std::size_t i = 0; i < n; ++i) row[i] = -row[i];
        }
    }
    std::vector<double> t(m);
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t c = 0; c < m; ++c) t[c] = terms[c * n + i];
        out[i] = combine(t.data(), m);
    }
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
    return {combine(lo.data(), m), combine(hi.data(), m)};
}

BBoxd Blend::boundingBox() const
{
    if (mOp != Op::Union) return Csg(mOp, mChildren).boundingBox();
    BBoxd b = mChildren[0]->boundingBox();
    for (const auto& c : mChildren) {
        if (!c->isExactSdf()) return infiniteBox();
        b.expand(c->boundingBox());
    }
    const double grow = std::log(double(mChildren.size())) / mP;
    return BBoxd(b.min() - Vec3d(grow), b.max() + Vec3d(grow));
}

} // namespace ivdb::implicit
