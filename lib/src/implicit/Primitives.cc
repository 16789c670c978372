// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/Primitives.h>

#include "../util/Simd.h"
#include "Checks.h"
#include "SphereMath.h"

#include <openvdb/Exceptions.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace ivdb::implicit {

using detail::requireFinite;
using detail::requirePositive;

namespace {



// The per-point formulas, shared by value() and values() so both give the same bits (the
// sphere's in SphereMath.h).
using detail::sphereValue;

inline double boxValue(double x, double y, double z, const Vec3d& c, const Vec3d& h)
{
    const double qx = std::abs(x - c[0]) - h[0];
    const double qy = std::abs(y - c[1]) - h[1];
    const double qz = std::abs(z - c[2]) - h[2];
    const double ox = std::max(qx, 0.0), oy = std::max(qy, 0.0), oz = std::max(qz, 0.0);
    const double outside = std::sqrt(ox * ox + oy * oy + oz * oz);
    const double inside = std::min(std::max(qx, std::max(qy, qz)), 0.0);
    return outside + inside;
}

/// The gradient of boxValue(): outside, towards the point from its nearest box point; inside,
/// along the axis of the nearest face.
Vec3d boxGradient(const Vec3d& p, const Vec3d& c, const Vec3d& h)
{
    Vec3d q, s;
    for (int i = 0; i < 3; ++i) {
        const double d = p[i] - c[i];
        s[i] = d < 0.0 ? -1.0 : 1.0;
        q[i] = std::abs(d) - h[i];
    }
    const Vec3d o(std::max(q[0], 0.0), std::max(q[1], 0.0), std::max(q[2], 0.0));
    const double len = o.length();
    if (len > 0.0) return Vec3d(s[0] * o[0], s[1] * o[1], s[2] * o[2]) / len;
    const int axis = (q[0] >= q[1] && q[0] >= q[2]) ? 0 : (q[1] >= q[2] ? 1 : 2);
    Vec3d g(0.0);
    g[axis] = s[axis];
    return g;
}

/// The point of the segment from @a a to @a a + @a ab nearest to @a p (@a invLen2 = 1 / |ab|^2,
/// or 0 for a point), as the offset p minus that point.
inline Vec3d segmentOffset(const Vec3d& p, const Vec3d& a, const Vec3d& ab, double invLen2)
{
    const Vec3d pa = p - a;
    const double h = std::min(1.0, std::max(0.0, pa.dot(ab) * invLen2));
    return pa - ab * h;
}

/// The point of the 2D segment (x0, y0)-(x1, y1) nearest to (px, py), into (cx, cy); returns
/// the squared distance.
IVDB_CLONE_INLINE double nearestOnSegment2(double px, double py, double x0, double y0, double x1,
                                double y1, double& cx, double& cy)
{
    const double ex = x1 - x0, ey = y1 - y0, len2 = ex * ex + ey * ey;
    const double h = len2 > 0.0
        ? std::min(1.0, std::max(0.0, ((px - x0) * ex + (py - y0) * ey) / len2)) : 0.0;
    cx = x0 + ex * h;
    cy = y0 + ey * h;
    return (px - cx) * (px - cx) + (py - cy) * (py - cy);
}

/// A capped cone's exact SDF at (x, y, z) (CappedCone::distance()'s value, the same operations
/// in the same order, so the same bits): the distance in the half-plane through the axis,
/// (rho, t), to the nearest of the section's three edges off the axis (the cap at a, the side,
/// the cap at b), negative inside. Without branches, so that a loop over points vectorizes.
IVDB_CLONE_INLINE double cappedConeValue(double x, double y, double z, const Vec3d& a,
                                         const Vec3d& axis, double L, double ra, double rb)
{
    const double q0 = x - a[0], q1 = y - a[1], q2 = z - a[2];
    const double t = q0 * axis[0] + q1 * axis[1] + q2 * axis[2];
    const double w0 = q0 - axis[0] * t, w1 = q1 - axis[1] * t, w2 = q2 - axis[2] * t;
    const double rho = std::sqrt(w0 * w0 + w1 * w1 + w2 * w2);
    double cx, cy;
    const double d0 = nearestOnSegment2(rho, t, 0.0, 0.0, ra, 0.0, cx, cy);
    const double d1 = nearestOnSegment2(rho, t, ra, 0.0, rb, L, cx, cy);
    const double d2 = nearestOnSegment2(rho, t, rb, L, 0.0, L, cx, cy);
    double best = std::numeric_limits<double>::max();
    best = d0 < best ? d0 : best;
    best = d1 < best ? d1 : best;
    best = d2 < best ? d2 : best;
    const bool inside = t >= 0.0 && t <= L && rho * L <= ra * L + (rb - ra) * t;
    const double d = std::sqrt(best), s = inside ? -1.0 : 1.0;
    return s * d;
}

inline double torusValue(double x, double y, double z, const Vec3d& c, double R, double r)
{
    const double dx = x - c[0], dy = y - c[1], dz = z - c[2];
    const double q = std::sqrt(dx * dx + dy * dy) - R;
    return std::sqrt(q * q + dz * dz) - r;
}

} // namespace

