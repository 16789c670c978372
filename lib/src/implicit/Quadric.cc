// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/Quadric.h>

#include "../util/Simd.h"
#include "Checks.h"

#include <openvdb/Exceptions.h>
#include <openvdb/math/Mat3.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace ivdb::implicit {

using detail::requireFinite;
using detail::requirePositive;

namespace {

inline double quadricValue(const Mat4& q, double x, double y, double z)
{
    // p^T A p + 2 b.p + c, written out so value() and values() round identically.
    return x * (q[0][0] * x + 2.0 * (q[0][1] * y + q[0][2] * z + q[0][3]))
         + y * (q[1][1] * y + 2.0 * (q[1][2] * z + q[1][3]))
         + z * (q[2][2] * z + 2.0 * q[2][3]) + q[3][3];
}

double det3(const double m[3][3])
{
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
         - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
         + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}



Mat4 diagonal(double a, double b, double c, double d)
{
    Mat4 q{};
    q[0][0] = a; q[1][1] = b; q[2][2] = c; q[3][3] = d;
    return q;
}

} // namespace

Quadric::Quadric(const Mat4& q): mQ(q), mBox(infiniteBox())
{
    double scale = 0.0;
    for (int i = 0; i < 4; ++i) {
        for (int j = 0; j < 4; ++j) {
            if (!std::isfinite(q[i][j])) {
                std::ostringstream os;
                os << "quadric matrix[" << i << "][" << j << "] must be finite, got " << q[i][j];
                OPENVDB_THROW(openvdb::ValueError, os.str());
            }
            scale = std::max(scale, std::abs(q[i][j]));
        }
    }
    if (scale == 0.0) OPENVDB_THROW(openvdb::ValueError, "quadric matrix is all zero: no surface");
    for (int i = 0; i < 4; ++i) {
        for (int j = i + 1; j < 4; ++j) {
            if (std::abs(q[i][j] - q[j][i]) > 1e-12 * scale) {
                std::ostringstream os;
                os << "quadric matrix must be symmetric, got matrix[" << i << "][" << j
                   << "] = " << q[i][j] << " but matrix[" << j << "][" << i << "] = " << q[j][i];
                OPENVDB_THROW(openvdb::ValueError, os.str());
            }
        }
    }
    // Symmetrize exactly so value and gradient agree.
    for (int i = 0; i < 4; ++i) {
        for (int j = i + 1; j < 4; ++j) mQ[i][j] = mQ[j][i] = 0.5 * (q[i][j] + q[j][i]);
    }
    prepareFootPoints();

    const double a[3][3] = {{mQ[0][0], mQ[0][1], mQ[0][2]},
                            {mQ[1][0], mQ[1][1], mQ[1][2]},
                            {mQ[2][0], mQ[2][1], mQ[2][2]}};
    double aScale = 0.0;
    for (auto& row : a) for (double v : row) aScale = std::max(aScale, std::abs(v));
    if (aScale == 0.0) {
        const double n = 2.0 * std::sqrt(mQ[0][3] * mQ[0][3] + mQ[1][3] * mQ[1][3] +
                                         mQ[2][3] * mQ[2][3]);
        mIsPlaneSdf = std::abs(n - 1.0) < 1e-12;
        if (n == 0.0) {
            // f is the constant c: everywhere inside or everywhere outside, no surface.
            OPENVDB_THROW(openvdb::ValueError,
                "quadric matrix is constant (only matrix[3][3] is non-zero): no surface");
        }
        return;
    }
    // Bounded iff A is positive definite (Sylvester's criterion): an ellipsoid, or empty.
    const double m1 = a[0][0], m2 = a[0][0] * a[1][1] - a[0][1] * a[1][0], m3 = det3(a);
    const double tol = 1e-14;
    if (m1 > tol * aScale && m2 > tol * aScale * aScale && m3 > tol * aScale * aScale * aScale) {
        // Inverse of A by cofactors; center m = -A^-1 b; k = f(m) = c - b^T A^-1 b.
        double inv[3][3];
        inv[0][0] = (a[1][1] * a[2][2] - a[1][2] * a[2][1]) / m3;
        inv[0][1] = (a[0][2] * a[2][1] - a[0][1] * a[2][2]) / m3;
        inv[0][2] = (a[0][1] * a[1][2] - a[0][2] * a[1][1]) / m3;
        inv[1][0] = inv[0][1];
        inv[1][1] = (a[0][0] * a[2][2] - a[0][2] * a[2][0]) / m3;
        inv[1][2] = (a[0][2] * a[1][0] - a[0][0] * a[1][2]) / m3;
        inv[2][0] = inv[0][2];
        inv[2][1] = inv[1][2];
        inv[2][2] = (a[0][0] * a[1][1] - a[0][1] * a[1][0]) / m3;
        const double b[3] = {mQ[0][3], mQ[1][3], mQ[2][3]};
        Vec3d center;
        for (int i = 0; i < 3; ++i) {
            center[i] = -(inv[i][0] * b[0] + inv[i][1] * b[1] + inv[i][2] * b[2]);
        }
        const double k = value(center);
        if (!(k < 0.0)) {
            mIsEmpty = true;
            mBox = BBoxd(center, center);
            return;
        }
        Vec3d half;
        for (int i = 0; i < 3; ++i) half[i] = std::sqrt(-k * inv[i][i]);
        mBox = BBoxd(center - half, center + half);
    }
}

