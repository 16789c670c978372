// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/Modifiers.h>

#include <ivdb/implicit/Blend.h>
#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/Primitives.h>

#include <openvdb/Exceptions.h>

#include "Feet.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <vector>

namespace ivdb::implicit {

namespace {

void requireChild(const Implicit::Ptr& child, const char* what)
{
    if (!child) OPENVDB_THROW(openvdb::ValueError, std::string(what) + " has a null child");
}

/// The part of @a a within @a b, both holding the same points (an infinite box is all space).
BBoxd within(const BBoxd& a, const BBoxd& b)
{
    if (!isFinite(a)) return b;
    if (!isFinite(b)) return a;
    const Vec3d lo = maxComponent(a.min(), b.min());
    return BBoxd(lo, maxComponent(lo, minComponent(a.max(), b.max())));
}

} // namespace

// ---- Offset ---------------------------------------------------------------------------------

namespace {

/// A capped cylinder or cone is its (convex) cone between two slabs: shrunk by @a delta, the
/// caps move in by delta along the axis and the side by delta across it, which at a slope
/// k = dr/ds takes delta sqrt(1 + k^2) off the radius. Null where the length or a radius would
/// reach 0 (the shrunk solid nothing, or a cone's tip).
std::shared_ptr<CappedCone> erodedCone(const CappedCone& c, double delta)
{
    const double length = c.length() - 2.0 * delta;
    if (!(length > 0.0)) return nullptr;
    const double k = (c.radiusB() - c.radiusA()) / c.length();
    const double cut = delta * std::sqrt(1.0 + k * k);
    const double ra = c.radiusA() + k * delta - cut, rb = c.radiusB() - k * delta - cut;
    if (!(ra > 0.0) || !(rb > 0.0)) return nullptr;
    const Vec3d a = c.a() + c.axis() * delta;
    return std::make_shared<CappedCone>(a, a + c.axis() * length, ra, rb, c.typeName());
}

/// The solid {f <= level} of a CSG node's value f as a CSG node itself: the node's value is the
/// min or max of its terms, so its level set is the union or intersection of theirs (min(a, b)
/// <= l where a <= l or b <= l; max(a, b) <= l where both are; max(a, -b) <= l where a <= l and
/// b >= -l). A part's own {a <= l}: erodedShape() or dilatedShape() where known, else, of an
/// exact SDF, its offset (whose foot points follow the part's gradient). A part with nothing
/// at that level (its values over its box all above it: a sphere thinner than the shrinking)
/// leaves a union or a difference's cut, and empties an intersection or a difference. Null if a
/// part has no such shape, or nothing is left.
Implicit::Ptr csgLevelShape(const Csg& c, double level)
{
    std::vector<Implicit::Ptr> parts;
    for (std::size_t k = 0; k < c.children().size(); ++k) {
        const Implicit::Ptr& part = c.children()[k];
        const bool cut = c.op() == CsgOp::Difference && k > 0;
        const double l = cut ? -level : level;
        if (l < 0.0 && part->interval(part->boundingBox()).lo >= l) {
            if (c.op() == CsgOp::Union || cut) continue;
            return nullptr; // an empty intersection or difference
        }
        Implicit::Ptr shape = l < 0.0 ? erodedShape(part, -l) : dilatedShape(part, l);
        if (!shape && part->isExactSdf()) shape = std::make_shared<Offset>(part, l);
        if (!shape) return nullptr;
        parts.push_back(std::move(shape));
    }
    if (parts.empty()) return nullptr;
    if (parts.size() == 1) return parts.front();
    return std::make_shared<Csg>(c.op(), std::move(parts));
}

/// The solid {f <= level} of a blend's value f as a blend itself: both kernels move with
/// their terms (a blend of the terms t - l is the blend of t, less l), so it is the same blend
/// of its children offset by the level (the ones a difference subtracts, by minus it). The
/// same values, not only the same surface (a blend's surface depends on its children's
/// values): so each child is its Offset, whose foot points are its own solid's where one is
/// known (a box's smaller box, a grown CSG's parts), and not that solid itself. The blend's
/// lead rule then takes a child's own foot points where it leads (Blend::footPoints).
Implicit::Ptr blendLevelShape(const Blend& b, double level)
{
    std::vector<Implicit::Ptr> parts;
    parts.reserve(b.children().size());
    for (std::size_t k = 0; k < b.children().size(); ++k) {
        const bool cut = b.op() == CsgOp::Difference && k > 0;
        parts.push_back(std::make_shared<Offset>(b.children()[k], cut ? -level : level));
    }
    return std::make_shared<Blend>(b.op(), b.kernel(), std::move(parts));
}

} // namespace

Implicit::Ptr dilatedShape(const Implicit::Ptr& child, double delta)
{
    if (!(delta > 0.0)) return nullptr;
    if (const auto* s = dynamic_cast<const Sphere*>(child.get())) {
        return std::make_shared<Sphere>(s->center(), s->radius() + delta);
    }
    // The points within delta of a box: the box of sides size + 2 delta with its edges and
    // corners rounded by delta.
    if (const auto* b = dynamic_cast<const Box*>(child.get())) {
        return std::make_shared<RoundedBox>(b->center(), b->size() + Vec3d(2.0 * delta), delta);
    }
    if (const auto* t = dynamic_cast<const Transform*>(child.get())) {
        const double s = t->uniformScale();
        const Implicit::Ptr outer = s > 0.0 ? dilatedShape(t->child(), delta / s) : nullptr;
        return outer ? t->moved(outer) : nullptr;
    }
    if (const auto* c = dynamic_cast<const Csg*>(child.get())) return csgLevelShape(*c, delta);
    if (const auto* b = dynamic_cast<const Blend*>(child.get())) return blendLevelShape(*b, delta);
    return nullptr;
}

Implicit::Ptr erodedShape(const Implicit::Ptr& child, double delta)
{
    if (!(delta > 0.0)) return nullptr;
    // A sphere's smaller sphere (on its own, its offset is exact anyway; as a part of a CSG
    // node below, it has to be a shape of its own).
    if (const auto* s = dynamic_cast<const Sphere*>(child.get())) {
        return s->radius() > delta ? std::make_shared<Sphere>(s->center(), s->radius() - delta)
                                   : nullptr;
    }
    // A rounded box is its inner box grown by its radius r: shrunk by delta < r, the rounded
    // box of radius r - delta; by more, the inner box shrunk by delta - r, with sharp edges.
    if (const auto* b = dynamic_cast<const RoundedBox*>(child.get())) {
        const Vec3d size = b->size() - Vec3d(2.0 * delta);
        if (!(std::min({size[0], size[1], size[2]}) > 0.0)) return nullptr;
        if (delta < b->radius()) {
            return std::make_shared<RoundedBox>(b->center(), size, b->radius() - delta);
        }
        return std::make_shared<Box>(b->center(), size);
    }
    // A box is the intersection of its slabs, and shrinking an intersection shrinks each part:
    // the smaller box, whose edges stay sharp (the offset's own value, f - d, is not its
    // distance near them).
    if (const auto* b = dynamic_cast<const Box*>(child.get())) {
        const Vec3d size = b->size() - Vec3d(2.0 * delta);
        if (!(std::min({size[0], size[1], size[2]}) > 0.0)) return nullptr;
        return std::make_shared<Box>(b->center(), size);
    }
    // A rigid motion or uniform scale s moves the shrunk child, shrunk by delta / s in its own
    // units.
    if (const auto* t = dynamic_cast<const Transform*>(child.get())) {
        const double s = t->uniformScale();
        const Implicit::Ptr inner = s > 0.0 ? erodedShape(t->child(), delta / s) : nullptr;
        return inner ? t->moved(inner) : nullptr;
    }
    // A capped cylinder or cone: the smaller one (erodedCone()), unless it is a cone's tip.
    if (const auto* c = dynamic_cast<const CappedCone*>(child.get())) return erodedCone(*c, delta);
    if (const auto* c = dynamic_cast<const Csg*>(child.get())) return csgLevelShape(*c, -delta);
    if (const auto* b = dynamic_cast<const Blend*>(child.get())) return blendLevelShape(*b, -delta);
    return nullptr;
}

Offset::Offset(Ptr child, double distance): mChild(std::move(child)), mDistance(distance)
{
    requireChild(mChild, "offset");
    if (!std::isfinite(distance)) {
        std::ostringstream os;
        os << "offset distance must be finite, got " << distance;
        OPENVDB_THROW(openvdb::ValueError, os.str());
    }
    if (distance < 0.0) mSolid = erodedShape(mChild, -distance);
    if (distance > 0.0 && !mChild->isExactSdf()) mSolid = dilatedShape(mChild, distance);
}

double Offset::value(const Vec3d& p) const { return mChild->value(p) - mDistance; }

Vec3d Offset::gradient(const Vec3d& p) const { return mChild->gradient(p); }

void Offset::values(const double* x, const double* y, const double* z, double* out,
                    std::size_t n) const
{
    mChild->values(x, y, z, out, n);
    for (std::size_t i = 0; i < n; ++i) out[i] -= mDistance;
}

void Offset::gradients(const double* x, const double* y, const double* z, double* gx,
                       double* gy, double* gz, std::size_t n) const
{
    mChild->gradients(x, y, z, gx, gy, gz, n);
}

Interval Offset::interval(const BBoxd& box) const
{
    return mChild->interval(box) + (-mDistance);
}

BBoxd Offset::boundingBox() const { return boundingBoxBelow(0.0); }

BBoxd Offset::boundingBoxBelow(double level) const
{
    // f - d below the level where the child's f is below level + d (shrunk, d <= 0: within the
    // child's box).
    BBoxd box = mChild->boundingBoxBelow(level + mDistance);
    // Grown from a child whose value is not the distance outside (an intersection or a
    // difference) but with a solid of its own (the parts grown, a difference's cut shrunk):
    // within that solid's box too.
    if (mSolid && level <= 0.0) box = within(box, mSolid->boundingBox());
    return box;
}

bool Offset::isExactOutside() const { return mDistance >= 0.0 && mChild->isExactOutside(); }

namespace {

/// erosionFactor() of a capped cylinder or cone. It is a solid of revolution, so a point's
/// nearest point of it, or of the smaller one (erodedShape(): the caps moved in by delta and
/// the side by delta across it), lies in the point's half-plane through the axis, where the
/// solid's section is a trapezoid: the intersection of its caps' and sides' half-planes, f at
/// least each one's signed distance (the exact distance to a convex intersection, inside and
/// out). The smaller trapezoid's half-planes are those moved in by delta, so each one's signed
/// distance is at most f + delta. Where the nearest point of the smaller trapezoid is a corner
/// of interior angle theta, the point lies in the corner's normal cone (its two edges' normals
/// pi - theta apart), where the larger of its distances to the two half-planes is at least
/// sin(theta / 2) times its distance to the corner; on an edge, that edge's distance is the
/// distance. The smallest angle is at the wide end's rims, pi/2 - atan(|k|) at the slope k =
/// dr/ds (sqrt(2) for a cylinder). Infinity where the smaller solid is not such a trapezoid (a
/// radius or the length reaching 0: erodedShape() has none either).
double cappedConeErosionFactor(const CappedCone& c, double delta)
{
    if (!erodedCone(c, delta)) return std::numeric_limits<double>::infinity();
    const double k = (c.radiusB() - c.radiusA()) / c.length();
    return 1.0 / std::sin(0.25 * M_PI - 0.5 * std::atan(std::abs(k)));
}

/// Of an exact SDF @a f shrunk by @a delta > 0: a factor K such that every point where
/// f + delta > 0 lies within K (f + delta) of the shrunk surface {f = -delta}. 1 where f + delta
/// is the shrunk shape's own exact SDF (a sphere's, a capsule's, a torus's, a rounded box's by
/// less than its radius); for a capped cylinder or cone, cappedConeErosionFactor();
/// sqrt(3) for a box (and a rounded box shrunk past its radius, its inner box shrunk): each
/// coordinate's excess over the smaller box is at most f + delta, so the distance to it at most
/// sqrt(3) times that; a rigid motion or uniform scale keeps it. Infinity for other shapes.
double erosionFactor(const Implicit& f, double delta)
{
    if (const auto* s = dynamic_cast<const Sphere*>(&f)) {
        return delta < s->radius() ? 1.0 : std::numeric_limits<double>::infinity();
    }
    if (const auto* b = dynamic_cast<const RoundedBox*>(&f)) {
        return delta < b->radius() ? 1.0 : std::sqrt(3.0);
    }
    if (dynamic_cast<const Box*>(&f)) return std::sqrt(3.0);
    // A capsule or a torus shrunk by less than its radius is the one of the smaller radius:
    // f + delta is its exact distance.
    if (const auto* c = dynamic_cast<const Capsule*>(&f)) {
        return delta < c->radius() ? 1.0 : std::numeric_limits<double>::infinity();
    }
    if (const auto* t = dynamic_cast<const Torus*>(&f)) {
        return delta < t->minorRadius() ? 1.0 : std::numeric_limits<double>::infinity();
    }
    if (const auto* c = dynamic_cast<const CappedCone*>(&f)) return cappedConeErosionFactor(*c, delta);
    if (const auto* t = dynamic_cast<const Transform*>(&f)) {
        const double s = t->uniformScale();
        if (s > 0.0) return erosionFactor(*t->child(), delta / s);
    }
    return std::numeric_limits<double>::infinity();
}

} // namespace

double Offset::distanceFactor(bool outside) const
{
    // Of an exact SDF f, f - d is the distance outside the grown shape (d >= 0) and inside the
    // shrunk one (d <= 0): there the segment to the child's foot point crosses the level set
    // after exactly |f - d|, and no point of it is nearer (f is 1-Lipschitz). Inside a convex
    // solid grown, too: it is a point's distance to the solid, d less it, and the level set
    // of a 1-Lipschitz function is no nearer. Outside one shrunk: erosionFactor().
    const double none = std::numeric_limits<double>::infinity();
    if (!mChild->isExactSdf()) return none;
    if (outside ? mDistance >= 0.0 : mDistance <= 0.0) return 1.0;
    if (outside) return erosionFactor(*mChild, -mDistance);
    return detail::convexSdf(*mChild) ? 1.0 : none;
}

Implicit::Ptr Offset::prune(const BBoxd& box) const
{
    Ptr c = mChild->prune(box);
    if (c == mChild) return shared_from_this();
    return std::make_shared<Offset>(std::move(c), mDistance);
}

// ---- Shell ----------------------------------------------------------------------------------

Shell::Shell(Ptr child, double thickness): mChild(std::move(child)), mHalf(0.5 * thickness)
{
    requireChild(mChild, "shell");
    if (!(thickness > 0.0) || !std::isfinite(thickness)) {
        std::ostringstream os;
        os << "shell thickness must be > 0 and finite, got " << thickness;
        OPENVDB_THROW(openvdb::ValueError, os.str());
    }
    mEroded = erodedShape(mChild, mHalf);
    // Of a child whose value is not a distance (a CSG node), the shell's solid {|f| <= t/2} is
    // its solid at t/2 less its solid at -t/2, each a shape of its own where known.
    if (!mChild->isExactSdf() && mEroded) {
        if (Ptr outer = dilatedShape(mChild, mHalf)) {
            mSolid = std::make_shared<Csg>(CsgOp::Difference, std::vector<Ptr>{outer, mEroded});
        }
    }
}

double Shell::value(const Vec3d& p) const { return std::abs(mChild->value(p)) - mHalf; }

Vec3d Shell::gradient(const Vec3d& p) const
{
    const Vec3d g = mChild->gradient(p);
    return mChild->value(p) < 0.0 ? -g : g;
}

void Shell::values(const double* x, const double* y, const double* z, double* out,
                   std::size_t n) const
{
    mChild->values(x, y, z, out, n);
    for (std::size_t i = 0; i < n; ++i) out[i] = std::abs(out[i]) - mHalf;
}

void Shell::gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                      double* gz, std::size_t n) const
{
    double v[kMaxBatch];
    mChild->values(x, y, z, v, n);
    mChild->gradients(x, y, z, gx, gy, gz, n);
    for (std::size_t i = 0; i < n; ++i) {
        if (v[i] < 0.0) gx[i] = -gx[i], gy[i] = -gy[i], gz[i] = -gz[i];
    }
}

Interval Shell::interval(const BBoxd& box) const
{
    const Interval c = mChild->interval(box);
    Interval a;
    if (c.lo >= 0.0) a = c;
    else if (c.hi <= 0.0) a = -c;
    else a = Interval(0.0, std::max(-c.lo, c.hi));
    return a + (-mHalf);
}

BBoxd Shell::boundingBox() const { return boundingBoxBelow(0.0); }

BBoxd Shell::boundingBoxBelow(double level) const
{
    // |f| - t/2 below the level only where f is below level + t/2.
    BBoxd box = mChild->boundingBoxBelow(level + mHalf);
    if (mSolid && level <= 0.0) box = within(box, mSolid->boundingBox());
    return box;
}

Implicit::Ptr Shell::prune(const BBoxd& box) const
{
    Ptr c = mChild->prune(box);
    if (c == mChild) return shared_from_this();
    return std::make_shared<Shell>(std::move(c), 2.0 * mHalf);
}

} // namespace ivdb::implicit