Interval lipschitzInterval(const Implicit& f, const BBoxd& box)
{
    const double v = f.value(box.getCenter());
    const double h = 0.5 * (box.max() - box.min()).length();
    return {v - h, v + h};
}

// ---- Sphere ---------------------------------------------------------------------------------

Sphere::Sphere(const Vec3d& center, double radius): mCenter(center), mRadius(radius)
{
    requireFinite(center, "sphere center");
    requirePositive(radius, "sphere radius");
}

double Sphere::value(const Vec3d& p) const
{
    return sphereValue(p[0], p[1], p[2], mCenter[0], mCenter[1], mCenter[2], mRadius);
}

Vec3d Sphere::gradient(const Vec3d& p) const
{
    // (p - c) times 1 / |p - c|: one division, not three (the batches' arithmetic).
    const Vec3d d = p - mCenter;
    const double len = d.length();
    if (!(len > 0.0)) return Vec3d(0.0, 0.0, 1.0);
    const double inv = 1.0 / len;
    return Vec3d(d[0] * inv, d[1] * inv, d[2] * inv);
}

namespace {

/// Sphere values (|p - c| - r, as sphereValue()) and gradients (as Sphere::gradient()) over a
/// batch, either output null; a loop that vectorizes (the gradients into local arrays, which
/// alias nothing).
IVDB_CLONE_INLINE void spherePoints(const Vec3d& c, double r, const double* x, const double* y,
                                    const double* z, std::size_t n, double* out, double* gx,
                                    double* gy, double* gz)
{
    const double cx = c[0], cy = c[1], cz = c[2];
    double ux[kMaxBatch], uy[kMaxBatch], uz[kMaxBatch], v[kMaxBatch];
    for (std::size_t i = 0; i < n; ++i) {
        const double dx = x[i] - cx, dy = y[i] - cy, dz = z[i] - cz;
        const double len = std::sqrt(dx * dx + dy * dy + dz * dz);
        v[i] = len - r;
        const bool ok = len > 0.0;
        const double inv = 1.0 / (ok ? len : 1.0);
        ux[i] = ok ? dx * inv : 0.0;
        uy[i] = ok ? dy * inv : 0.0;
        uz[i] = ok ? dz * inv : 1.0;
    }
    if (out) std::copy(v, v + n, out);
    if (gx) {
        std::copy(ux, ux + n, gx);
        std::copy(uy, uy + n, gy);
        std::copy(uz, uz + n, gz);
    }
}

} // namespace

IVDB_VECTOR_CLONES
void Sphere::gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                       double* gz, std::size_t n) const
{
    spherePoints(mCenter, mRadius, x, y, z, n, nullptr, gx, gy, gz);
}

IVDB_VECTOR_CLONES
void Sphere::valuesAndGradients(const double* x, const double* y, const double* z, double* out,
                                double* gx, double* gy, double* gz, std::size_t n) const
{
    spherePoints(mCenter, mRadius, x, y, z, n, out, gx, gy, gz);
}

IVDB_VECTOR_CLONES
void Sphere::values(const double* x, const double* y, const double* z, double* out,
                    std::size_t n) const
{
    const double cx = mCenter[0], cy = mCenter[1], cz = mCenter[2], r = mRadius;
    for (std::size_t i = 0; i < n; ++i) out[i] = sphereValue(x[i], y[i], z[i], cx, cy, cz, r);
}