void Quadric::prepareFootPoints()
{
    // A = R diag(d) R^T, so that the foot point's equation separates (see footPoints()).
    openvdb::math::Mat3d a, r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) a(i, j) = mQ[i][j];
    openvdb::math::Vec3d d;
    if (!openvdb::math::diagonalizeSymmetricMatrix(a, r, d)) return;
    double scale = 0.0, err = 0.0;
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
            double back = 0.0;
            for (int k = 0; k < 3; ++k) back += r(i, k) * d[k] * r(j, k);
            err = std::max(err, std::abs(back - a(i, j)));
            scale = std::max(scale, std::abs(a(i, j)));
        }
    }
    if (!(err <= 1e-12 * std::max(scale, 1e-300))) return;
    for (int i = 0; i < 3; ++i) {
        mEigen[i] = d[i];
        for (int j = 0; j < 3; ++j) mFrame[i][j] = r(i, j);
    }
    for (int k = 0; k < 3; ++k) {
        mLinear[k] = mFrame[0][k] * mQ[0][3] + mFrame[1][k] * mQ[1][3] + mFrame[2][k] * mQ[2][3];
    }
    mHasFrame = true;
}

namespace {

/// A quadric in the eigenframe of its matrix A (primes): f = sum_i d_i q'_i^2 + 2 b'_i q'_i + c.
/// The foot point q of p satisfies p - q = mu grad f(q) = 2 mu (A q + b), that is
/// (1 + 2 mu d_i) q'_i = p'_i - 2 mu b'_i: q is a function of mu alone, and g(mu) = f(q(mu)) = 0
/// is one equation in one unknown, solved by Newton's method. The nearest foot point has
/// 1 + 2 mu d_i > 0 for every i, mu in (lo, hi); an iteration that leaves that region (near a
/// medial axis) is not certified.
struct EigenQuadric
{
    double d0, d1, d2, b0, b1, b2, c;
    double lo, hi;

    EigenQuadric(const double eigen[3], const double linear[3], double constant)
        : d0(eigen[0]), d1(eigen[1]), d2(eigen[2]), b0(linear[0]), b1(linear[1]), b2(linear[2]),
          c(constant)
    {
        const double dMax = std::max({d0, d1, d2}), dMin = std::min({d0, d1, d2});
        const double inf = std::numeric_limits<double>::infinity();
        lo = dMax > 0.0 ? -0.5 / dMax : -inf;
        hi = dMin < 0.0 ? -0.5 / dMin : inf;
    }

