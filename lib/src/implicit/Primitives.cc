// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/Primitives.h>

#include "Checks.h"

#include <openvdb/Exceptions.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace ivdb::implicit {

using detail::requireFinite;
using detail::requirePositive;

namespace {



// The per-point formulas, shared by value() and values() so both give the same bits.
inline double sphereValue(double x, double y, double z, double cx, double cy, double cz, double r)
{
    const double dx = x - cx, dy = y - cy, dz = z - cz;
    return std::sqrt(dx * dx + dy * dy + dz * dz) - r;
}

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
    const Vec3d d = p - mCenter;
    const double len = d.length();
    return len > 0.0 ? d / len : Vec3d(0.0, 0.0, 1.0);
}

void Sphere::gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                       double* gz, std::size_t n) const
{
    for (std::size_t i = 0; i < n; ++i) {
        const Vec3d g = gradient(Vec3d(x[i], y[i], z[i])); // inlined: the same arithmetic
        gx[i] = g[0];
        gy[i] = g[1];
        gz[i] = g[2];
    }
}

void Sphere::values(const double* x, const double* y, const double* z, double* out,
                    std::size_t n) const
{
    const double cx = mCenter[0], cy = mCenter[1], cz = mCenter[2], r = mRadius;
    for (std::size_t i = 0; i < n; ++i) out[i] = sphereValue(x[i], y[i], z[i], cx, cy, cz, r);
}

Interval Sphere::interval(const BBoxd& box) const
{
    // Exact range of |p - c| over the box: nearest point (clamped) and farthest corner.
    double near2 = 0.0, far2 = 0.0;
    for (int i = 0; i < 3; ++i) {
        const double lo = box.min()[i] - mCenter[i], hi = box.max()[i] - mCenter[i];
        const double n = lo > 0.0 ? lo : (hi < 0.0 ? hi : 0.0);
        const double f = std::max(std::abs(lo), std::abs(hi));
        near2 += n * n;
        far2 += f * f;
    }
    return {std::sqrt(near2) - mRadius, std::sqrt(far2) - mRadius};
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

Vec3d Box::gradient(const Vec3d& p) const
{
    Vec3d q, s;
    for (int i = 0; i < 3; ++i) {
        const double d = p[i] - mCenter[i];
        s[i] = d < 0.0 ? -1.0 : 1.0;
        q[i] = std::abs(d) - mHalf[i];
    }
    const Vec3d o(std::max(q[0], 0.0), std::max(q[1], 0.0), std::max(q[2], 0.0));
    const double len = o.length();
    if (len > 0.0) {
        return Vec3d(s[0] * o[0], s[1] * o[1], s[2] * o[2]) / len;
    }
    // Inside: the gradient points along the axis of the nearest face.
    const int axis = (q[0] >= q[1] && q[0] >= q[2]) ? 0 : (q[1] >= q[2] ? 1 : 2);
    Vec3d g(0.0);
    g[axis] = s[axis];
    return g;
}

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

} // namespace ivdb::implicit