Interval Sphere::interval(const BBoxd& box) const
{
    Interval iv;
    detail::sphereRange(box.min()[0] - mCenter[0], box.max()[0] - mCenter[0],
                        box.min()[1] - mCenter[1], box.max()[1] - mCenter[1],
                        box.min()[2] - mCenter[2], box.max()[2] - mCenter[2], mRadius, iv.lo, iv.hi);
    return iv;
}

IVDB_VECTOR_CLONES
void Sphere::intervals(const double* cx, const double* cy, const double* cz, const Vec3d& half,
                       std::size_t n, double* lo, double* hi) const
{
    // interval() per box (centre +/- half), written out so that the loop vectorizes.
    const double c0 = mCenter[0], c1 = mCenter[1], c2 = mCenter[2], r = mRadius;
    const double h0 = half[0], h1 = half[1], h2 = half[2];
    double near[kMaxBatch], far[kMaxBatch];
    for (std::size_t i = 0; i < n; ++i) {
        detail::sphereRange((cx[i] - h0) - c0, (cx[i] + h0) - c0, (cy[i] - h1) - c1,
                            (cy[i] + h1) - c1, (cz[i] - h2) - c2, (cz[i] + h2) - c2, r, near[i],
                            far[i]);
    }
    std::copy(near, near + n, lo);
    std::copy(far, far + n, hi);
}

BBoxd Sphere::boundingBox() const
{
    return BBoxd(mCenter - Vec3d(mRadius), mCenter + Vec3d(mRadius));
}

// ---- Box ------------------------------------------------------------------------------------

Box::Box(const Vec3d& center, const Vec3d& size): mCenter(center), mHalf(size * 0.5)
{
    requireFinite(center, "box center");
    requireFinite(size, "box size");
    for (int i = 0; i < 3; ++i) requirePositive(size[i], "box size");
}

double Box::value(const Vec3d& p) const { return boxValue(p[0], p[1], p[2], mCenter, mHalf); }

Vec3d Box::gradient(const Vec3d& p) const { return boxGradient(p, mCenter, mHalf); }

void Box::values(const double* x, const double* y, const double* z, double* out,
                 std::size_t n) const
{
    for (std::size_t i = 0; i < n; ++i) out[i] = boxValue(x[i], y[i], z[i], mCenter, mHalf);
}

Interval Box::interval(const BBoxd& box) const { return lipschitzInterval(*this, box); }

BBoxd Box::boundingBox() const { return BBoxd(mCenter - mHalf, mCenter + mHalf); }

// ---- Torus ----------------------------------------------------------------------------------

Torus::Torus(const Vec3d& center, double majorRadius, double minorRadius)
    : mCenter(center), mMajor(majorRadius), mMinor(minorRadius)
{
    requireFinite(center, "torus center");
    requirePositive(majorRadius, "torus major_radius");
    requirePositive(minorRadius, "torus minor_radius");
    if (!(minorRadius < majorRadius)) {
        std::ostringstream os;
        os << "torus minor_radius must be < major_radius (a ring torus), got minor_radius "
           << minorRadius << " and major_radius " << majorRadius;
        OPENVDB_THROW(openvdb::ValueError, os.str());
    }
}

double Torus::value(const Vec3d& p) const
{
    return torusValue(p[0], p[1], p[2], mCenter, mMajor, mMinor);
}

Vec3d Torus::gradient(const Vec3d& p) const
{
    const Vec3d d = p - mCenter;
    const double rho = std::sqrt(d[0] * d[0] + d[1] * d[1]);
    const double q = rho - mMajor;
    const double len = std::sqrt(q * q + d[2] * d[2]);
    if (len <= 0.0) return Vec3d(0.0, 0.0, 1.0);
    const double cx = rho > 0.0 ? d[0] / rho : 1.0, cy = rho > 0.0 ? d[1] / rho : 0.0;
    return Vec3d(q * cx / len, q * cy / len, d[2] / len);
}

void Torus::values(const double* x, const double* y, const double* z, double* out,
                   std::size_t n) const
{
    for (std::size_t i = 0; i < n; ++i) {
        out[i] = torusValue(x[i], y[i], z[i], mCenter, mMajor, mMinor);
    }
}