    /// One Newton step for the point (a, b, e) in the eigenframe: mu moves, the step is returned.
    IVDB_CLONE_INLINE double newtonStep(double a, double b, double e, double& u) const
    {
        const double i0 = 1.0 / (1.0 + 2.0 * u * d0), i1 = 1.0 / (1.0 + 2.0 * u * d1),
                     i2 = 1.0 / (1.0 + 2.0 * u * d2);
        const double q0 = (a - 2.0 * u * b0) * i0, q1 = (b - 2.0 * u * b1) * i1,
                     q2 = (e - 2.0 * u * b2) * i2;
        const double t0 = d0 * q0 + b0, t1 = d1 * q1 + b1, t2 = d2 * q2 + b2;
        const double g = q0 * (d0 * q0 + 2.0 * b0) + q1 * (d1 * q1 + 2.0 * b1) +
                         q2 * (d2 * q2 + 2.0 * b2) + c;
        // dg < 0 where every 1 + 2 mu d_i > 0 (the starting point and every step stay there).
        const double dg = std::min(-4.0 * (t0 * t0 * i0 + t1 * t1 * i1 + t2 * t2 * i2), -1e-300);
        // Newton's step, kept inside (lo, hi): at most halfway to either edge (selects, no
        // branches, so that the loop over a batch vectorizes).
        const double next = std::min(std::max(u - g / dg, 0.5 * (u + lo)), 0.5 * (u + hi));
        const double s = u - next;
        u = next;
        return s;
    }

    /// The foot point (q0, q1, q2) for the multiplier @a u of the point (a, b, e), its distance,
    /// and whether it is certified: on the surface within @a tol, inside (lo, hi), its distance
    /// within @a agreement of the estimate @a est, and at most @a cap (the distance to a point
    /// of the surface already known) beyond the tolerance.
    IVDB_CLONE_INLINE bool foot(double a, double b, double e, double u, double est, double cap,
                                double tol, double agreement, double& q0, double& q1,
                                double& q2, double& dist) const
    {
        const double e0 = 1.0 + 2.0 * u * d0, e1 = 1.0 + 2.0 * u * d1, e2 = 1.0 + 2.0 * u * d2;
        q0 = (a - 2.0 * u * b0) / e0;
        q1 = (b - 2.0 * u * b1) / e1;
        q2 = (e - 2.0 * u * b2) / e2;
        const double g0 = 2.0 * (d0 * q0 + b0), g1 = 2.0 * (d1 * q1 + b1), g2 = 2.0 * (d2 * q2 + b2);
        const double glq = std::sqrt(g0 * g0 + g1 * g1 + g2 * g2);
        const double g = q0 * (d0 * q0 + 2.0 * b0) + q1 * (d1 * q1 + 2.0 * b1) +
                         q2 * (d2 * q2 + 2.0 * b2) + c;
        const double r0 = a - q0, r1 = b - q1, r2 = e - q2;
        dist = std::sqrt(r0 * r0 + r1 * r1 + r2 * r2);
        return std::min(e0, std::min(e1, e2)) > 0.0 && glq > 0.0 && std::abs(g) <= tol * glq &&
               std::abs(dist - est) <= agreement * est + tol && dist <= cap + tol;
    }
};

} // namespace

