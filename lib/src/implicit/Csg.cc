// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/Csg.h>

#include <ivdb/implicit/Primitives.h>

#include <openvdb/Exceptions.h>

#include "../util/Simd.h"
#include "Children.h"
#include "Scratch.h"
#include "SphereMath.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ivdb::implicit {

Csg::Csg(Op op, std::vector<Ptr> children): mOp(op), mChildren(std::move(children))
{
    if (mChildren.empty()) OPENVDB_THROW(openvdb::ValueError, typeName() + " needs children");
    for (const auto& c : mChildren) {
        if (!c) OPENVDB_THROW(openvdb::ValueError, typeName() + " has a null child");
    }
    const std::size_t n = mChildren.size();
    if (n < 2) return;
    std::vector<double> rows(4 * n);
    for (std::size_t i = 0; i < n; ++i) {
        const auto* sphere = dynamic_cast<const Sphere*>(mChildren[i].get());
        if (!sphere) return;
        rows[i] = sphere->center()[0];
        rows[n + i] = sphere->center()[1];
        rows[2 * n + i] = sphere->center()[2];
        rows[3 * n + i] = sphere->radius();
    }
    mSpheres = std::move(rows);
}

namespace {

/// Sphere::interval() for @a n spheres (centres @a cx, @a cy, @a cz, radii @a r) over one box,
/// the same operations in the same order, in a loop that vectorizes.
IVDB_VECTOR_CLONES
void sphereIntervals(const double* __restrict cx, const double* __restrict cy,
                     const double* __restrict cz, const double* __restrict r, std::size_t n,
                     const Vec3d& bmin, const Vec3d& bmax, double* __restrict lo,
                     double* __restrict hi)
{
    const double l0 = bmin[0], l1 = bmin[1], l2 = bmin[2];
    const double u0 = bmax[0], u1 = bmax[1], u2 = bmax[2];
    for (std::size_t i = 0; i < n; ++i) {
        detail::sphereRange(l0 - cx[i], u0 - cx[i], l1 - cy[i], u1 - cy[i], l2 - cz[i],
                            u2 - cz[i], r[i], lo[i], hi[i]);
    }
}

} // namespace

void Csg::childIntervals(const BBoxd& box, double* lo, double* hi) const
{
    const std::size_t n = mChildren.size();
    if (!mSpheres.empty()) {
        const double* s = mSpheres.data();
        sphereIntervals(s, s + n, s + 2 * n, s + 3 * n, n, box.min(), box.max(), lo, hi);
        return;
    }
    for (std::size_t i = 0; i < n; ++i) {
        const Interval iv = mChildren[i]->interval(box);
        lo[i] = iv.lo;
        hi[i] = iv.hi;
    }
}

std::string Csg::typeName() const
{
    return toString(mOp);
}

double Csg::value(const Vec3d& p) const
{
    double v = mChildren[0]->value(p);
    for (std::size_t i = 1; i < mChildren.size(); ++i) {
        const double c = mChildren[i]->value(p);
        switch (mOp) {
        case Op::Union: v = std::min(v, c); break;
        case Op::Intersection: v = std::max(v, c); break;
        case Op::Difference: v = std::max(v, -c); break;
        }
    }
    return v;
}

Vec3d Csg::gradient(const Vec3d& p) const
{
    // The gradient of the child that decides the value (the first one on ties, as value()).
    std::size_t best = 0;
    double v = mChildren[0]->value(p);
    for (std::size_t i = 1; i < mChildren.size(); ++i) {
        const double c = mChildren[i]->value(p);
        const bool better = mOp == Op::Union ? c < v : (mOp == Op::Intersection ? c > v : -c > v);
        if (better) {
            best = i;
            v = mOp == Op::Difference ? -c : c;
        }
    }
    const Vec3d g = mChildren[best]->gradient(p);
    return (mOp == Op::Difference && best > 0) ? -g : g;
}

namespace {

/// The union of @a m spheres (rows as Csg::mSpheres) at @a n points: Sphere::values()'s
/// arithmetic, each sphere's value folded into the minimum as it comes (a loop over the points
/// per sphere, which vectorizes).
IVDB_VECTOR_CLONES
void sphereUnionValues(const double* __restrict s, std::size_t m, const double* __restrict x,
                       const double* __restrict y, const double* __restrict z,
                       double* __restrict out, std::size_t n)
{
    for (std::size_t c = 0; c < m; ++c) {
        const double cx = s[c], cy = s[m + c], cz = s[2 * m + c], r = s[3 * m + c];
        for (std::size_t i = 0; i < n; ++i) {
            const double v = detail::sphereValue(x[i], y[i], z[i], cx, cy, cz, r);
            out[i] = c == 0 ? v : std::min(out[i], v);
        }
    }
}

} // namespace