Interval Torus::interval(const BBoxd& box) const { return lipschitzInterval(*this, box); }

BBoxd Torus::boundingBox() const
{
    const double e = mMajor + mMinor;
    return BBoxd(mCenter - Vec3d(e, e, mMinor), mCenter + Vec3d(e, e, mMinor));
}

// ---- Capsule ------------------------------------------------------------------------------

Capsule::Capsule(const Vec3d& a, const Vec3d& b, double radius)
    : mA(a), mAb(b - a), mRadius(radius)
{
    requireFinite(a, "capsule a");
    requireFinite(b, "capsule b");
    requirePositive(radius, "capsule radius");
    const double len2 = mAb.lengthSqr();
    mInvLen2 = len2 > 0.0 ? 1.0 / len2 : 0.0;
}

double Capsule::value(const Vec3d& p) const
{
    return segmentOffset(p, mA, mAb, mInvLen2).length() - mRadius;
}

Vec3d Capsule::gradient(const Vec3d& p) const
{
    const Vec3d d = segmentOffset(p, mA, mAb, mInvLen2);
    const double len = d.length();
    return len > 0.0 ? d / len : Vec3d(0.0, 0.0, 1.0);
}

void Capsule::values(const double* x, const double* y, const double* z, double* out,
                     std::size_t n) const
{
    for (std::size_t i = 0; i < n; ++i) out[i] = value(Vec3d(x[i], y[i], z[i]));
}

Interval Capsule::interval(const BBoxd& box) const { return lipschitzInterval(*this, box); }

BBoxd Capsule::boundingBox() const
{
    const Vec3d b = mA + mAb;
    return BBoxd(minComponent(mA, b) - Vec3d(mRadius), maxComponent(mA, b) + Vec3d(mRadius));
}

// ---- RoundedBox -----------------------------------------------------------------------------

RoundedBox::RoundedBox(const Vec3d& center, const Vec3d& size, double radius)
    : mCenter(center), mInner(size * 0.5 - Vec3d(radius)), mRadius(radius)
{
    requireFinite(center, "rounded_box center");
    requireFinite(size, "rounded_box size");
    for (int i = 0; i < 3; ++i) requirePositive(size[i], "rounded_box size");
    requirePositive(radius, "rounded_box radius");
    const double most = 0.5 * std::min({size[0], size[1], size[2]});
    if (!(radius <= most)) {
        std::ostringstream os;
        os << "rounded_box radius must be <= half the smallest size (" << most << "), got "
           << radius;
        OPENVDB_THROW(openvdb::ValueError, os.str());
    }
}

double RoundedBox::value(const Vec3d& p) const
{
    return boxValue(p[0], p[1], p[2], mCenter, mInner) - mRadius;
}

Vec3d RoundedBox::gradient(const Vec3d& p) const { return boxGradient(p, mCenter, mInner); }

void RoundedBox::values(const double* x, const double* y, const double* z, double* out,
                        std::size_t n) const
{
    for (std::size_t i = 0; i < n; ++i) {
        out[i] = boxValue(x[i], y[i], z[i], mCenter, mInner) - mRadius;
    }
}

Interval RoundedBox::interval(const BBoxd& box) const { return lipschitzInterval(*this, box); }

BBoxd RoundedBox::boundingBox() const
{
    const Vec3d h = mInner + Vec3d(mRadius);
    return BBoxd(mCenter - h, mCenter + h);
}

// ---- CappedCone -----------------------------------------------------------------------------