// GCC cannot see that only the entries written are read.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
IVDB_VECTOR_CLONES
void Quadric::footPoints(const double* x, const double* y, const double* z, const double* values,
                         std::size_t n, const FootQuery& query, FootPoints& out) const
{
    if (!mHasFrame || mIsPlaneSdf) {
        Implicit::footPoints(x, y, z, values, n, query, out);
        return;
    }
    // Newton's method on g(mu) (EigenQuadric) from the first-order mu = f / |grad f|^2. It
    // converges quadratically: three steps for all points (a loop the compiler vectorizes; the
    // third is below 1e-6 mu almost everywhere in the band), more only where the surface curves
    // strongly within the distance.
    const EigenQuadric q(mEigen, mLinear, mQ[3][3]);
    const double normA = std::max({std::abs(q.d0), std::abs(q.d1), std::abs(q.d2)});
    double p0[kMaxBatch], p1[kMaxBatch], p2[kMaxBatch], mu[kMaxBatch], step[kMaxBatch];
    // The points in the eigenframe, their gradients and first-order estimates (a loop that
    // vectorizes), then the ones near enough to need the foot point, compacted.
    double e[kMaxBatch], gl[kMaxBatch], along[kMaxBatch], cap[kMaxBatch];
    bool near[kMaxBatch];
    const double far = query.far, reach = normA * query.far * query.far;
    for (std::size_t i = 0; i < n; ++i) {
        p0[i] = mFrame[0][0] * x[i] + mFrame[1][0] * y[i] + mFrame[2][0] * z[i];
        p1[i] = mFrame[0][1] * x[i] + mFrame[1][1] * y[i] + mFrame[2][1] * z[i];
        p2[i] = mFrame[0][2] * x[i] + mFrame[1][2] * y[i] + mFrame[2][2] * z[i];
        const double g0 = 2.0 * (q.d0 * p0[i] + q.b0), g1 = 2.0 * (q.d1 * p1[i] + q.b1),
                     g2 = 2.0 * (q.d2 * p2[i] + q.b2);
        gl[i] = std::sqrt(g0 * g0 + g1 * g1 + g2 * g2);
        e[i] = values[i] / gl[i];
        // The distance along the normal line to where it crosses the surface: f(p + t n) =
        // f + |grad f| t + (n^T A n) t^2 exactly, its root nearest 0 (a circle's distance
        // exactly, where f / |grad f| is 25% off a third of the radius inside). A point of the
        // surface: no foot point is certified beyond it. Where the line does not cross, |e|.
        const double curve = (q.d0 * g0 * g0 + q.d1 * g1 * g1 + q.d2 * g2 * g2) / (gl[i] * gl[i]);
        const double disc = gl[i] * gl[i] - 4.0 * curve * values[i];
        const bool crosses = disc >= 0.0;
        along[i] = crosses ? 2.0 * std::abs(values[i]) / (gl[i] + std::sqrt(std::max(disc, 0.0)))
                           : std::abs(e[i]);
        cap[i] = crosses ? along[i] : std::numeric_limits<double>::infinity();
        const double v = values[i];
        const bool valid = gl[i] > 0.0 && std::isfinite(gl[i]);
        // f(p + h) = f(p) + grad f . h + h^T A h: no surface within far of p if |f| exceeds
        // what the two terms can take away (then |e| > far too).
        const bool beyond = v == 0.0 || std::abs(v) > gl[i] * far + reach;
        out.distance[i] = valid ? e[i] : (v > 0.0 ? far : -far);
        out.ok[i] = valid && beyond;
        near[i] = valid && !beyond;
        // The first-order multiplier, moved inside (lo, hi) if it is not.
        double u = v / (gl[i] * gl[i]);
        u = u <= q.lo ? 0.5 * q.lo : u;
        u = u >= q.hi ? 0.5 * q.hi : u;
        mu[i] = u;
    }
    std::copy(x, x + n, out.x);
    std::copy(y, y + n, out.y);
    std::copy(z, z + n, out.z);
    // The near points compacted, without branches (every point is written, and the next
    // overwrites it unless it is near).
    std::size_t idx[kMaxBatch], m = 0;
    for (std::size_t i = 0; i < n; ++i) {
        idx[m] = i;
        p0[m] = p0[i];
        p1[m] = p1[i];
        p2[m] = p2[i];
        mu[m] = mu[i];
        along[m] = along[i]; // compacted too: read as along[idx[k]] it was a gather, slower
        cap[m] = cap[i];
        m += near[i] ? 1 : 0;
    }
    for (int round = 0; round < 3; ++round) {
        for (std::size_t k = 0; k < m; ++k) step[k] = q.newtonStep(p0[k], p1[k], p2[k], mu[k]);
    }
    for (std::size_t k = 0; k < m; ++k) {
        // Further steps where the two were not enough (a surface curving within the distance):
        // the error after a step of relative size s is about s^2, so a last step below 1e-6
        // leaves mu right to 1e-12 (and where neighbours stop after different numbers of steps
        // their distances differ by that much: far below what curvature can see).
        for (int it = 0; it < 12 && std::abs(step[k]) > 1e-6 * std::abs(mu[k]); ++it) {
            step[k] = q.newtonStep(p0[k], p1[k], p2[k], mu[k]);
        }
    }
    // The foot points (in the eigenframe), the distances and the certificates: a vectorized loop.
    // On an ellipsoid (A positive definite) g is strictly decreasing where every 1 + 2 mu d_i >
    // 0, and its one root there is the closest point: certified. Other quadrics also check the
    // distance against the crossing of the normal line (a point of the surface: never beyond
    // it), as the smooth iteration does against the first-order estimate.
    double q0[kMaxBatch], q1[kMaxBatch], q2[kMaxBatch], dist[kMaxBatch], good[kMaxBatch];
    const double agreement = q.d0 > 0.0 && q.d1 > 0.0 && q.d2 > 0.0
                                 ? std::numeric_limits<double>::infinity() : 0.25;
    for (std::size_t k = 0; k < m; ++k) {
        good[k] = q.foot(p0[k], p1[k], p2[k], mu[k], along[k], cap[k], query.tolerance,
                         agreement, q0[k], q1[k], q2[k], dist[k]) ? 1.0 : 0.0;
    }
    for (std::size_t k = 0; k < m; ++k) {
        if (good[k] == 0.0) continue;
        const std::size_t i = idx[k];
        out.distance[i] = std::copysign(dist[k], values[i]);
        out.ok[i] = true;
        if (!query.feet) continue;
        out.x[i] = mFrame[0][0] * q0[k] + mFrame[0][1] * q1[k] + mFrame[0][2] * q2[k];
        out.y[i] = mFrame[1][0] * q0[k] + mFrame[1][1] * q1[k] + mFrame[1][2] * q2[k];
        out.z[i] = mFrame[2][0] * q0[k] + mFrame[2][1] * q1[k] + mFrame[2][2] * q2[k];
    }
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

double Quadric::value(const Vec3d& p) const { return quadricValue(mQ, p[0], p[1], p[2]); }

Vec3d Quadric::gradient(const Vec3d& p) const
{
    Vec3d g;
    for (int i = 0; i < 3; ++i) {
        g[i] = 2.0 * (mQ[i][0] * p[0] + mQ[i][1] * p[1] + mQ[i][2] * p[2] + mQ[i][3]);
    }
    return g;
}

IVDB_VECTOR_CLONES
void Quadric::values(const double* x, const double* y, const double* z, double* out,
                     std::size_t n) const
{
    const Mat4 q = mQ;
    for (std::size_t i = 0; i < n; ++i) out[i] = quadricValue(q, x[i], y[i], z[i]);
}

void Quadric::gradients(const double* x, const double* y, const double* z, double* gx,
                        double* gy, double* gz, std::size_t n) const
{
    const Mat4 q = mQ;
    for (std::size_t i = 0; i < n; ++i) {
        gx[i] = 2.0 * (q[0][0] * x[i] + q[0][1] * y[i] + q[0][2] * z[i] + q[0][3]);
        gy[i] = 2.0 * (q[1][0] * x[i] + q[1][1] * y[i] + q[1][2] * z[i] + q[1][3]);
        gz[i] = 2.0 * (q[2][0] * x[i] + q[2][1] * y[i] + q[2][2] * z[i] + q[2][3]);
    }
}

Interval Quadric::interval(const BBoxd& box) const
{
    const Vec3d m = box.getCenter();
    const Vec3d h = (box.max() - box.min()) * 0.5;
    const Vec3d g = gradient(m);
    double lo = value(m), hi = lo;
    for (int i = 0; i < 3; ++i) {
        const double lin = std::abs(g[i]) * h[i];
        const double sq = mQ[i][i] * h[i] * h[i];
        lo += -lin + std::min(sq, 0.0);
        hi += lin + std::max(sq, 0.0);
        for (int j = i + 1; j < 3; ++j) {
            const double cross = 2.0 * std::abs(mQ[i][j]) * h[i] * h[j];
            lo -= cross;
            hi += cross;
        }
    }
    return {lo, hi};
}

IVDB_VECTOR_CLONES
void Quadric::intervals(const double* cx, const double* cy, const double* cz, const Vec3d& half,
                        std::size_t n, double* lo, double* hi) const
{
    // interval() per box, with the terms that depend only on the boxes' common size summed once.
    const Mat4 q = mQ;
    const double h[3] = {half[0], half[1], half[2]};
    double down = 0.0, up = 0.0;
    for (int i = 0; i < 3; ++i) {
        const double sq = q[i][i] * h[i] * h[i];
        down += std::min(sq, 0.0);
        up += std::max(sq, 0.0);
        for (int j = i + 1; j < 3; ++j) {
            const double cross = 2.0 * std::abs(q[i][j]) * h[i] * h[j];
            down -= cross;
            up += cross;
        }
    }
    for (std::size_t i = 0; i < n; ++i) {
        const double x = cx[i], y = cy[i], z = cz[i];
        const double g0 = 2.0 * (q[0][0] * x + q[0][1] * y + q[0][2] * z + q[0][3]);
        const double g1 = 2.0 * (q[1][0] * x + q[1][1] * y + q[1][2] * z + q[1][3]);
        const double g2 = 2.0 * (q[2][0] * x + q[2][1] * y + q[2][2] * z + q[2][3]);
        const double lin = std::abs(g0) * h[0] + std::abs(g1) * h[1] + std::abs(g2) * h[2];
        const double v = quadricValue(q, x, y, z);
        lo[i] = v - lin + down;
        hi[i] = v + lin + up;
    }
}

BBoxd Quadric::boundingBox() const { return mBox; }

std::array<Vec3d, 3> frameFromAxis(const Vec3d& axis)
{
    requireFinite(axis, "axis");
    const double len = axis.length();
    if (!(len > 0.0)) OPENVDB_THROW(openvdb::ValueError, "axis must be non-zero");
    const Vec3d a = axis / len;
    const double c = a[2]; // cos of the angle between +z and a
    if (c > 1.0 - 1e-15) return {Vec3d(1, 0, 0), Vec3d(0, 1, 0), Vec3d(0, 0, 1)};
    if (c < -1.0 + 1e-15) return {Vec3d(1, 0, 0), Vec3d(0, -1, 0), Vec3d(0, 0, -1)};
    // Rodrigues: R = I + [v]x + [v]x^2 / (1 + c) with v = z x a.
    const Vec3d v(-a[1], a[0], 0.0);
    const double k = 1.0 / (1.0 + c);
    const double r[3][3] = {
        {1.0 - k * v[1] * v[1], k * v[0] * v[1], v[1]},
        {k * v[0] * v[1], 1.0 - k * v[0] * v[0], -v[0]},
        {-v[1], v[0], c}};
    return {Vec3d(r[0][0], r[1][0], r[2][0]), Vec3d(r[0][1], r[1][1], r[2][1]),
            Vec3d(r[0][2], r[1][2], r[2][2])};
}

Mat4 placeQuadric(const Mat4& local, const Vec3d& origin, const std::array<Vec3d, 3>& frame)
{
    // local q = R^T (p - o), i.e. [q 1] = M [p 1] with M = [[R^T, -R^T o], [0, 1]].
    Mat4 m{};
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) m[i][j] = frame[i][j];
        m[i][3] = -frame[i].dot(origin);
    }
    m[3][3] = 1.0;
    return mapQuadric(local, m);
}

