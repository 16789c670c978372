// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/Csg.h>

#include <openvdb/Exceptions.h>

#include <algorithm>

namespace ivdb::implicit {

Csg::Csg(Op op, std::vector<Ptr> children): mOp(op), mChildren(std::move(children))
{
    if (mChildren.empty()) OPENVDB_THROW(openvdb::ValueError, typeName() + " needs children");
    for (const auto& c : mChildren) {
        if (!c) OPENVDB_THROW(openvdb::ValueError, typeName() + " has a null child");
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

void Csg::values(const double* x, const double* y, const double* z, double* out,
                 std::size_t n) const
{
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
    Interval v = mChildren[0]->interval(box);
    for (std::size_t i = 1; i < mChildren.size(); ++i) {
        const Interval c = mChildren[i]->interval(box);
        switch (mOp) {
        case Op::Union: v = min(v, c); break;
        case Op::Intersection: v = max(v, c); break;
        case Op::Difference: v = max(v, -c); break;
        }
    }
    return v;
}

BBoxd Csg::boundingBox() const
{
    switch (mOp) {
    case Op::Union: {
        BBoxd b = mChildren[0]->boundingBox();
        for (std::size_t i = 1; i < mChildren.size(); ++i) b.expand(mChildren[i]->boundingBox());
        return b;
    }
    case Op::Intersection: {
        BBoxd b = mChildren[0]->boundingBox();
        for (std::size_t i = 1; i < mChildren.size(); ++i) {
            const BBoxd c = mChildren[i]->boundingBox();
            b = BBoxd(maxComponent(b.min(), c.min()), minComponent(b.max(), c.max()));
        }
        // An empty intersection keeps an empty (inverted-free) box at its min corner.
        return BBoxd(b.min(), maxComponent(b.min(), b.max()));
    }
    case Op::Difference: return mChildren[0]->boundingBox();
    }
    return infiniteBox();
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
    std::vector<Interval> iv(mChildren.size());
    for (std::size_t i = 0; i < mChildren.size(); ++i) {
        iv[i] = mChildren[i]->interval(box);
        if (mOp == Op::Difference && i > 0) iv[i] = -iv[i];
    }
    double bound = mOp == Op::Union ? iv[0].hi : iv[0].lo;
    for (const Interval& v : iv) bound = mOp == Op::Union ? std::min(bound, v.hi)
                                                          : std::max(bound, v.lo);
    std::vector<Ptr> kept;
    kept.reserve(mChildren.size());
    bool changed = false;
    for (std::size_t i = 0; i < mChildren.size(); ++i) {
        const bool useless = mOp == Op::Union ? iv[i].lo > bound : iv[i].hi < bound;
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