void Csg::values(const double* x, const double* y, const double* z, double* out,
                 std::size_t n) const
{
    if (mOp == Op::Union && !mSpheres.empty()) {
        sphereUnionValues(mSpheres.data(), mChildren.size(), x, y, z, out, n);
        return;
    }
    mChildren[0]->values(x, y, z, out, n);
    double tmp[kMaxBatch];
    for (std::size_t c = 1; c < mChildren.size(); ++c) {
        mChildren[c]->values(x, y, z, tmp, n);
        switch (mOp) {
        case Op::Union:
            for (std::size_t i = 0; i < n; ++i) out[i] = std::min(out[i], tmp[i]);
            break;
        case Op::Intersection:
            for (std::size_t i = 0; i < n; ++i) out[i] = std::max(out[i], tmp[i]);
            break;
        case Op::Difference:
            for (std::size_t i = 0; i < n; ++i) out[i] = std::max(out[i], -tmp[i]);
            break;
        }
    }
}

Interval Csg::interval(const BBoxd& box) const
{
    const std::size_t n = mChildren.size();
    detail::Scratch rows(2 * n);
    double *lo = rows.data(), *hi = lo + n;
    childIntervals(box, lo, hi);
    Interval v{lo[0], hi[0]};
    for (std::size_t i = 1; i < n; ++i) {
        const Interval c{lo[i], hi[i]};
        switch (mOp) {
        case Op::Union: v = min(v, c); break;
        case Op::Intersection: v = max(v, c); break;
        case Op::Difference: v = max(v, -c); break;
        }
    }
    return v;
}

BBoxd Csg::boundingBox() const { return boundingBoxBelow(0.0); }

BBoxd Csg::boundingBoxBelow(double level) const
{
    // min < level where some child is; max < level where every child is (a difference's
    // subtracted terms -b only narrow it: its first child's box).
    switch (mOp) {
    case Op::Union: {
        BBoxd b = mChildren[0]->boundingBoxBelow(level);
        for (std::size_t i = 1; i < mChildren.size(); ++i) b.expand(mChildren[i]->boundingBoxBelow(level));
        return b;
    }
    case Op::Intersection: {
        BBoxd b = mChildren[0]->boundingBoxBelow(level);
        for (std::size_t i = 1; i < mChildren.size(); ++i) {
            const BBoxd c = mChildren[i]->boundingBoxBelow(level);
            b = BBoxd(maxComponent(b.min(), c.min()), minComponent(b.max(), c.max()));
        }
        // An empty intersection keeps an empty (inverted-free) box at its min corner.
        return BBoxd(b.min(), maxComponent(b.min(), b.max()));
    }
    case Op::Difference: return mChildren[0]->boundingBoxBelow(level);
    }
    return infiniteBox();
}

bool Csg::isDistanceBound() const { return detail::allDistanceBound(mChildren); }

double Csg::lipschitzBound() const { return detail::largestLipschitzBound(mChildren); }

double Csg::distanceFactor(bool outside) const
{
    // Outside a union, the least child value is the distance where every child's positive
    // value is; inside an intersection, the greatest (least deep) where every child's negative
    // one is (a difference intersects the first child with the others' complements).
    const double none = std::numeric_limits<double>::infinity();
    if (mChildren.size() == 1) return mChildren[0]->distanceFactor(outside);
    if (outside != (mOp == Op::Union)) return none;
    for (std::size_t c = 0; c < mChildren.size(); ++c) {
        const bool side = mOp == Op::Difference && c > 0 ? !outside : outside;
        if (mChildren[c]->distanceFactor(side) != 1.0) return none;
    }
    return 1.0;
}

bool Csg::isExactOutside() const
{
    if (mOp != Op::Union) return isExactSdf();
    for (const auto& c : mChildren) {
        if (!c->isExactOutside()) return false;
    }
    return true;
}

bool Csg::isExactSdf() const
{
    return mChildren.size() == 1 && mChildren[0]->isExactSdf();
}

Implicit::Ptr Csg::prune(const BBoxd& box) const
{
    if (mChildren.size() == 1) return mChildren[0]->prune(box);

    // Terms whose interval cannot reach the decisive bound anywhere in the box are dropped:
    // for a union, a child whose lowest value lies above another child's highest value.
    const std::size_t n = mChildren.size();
    detail::Scratch rows(2 * n);
    double *lo = rows.data(), *hi = lo + n;
    childIntervals(box, lo, hi);
    for (std::size_t i = 1; i < n && mOp == Op::Difference; ++i) {
        const double l = lo[i];
        lo[i] = -hi[i];
        hi[i] = -l;
    }
    double bound = mOp == Op::Union ? hi[0] : lo[0];
    for (std::size_t i = 0; i < n; ++i) bound = mOp == Op::Union ? std::min(bound, hi[i])
                                                                 : std::max(bound, lo[i]);
    std::vector<Ptr> kept;
    kept.reserve(mChildren.size());
    bool changed = false;
    for (std::size_t i = 0; i < mChildren.size(); ++i) {
        const bool useless = mOp == Op::Union ? lo[i] > bound : hi[i] < bound;
        // A difference keeps its first child: max(-B) alone is not a node type.
        if (useless && !(mOp == Op::Difference && i == 0)) {
            changed = true;
            continue;
        }
        Ptr c = mChildren[i]->prune(box);
        changed = changed || c != mChildren[i];
        kept.push_back(std::move(c));
    }
    if (!changed) return shared_from_this();
    if (kept.size() == 1) return kept[0];
    return std::make_shared<Csg>(mOp, std::move(kept));
}

} // namespace ivdb::implicit