Mat4 mapQuadric(const Mat4& local, const Mat4& m)
{
    // Q_world = M^T Q_local M.
    double t[4][4] = {};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            for (int k = 0; k < 4; ++k) t[i][j] += local[i][k] * m[k][j];
    Mat4 out{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            for (int k = 0; k < 4; ++k) out[i][j] += m[k][i] * t[k][j];
    // Remove rounding asymmetry.
    for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) out[i][j] = out[j][i] = 0.5 * (out[i][j] + out[j][i]);
    return out;
}

Implicit::Ptr makePlane(const Vec3d& normal, double offset)
{
    requireFinite(normal, "plane normal");
    if (!std::isfinite(offset)) OPENVDB_THROW(openvdb::ValueError, "plane offset must be finite");
    const double len = normal.length();
    if (!(len > 0.0)) OPENVDB_THROW(openvdb::ValueError, "plane normal must be non-zero");
    const Vec3d n = normal / len;
    Mat4 q{};
    for (int i = 0; i < 3; ++i) q[i][3] = q[3][i] = 0.5 * n[i];
    q[3][3] = -offset / len;
    return std::make_shared<Quadric>(q);
}

Implicit::Ptr makeCylinder(const Vec3d& center, const Vec3d& axis, double radius)
{
    requireFinite(center, "cylinder center");
    requirePositive(radius, "cylinder radius");
    return std::make_shared<Quadric>(
        placeQuadric(diagonal(1.0, 1.0, 0.0, -radius * radius), center, frameFromAxis(axis)));
}