CappedCone::CappedCone(const Vec3d& a, const Vec3d& b, double radiusA, double radiusB,
                       std::string name)
    : mA(a), mRadiusA(radiusA), mRadiusB(radiusB), mName(std::move(name))
{
    requireFinite(a, (mName + " a").c_str());
    requireFinite(b, (mName + " b").c_str());
    if (!(radiusA >= 0.0) || !(radiusB >= 0.0) || !std::isfinite(radiusA) ||
        !std::isfinite(radiusB) || (radiusA == 0.0 && radiusB == 0.0)) {
        std::ostringstream os;
        os << mName << " radii must be >= 0, finite and not both 0, got " << radiusA << " and "
           << radiusB;
        OPENVDB_THROW(openvdb::ValueError, os.str());
    }
    mLength = (b - a).length();
    if (!(mLength > 0.0)) {
        OPENVDB_THROW(openvdb::ValueError, mName + " a and b must be different points");
    }
    mAxis = (b - a) / mLength;
    // Any unit vector normal to the axis: the axis crossed with its least aligned unit axis.
    const int least = std::abs(mAxis[0]) <= std::abs(mAxis[1])
        ? (std::abs(mAxis[0]) <= std::abs(mAxis[2]) ? 0 : 2)
        : (std::abs(mAxis[1]) <= std::abs(mAxis[2]) ? 1 : 2);
    Vec3d e(0.0);
    e[least] = 1.0;
    mPerp = mAxis.cross(e).unitSafe();
}

double CappedCone::distance(const Vec3d& p, double dir[2], Vec3d& radial) const
{
    const Vec3d q = p - mA;
    const double t = q.dot(mAxis);
    const Vec3d w = q - mAxis * t;
    const double rho = w.length();
    radial = rho > 0.0 ? w / rho : mPerp;
    // The three edges off the axis: the cap at a, the side, the cap at b, with their outward
    // normals (for a point exactly on one).
    const double L = mLength, ra = mRadiusA, rb = mRadiusB;
    const double ends[3][4] = {{0.0, 0.0, ra, 0.0}, {ra, 0.0, rb, L}, {rb, L, 0.0, L}};
    const double sideLen = std::sqrt((rb - ra) * (rb - ra) + L * L);
    const double normals[3][2] = {{0.0, -1.0}, {L / sideLen, (ra - rb) / sideLen}, {0.0, 1.0}};
    double best = std::numeric_limits<double>::max(), bx = 0.0, by = 0.0;
    int edge = 0;
    for (int e = 0; e < 3; ++e) {
        double cx, cy;
        const double d2 =
            nearestOnSegment2(rho, t, ends[e][0], ends[e][1], ends[e][2], ends[e][3], cx, cy);
        if (d2 < best) best = d2, bx = cx, by = cy, edge = e;
    }
    const bool inside = t >= 0.0 && t <= L && rho * L <= ra * L + (rb - ra) * t;
    const double d = std::sqrt(best), s = inside ? -1.0 : 1.0;
    // The direction from the nearest point, unless p is on the surface within rounding: there
    // (rho, t) - (bx, by) is rounding noise, and the edge's normal is the gradient.
    if (d > 1e-10 * (L + ra + rb)) {
        dir[0] = s * (rho - bx) / d;
        dir[1] = s * (t - by) / d;
    } else {
        dir[0] = normals[edge][0];
        dir[1] = normals[edge][1];
    }
    return s * d;
}

double CappedCone::value(const Vec3d& p) const
{
    return cappedConeValue(p[0], p[1], p[2], mA, mAxis, mLength, mRadiusA, mRadiusB);
}

Vec3d CappedCone::gradient(const Vec3d& p) const
{
    double dir[2];
    Vec3d radial;
    distance(p, dir, radial);
    return radial * dir[0] + mAxis * dir[1];
}

IVDB_VECTOR_CLONES
void CappedCone::values(const double* x, const double* y, const double* z, double* out,
                        std::size_t n) const
{
    const Vec3d a = mA, axis = mAxis;
    const double L = mLength, ra = mRadiusA, rb = mRadiusB;
    for (std::size_t i = 0; i < n; ++i) out[i] = cappedConeValue(x[i], y[i], z[i], a, axis, L, ra, rb);
}

Interval CappedCone::interval(const BBoxd& box) const { return lipschitzInterval(*this, box); }

BBoxd CappedCone::boundingBox() const
{
    // Each end is a disc normal to the axis: its extent along x_i is r sqrt(1 - axis_i^2).
    Vec3d ext;
    for (int i = 0; i < 3; ++i) ext[i] = std::sqrt(std::max(0.0, 1.0 - mAxis[i] * mAxis[i]));
    const Vec3d b = mA + mAxis * mLength;
    BBoxd box(mA - ext * mRadiusA, mA + ext * mRadiusA);
    box.expand(BBoxd(b - ext * mRadiusB, b + ext * mRadiusB));
    return box;
}

} // namespace ivdb::implicit