Implicit::Ptr makeEllipsoid(const Vec3d& center, const Vec3d& radii)
{
    requireFinite(center, "ellipsoid center");
    for (int i = 0; i < 3; ++i) requirePositive(radii[i], "ellipsoid radii");
    Mat4 q = diagonal(1.0 / (radii[0] * radii[0]), 1.0 / (radii[1] * radii[1]),
                      1.0 / (radii[2] * radii[2]), -1.0);
    return std::make_shared<Quadric>(placeQuadric(q, center, frameFromAxis(Vec3d(0, 0, 1))));
}

Implicit::Ptr makeCone(const Vec3d& apex, const Vec3d& axis, double halfAngleDeg)
{
    requireFinite(apex, "cone apex");
    if (!(halfAngleDeg > 0.0 && halfAngleDeg < 90.0)) {
        std::ostringstream os;
        os << "cone half_angle_deg must be in (0, 90), got " << halfAngleDeg;
        OPENVDB_THROW(openvdb::ValueError, os.str());
    }
    const double t = std::tan(halfAngleDeg * M_PI / 180.0);
    return std::make_shared<Quadric>(
        placeQuadric(diagonal(1.0, 1.0, -t * t, 0.0), apex, frameFromAxis(axis)));
}

Implicit::Ptr makeParaboloid(const Vec3d& vertex, const Vec3d& axis, bool hyperbolic, double a,
                             double b)
{
    requireFinite(vertex, "paraboloid vertex");
    requirePositive(a, "paraboloid a");
    requirePositive(b, "paraboloid b");
    Mat4 q = diagonal(1.0 / (a * a), (hyperbolic ? -1.0 : 1.0) / (b * b), 0.0, 0.0);
    q[2][3] = q[3][2] = -0.5;
    return std::make_shared<Quadric>(placeQuadric(q, vertex, frameFromAxis(axis)));
}

Implicit::Ptr makeHyperboloid(const Vec3d& center, const Vec3d& axis, bool twoSheets,
                              const Vec3d& radii)
{
    requireFinite(center, "hyperboloid center");
    for (int i = 0; i < 3; ++i) requirePositive(radii[i], "hyperboloid radii");
    Mat4 q = diagonal(1.0 / (radii[0] * radii[0]), 1.0 / (radii[1] * radii[1]),
                      -1.0 / (radii[2] * radii[2]), twoSheets ? 1.0 : -1.0);
    return std::make_shared<Quadric>(placeQuadric(q, center, frameFromAxis(axis)));
}

} // namespace ivdb::implicit
