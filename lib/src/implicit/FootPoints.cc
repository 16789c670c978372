// SPDX-License-Identifier: Apache-2.0
// True distances found locally (docs/method.md#true-distances): foot points on the surface of
// exact SDFs, of smooth fields (Newton steps), and of CSG nodes (their children's foot points,
// and the crease where two children meet).
#include <ivdb/implicit/Blend.h>
#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/Modifiers.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/implicit/Quadric.h>

#include "../util/Simd.h"
#include "Feet.h"
#include "Scratch.h"
#include "SphereMath.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <limits>
#include <memory>
#include <vector>

namespace ivdb::implicit {

namespace {

/// The smooth-field iteration (and the crease iteration) repeats its round (a projection onto
/// the surface along the gradient, then a move towards the foot of the perpendicular; the
/// tangential error shrinks by about kappa d a round) until the distance it reports is within
/// kConverged of the tolerance, at most kMaxRounds times. Converging that far, not stopping at
/// the tolerance, keeps the distances a smooth function of the query point: neighbours that stop
/// after different numbers of rounds differ by far less than a voxel's second differences can
/// see (curvature stays smooth).
constexpr int kMaxRounds = 12;
/// The crease iteration's rounds (creasePoint()): where two surfaces meet at a shallow angle, or
/// the crease curves tightly (a rounded box's edge) for its distance from the point, the
/// tangential error shrinks by a constant factor near 1 a round. A round costs two values and
/// gradients; the lattice search that takes a crease not found costs thousands of values.
constexpr int kMaxCreaseRounds = 48;
constexpr double kConverged = 1e-4;

/// Whether a smooth-field round's point q has converged (kConverged, as @a converged world
/// units): on the surface within it (@a off enters the distance at first order), and p's
/// @a tangential offset from q's normal small enough that the distance |p - q| = @a dist is
/// within it. On the surface, q a tangential offset t from the foot point, |p - q| exceeds the
/// distance D by about t^2 / (2 D (1 - kappa D)) (kappa the curvature along t): second order,
/// so t^2 <= converged D suffices wherever kappa D <= 1/2, a round or more sooner than
/// t <= converged.
inline bool roundConverged(double off, double tangential, double dist, double converged)
{
    return off <= converged && tangential * tangential <= converged * dist;
}
/// roundConverged() from the squares of the tangential offset and the distance (t^2 <= c D as
/// t^4 <= c^2 D^2, both sides non-negative).
inline bool roundConverged2(double off, double tangential2, double dist2, double converged)
{
    return off <= converged && tangential2 * tangential2 <= converged * converged * dist2;
}
/// A certified distance agrees with the first-order estimate f / |grad f| within this share:
/// a larger gap means the iteration went to another part of the surface (a medial axis) or
/// past a singular point, where the local answer cannot be trusted.
constexpr double kEstimateAgreement = 0.25;

double dot(const Vec3d& a, const Vec3d& b) { return a.dot(b); }

/// Foot points of an exact SDF: its value, and the point moved back along its unit gradient.
void exactFootPoints(const Implicit& f, const double* x, const double* y, const double* z,
                     const double* values, std::size_t n, FootPoints& out)
{
    double gx[kMaxBatch], gy[kMaxBatch], gz[kMaxBatch];
    f.gradients(x, y, z, gx, gy, gz, n);
    for (std::size_t i = 0; i < n; ++i) {
        const double v = values[i];
        const double len = std::sqrt(gx[i] * gx[i] + gy[i] * gy[i] + gz[i] * gz[i]);
        out.distance[i] = v;
        // A unit gradient, as an exact SDF has wherever its gradient is defined.
        out.ok[i] = len > 0.5 && len < 1.5;
        const double s = out.ok[i] ? v / len : 0.0;
        out.x[i] = x[i] - s * gx[i];
        out.y[i] = y[i] - s * gy[i];
        out.z[i] = z[i] - s * gz[i];
    }
}

/// The smooth iteration's start, for every point at once (a loop that vectorizes): the
/// first-order estimate e = f / |grad f| as the distance, certified where f = 0 or |e| is beyond
/// twice @a far (only "farther" matters there: the estimate's error is second order in the
/// distance, a factor 2 only where the surface curves within it), +/- far where there is no
/// gradient (a singular point: no local answer); @a near marks the points that iterate, from the
/// projection q0 = p - f grad f / |grad f|^2.
IVDB_VECTOR_CLONES
void firstOrder(const double* __restrict x, const double* __restrict y,
                const double* __restrict z, const double* __restrict values,
                const double* __restrict gx, const double* __restrict gy,
                const double* __restrict gz, std::size_t n, double far,
                FootPoints& __restrict out, bool* __restrict near, double* __restrict qx,
                double* __restrict qy, double* __restrict qz)
{
    for (std::size_t i = 0; i < n; ++i) {
        const double v = values[i], g2 = gx[i] * gx[i] + gy[i] * gy[i] + gz[i] * gz[i];
        const bool valid = g2 > 0.0 && std::isfinite(g2);
        const double inv2 = 1.0 / g2, e = v * std::sqrt(inv2), s = v * inv2;
        const bool done = v == 0.0 || std::abs(e) >= 2.0 * far;
        out.x[i] = x[i];
        out.y[i] = y[i];
        out.z[i] = z[i];
        out.distance[i] = valid ? e : (v > 0.0 ? far : -far);
        out.ok[i] = valid && done;
        near[i] = valid && !done;
        qx[i] = x[i] - gx[i] * s;
        qy[i] = y[i] - gy[i] * s;
        qz[i] = z[i] - gz[i] * s;
    }
}

/// One round of the smooth iteration, for every point at once (a loop that vectorizes): at the
/// current point q (value f, gradient h) of query point p, whether h is usable, q's distance off
/// the surface, the squares of p's distance off q's normal and of |p - q|, and the next point
/// (onto the surface along h, then along the tangent plane towards the foot of the
/// perpendicular from p). One square root and one division a point: squares are compared
/// where a length would need another.
struct RoundState
{
    double off[kMaxBatch], tangential2[kMaxBatch], dist2[kMaxBatch];
    double nx[kMaxBatch], ny[kMaxBatch], nz[kMaxBatch];
    bool valid[kMaxBatch];
};

IVDB_VECTOR_CLONES
void smoothRound(const double* __restrict px, const double* __restrict py,
                 const double* __restrict pz, const double* __restrict qx,
                 const double* __restrict qy, const double* __restrict qz,
                 const double* __restrict f, const double* __restrict hx,
                 const double* __restrict hy, const double* __restrict hz, std::size_t m,
                 RoundState& __restrict st)
{
    for (std::size_t k = 0; k < m; ++k) {
        const double h2 = hx[k] * hx[k] + hy[k] * hy[k] + hz[k] * hz[k];
        st.valid[k] = h2 > 0.0 && std::isfinite(h2);
        const double inv2 = 1.0 / h2, invl = std::sqrt(inv2);
        const double rx = px[k] - qx[k], ry = py[k] - qy[k], rz = pz[k] - qz[k];
        // (r . h) h / h2: r's part along the normal.
        const double along = (rx * hx[k] + ry * hy[k] + rz * hz[k]) * inv2;
        const double tx = rx - hx[k] * along, ty = ry - hy[k] * along, tz = rz - hz[k] * along;
        st.off[k] = std::abs(f[k]) * invl;
        st.tangential2[k] = tx * tx + ty * ty + tz * tz;
        st.dist2[k] = rx * rx + ry * ry + rz * rz;
        // q -= h f / h2; then q += t - h (t . h) / h2 with t = p - q.
        const double s = f[k] * inv2;
        const double ax = qx[k] - hx[k] * s, ay = qy[k] - hy[k] * s, az = qz[k] - hz[k] * s;
        const double wx = px[k] - ax, wy = py[k] - ay, wz = pz[k] - az;
        const double c = (wx * hx[k] + wy * hy[k] + wz * hz[k]) * inv2;
        st.nx[k] = ax + (wx - hx[k] * c);
        st.ny[k] = ay + (wy - hy[k] * c);
        st.nz[k] = az + (wz - hz[k] * c);
    }
}

} // namespace

void Implicit::gradients(const double* x, const double* y, const double* z, double* gx,
                         double* gy, double* gz, std::size_t n) const
{
    for (std::size_t i = 0; i < n; ++i) {
        const Vec3d g = gradient(Vec3d(x[i], y[i], z[i]));
        gx[i] = g[0];
        gy[i] = g[1];
        gz[i] = g[2];
    }
}

// GCC cannot see that only the m entries written are read.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
void Implicit::footPoints(const double* x, const double* y, const double* z,
                          const double* values, std::size_t n, const FootQuery& query,
                          FootPoints& out) const
{
    if (isExactSdf()) {
        exactFootPoints(*this, x, y, z, values, n, out);
        return;
    }
    if (isDistanceBound()) {
        // |f| never exceeds the distance: a point with |f| >= far is that far at least, which
        // is all that is asked there, without iterating (where the iteration need not
        // converge: a shrunk rounded box scaled non-uniformly).
        for (std::size_t i = 0; i < n; ++i) {
            out.ok[i] = std::abs(values[i]) >= query.far;
            out.distance[i] = values[i];
            out.x[i] = x[i], out.y[i] = y[i], out.z[i] = z[i];
        }
        detail::iterateUncertified(*this, x, y, z, values, n, query, out);
        return;
    }
    double gx[kMaxBatch], gy[kMaxBatch], gz[kMaxBatch];
    gradients(x, y, z, gx, gy, gz, n);
    detail::smoothFootPoints(*this, x, y, z, values, gx, gy, gz, n, query, out);
}

void detail::smoothFootPoints(const Implicit& f, const double* x, const double* y,
                              const double* z, const double* values, const double* gx,
                              const double* gy, const double* gz, std::size_t n,
                              const FootQuery& query, FootPoints& out)
{
    // The points that iterate, compacted: index, query point, current point.
    std::size_t idx[kMaxBatch];
    double px[kMaxBatch], py[kMaxBatch], pz[kMaxBatch], qx[kMaxBatch], qy[kMaxBatch],
        qz[kMaxBatch], fq[kMaxBatch], hx[kMaxBatch], hy[kMaxBatch], hz[kMaxBatch];
    bool near[kMaxBatch];
    firstOrder(x, y, z, values, gx, gy, gz, n, query.far, out, near, qx, qy, qz);
    // The near points compacted, without branches (every point is written, and the next
    // overwrites it unless it is near).
    std::size_t m = 0;
    for (std::size_t i = 0; i < n; ++i) {
        idx[m] = i;
        px[m] = x[i];
        py[m] = y[i];
        pz[m] = z[i];
        qx[m] = qx[i];
        qy[m] = qy[i];
        qz[m] = qz[i];
        m += near[i] ? 1 : 0;
    }
    const double converged = kConverged * query.tolerance;
    for (int round = 0; m > 0; ++round) {
        f.valuesAndGradients(qx, qy, qz, fq, hx, hy, hz, m);
        RoundState st;
        smoothRound(px, py, pz, qx, qy, qz, fq, hx, hy, hz, m, st);
        const bool last = round + 1 == kMaxRounds;
        std::size_t kept = 0;
        for (std::size_t k = 0; k < m; ++k) {
            const bool valid = st.valid[k]; // no gradient: not certified, and no next point
            const bool stop =
                roundConverged2(st.off[k], st.tangential2[k], st.dist2[k], converged) || last;
            if (valid && stop) {
                // Certify q: on the surface, p on its normal, and the distance near the
                // first-order estimate.
                const std::size_t i = idx[k];
                const double d = std::copysign(std::sqrt(st.dist2[k]), values[i]);
                const double e = out.distance[i];
                if (st.off[k] <= query.tolerance &&
                    st.tangential2[k] <= query.tolerance * query.tolerance &&
                    std::abs(d - e) <= kEstimateAgreement * std::abs(e) + query.tolerance) {
                    out.distance[i] = d;
                    out.x[i] = qx[k];
                    out.y[i] = qy[k];
                    out.z[i] = qz[k];
                    out.ok[i] = true;
                }
            }
            // The points that go on, compacted without branches (as above; after the
            // certification, which reads q at k >= kept).
            idx[kept] = idx[k];
            px[kept] = px[k];
            py[kept] = py[k];
            pz[kept] = pz[k];
            qx[kept] = st.nx[k];
            qy[kept] = st.ny[k];
            qz[kept] = st.nz[k];
            kept += valid && !stop ? 1 : 0;
        }
        m = kept;
    }
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

namespace {

/// Solve the 4x4 system @a a x = @a b in place (Gaussian elimination with partial pivoting);
/// false if it is singular.
bool solve4(double a[4][4], double b[4])
{
    for (int c = 0; c < 4; ++c) {
        int pivot = c;
        for (int r = c + 1; r < 4; ++r) {
            if (std::abs(a[r][c]) > std::abs(a[pivot][c])) pivot = r;
        }
        if (!(std::abs(a[pivot][c]) > 0.0)) return false;
        if (pivot != c) {
            for (int k = 0; k < 4; ++k) std::swap(a[c][k], a[pivot][k]);
            std::swap(b[c], b[pivot]);
        }
        for (int r = c + 1; r < 4; ++r) {
            const double m = a[r][c] / a[c][c];
            for (int k = c; k < 4; ++k) a[r][k] -= m * a[c][k];
            b[r] -= m * b[c];
        }
    }
    for (int c = 3; c >= 0; --c) {
        for (int k = c + 1; k < 4; ++k) b[c] -= a[c][k] * b[k];
        b[c] /= a[c][c];
    }
    return std::isfinite(b[0]) && std::isfinite(b[1]) && std::isfinite(b[2]) &&
           std::isfinite(b[3]);
}

/// refineFootPoint()'s smooth iteration: the rounds of Implicit::footPoints from @a start.
bool smoothRefine(const Implicit& f, const Vec3d& p, const Vec3d& start, double tol, Vec3d& q)
{
    q = start;
    for (int round = 0; round < kMaxRounds; ++round) {
        const double v = f.value(q);
        const Vec3d h = f.gradient(q);
        const double h2 = h.lengthSqr();
        if (!(h2 > 0.0) || !std::isfinite(h2)) return false;
        const double hl = std::sqrt(h2);
        const Vec3d r = p - q, nrm = h / hl;
        const double off = std::abs(v) / hl, tangential = (r - nrm * dot(r, nrm)).length();
        if (roundConverged(off, tangential, r.length(), kConverged * tol)) return true;
        if (round + 1 == kMaxRounds) return off <= tol && tangential <= tol;
        q -= h * (v / h2);
        const Vec3d t = p - q;
        q += t - h * (dot(t, h) / h2);
    }
    return false;
}

/// The foot point of @a p near @a start by Newton's method on the conditions for a nearest
/// point (q - p + lambda grad f(q) = 0 and f(q) = 0), the Hessian of f from central
/// differences of its gradient, each step at most half the distance: it converges where the
/// surface curves tightly for the distance (kappa d > 1, a blend's rounded edge), where the
/// smooth iteration's rounds grow the error by kappa d each. Certified as the smooth iteration
/// is (on the surface, the point on its normal, within @a tol), and only at a nearest point
/// along the surface (the distance's second derivative along the tangent plane not negative).
bool newtonFootPoint(const Implicit& f, const Vec3d& p, const Vec3d& start, double tol, Vec3d& q)
{
    // Unknowns q and lambda; conditions q - p + lambda grad f(q) = 0 and f(q) = 0; Jacobian
    // [[I + lambda H, g], [g^T, 0]], H from central differences of the analytic gradient.
    constexpr int kMaxNewtonRounds = 30;
    q = start;
    const double scale = std::max((p - start).length(), tol);
    const double h = 1e-4 * scale;
    double lambda = 0.0;
    for (int round = 0; round < kMaxNewtonRounds; ++round) {
        const double v = f.value(q);
        const Vec3d g = f.gradient(q);
        const double g2 = g.lengthSqr();
        if (!(g2 > 0.0) || !std::isfinite(g2) || !std::isfinite(v)) return false;
        if (round == 0) lambda = dot(p - q, g) / g2;
        const double gl = std::sqrt(g2);
        const Vec3d r = p - q, nrm = g / gl;
        const double off = std::abs(v) / gl, tangential = (r - nrm * dot(r, nrm)).length();
        double hess[3][3];
        for (int k = 0; k < 3; ++k) {
            Vec3d e(0.0);
            e[k] = h;
            const Vec3d d = (f.gradient(q + e) - f.gradient(q - e)) / (2.0 * h);
            for (int i = 0; i < 3; ++i) hess[i][k] = d[i];
        }
        for (int i = 0; i < 3; ++i) {
            for (int k = i + 1; k < 3; ++k) hess[i][k] = hess[k][i] = 0.5 * (hess[i][k] + hess[k][i]);
        }
        const bool converged = roundConverged(off, tangential, r.length(), kConverged * tol);
        if (converged || round + 1 == kMaxNewtonRounds) {
            if (!(off <= tol && tangential <= tol)) return false;
            // A nearest point, not a farthest or a saddle: I + lambda H is not negative along
            // the tangent plane (the distance has a minimum there along the surface).
            const Vec3d t1 = nrm.cross(std::abs(nrm[0]) < 0.9 ? Vec3d(1, 0, 0) : Vec3d(0, 1, 0)).unit();
            const Vec3d t2 = nrm.cross(t1);
            auto form = [&](const Vec3d& a, const Vec3d& b) {
                double sum = dot(a, b);
                for (int i = 0; i < 3; ++i) {
                    for (int k = 0; k < 3; ++k) sum += lambda * a[i] * hess[i][k] * b[k];
                }
                return sum;
            };
            const double m11 = form(t1, t1), m22 = form(t2, t2), m12 = form(t1, t2);
            return m11 >= -1e-9 && m22 >= -1e-9 && m11 * m22 - m12 * m12 >= -1e-9;
        }
        double a[4][4], b[4];
        for (int i = 0; i < 3; ++i) {
            for (int k = 0; k < 3; ++k) a[i][k] = (i == k ? 1.0 : 0.0) + lambda * hess[i][k];
            a[i][3] = g[i];
            a[3][i] = g[i];
            b[i] = -(q[i] - p[i] + lambda * g[i]);
        }
        a[3][3] = 0.0;
        b[3] = -v;
        if (!solve4(a, b)) return false;
        Vec3d step(b[0], b[1], b[2]);
        // No step longer than half the distance: the Newton step of a poor start can leave
        // the part of the surface it was near.
        const double most = 0.5 * std::max(r.length(), tol);
        const double len = step.length();
        const double damp = len > most ? most / len : 1.0;
        q += step * damp;
        lambda += b[3] * damp;
    }
    return false;
}

} // namespace

bool refineFootPoint(const Implicit& f, const Vec3d& p, const Vec3d& start, double tol, Vec3d& q,
                     bool newton)
{
    // Where the surface curves tightly for the distance (kappa d > 1: a blend's rounded edge)
    // the rounds grow the error; Newton's method on the nearest point's conditions converges.
    const bool found = smoothRefine(f, p, start, tol, q) ||
                       (newton && newtonFootPoint(f, p, start, tol, q));
    // Across a kink of the field within the distance, another point may be nearer.
    return found && !f.mayKinkWithin(p, (q - p).length() + tol);
}

namespace {

/// A smooth piece of a CSG term's surface, as the crease and corner searches see it: the whole
/// term (a smooth surface), a plane n . q = offset (unit n) that holds a face of a box, or the
/// infinite cone (a cylinder at slope 0) that holds a capped cone's side (pieceParts()).
struct Piece
{
    enum class Kind { Whole, Plane, Side };
    Kind kind = Kind::Whole;
    const Implicit* f = nullptr; // Whole
    Vec3d n;                     // Plane: the unit normal; Side: the unit axis
    double offset = 0.0;         // Plane
    Vec3d a;                     // Side: a point of the axis, where the radius is r
    double r = 0.0, slope = 0.0, cosine = 1.0; // Side: radius r + slope s at s along the axis
    /// The value is a convex function: a plane's, a side's (the distance from the axis is), a
    /// convex solid's exact SDF.
    bool convex = false;
    /// Whole: one child of a term of several pieces (a world quadric in a CSG term), whose
    /// points count only where they lie on the term's surface, as a plane's or a side's do.
    bool part = false;

    /// Of a side, the signed distance to its line in the half-plane through the axis (the
    /// distance to the cone near it, away from the apex).
    double value(const Vec3d& q) const
    {
        if (kind == Kind::Whole) return f->value(q);
        if (kind == Kind::Plane) return dot(n, q) - offset;
        const Vec3d w = q - a;
        const double s = dot(w, n);
        return ((w - n * s).length() - r - slope * s) * cosine;
    }
    Vec3d gradient(const Vec3d& q) const
    {
        if (kind == Kind::Whole) return f->gradient(q);
        if (kind == Kind::Plane) return n;
        const Vec3d w = q - a, radial = w - n * dot(w, n);
        const double len = radial.length();
        if (!(len > 0.0)) return Vec3d(0.0); // on the axis: no normal
        return (radial / len - n * slope) * cosine;
    }
    /// Moved out by @a d: the value less d (a plane moved along its normal, a side's radius
    /// grown by d over the cosine of its slope).
    void shift(double d)
    {
        if (kind == Kind::Plane) offset += d;
        else if (kind == Kind::Side) r += d / cosine;
    }
    /// Moved by @a t (a rigid motion with a uniform scale).
    void move(const Transform& t, double s)
    {
        const Vec3d origin = t.toWorld(Vec3d(0.0));
        Vec3d rn = (t.toWorld(n) - origin) / s;
        rn /= rn.length();
        if (kind == Kind::Plane) {
            // n . q = o with q = R^T (w - t) / s: (R n) . w = s o + (R n) . t.
            offset = s * offset + dot(rn, origin);
        } else {
            a = t.toWorld(a);
            r *= s;
        }
        n = rn;
    }
};

/// The six face planes of the box of centre @a c and half size @a h, appended to @a out.
void boxPlanes(const Vec3d& c, const Vec3d& h, std::vector<Piece>& out)
{
    for (int k = 0; k < 3; ++k) {
        Piece plus, minus;
        plus.kind = minus.kind = Piece::Kind::Plane;
        plus.convex = minus.convex = true;
        plus.n = minus.n = Vec3d(0.0);
        plus.n[k] = 1.0;
        plus.offset = c[k] + h[k];
        minus.n[k] = -1.0;
        minus.offset = h[k] - c[k];
        out.push_back(plus);
        out.push_back(minus);
    }
}

/// A CSG term with more pieces than this (eight boxes) is searched whole.
constexpr std::size_t kMaxTermPieces = 48;

/// The smooth pieces that hold every part of @a f's surface, if @a f is made of planes and cone
/// sides: a box (its six faces' planes), a capped cylinder or cone (its side's cone and its caps'
/// planes), a CSG node of such children, or one of those moved rigidly or scaled uniformly.
/// Appends them to @a out and returns true; false (nothing appended) for any other shape. Where
/// such a term meets another, the crease is a chain of pieces that kinks at the term's own edges
/// (a box's edges, a cone's rims), and the nearest point of it is often a kink: searched piece by
/// piece.
bool pieceParts(const Implicit& f, std::vector<Piece>& out)
{
    if (const auto* box = dynamic_cast<const Box*>(&f)) {
        boxPlanes(box->center(), box->size() * 0.5, out);
        return true;
    }
    if (const auto* cone = dynamic_cast<const CappedCone*>(&f)) {
        const Vec3d u = cone->axis();
        Piece side, capA, capB;
        side.kind = Piece::Kind::Side;
        side.convex = true;
        side.n = u;
        side.a = cone->a();
        side.r = cone->radiusA();
        side.slope = (cone->radiusB() - cone->radiusA()) / cone->length();
        side.cosine = 1.0 / std::sqrt(1.0 + side.slope * side.slope);
        capA.kind = capB.kind = Piece::Kind::Plane;
        capA.convex = capB.convex = true;
        capA.n = -u;
        capA.offset = -dot(u, cone->a());
        capB.n = u;
        capB.offset = dot(u, cone->a()) + cone->length();
        out.push_back(side);
        out.push_back(capA);
        out.push_back(capB);
        return true;
    }
    const std::size_t before = out.size();
    if (const auto* t = dynamic_cast<const Transform*>(&f)) {
        const double s = t->uniformScale();
        if (!(s > 0.0) || !pieceParts(*t->child(), out)) return false;
        for (std::size_t k = before; k < out.size(); ++k) {
            if (out[k].kind == Piece::Kind::Whole) { // a quadric: not moved here
                out.resize(before);
                return false;
            }
            out[k].move(*t, s);
        }
        return true;
    }
    if (const auto* csg = dynamic_cast<const Csg*>(&f)) {
        for (const auto& child : csg->children()) {
            // A quadric within a CSG (a non-uniformly scaled capped cone's world quadric
            // between its cap planes, a sheared box's face planes): a unit-normal plane is a
            // plane piece; another quadric a piece of its own, iterated whole. Taken whole, such
            // a term's crease with another follows its gradient across its rims onto its other
            // pieces, and stopped at a crease point of its side where the nearest was on a cap.
            if (const auto* q = dynamic_cast<const Quadric*>(child.get())) {
                const Mat4& m = q->matrix();
                Piece piece;
                if (q->isExactSdf()) {
                    piece.kind = Piece::Kind::Plane;
                    piece.convex = true;
                    piece.n = Vec3d(2.0 * m[0][3], 2.0 * m[1][3], 2.0 * m[2][3]);
                    piece.offset = -m[3][3];
                } else {
                    piece.f = q;
                    piece.part = true;
                }
                out.push_back(piece);
                continue;
            }
            if (!pieceParts(*child, out)) {
                out.resize(before);
                return false;
            }
        }
        return true;
    }
    return false;
}

/// The pieces whose values tell where @a f's distance may kink (piecesKinkWithin()):
/// pieceParts() of an exact SDF (a box, a capped cylinder or cone), and of a rounded box its
/// outer box's faces, with @a round its radius: a rounded box is its inner box's distance less
/// r, and its outer faces are the inner ones moved out by r, so inside the inner box (where
/// its distance kinks: the faces tie) its value is the largest of them. An offset of any of
/// those by d (moved rigidly or scaled uniformly) likewise: its value is the child's less d,
/// its pieces the child's moved out by d, @a round the child's plus d (negative for a shrunk
/// one). So the value plus @a round is the unshifted solid's own distance, which kinks only
/// inside it. False for none (and for every other shape, a CSG node's included).
bool kinkPieces(const Implicit& f, std::vector<Piece>& out, double& round)
{
    round = 0.0;
    if (f.isExactSdf() && pieceParts(f, out)) return true;
    if (const auto* rounded = dynamic_cast<const RoundedBox*>(&f)) {
        boxPlanes(rounded->center(), rounded->size() * 0.5, out);
        round = rounded->radius();
        return true;
    }
    const std::size_t before = out.size();
    if (const auto* t = dynamic_cast<const Transform*>(&f)) {
        const double s = t->uniformScale();
        if (!(s > 0.0) || !kinkPieces(*t->child(), out, round)) return false;
        for (std::size_t k = before; k < out.size(); ++k) out[k].move(*t, s);
        round *= s;
        return true;
    }
    if (const auto* o = dynamic_cast<const Offset*>(&f)) {
        if (!kinkPieces(*o->child(), out, round)) return false;
        for (std::size_t k = before; k < out.size(); ++k) out[k].shift(o->distance());
        round += o->distance();
        return true;
    }
    return false;
}

/// Of a shape made of @a pieces (kinkPieces()), where the distance of the solid they shift
/// (its value plus kinkPieces()' round) is @a own at @a p: the largest of the pieces' values at
/// @a p, and whether the shape's value may kink within @a radius of @a p. Outside a convex
/// solid its distance is smooth (C1); inside, it is the largest of its pieces' values, each
/// 1-Lipschitz, so the same piece stays the largest within the ball unless the two largest
/// differ by 2 radius or less: the ball reaches inside (own < radius) and the two largest are
/// that close. A shift moves every piece's value alike.
bool piecesKinkWithin(const std::vector<Piece>& pieces, const Vec3d& p, double own,
                      double radius, double* largest = nullptr)
{
    if (own >= radius) return false;
    double first = -std::numeric_limits<double>::max(), second = first;
    for (const Piece& piece : pieces) {
        const double v = piece.value(p);
        if (v > first) second = first, first = v;
        else if (v > second) second = v;
    }
    if (largest) *largest = first;
    return first - second <= 2.0 * radius;
}

/// An edge where two pieces of a convex solid meet: two of a box's faces (at right angles, along
/// a line; or three at a corner), or a capped cylinder's or cone's side and a cap (a rim
/// circle). Outside the solid, where its nearest point is on the edge (the edge's region), its
/// distance is the distance to the edge.
struct Edge
{
    std::size_t a = 0, b = 0;   // the pieces (a rim: the side, then the cap)
    std::size_t c = 0;          // a box's corner: its third piece
    bool rim = false, corner = false;
    /// A box's edge: the pieces across it (at right angles to both of its own), at most 0 in
    /// its region; how many.
    std::size_t across[2] = {0, 0}, nAcross = 0;
    /// kinkPieces()' shift (a rounded box's radius, an offset's distance): the pieces less it
    /// (the rim's circle, s0 and r0, already without it) meet on the edge, whose distance is
    /// less it too.
    double round = 0.0;
    Vec3d origin, axis;         // rim: the axis, s measured along it from origin
    double s0 = 0.0, r0 = 0.0;  // rim: the circle's place on the axis and its radius
    double capS = 1.0;          // rim: the cap's outward normal, (capS, 0) in (s, rho)
    double sideS = 0.0, sideR = 1.0; // rim: the side's outward unit normal in (s, rho)

    /// A rim: @a p's coordinates along the axis and from it, and the unit radial direction.
    void meridian(const Vec3d& p, double& s, double& r, Vec3d& radial) const
    {
        const Vec3d w = p - origin;
        s = dot(w, axis);
        radial = w - axis * s;
        r = radial.length();
        radial = r > 0.0 ? radial / r : Vec3d(0.0);
    }
    /// The distance from @a p to the edge (to the cylinder of radius round about it).
    double distance(const std::vector<Piece>& pieces, const Vec3d& p) const
    {
        if (!rim) {
            const double w = corner ? pieces[c].value(p) + round : 0.0;
            return std::hypot(pieces[a].value(p) + round, pieces[b].value(p) + round, w) - round;
        }
        double s, r;
        Vec3d radial;
        meridian(p, s, r, radial);
        return std::hypot(s - s0, r - r0) - round;
    }
    Vec3d gradient(const std::vector<Piece>& pieces, const Vec3d& p) const
    {
        double u, v, w = 0.0;
        Vec3d du, dv, dw(0.0);
        if (!rim) {
            u = pieces[a].value(p) + round, v = pieces[b].value(p) + round;
            du = pieces[a].gradient(p), dv = pieces[b].gradient(p);
            if (corner) w = pieces[c].value(p) + round, dw = pieces[c].gradient(p);
        } else {
            double s, r;
            meridian(p, s, r, dv);
            u = s - s0, v = r - r0, du = axis;
        }
        const double len = std::hypot(u, v, w);
        if (!(len > 0.0)) return Vec3d(0.0); // on the edge: no normal
        return (du * u + dv * v + dw * w) / len;
    }
    /// How far @a p is from the edge's region: where two faces of a box at right angles are
    /// both >= 0 (a rounded box's: -round) and those across at most that (a corner's: its
    /// three); for a rim, the wedge of the two outward normals at the circle, in the
    /// half-plane through the axis (the region is a solid of revolution).
    double regionDistance(const std::vector<Piece>& pieces, const Vec3d& p) const
    {
        if (!rim) {
            // At most one of the pieces across is above 0 (they are parallel).
            double over = 0.0;
            for (std::size_t k = 0; k < nAcross; ++k) {
                over = std::max(over, pieces[across[k]].value(p) + round);
            }
            return std::hypot(std::hypot(std::max(-pieces[a].value(p) - round, 0.0),
                                         std::max(-pieces[b].value(p) - round, 0.0)),
                              std::hypot(corner ? std::max(-pieces[c].value(p) - round, 0.0) : 0.0,
                                         over));
        }
        double s, r;
        Vec3d radial;
        meridian(p, s, r, radial);
        const double ws = s - s0, wr = r - r0;
        // Inside the wedge: a combination of the two normals, (capS, 0) and (sideS, sideR) with
        // capS = +-1 and sideR > 0, with weights >= 0.
        const double kSide = wr / sideR, kCap = (ws - kSide * sideS) / capS;
        if (kSide >= 0.0 && kCap >= 0.0) return 0.0;
        // Else the nearest of its two boundary rays.
        auto toRay = [&](double ns, double nr) {
            const double t = std::max(ws * ns + wr * nr, 0.0);
            return std::hypot(ws - t * ns, wr - t * nr);
        };
        return std::min(toRay(capS, 0.0), toRay(sideS, sideR));
    }
};

/// The edges and corners of a convex solid made of @a pieces (pieceParts()): a box's twelve
/// edges (pairs of faces at right angles) and eight corners (triples, Edge::corner), with
/// @a perpendicular (row-major, pieces by pieces: which pairs meet at right angles, the others
/// parallel) and @a square true; a capped cylinder's or cone's two rims (@a square true only for
/// a cylinder's: its pieces meet at right angles). Where at most one of the pieces' values is
/// positive the solid's distance is their largest; where only an edge's two are, in its region,
/// the distance to the edge; near a corner, the distance to it. A rounded box's pieces are its
/// outer box's faces and @a round its radius: the same with every "positive" read as "above
/// -round", and the distances to its edges and corners those to cylinders and balls of that
/// radius (Edge::round). False for other pieces.
bool solidEdges(const std::vector<Piece>& pieces, double round, std::vector<Edge>& edges,
                std::vector<char>& perpendicular, bool& square)
{
    edges.clear();
    const std::size_t np = pieces.size();
    perpendicular.assign(np * np, 0);
    square = false;
    if (np == 3 && pieces[0].kind == Piece::Kind::Side && pieces[1].kind == Piece::Kind::Plane &&
        pieces[2].kind == Piece::Kind::Plane) {
        const Piece& side = pieces[0];
        square = side.slope == 0.0;
        for (std::size_t c = 1; c < 3; ++c) {
            const Piece& cap = pieces[c];
            const double along = dot(cap.n, side.n); // +-1: a cap is across the axis
            if (std::abs(std::abs(along) - 1.0) > 1e-9) return false;
            Edge e;
            e.a = 0, e.b = c, e.rim = true, e.round = round;
            e.origin = side.a, e.axis = side.n;
            // The cap's plane n . q = offset (moved back by the shift, as the side's radius):
            // along the axis at s0 from origin.
            e.capS = along > 0.0 ? 1.0 : -1.0;
            e.s0 = e.capS * (cap.offset - round) - dot(side.n, side.a);
            e.r0 = side.r - round / side.cosine + side.slope * e.s0;
            e.sideS = -side.slope * side.cosine, e.sideR = side.cosine;
            if (!(e.r0 >= 0.0)) return false;
            edges.push_back(e);
            perpendicular[c] = perpendicular[c * np] = square;
        }
        return true;
    }
    for (std::size_t i = 0; i < np; ++i) {
        for (std::size_t k = i + 1; k < np; ++k) {
            if (pieces[i].kind != Piece::Kind::Plane || pieces[k].kind != Piece::Kind::Plane) {
                return false;
            }
            const double c = dot(pieces[i].n, pieces[k].n); // the cosine of their angle
            if (std::abs(c) > 1.0 - 1e-9) continue;          // parallel: never both outside
            if (std::abs(c) > 1e-9) return false;
            perpendicular[i * np + k] = perpendicular[k * np + i] = 1;
            Edge e;
            e.a = i, e.b = k, e.round = round;
            edges.push_back(e);
        }
    }
    const std::size_t pairs = edges.size();
    for (Edge& e : edges) {
        for (std::size_t l = 0; l < np && e.nAcross < 2; ++l) {
            if (perpendicular[e.a * np + l] && perpendicular[e.b * np + l]) {
                e.across[e.nAcross++] = l;
            }
        }
    }
    for (std::size_t k = 0; k < pairs; ++k) {
        const Edge e = edges[k];
        for (std::size_t l = e.b + 1; l < np; ++l) {
            if (perpendicular[e.a * np + l] && perpendicular[e.b * np + l]) {
                Edge v = e;
                v.c = l, v.corner = true, v.nAcross = 0;
                edges.push_back(v);
            }
        }
    }
    square = true;
    return true;
}

/// A piece's field (a face's plane, a capped cone's side) as a shape: the signed distance to the
/// half-space or the solid cone whose boundary holds it, exact in the solid the piece bounds
/// near it; or the distance to an edge of a solid's pieces (a box's edge line, a capped
/// cylinder's or cone's rim circle). The stand-in for a box or a capped cone in a blend's
/// sheets (sheetFeet()).
class PieceField final: public Implicit
{
public:
    explicit PieceField(const Piece& piece): mPieces{piece} {}
    PieceField(const std::vector<Piece>& pieces, const Edge& edge)
        : mPieces(pieces), mEdge(edge), mIsEdge(true) {}
    double value(const Vec3d& p) const override
    {
        return mIsEdge ? mEdge.distance(mPieces, p) : mPieces[0].value(p);
    }
    Vec3d gradient(const Vec3d& p) const override
    {
        return mIsEdge ? mEdge.gradient(mPieces, p) : mPieces[0].gradient(p);
    }
    /// 1-Lipschitz: the value at the centre, give or take half the diagonal.
    Interval interval(const BBoxd& box) const override
    {
        const double v = value(box.getCenter()), r = 0.5 * (box.max() - box.min()).length();
        return Interval(v - r, v + r);
    }
    BBoxd boundingBox() const override { return infiniteBox(); }
    bool isExactSdf() const override { return true; }
    std::string typeName() const override { return mIsEdge ? "edge" : "piece"; }

private:
    std::vector<Piece> mPieces;
    Edge mEdge;
    bool mIsEdge = false;
};

/// Of a capped cone (its @a pieces and two @a rims, solidEdges()): how far @a p is from where
/// piece j's value lies in [@a lo, @a hi] and its nearest point is on the piece's own part (the
/// side's segment between the rims, a cap's disc): in the half-plane through the axis, a
/// rectangle in the piece's own frame (along it and along its normal).
double coneFaceDistance(const std::vector<Piece>& pieces, const std::vector<Edge>& rims,
                        std::size_t j, const Vec3d& p, double lo, double hi)
{
    double s, r;
    Vec3d radial;
    rims[0].meridian(p, s, r, radial);
    const double v = pieces[j].value(p);
    double t, t0, t1;
    if (j == 0) { // the side, along it (its unit tangent (sideR, -sideS)) from the first rim
        const Edge &a = rims[0], &b = rims[1];
        auto along = [&](double ss, double rr) { return (ss - a.s0) * a.sideR - (rr - a.r0) * a.sideS; };
        t = along(s, r);
        t0 = std::min(0.0, along(b.s0, b.r0)), t1 = std::max(0.0, along(b.s0, b.r0));
    } else { // a cap, across the axis out to its rim
        t = r, t0 = 0.0, t1 = rims[j - 1].r0;
    }
    return std::hypot(std::max({t0 - t, t - t1, 0.0}), std::max({lo - v, v - hi, 0.0}));
}

/// How far below a term a of @a n a blend's union form U can lie, where every other term
/// exceeds a by @a gap: a - U <= log(1 + (n - 1) e^(-p gap)) / p for the super-elliptic blend;
/// for the smooth minimum 0 beyond k (it folds from the left, each fold exact there), else of
/// two k/4 h^2 (h = (k - gap) / k, and -gap more below 0), of more -gap and k/4 a fold.
double dipAbove(const BlendKernel& kernel, std::size_t n, double gap)
{
    if (kernel.kind == BlendKernel::Kind::SuperElliptic) {
        return std::log1p(double(n - 1) * std::exp(-kernel.p * gap)) / kernel.p;
    }
    if (gap >= kernel.k) return 0.0;
    if (n == 2) {
        const double h = (kernel.k - std::max(gap, 0.0)) / kernel.k;
        return std::max(-gap, 0.0) + 0.25 * kernel.k * h * h;
    }
    return std::max(-gap, 0.0) + 0.25 * kernel.k * double(n - 1);
}

/// Of two terms, the other exceeding a by @a gap >= 0: how far below a the union form lies at
/// least (exactly, for two).
double dipBelow(const BlendKernel& kernel, double gap)
{
    if (kernel.kind == BlendKernel::Kind::SuperElliptic) {
        return std::log1p(std::exp(-kernel.p * gap)) / kernel.p;
    }
    const double h = std::max(kernel.k - gap, 0.0) / kernel.k;
    return 0.25 * kernel.k * h * h;
}

bool creasePoint(const Piece& a, const Piece& b, const Vec3d& p, Vec3d q, double tol,
                 Vec3d& out, double& floor);

/// Certified distances near a kink of one child's distance, from the sheets the blend's surface
/// is made of there (@a kinked points of @a blend, the children's @a pieces as
/// Blend::nearerFeet() found them, with kinkPieces()' shifts in @a rounds: a rounded box's
/// radius, an offset's distance; @a done set where certified).
///
/// Child C, a box or a capped cone (or a rounded box, or an offset of one: the same read with
/// its pieces shifted and "positive" as "above -round", kinkPieces()), is the largest of its
/// pieces' values phi_j (each the exact distance to its plane or cone side) inside it and
/// wherever at most one of them is positive (region R0: C itself, and face j's region where
/// only phi_j is), and at least that largest
/// everywhere; where only the two of an edge e are positive (R_e, of pieces meeting at right
/// angles: rightAngles()) it is their hypot, the distance l_e to the edge. Within the ball B of
/// radius r about p only the pieces within 2 r of the largest at p (J) can be the largest. The
/// kernel U is increasing in every term, so with C's term s C (s = 1 in a union, -1 in an
/// intersection) and no other child kinking in B, the blend in union form
/// F = U(.., s C, ..) is, in B, the largest (s = 1) or the least (s = -1) of the face sheets
/// G_j = U(.., s phi_j, ..) on R0, G_j on face j's region, and the edge sheet
/// G_e = U(.., s l_e, ..) on R_e; each a smooth blend of exact SDFs (or of their offsets)
/// whose distance d_j the blend's own rules certify. Every point y of B on the surface
/// (F(y) = 0) lies
/// - in R0, farther than the least d_j where F(p) s < 0 (p inside the sheets' intersection,
///   or outside their union: on F's side of every sheet), else farther than the largest d_j of
///   the sheets p is on F's side of (a crease where sheets meet), and:
///   - s = 1, F(p) < 0: in face j's region, farther than d_j, than -phi_j(p) and than the
///     other pieces' phi_m(p) (F < 0 on C's inside);
///   - s = 1, F(p) > 0: on C (own(p)), or in face j's region, farther than the other pieces'
///     phi_m(p), than d_j where p is on F's side of G_j, and than where phi_j <= tol or the
///     other children's least term leads phi_j by less than the lead rule's margin (beyond
///     both, G_j >= phi_j - tol > 0);
///   - s = -1, F(p) < 0: on C (F < 0 on its faces' regions);
/// - in R_e, farther than R_e, and than G_e's surface where p is on F's side of it;
/// - farther than the corners' regions, or their sheets likewise, and than r.
/// The least of those bounds the distance below; the nearest point found on F's other side
/// bounds it above (a sheet's; or the one @a out holds, r less the tolerance). Where they meet
/// within the tolerance it is certified; elsewhere the lattice search goes on.
void sheetFeet(const Blend& blend, const double* x, const double* y, const double* z,
               const double* values, std::size_t n, const FootQuery& query,
               const double* terms, const std::vector<std::vector<Piece>>& pieces,
               const std::vector<double>& rounds, const bool* kinked, FootPoints& out, bool* done)
{
    const auto& children = blend.children();
    const std::size_t nc = children.size();
    const double rho = blend.op() == Blend::Op::Union ? 1.0 : -1.0;
    auto sign = [&](std::size_t c) {
        return blend.op() == Blend::Op::Difference && c > 0 ? -1.0 : 1.0;
    };
    const double inf = std::numeric_limits<double>::infinity();
    const BlendKernel& kernel = blend.kernel();
    std::vector<std::vector<Edge>> edges(nc);
    std::vector<std::vector<char>> perpendicular(nc);
    std::vector<char> known(nc, 0), square(nc, 0);
    std::size_t np = 0; // the most pieces of a child
    for (std::size_t c = 0; c < nc; ++c) {
        bool right = false;
        known[c] = solidEdges(pieces[c], rounds[c], edges[c], perpendicular[c], right);
        square[c] = right;
        np = std::max(np, pieces[c].size());
    }
    // Per point: the one child that kinks (nc: none, or not certifiable here), the ball's
    // radius, the largest of that child's piece values, whether B lies inside C, the regions'
    // and edge sheets' bound, C's term's sign s, whether every face sheet is on F's side
    // (least), the other children's least term, and how far an edge's region's surface keeps
    // from the edge (tube).
    std::size_t kinker[kMaxBatch];
    double radius[kMaxBatch], largest[kMaxBatch], regions[kMaxBatch], term[kMaxBatch],
        second[kMaxBatch], tube[kMaxBatch];
    bool inside[kMaxBatch], least[kMaxBatch];
    bool any = false;
    for (std::size_t i = 0; i < n; ++i) {
        kinker[i] = nc;
        if (!kinked[i]) continue;
        const Vec3d p(x[i], y[i], z[i]);
        const double r = (out.surface[i] ? std::abs(out.distance[i]) : query.far) + query.tolerance;
        std::size_t found = nc;
        bool several = false;
        for (std::size_t c = 0; c < nc && !several; ++c) {
            several = children[c]->mayKinkWithin(p, r);
            double big = 0.0;
            if (several) break;
            if (pieces[c].empty() ||
                !piecesKinkWithin(pieces[c], p, sign(c) * terms[c * n + i] + rounds[c], r,
                                  &big)) {
                continue;
            }
            several = found != nc;
            found = c;
            largest[i] = big;
        }
        // (Pieces are kinkPieces()' only of a convex solid, shifted or not.)
        if (several || found == nc) continue;
        // No edge region in B (a rounded box's reach inside it by its radius).
        inside[i] = sign(found) * terms[found * n + i] + r + rounds[found] <= 0.0;
        if (!inside[i] && !known[found]) continue;
        regions[i] = r;
        kinker[i] = found;
        radius[i] = r;
        term[i] = rho * sign(found);
        least[i] = term[i] * rho * values[i] < 0.0;
        second[i] = inf;
        for (std::size_t o = 0; o < nc; ++o) {
            if (o != found) second[i] = std::min(second[i], rho * terms[o * n + i]);
        }
        // s = 1, F(p) < 0, of two: on an edge's region F >= 0 needs l_e >= tau with
        // U(tau, b) = 0, and b <= b(p) + r in B, so tau >= the dip below at that gap.
        tube[i] = term[i] > 0.0 && least[i] && nc == 2 && square[found] && rounds[found] == 0.0
            ? dipBelow(kernel, second[i] + r)
            : 0.0;
        any = true;
    }
    if (!any) return;
    // Per point and piece of the kinking child: the face sheet's distance d_j (or a bound below
    // it), NaN where it is not in J; whether p is on F's side of it.
    std::vector<double> sheetDistance(n * np, std::numeric_limits<double>::quiet_NaN());
    std::vector<char> sheetSide(n * np, 0);
    double best[kMaxBatch], bx[kMaxBatch], by[kMaxBatch], bz[kMaxBatch];
    for (std::size_t i = 0; i < n; ++i) {
        best[i] = out.surface[i] ? std::abs(out.distance[i]) : inf;
        bx[i] = out.x[i], by[i] = out.y[i], bz[i] = out.z[i];
    }
    // A point @a q found for point i: a bound above where F is on the other side of it, within
    // the tolerance.
    auto offer = [&](std::size_t i, const Vec3d& q) {
        const double d = (q - Vec3d(x[i], y[i], z[i])).length();
        if (!(d < best[i])) return;
        const double beyond = values[i] > 0.0 ? blend.value(q) : -blend.value(q);
        if (beyond > 0.0 && !(beyond <= query.tolerance * blend.gradient(q).length())) return;
        best[i] = d;
        bx[i] = q[0], by[i] = q[1], bz[i] = q[2];
    };
    // The sheet of child c with @a field in its place, at the points @a wanted says (with the
    // distance to the region where it holds, 0 for a face sheet); face sheet j's (@a j < np)
    // distances to sheetDistance, an edge sheet's (@a j = np) bound to regions.
    std::vector<Implicit::Ptr> faceSheets(nc * np); // kept for their creases (below)
    auto sheetAt = [&](std::size_t c, std::size_t j, const Implicit::Ptr& field, auto&& wanted) {
        std::size_t idx[kMaxBatch], m = 0;
        double px[kMaxBatch], py[kMaxBatch], pz[kMaxBatch], region[kMaxBatch];
        for (std::size_t i = 0; i < n; ++i) {
            if (kinker[i] != c || !wanted(i, region[m])) continue;
            idx[m] = i;
            px[m] = x[i], py[m] = y[i], pz[m++] = z[i];
        }
        if (m == 0) return;
        std::vector<Implicit::Ptr> sheetChildren = children;
        sheetChildren[c] = field;
        const auto sheet =
            std::make_shared<Blend>(blend.op(), blend.kernel(), std::move(sheetChildren));
        if (j < np) faceSheets[c * np + j] = sheet;
        double sv[kMaxBatch];
        FootPoints feet;
        FootQuery withFeet = query;
        withFeet.feet = true; // the points bound the distance above
        sheet->valuesAndFootPoints(px, py, pz, m, withFeet, sv, feet);
        for (std::size_t k = 0; k < m; ++k) {
            const std::size_t i = idx[k];
            // The sheet's distance where certified at a foot point, else a bound below it
            // (it is 1-Lipschitz): an answer without one is only said to be far, and the
            // first-order estimate that says so can be far too large where the sheet's
            // gradient is small (a valley between a cap's plane and the other child).
            const bool foot =
                feet.ok[k] && (feet.x[k] != px[k] || feet.y[k] != py[k] || feet.z[k] != pz[k]);
            const double d = foot ? std::abs(feet.distance[k]) : std::abs(sv[k]);
            const bool side = (sv[k] > 0.0) == (values[i] > 0.0); // p on F's side of it
            if (j == np) {
                regions[i] = std::min(regions[i], std::max(region[k], side ? d : 0.0));
            } else {
                sheetDistance[i * np + j] = d;
                sheetSide[i * np + j] = side;
            }
            // A point of the sheet's surface, certified or not (a rim of the edge sheet too
            // tight for the iteration), bounds the distance above where F is past it too.
            if (feet.ok[k] || feet.surface[k]) offer(i, Vec3d(feet.x[k], feet.y[k], feet.z[k]));
        }
    };
    for (std::size_t c = 0; c < nc; ++c) {
        for (std::size_t j = 0; j < pieces[c].size(); ++j) {
            const Piece& piece = pieces[c][j];
            sheetAt(c, j, std::make_shared<PieceField>(piece), [&](std::size_t i, double& region) {
                region = 0.0;
                return piece.value(Vec3d(x[i], y[i], z[i])) >= largest[i] - 2.0 * radius[i];
            });
        }
        for (const Edge& e : edges[c]) {
            const Piece &a = pieces[c][e.a], &b = pieces[c][e.b];
            const auto field = std::make_shared<PieceField>(pieces[c], e);
            sheetAt(c, np, field, [&](std::size_t i, double& region) {
                if (inside[i]) return false;
                const Vec3d p(x[i], y[i], z[i]);
                region = e.regionDistance(pieces[c], p);
                // From inside both pieces at right angles, a point beyond the edge at l_e >= tau
                // is at least hypot(region, tau) away.
                if (a.value(p) <= 0.0 && b.value(p) <= 0.0) region = std::hypot(region, tube[i]);
                return region < radius[i];
            });
            // The edge's own point nearest p (where the sheet's foot points, on the edge, have
            // no normal: a sharp edge of the surface).
            for (std::size_t i = 0; i < n; ++i) {
                if (kinker[i] != c || inside[i]) continue;
                const Vec3d p(x[i], y[i], z[i]);
                if (!(e.distance(pieces[c], p) < best[i])) continue;
                // The nearest point q of the line (or the corner) where the planes moved in by
                // round meet, or of the rim's circle; then out towards p by round.
                Vec3d q;
                if (!e.rim) {
                    const double va = a.value(p) + e.round, vb = b.value(p) + e.round;
                    q = p - a.gradient(p) * va - b.gradient(p) * vb;
                    if (e.corner) {
                        const Piece& third = pieces[c][e.c];
                        q -= third.gradient(p) * (third.value(p) + e.round);
                    }
                } else {
                    double sp, rp;
                    Vec3d radial;
                    e.meridian(p, sp, rp, radial);
                    if (!(rp > 0.0)) continue;
                    q = e.origin + e.axis * e.s0 + radial * e.r0;
                }
                const double len = (p - q).length();
                if (e.round == 0.0 || len > 0.0) {
                    offer(i, q + (p - q) * (e.round / std::max(len, 1e-300)));
                }
            }
        }
    }
    double phi[8];
    for (std::size_t i = 0; i < n; ++i) {
        const std::size_t c = kinker[i];
        if (c == nc) continue;
        const Vec3d p(x[i], y[i], z[i]);
        const std::vector<Piece>& ps = pieces[c];
        for (std::size_t j = 0; j < ps.size(); ++j) phi[j] = ps[j].value(p);
        const double s = term[i], f = rho * values[i]; // C's term is s C; F(p)
        const double own = sign(c) * terms[c * n + i];
        // R0: the sheets' own bound (the least, or the largest on F's side), and by regions
        // (of pieces at right angles: the distance to where some of their values are at most
        // some bounds is the hypot of p's excesses).
        double sheets = least[i] ? inf : 0.0, split = s > 0.0 && f > 0.0 ? std::max(own, 0.0) : inf;
        // A capped cone's pieces need not meet at right angles: its faces' regions are
        // rectangles in the half-plane through the axis.
        const bool cone = !square[c] && edges[c].size() == 2 && edges[c][0].rim;
        if (s > 0.0 && !square[c] && !cone) split = 0.0; // no bound by regions
        for (std::size_t j = 0; j < ps.size(); ++j) {
            const double d = sheetDistance[i * np + j];
            if (std::isnan(d)) continue; // not in J
            if (least[i]) sheets = std::min(sheets, d);
            else if (sheetSide[i * np + j]) sheets = std::max(sheets, d);
            if (s < 0.0 || (!square[c] && !cone)) continue;
            // G_j <= 0 needs phi_j at most the dip where the other terms lead phi_j: by their
            // lead at p less 2 r in B, and so, where phi_j is at most that dip, by the other
            // terms' least at p less r and the dip.
            double dip = dipAbove(kernel, nc, second[i] - phi[j] - 2.0 * radius[i]);
            dip = std::min(dip, dipAbove(kernel, nc, second[i] - radius[i] - dip));
            if (cone) {
                // F >= 0 in face j's region needs G_j >= 0 (F < 0 on C); F <= 0 needs phi_j at
                // most the dip.
                double region = f < 0.0 ? std::max(d, coneFaceDistance(ps, edges[c], j, p, 0.0, inf))
                                        : coneFaceDistance(ps, edges[c], j, p, 0.0, dip);
                if (f > 0.0 && sheetSide[i * np + j]) region = std::max(region, d);
                split = std::min(split, region);
                continue;
            }
            // Face j's region: the other pieces' values at most 0 there (at most one of each
            // parallel pair above 0 at p; a piece parallel to j bounds along j's normal).
            double others = 0.0, along = 0.0;
            for (std::size_t m = 0; m < ps.size(); ++m) {
                if (m == j) continue;
                // (A rounded box's: at most -round.)
                const double over = phi[m] + rounds[c];
                if (perpendicular[c][j * ps.size() + m]) {
                    others += std::pow(std::max(over, 0.0), 2);
                } else {
                    along = std::max(along, over);
                }
            }
            double region;
            if (f < 0.0) {
                // F >= 0 there needs phi_j >= 0 (F < 0 on C).
                region = std::max(d, std::sqrt(others + std::pow(std::max(-phi[j], along), 2)));
            } else {
                region = std::sqrt(others + std::pow(std::max(phi[j] - dip, along), 2));
                if (sheetSide[i * np + j]) region = std::max(region, d);
            }
            split = std::min(split, region);
        }
        if (s < 0.0 && f < 0.0) split = std::max(own, 0.0); // F < 0 on the faces' regions
        double faces = s < 0.0 && f > 0.0 ? sheets : std::max(sheets, split);
        if (square[c]) {
            // R0 itself: where at most one of the pieces (moved in by a rounded box's radius)
            // is above 0, as far as the hypot of p's excesses but the largest (at right angles).
            double sum = 0.0, top = 0.0;
            for (std::size_t j = 0; j < ps.size(); ++j) {
                const double over = std::max(phi[j] + rounds[c], 0.0);
                sum += over * over;
                top = std::max(top, over);
            }
            faces = std::max(faces, std::sqrt(std::max(sum - top * top, 0.0)));
        }
        const double below = std::min({faces, regions[i], radius[i]});
        if (!std::isfinite(best[i]) && below >= query.far) {
            // Farther than far from the surface: all that is asked there.
            out.ok[i] = true;
            out.surface[i] = false;
            out.distance[i] = std::copysign(below, values[i]);
            out.x[i] = x[i], out.y[i] = y[i], out.z[i] = z[i];
            done[i] = true;
            continue;
        }
        if (!(best[i] <= below + query.tolerance)) {
            // Where two face sheets meet at a sharp edge of F (a shrunk box's or cone's edge
            // the other children do not round), the nearest point can be on their crease,
            // which neither sheet's foot point is: offered from p.
            for (std::size_t j = 0; j < ps.size(); ++j) {
                for (std::size_t k = j + 1; k < ps.size(); ++k) {
                    // (A sheet distance is set only where its sheet was made.)
                    if (std::isnan(sheetDistance[i * np + j]) ||
                        std::isnan(sheetDistance[i * np + k])) {
                        continue;
                    }
                    Piece a, b;
                    a.f = faceSheets[c * np + j].get();
                    b.f = faceSheets[c * np + k].get();
                    Vec3d q;
                    double floor = 0.0;
                    if (creasePoint(a, b, p, p, query.tolerance, q, floor)) offer(i, q);
                }
            }
        }
        if (!(best[i] <= below + query.tolerance)) {
            // Not certified: the nearest point found still bounds the lattice search's answer.
            if (std::isfinite(best[i]) && !out.ok[i] &&
                (!out.surface[i] || best[i] < std::abs(out.distance[i]))) {
                out.surface[i] = true;
                out.distance[i] = std::copysign(best[i], values[i]);
                out.x[i] = bx[i], out.y[i] = by[i], out.z[i] = bz[i];
            }
            continue;
        }
        out.ok[i] = true;
        out.surface[i] = false;
        out.distance[i] = std::copysign(best[i], values[i]);
        out.x[i] = bx[i], out.y[i] = by[i], out.z[i] = bz[i];
        done[i] = true;
    }
}

/// Of two convex functions a and b with values @a fa, @a fb and gradients @a ga, @a gb at @a x:
/// how near @a p a point where both are 0 can be. Such a point q lies in both half-spaces
/// a(x) + ga . (q - x) <= 0 and b(x) + gb . (q - x) <= 0 (each function lies above its tangent
/// plane): the distance from p to their intersection (0 if p is in it; else the nearest of p's
/// projections onto either boundary that satisfies the other, and onto their common line).
double convexCreaseFloor(const Vec3d& p, const Vec3d& x, double fa, const Vec3d& ga, double fb,
                         const Vec3d& gb)
{
    const double la = ga.length(), lb = gb.length();
    if (!(la > 0.0) || !(lb > 0.0)) return 0.0;
    const Vec3d na = ga / la, nb = gb / lb;
    // The half-spaces n . q <= o.
    const double oa = dot(na, x) - fa / la, ob = dot(nb, x) - fb / lb;
    const double ha = dot(na, p) - oa, hb = dot(nb, p) - ob; // p's heights above the planes
    if (ha <= 0.0 && hb <= 0.0) return 0.0;
    double best = std::numeric_limits<double>::infinity();
    if (ha > 0.0 && hb - ha * dot(na, nb) <= 0.0) best = std::min(best, ha);
    if (hb > 0.0 && ha - hb * dot(na, nb) <= 0.0) best = std::min(best, hb);
    const double c = dot(na, nb), det = 1.0 - c * c;
    if (det > 1e-12) {
        const double ka = (ha - hb * c) / det, kb = (hb - ha * c) / det;
        best = std::min(best, (na * ka + nb * kb).length());
    }
    // Nearly parallel planes: their common line is too ill-conditioned to bound anything (two
    // planes facing each other across a gap still meet, far away, unless exactly parallel).
    return std::isfinite(best) ? best : 0.0;
}

/// The point of the crease {a = 0} and {b = 0} closest to @a p, from @a start: rounds of a
/// Gauss-Newton step onto both surfaces (the smallest move that zeroes both linearized values)
/// and a move along the crease's tangent to the foot of the perpendicular from p, until
/// converged (kConverged). Certified when q is on both surfaces and p - q is perpendicular to
/// the crease, within @a tol.
/// Where @a a is a plane, @a start on it, and @a b convex (Piece::convex), every round's point x
/// on the plane bounds the crease from p, whether it is found or not: b >= b(x) + g.(q - x) on
/// the plane (g the part of b's gradient along it), so a crease point q lies where g.(q - x)
/// <= -b(x), at least (g.(q0 - x) + b(x)) / |g| from q0, p's foot on the plane. The largest such
/// bound, with p's height above the plane, goes to @a floor (0 if none): a plane that passes
/// near a cone's side without cutting it there has no crease for the rounds to converge to.
/// Of two other convex pieces, each round's point bounds it likewise (convexCreaseFloor()).
bool creasePoint(const Piece& a, const Piece& b, const Vec3d& p, Vec3d q, double tol,
                 Vec3d& out, double& floor)
{
    floor = 0.0;
    const bool bounded = a.kind == Piece::Kind::Plane && b.convex;
    const double height = bounded ? a.value(p) : 0.0;
    const Vec3d q0 = p - a.n * height;
    double away = 0.0; // the largest bound on |q - q0| so far
    // The move along the crease's tangent assumes a straight crease; where it curves within the
    // distance, the move can overshoot, by a near constant factor, and the rounds alternate about
    // the foot point. After an overshoot, that factor (the gain: how much of the last move the
    // gap along the tangent closed) divides the next move (a secant step).
    double lastGap = 0.0, lastMove = 0.0;
    for (int round = 0; round < kMaxCreaseRounds; ++round) {
        const double fa = a.value(q), fb = b.value(q);
        const Vec3d ga = a.gradient(q), gb = b.gradient(q);
        if (bounded && fb > 0.0 && gb.lengthSqr() > 0.0) {
            const Vec3d g = gb - a.n * dot(a.n, gb);
            const double len = g.length();
            away = std::max(away, len > 0.0 ? (dot(g, q0 - q) + fb) / len
                                            : std::numeric_limits<double>::infinity());
            floor = std::sqrt(height * height + away * away);
        } else if (!bounded && a.convex && b.convex) {
            floor = std::max(floor, convexCreaseFloor(p, q, fa, ga, fb, gb));
        }
        const double aa = dot(ga, ga), ab = dot(ga, gb), bb = dot(gb, gb);
        const double det = aa * bb - ab * ab; // |ga x gb|^2
        if (!(det > 1e-12 * aa * bb) || !std::isfinite(det)) return false; // tangent surfaces
        Vec3d t = ga.cross(gb);
        t /= std::sqrt(det);
        const double offA = std::abs(fa) / std::sqrt(aa), offB = std::abs(fb) / std::sqrt(bb);
        const double gap = dot(p - q, t), along = std::abs(gap);
        out = q;
        const double c = kConverged * tol;
        if (offA <= c && offB <= c && along <= c) return true;
        if (round + 1 == kMaxCreaseRounds) return offA <= tol && offB <= tol && along <= tol;
        const double la = (fa * bb - fb * ab) / det, lb = (fb * aa - fa * ab) / det;
        q -= ga * la + gb * lb;
        double gain = 1.0;
        if (lastMove != 0.0 && (gap < 0.0) != (lastGap < 0.0)) {
            const double g = (lastGap - gap) / lastMove;
            if (g > 1.0 && g < 10.0) gain = g;
        }
        lastGap = dot(p - q, t);
        lastMove = lastGap / gain;
        q += t * lastMove;
    }
    return false;
}

/// What the crease of two children offers a point: its nearest point, no crease at all, or
/// nothing certain (the iteration did not converge).
enum class Crease { Found, None, Failed };

/// The crease of two spheres: a circle (centre, unit axis u, radius rho), or none where they do
/// not cut each other.
struct SphereCircle
{
    bool exists = false;
    Vec3d centre, u;
    double rho = 0.0, scale = 0.0; // scale: d + ra, for the on-axis test

    SphereCircle(const Sphere& a, const Sphere& b)
    {
        const Vec3d axis = b.center() - a.center();
        const double d = axis.length(), ra = a.radius(), rb = b.radius();
        if (!(d > std::abs(ra - rb)) || !(d < ra + rb)) return;
        exists = true;
        u = axis / d;
        const double t = (d * d + ra * ra - rb * rb) / (2.0 * d);
        rho = std::sqrt(std::max(ra * ra - t * t, 0.0));
        centre = a.center() + u * t;
        scale = d + ra;
    }

    /// The circle's point nearest @a p (exists), any of them for a point on its axis.
    Vec3d nearest(const Vec3d& p) const
    {
        Vec3d w = (p - centre) - u * dot(p - centre, u);
        double len = w.length();
        if (!(len > 1e-12 * scale)) { // on the axis: every point of the circle is as near
            w = std::abs(u[0]) < 0.9 ? u.cross(Vec3d(1, 0, 0)) : u.cross(Vec3d(0, 1, 0));
            len = w.length();
        }
        return centre + w * (rho / len);
    }
};

/// The crease of two spheres is a circle, or nothing where they do not cut each other: the
/// circle's point nearest @a p in closed form (any of them for a point on its axis).
Crease sphereCrease(const Sphere& a, const Sphere& b, const Vec3d& p, Vec3d& out)
{
    const SphereCircle circle(a, b);
    if (!circle.exists) return Crease::None;
    out = circle.nearest(p);
    return Crease::Found;
}

/// The nearest point of the crease of @a a and @a b to @a p: in closed form for two spheres
/// (@a sa and @a sb, null for other shapes) and for two planes (their line, none if they are
/// parallel), else by creasePoint() from @a start (from p's foot on a plane, if one is), which
/// also bounds how near p a crease it did not find can be (@a floor, else 0).
Crease nearestCreasePoint(const Piece& a, const Piece& b, const Sphere* sa, const Sphere* sb,
                          const Vec3d& p, const Vec3d& start, double tol, Vec3d& out,
                          double& floor)
{
    floor = 0.0;
    if (sa && sb) return sphereCrease(*sa, *sb, p, out);
    if (a.kind == Piece::Kind::Plane && b.kind == Piece::Kind::Plane) {
        // The least move from p onto both planes: p - la n_a - lb n_b, with [1 c; c 1] [la lb]
        // = [f_a f_b] (c = n_a . n_b), lands on the foot of the perpendicular from p.
        const double c = dot(a.n, b.n), det = 1.0 - c * c;
        if (!(det > 1e-12)) return Crease::None;
        const double fa = a.value(p), fb = b.value(p);
        out = p - a.n * ((fa - fb * c) / det) - b.n * ((fb - fa * c) / det);
        return Crease::Found;
    }
    // A plane first: it bounds the crease where the iteration fails (creasePoint()).
    if (b.kind == Piece::Kind::Plane && a.kind != Piece::Kind::Plane) {
        return creasePoint(b, a, p, p - b.n * b.value(p), tol, out, floor) ? Crease::Found
                                                                        : Crease::Failed;
    }
    return creasePoint(a, b, p, start, tol, out, floor) ? Crease::Found : Crease::Failed;
}

} // namespace

namespace {

/// The points where three spheres' surfaces meet, in closed form (trilateration): their count
/// (0 to 2) into @a out, or -1 if one of @a s is null (not a sphere). Centres on one line give
/// no isolated points (the spheres meet in a circle or not at all): 0.
int sphereCorners(const std::array<const Sphere*, 3>& s, Vec3d out[2])
{
    for (int k = 0; k < 3; ++k) {
        if (!s[k]) return -1;
    }
    const Vec3d p1 = s[0]->center(), d12 = s[1]->center() - p1, d13 = s[2]->center() - p1;
    const double d = d12.length();
    if (!(d > 0.0)) return 0;
    const Vec3d ex = d12 / d;
    const double i = dot(ex, d13);
    Vec3d ey = d13 - ex * i;
    const double j = ey.length();
    if (!(j > 1e-9 * (d + d13.length()))) return 0;
    ey /= j;
    const Vec3d ez = ex.cross(ey);
    const double r1 = s[0]->radius(), r2 = s[1]->radius(), r3 = s[2]->radius();
    const double x = (r1 * r1 - r2 * r2 + d * d) / (2.0 * d);
    const double y = (r1 * r1 - r3 * r3 + i * i + j * j) / (2.0 * j) - (i / j) * x;
    const double z2 = r1 * r1 - x * x - y * y;
    if (!(z2 >= 0.0)) return 0;
    const double z = std::sqrt(z2);
    const Vec3d base = p1 + ex * x + ey * y;
    out[0] = base + ez * z;
    out[1] = base - ez * z;
    return z > 0.0 ? 2 : 1;
}

/// Where two planes and a cone's side meet, in closed form: the planes' line o + t d cuts the
/// side's cone (radius r + slope s at s along the axis) where its distance from the axis equals
/// that radius, a quadratic in t; both roots (0 to 2 into @a out) where the radius is not
/// negative (the nappe the side is on). -1 unless @a f is two planes and a side, or the planes
/// are parallel.
int planePlaneSideCorners(const std::array<const Piece*, 3>& f, const Vec3d& p, Vec3d out[2])
{
    const Piece *a = nullptr, *b = nullptr, *side = nullptr;
    for (const Piece* k : f) {
        if (k->kind == Piece::Kind::Side && !side) side = k;
        else if (k->kind == Piece::Kind::Plane && !a) a = k;
        else if (k->kind == Piece::Kind::Plane && !b) b = k;
        else return -1;
    }
    if (!a || !b || !side) return -1;
    const double c = dot(a->n, b->n), det = 1.0 - c * c;
    if (!(det > 1e-12)) return -1;
    // The line's point nearest p (as nearestCreasePoint()) and its unit direction.
    const double fa = a->value(p), fb = b->value(p);
    const Vec3d o = p - a->n * ((fa - fb * c) / det) - b->n * ((fb - fa * c) / det);
    const Vec3d d = a->n.cross(b->n) / std::sqrt(det);
    // Radial part R0 + t Rd from the axis, and the radius c0 + c1 t, at o + t d.
    const Vec3d w0 = o - side->a;
    const double s0 = dot(w0, side->n), sd = dot(d, side->n);
    const Vec3d r0 = w0 - side->n * s0, rd = d - side->n * sd;
    const double c0 = side->r + side->slope * s0, c1 = side->slope * sd;
    // |R0 + t Rd|^2 = (c0 + c1 t)^2.
    const double qa = rd.lengthSqr() - c1 * c1, qb = dot(r0, rd) - c0 * c1,
                 qc = r0.lengthSqr() - c0 * c0;
    double roots[2];
    int count = 0;
    const double scale = rd.lengthSqr() + c1 * c1;
    if (std::abs(qa) <= 1e-12 * scale) {
        // The line parallel to a generator of the cone (or to the cylinder's axis): one root
        // at most, 2 qb t + qc = 0.
        if (std::abs(qb) > 0.0) roots[count++] = -qc / (2.0 * qb);
    } else {
        const double disc = qb * qb - qa * qc;
        if (disc < 0.0) return 0;
        // The root of larger magnitude first, the other from their product (no cancellation).
        const double big = -(qb + std::copysign(std::sqrt(disc), qb));
        if (big != 0.0) {
            roots[count++] = big / qa;
            roots[count++] = qc / big;
        } else {
            roots[count++] = 0.0; // qb = 0 and disc = 0: a double root at t = 0
        }
    }
    int kept = 0;
    for (int k = 0; k < count; ++k) {
        if (std::isfinite(roots[k]) && c0 + c1 * roots[k] >= 0.0) out[kept++] = o + d * roots[k];
    }
    return kept;
}

/// The point where the surfaces of @a f[0..2] meet nearest @a start: Newton's method on the
/// three values (a 3x3 system a step). Certified when q is on all three within @a tol.
bool cornerPoint(const std::array<const Piece*, 3>& f, Vec3d q, double tol, Vec3d& out)
{
    for (int round = 0; round < kMaxRounds; ++round) {
        Vec3d g[3];
        double v[3], off = 0.0;
        for (int k = 0; k < 3; ++k) {
            v[k] = f[k]->value(q);
            g[k] = f[k]->gradient(q);
            const double gl = g[k].length();
            if (!(gl > 0.0)) return false;
            off = std::max(off, std::abs(v[k]) / gl);
        }
        out = q;
        if (off <= kConverged * tol) return true;
        if (round + 1 == kMaxRounds) return off <= tol;
        // Solve [g0; g1; g2] dq = v by Cramer's rule.
        const double det = g[0].dot(g[1].cross(g[2]));
        if (!(std::abs(det) > 1e-12 * g[0].length() * g[1].length() * g[2].length())) return false;
        const Vec3d dq = (g[1].cross(g[2]) * v[0] + g[2].cross(g[0]) * v[1] +
                          g[0].cross(g[1]) * v[2]) / det;
        q -= dq;
    }
    return false;
}

} // namespace

namespace {

/// One batch of a CSG node's children as terms t_c = s_c f_c, in which the node is rho * min_c
/// t_c: a union of the sets {t_c < 0} (rho = 1), or the complement of one (rho = -1: an
/// intersection is the complement of the union of the children's outsides, a difference A - B
/// of A's outside and B). The surface, and so the distance up to its sign, is that of the union.
/// Each child's distances: an exact SDF's are its values (its foot points are found only where a
/// crease needs them); the others' come from their own foot points.
class CsgTerms
{
public:
    /// @a deepestTried: the deepest term's foot point was already tried at every point
    /// (nearestInside() does not try it again).
    CsgTerms(const std::vector<Implicit::Ptr>& children, Csg::Op op, const double* x,
             const double* y, const double* z, std::size_t n, const FootQuery& query,
             bool deepestTried)
        : mChildren(children), mOp(op), mX(x), mY(y), mZ(z), mQuery(query),
          mDeepestTried(deepestTried),
          mN(n), mValues(new double[children.size() * n]), mFeet(children.size()),
          mWhole(children.size()), mParts(children.size())
    {
        for (std::size_t c = 0; c < children.size(); ++c) {
            mSphere.push_back(dynamic_cast<const Sphere*>(children[c].get()));
            mWhole[c].f = children[c].get();
            mWhole[c].convex = detail::convexSdf(*children[c]);
            // Pieces are searched one by one: a term of many (a union of many boxes) is
            // searched whole instead, its crease by the iteration.
            if (!mSphere[c] && pieceParts(*children[c], mParts[c]) &&
                mParts[c].size() > kMaxTermPieces) {
                mParts[c].clear();
            }
            mPolyhedron.push_back(!mParts[c].empty());
            for (const Piece& piece : mParts[c]) {
                if (piece.kind != Piece::Kind::Plane) mPolyhedron.back() = false;
            }
            children[c]->values(x, y, z, value(c), n);
            if (children[c]->isExactSdf()) continue;
            mFeet[c] = std::make_unique<FootPoints>();
            FootQuery childQuery = query;
            childQuery.feet = true; // the creases start from them
            children[c]->footPoints(x, y, z, value(c), n, childQuery, *mFeet[c]);
        }
    }

    std::size_t size() const { return mChildren.size(); }
    /// Every child is an exact SDF: its distances are its values.
    bool allExact() const
    {
        for (const auto& f : mFeet) {
            if (f) return false;
        }
        return true;
    }
    /// The least term distance @a u and the next @a second at every point (allExact()).
    void firstTwo(std::size_t n, double* u, double* second) const;
    double sign(std::size_t c) const
    {
        return mOp == Csg::Op::Union ? 1.0
               : mOp == Csg::Op::Intersection ? -1.0 : (c == 0 ? -1.0 : 1.0);
    }
    /// The signed distance of child @a c at point @a i, and whether it is certified (below).
    double distance(std::size_t c, std::size_t i) const
    {
        return mFeet[c] ? mFeet[c]->distance[i] : value(c)[i];
    }
    bool certified(std::size_t c, std::size_t i) const { return !mFeet[c] || mFeet[c]->ok[i]; }
    /// Child @a c's point of its surface at point @a i where its distance is not certified
    /// (FootPoints::surface), to @a q; false where it has none.
    bool surfacePoint(std::size_t c, std::size_t i, Vec3d& q) const
    {
        if (!mFeet[c] || mFeet[c]->ok[i] || !mFeet[c]->surface[i]) return false;
        q = Vec3d(mFeet[c]->x[i], mFeet[c]->y[i], mFeet[c]->z[i]);
        return true;
    }
    /// Child @a c's value at point @a i.
    double childValue(std::size_t c, std::size_t i) const { return value(c)[i]; }

    /// Child @a c's foot point of point @a i; false where it is not certified.
    bool foot(std::size_t c, std::size_t i, Vec3d& q) const
    {
        if (mFeet[c]) {
            q = Vec3d(mFeet[c]->x[i], mFeet[c]->y[i], mFeet[c]->z[i]);
            return mFeet[c]->ok[i];
        }
        const Vec3d p(mX[i], mY[i], mZ[i]);
        if (const Sphere* sphere = mSphere[c]) {
            // The radial projection (none from the centre itself).
            const Vec3d r = p - sphere->center();
            const double len = r.length();
            q = len > 0.0 ? sphere->center() + r * (sphere->radius() / len) : p;
            return len > 0.0;
        }
        const Vec3d g = mChildren[c]->gradient(p);
        const double len = g.length();
        q = p - g * (len > 0.0 ? value(c)[i] / len : 0.0);
        return len > 0.5 && len < 1.5; // an exact SDF's gradient is a unit vector
    }

    /// Inside the union at point @a i (deepest term value @a u), near a crease: the nearest point
    /// of the union's surface is a term's foot point, a point of the crease of two terms or a
    /// corner of three, that lies outside every other term. Only terms whose surface is within
    /// reach can offer one. A term made of planes and cone sides (pieceParts()) is cut into
    /// them: the foot of the perpendicular on each, the crease of each two pieces (the term's own
    /// edges among them) and the corner of each three, where such a point lies on the term's
    /// surface. Writes the distance (at most far) and that point; returns whether certified.
    bool nearestInside(std::size_t i, double u, double& depth, Vec3d& nearest);

private:
    /// Point @a q lies on term @a c's surface, within the tolerance (a polyhedral term: its
    /// value is an exact distance outside and a lower bound inside, zero only on its surface).
    bool onTerm(std::size_t c, const Vec3d& q) const
    {
        return std::abs(mChildren[c]->value(q)) <= mQuery.tolerance;
    }

    /// Outside every term at q, within the tolerance (the terms in @a on excepted), for the
    /// query point @a p. Only the terms within reach (mNear) are asked when q is within far of
    /// p: any other term is at least far outside at p, so still outside at q (1-Lipschitz).
    bool outsideOthers(const Vec3d& p, const Vec3d& q, std::initializer_list<std::size_t> on) const
    {
        auto outside = [&](std::size_t c) {
            if (std::find(on.begin(), on.end(), c) != on.end()) return true;
            if (const Sphere* sphere = mSphere[c]) {
                // sign (|q - centre| - radius) >= -tolerance, squared (no square root).
                const double r2 = (q - sphere->center()).lengthSqr();
                if (sign(c) > 0.0) {
                    const double least = sphere->radius() - mQuery.tolerance;
                    return least <= 0.0 || r2 >= least * least;
                }
                const double most = sphere->radius() + mQuery.tolerance;
                return r2 <= most * most;
            }
            return sign(c) * mChildren[c]->value(q) >= -mQuery.tolerance;
        };
        if ((q - p).lengthSqr() <= mQuery.far * mQuery.far) {
            for (std::size_t c : mNear) {
                if (!outside(c)) return false;
            }
            return true;
        }
        for (std::size_t c = 0; c < mChildren.size(); ++c) {
            if (!outside(c)) return false;
        }
        return true;
    }

    const std::vector<Implicit::Ptr>& mChildren;
    Csg::Op mOp;
    const double *mX, *mY, *mZ;
    const FootQuery& mQuery;
    bool mDeepestTried;
    /// Child @a c's values (a row of the batch).
    double* value(std::size_t c) const { return mValues.get() + c * mN; }

    std::size_t mN;
    std::unique_ptr<double[]> mValues; // a row of n per child, written before it is read
    std::vector<std::unique_ptr<FootPoints>> mFeet;
    std::vector<const Sphere*> mSphere; // the children that are spheres (closed forms), else null
    std::vector<Piece> mWhole;                // each child as one piece
    std::vector<std::vector<Piece>> mParts;   // a child's pieces (pieceParts()), else empty
    std::vector<bool> mPolyhedron;            // its pieces are all planes
    std::vector<std::size_t> mNear; // reused across points
    std::vector<Vec3d> mNearFeet;   // their foot points (where found), as mNear
    /// A piece within reach of the point: of term @a term, no point of it on the term's surface
    /// nearer than @a bound, its search starting from @a start.
    struct NearPiece
    {
        const Piece* piece;
        std::size_t term;
        double bound;
        Vec3d start;
    };
    std::vector<NearPiece> mPieces; // reused across points
};

/// The least of @a m rows of signed terms s_c v_c (@a rows, @a signs) and the next, at @a n
/// points: a loop over the points per row, which vectorizes.
IVDB_VECTOR_CLONES
void firstTwoRows(const double* const* rows, const double* signs, std::size_t m, std::size_t n,
                  double* __restrict u, double* __restrict second)
{
    for (std::size_t i = 0; i < n; ++i) {
        u[i] = signs[0] * rows[0][i];
        second[i] = std::numeric_limits<double>::max();
    }
    for (std::size_t c = 1; c < m; ++c) {
        const double s = signs[c];
        const double* v = rows[c];
        for (std::size_t i = 0; i < n; ++i) {
            const double d = s * v[i];
            second[i] = std::min(second[i], std::max(u[i], d));
            u[i] = std::min(u[i], d);
        }
    }
}

void CsgTerms::firstTwo(std::size_t n, double* u, double* second) const
{
    std::vector<const double*> rows(size());
    std::vector<double> signs(size());
    for (std::size_t c = 0; c < size(); ++c) rows[c] = value(c), signs[c] = sign(c);
    firstTwoRows(rows.data(), signs.data(), size(), n, u, second);
}

bool CsgTerms::nearestInside(std::size_t i, double u, double& depth, Vec3d& nearest)
{
    const Vec3d p(mX[i], mY[i], mZ[i]);
    mNear.clear();
    std::size_t deepest = 0;
    for (std::size_t c = 0; c < size(); ++c) {
        const double t = sign(c) * distance(c, i);
        if (t < mQuery.far) mNear.push_back(c);
        if (t == u) deepest = c;
    }
    // The deepest term's foot point, where it lies outside every other term, is the nearest
    // point: it is -u away, and every point of the union's surface is at least as far (it lies
    // outside the deepest term, whose surface is -u away).
    if (!mDeepestTried && foot(deepest, i, nearest) && outsideOthers(p, nearest, {deepest})) {
        depth = std::min((p - nearest).length(), mQuery.far);
        if (depth <= -u + mQuery.tolerance) return true;
    }
    // Nearest surfaces first: a crease (or corner) point of terms a and b is |p - q| >= |d_a|
    // and >= |d_b| away (the distance to each surface is at most that), so once a term is as far
    // as the best candidate so far, no later pair or corner can beat it.
    std::sort(mNear.begin(), mNear.end(), [&](std::size_t l, std::size_t r) {
        return std::abs(distance(l, i)) < std::abs(distance(r, i));
    });
    double best = std::numeric_limits<double>::max();
    nearest = p;
    bool complete = true; // every candidate was found
    // Every term within reach a sphere, or every one polyhedral: feet, creases and corners all
    // in closed form (each crease and corner of planes is one point), so finding none outside
    // the other terms proves the nearest surface point lies beyond far.
    bool spheres = true, polyhedra = true;
    for (std::size_t c : mNear) {
        spheres = spheres && mSphere[c] != nullptr;
        polyhedra = polyhedra && mPolyhedron[c];
    }
    const bool closedForms = spheres || polyhedra;
    auto offer = [&](const Vec3d& q) {
        const double d = (p - q).length();
        if (d < best) best = d, nearest = q;
    };
    mNearFeet.resize(mNear.size());
    for (std::size_t a = 0; a < mNear.size(); ++a) {
        const std::size_t c = mNear[a];
        Vec3d& q = mNearFeet[a];
        if (!foot(c, i, q)) complete = false;
        else if (outsideOthers(p, q, {c})) offer(q);
    }
    // The pieces within reach, nearest first: a smooth term whole, another term's planes and
    // cone sides (a point of the term's surface on one is at least as far as the plane, or as
    // the side's line in the half-plane through the axis, and as that surface; the foot of the
    // perpendicular on a piece is a candidate where it lies on the term's surface).
    mPieces.clear();
    for (std::size_t a = 0; a < mNear.size(); ++a) {
        const std::size_t c = mNear[a];
        const double dc = std::abs(distance(c, i));
        if (mParts[c].empty()) {
            mPieces.push_back({&mWhole[c], c, dc, mNearFeet[a]});
            continue;
        }
        for (const Piece& piece : mParts[c]) {
            if (piece.kind == Piece::Kind::Whole) {
                // A quadric part: its own foot point (Quadric::footPoints), a candidate where it
                // lies on the term's surface, as a plane's is (from inside an elliptic cone the
                // term's nearest point can be on a cap outside the others, the side's nearer
                // than any crease); not certified, a candidate may be missing.
                const double px = p[0], py = p[1], pz = p[2], fv = piece.f->value(p);
                FootPoints own;
                FootQuery query = mQuery;
                query.feet = true;
                piece.f->footPoints(&px, &py, &pz, &fv, 1, query, own);
                if (!own.ok[0]) complete = false;
                const Vec3d q(own.x[0], own.y[0], own.z[0]);
                const double bound = own.ok[0] ? std::max(dc, std::abs(own.distance[0])) : dc;
                if (bound >= std::min(best, mQuery.far)) continue;
                mPieces.push_back({&piece, c, bound, own.ok[0] ? q : mNearFeet[a]});
                if (own.ok[0] && onTerm(c, q) && outsideOthers(p, q, {c})) offer(q);
                continue;
            }
            const double f = piece.value(p), bound = std::max(dc, std::abs(f));
            if (bound >= std::min(best, mQuery.far)) continue;
            const Vec3d q = p - piece.gradient(p) * f;
            mPieces.push_back({&piece, c, bound, q});
            if (onTerm(c, q) && outsideOthers(p, q, {c})) offer(q);
        }
    }
    std::stable_sort(mPieces.begin(), mPieces.end(),
                     [](const NearPiece& l, const NearPiece& r) { return l.bound < r.bound; });
    // A point found on a piece lies on its term's surface: a whole term's by construction, a
    // plane's, side's or quadric part's where the term's value there is zero (within a face or
    // on its edges).
    auto onPieces = [&](std::initializer_list<const NearPiece*> pieces, const Vec3d& q) {
        for (const NearPiece* e : pieces) {
            if ((e->piece->kind != Piece::Kind::Whole || e->piece->part) && !onTerm(e->term, q)) {
                return false;
            }
        }
        return true;
    };
    auto sphereOf = [&](const NearPiece& e) {
        return e.piece->kind == Piece::Kind::Whole ? mSphere[e.term] : nullptr;
    };
    auto beyond = [&](const NearPiece& e) { return e.bound >= best; };
    double failedFloor = std::numeric_limits<double>::infinity(); // of the creases not found
    for (std::size_t a = 0; a < mPieces.size() && !beyond(mPieces[a]); ++a) {
        const NearPiece& pa = mPieces[a];
        for (std::size_t b = a + 1; b < mPieces.size() && !beyond(mPieces[b]); ++b) {
            const NearPiece& pb = mPieces[b];
            Vec3d q;
            double floor;
            const Crease crease = nearestCreasePoint(*pa.piece, *pb.piece, sphereOf(pa),
                                                     sphereOf(pb), p, pa.start,
                                                     mQuery.tolerance, q, floor);
            if (crease == Crease::None) continue; // the two surfaces do not meet
            if (crease == Crease::Failed) {
                // Not found: missing, unless no crease point can be nearer than the best (the
                // final one, below). A point of it lies on both pieces, as far as either's
                // bound at least.
                failedFloor = std::min(failedFloor, std::max({floor, pa.bound, pb.bound}));
                continue;
            }
            if (onPieces({&pa, &pb}, q) && outsideOthers(p, q, {pa.term, pb.term})) offer(q);
            // Where a third surface cuts this crease: a corner (both of three spheres', and of
            // two planes and a cone's side, in closed form; else the one Newton's method finds
            // from q).
            for (std::size_t k = b + 1; k < mPieces.size() && !beyond(mPieces[k]); ++k) {
                const NearPiece& pk = mPieces[k];
                Vec3d corners[2];
                int count = sphereCorners({sphereOf(pa), sphereOf(pb), sphereOf(pk)}, corners);
                if (count < 0) count = planePlaneSideCorners({pa.piece, pb.piece, pk.piece}, p, corners);
                if (count < 0) {
                    count = cornerPoint({pa.piece, pb.piece, pk.piece}, q, mQuery.tolerance,
                                        corners[0]) ? 1 : 0;
                }
                for (int c = 0; c < count; ++c) {
                    if (onPieces({&pa, &pb, &pk}, corners[c]) &&
                        outsideOthers(p, corners[c], {pa.term, pb.term, pk.term})) {
                        offer(corners[c]);
                    }
                }
            }
        }
    }
    if (failedFloor < std::min(best, mQuery.far)) complete = false;
    depth = std::min(best, mQuery.far);
    // Certified if every candidate was found, or the best reaches the lower bound |u| of the
    // distance (inside the union the distance is at least the deepest term's depth). With none
    // found, only closed forms prove that the surface lies beyond far (a point of it lies on some
    // term's surface, at least that term's |distance| away; here a crease point lies in a sphere
    // too far away to be asked, and the arc's ends are farther still): then depth = far.
    const bool found = best < std::numeric_limits<double>::max();
    return (complete && (found || closedForms)) || (found && best <= -u + mQuery.tolerance);
}

} // namespace

namespace {

/// The second least of @a m spheres' values (rows as Csg::mSpheres) at @a n points (the least
/// is the union's value): Sphere::values()' arithmetic, a loop over the points per sphere,
/// which vectorizes.
IVDB_VECTOR_CLONES
void sphereUnionSecond(const double* __restrict s, std::size_t m, const double* __restrict x,
                       const double* __restrict y, const double* __restrict z, std::size_t n,
                       double* __restrict second)
{
    double least[kMaxBatch];
    for (std::size_t i = 0; i < n; ++i) {
        least[i] = std::numeric_limits<double>::max();
        second[i] = std::numeric_limits<double>::max();
    }
    for (std::size_t c = 0; c < m; ++c) {
        const double cx = s[c], cy = s[m + c], cz = s[2 * m + c], r = s[3 * m + c];
        for (std::size_t i = 0; i < n; ++i) {
            const double v = detail::sphereValue(x[i], y[i], z[i], cx, cy, cz, r);
            second[i] = std::min(second[i], std::max(least[i], v));
            least[i] = std::min(least[i], v);
        }
    }
}

/// Inside a union of @a m spheres (rows as Csg::mSpheres), at @a n points of union value @a u:
/// the deepest sphere's foot point q (the radial projection) and its distance @a depth (at most
/// @a far), found where q lies outside every other sphere within @a tol and depth <= -u + tol
/// (then it is the nearest point of the union's surface). Loops over the points per sphere.
IVDB_VECTOR_CLONES
void sphereUnionDeepestFeet(const double* __restrict s, std::size_t m, const double* __restrict x,
                            const double* __restrict y, const double* __restrict z,
                            const double* __restrict u, std::size_t n, double tol, double far,
                            double* __restrict qx, double* __restrict qy, double* __restrict qz,
                            double* __restrict depth, bool* __restrict found)
{
    // The deepest sphere (the last whose value is u, as CsgTerms::nearestInside() takes it).
    std::size_t deepest[kMaxBatch];
    for (std::size_t i = 0; i < n; ++i) deepest[i] = 0;
    for (std::size_t c = 0; c < m; ++c) {
        const double cx = s[c], cy = s[m + c], cz = s[2 * m + c], r = s[3 * m + c];
        for (std::size_t i = 0; i < n; ++i) {
            const double v = detail::sphereValue(x[i], y[i], z[i], cx, cy, cz, r);
            deepest[i] = v == u[i] ? c : deepest[i];
        }
    }
    bool outside[kMaxBatch];
    for (std::size_t i = 0; i < n; ++i) {
        const std::size_t c = deepest[i];
        const Vec3d centre(s[c], s[m + c], s[2 * m + c]), p(x[i], y[i], z[i]);
        const Vec3d r = p - centre;
        const double len = r.length();
        const Vec3d q = len > 0.0 ? centre + r * (s[3 * m + c] / len) : p;
        qx[i] = q[0], qy[i] = q[1], qz[i] = q[2];
        depth[i] = std::min((p - q).length(), far);
        outside[i] = len > 0.0;
    }
    for (std::size_t c = 0; c < m; ++c) {
        const double cx = s[c], cy = s[m + c], cz = s[2 * m + c];
        const double least = s[3 * m + c] - tol, least2 = least * least;
        for (std::size_t i = 0; i < n; ++i) {
            const double dx = qx[i] - cx, dy = qy[i] - cy, dz = qz[i] - cz;
            const bool out = least <= 0.0 || dx * dx + dy * dy + dz * dz >= least2;
            outside[i] = outside[i] && (deepest[i] == c || out);
        }
    }
    for (std::size_t i = 0; i < n; ++i) found[i] = outside[i] && depth[i] <= -u[i] + tol;
}

/// sphereUnionNearest() takes unions of at most this many spheres (their corners, one for each
/// three, are found for every batch); nearestInside() the others.
constexpr std::size_t kMaxClosedFormSpheres = 12;

/// Inside a union of spheres @a children, near a crease (where the deepest sphere's foot point lies in
/// another sphere), at @a n points: CsgTerms::nearestInside()'s candidates
/// in closed form, without its set-up: each sphere's foot point (the radial projection), the
/// nearest point of each two spheres' crease circle, and each three spheres' corners, where the
/// point lies outside every other sphere (within @a tol), of the spheres within @a far of the
/// point (any other sphere's points are farther). The nearest is the nearest point of the
/// union's surface: @a depth (at most far) and @a q, certified in @a found, unless a point is
/// at a sphere's centre (no foot point: left uncertified for nearestInside()).
void sphereUnionNearest(const std::vector<Implicit::Ptr>& children, const double* x,
                        const double* y, const double* z, std::size_t n,
                        double tol, double far, double* qx, double* qy, double* qz,
                        double* depth, bool* found)
{
    const std::size_t m = children.size();
    const Sphere* s[kMaxClosedFormSpheres];
    for (std::size_t c = 0; c < m; ++c) s[c] = static_cast<const Sphere*>(children[c].get());
    auto outsideOthers = [&](const Vec3d& q, std::size_t a, std::size_t b, std::size_t e) {
        for (std::size_t c = 0; c < m; ++c) {
            if (c == a || c == b || c == e) continue;
            // CsgTerms::outsideOthers()' test: |q - centre| >= radius - tolerance, squared.
            const double least = s[c]->radius() - tol;
            if (!(least <= 0.0 || (q - s[c]->center()).lengthSqr() >= least * least)) return false;
        }
        return true;
    };
    // The corners do not depend on the point: those outside the other spheres, once, with the
    // spheres they lie on as bits.
    struct Corner
    {
        Vec3d q;
        std::uint64_t on;
    };
    Corner corners[2 * kMaxClosedFormSpheres * kMaxClosedFormSpheres * kMaxClosedFormSpheres / 6];
    std::size_t cornerCount = 0;
    for (std::size_t a = 0; a < m; ++a) {
        for (std::size_t b = a + 1; b < m; ++b) {
            for (std::size_t c = b + 1; c < m; ++c) {
                Vec3d at[2];
                const int count = sphereCorners({s[a], s[b], s[c]}, at);
                for (int k = 0; k < count; ++k) {
                    if (outsideOthers(at[k], a, b, c)) {
                        corners[cornerCount++] = {at[k], (1ull << a) | (1ull << b) | (1ull << c)};
                    }
                }
            }
        }
    }
    // The crease circles, likewise (sphereCrease()'s).
    std::vector<SphereCircle> circles;
    circles.reserve(m * (m - 1) / 2);
    for (std::size_t a = 0; a < m; ++a) {
        for (std::size_t b = a + 1; b < m; ++b) circles.emplace_back(*s[a], *s[b]);
    }
    const std::size_t none = m;
    for (std::size_t i = 0; i < n; ++i) {
        const Vec3d p(x[i], y[i], z[i]);
        double best = std::numeric_limits<double>::max();
        Vec3d nearest = p;
        auto offer = [&](const Vec3d& q) {
            const double d = (p - q).length();
            if (d < best) best = d, nearest = q;
        };
        std::uint64_t near = 0;
        bool complete = true;
        for (std::size_t c = 0; c < m; ++c) {
            const Vec3d& centre = s[c]->center();
            const double t =
                detail::sphereValue(p[0], p[1], p[2], centre[0], centre[1], centre[2],
                                    s[c]->radius());
            if (!(t < far)) continue;
            near |= 1ull << c;
            const Vec3d r = p - centre;
            const double len = r.length();
            if (!(len > 0.0)) {
                complete = false;
                continue;
            }
            const Vec3d q = centre + r * (s[c]->radius() / len);
            if (outsideOthers(q, c, none, none)) offer(q);
        }
        for (std::size_t a = 0, pair = 0; a < m && complete; ++a) {
            for (std::size_t b = a + 1; b < m; ++b, ++pair) {
                if (!(near >> a & 1) || !(near >> b & 1) || !circles[pair].exists) continue;
                const Vec3d q = circles[pair].nearest(p);
                if (outsideOthers(q, a, b, none)) offer(q);
            }
        }
        for (std::size_t k = 0; k < cornerCount; ++k) {
            if ((corners[k].on & near) == corners[k].on) offer(corners[k].q);
        }
        found[i] = complete;
        depth[i] = std::min(best, far);
        qx[i] = nearest[0], qy[i] = nearest[1], qz[i] = nearest[2];
    }
}

/// Csg::footPoints at every point (the children's distances, then the lead rule or the nearest
/// point inside).
void csgFootPoints(const std::vector<Implicit::Ptr>& children, Csg::Op op, const double* x,
                   const double* y, const double* z, std::size_t n, const FootQuery& query,
                   FootPoints& out, bool deepestTried = false)
{
    CsgTerms terms(children, op, x, y, z, n, query, deepestTried);
    const double rho = op == Csg::Op::Union ? 1.0 : -1.0;
    // The deciding term (by distance) u, its index and the next, second; whether all are
    // certified. Exact children without foot points asked: the least two in vectorized passes.
    // allOk: every term certified; bounded: the deciding term certified, and every other
    // certified or bounded below by its value (a 1-Lipschitz child's positive term: its
    // distance is at least its value), which is all the lead rule below needs of it.
    double u[kMaxBatch], second[kMaxBatch];
    std::size_t first[kMaxBatch];
    bool allOk[kMaxBatch], bounded[kMaxBatch];
    if (terms.allExact() && !query.feet) {
        terms.firstTwo(n, u, second);
        std::fill(allOk, allOk + n, true);
        std::fill(bounded, bounded + n, true);
    } else {
        for (std::size_t i = 0; i < n; ++i) {
            first[i] = 0;
            u[i] = std::numeric_limits<double>::max();
            second[i] = std::numeric_limits<double>::max();
            allOk[i] = bounded[i] = true;
            bool firstCertified = false;
            for (std::size_t c = 0; c < terms.size(); ++c) {
                const bool certified = terms.certified(c, i);
                double d = terms.sign(c) * terms.distance(c, i);
                allOk[i] = allOk[i] && certified;
                if (!certified) {
                    const double t = terms.sign(c) * terms.childValue(c, i);
                    if (t > 0.0 && children[c]->isDistanceBound()) d = t;
                    else bounded[i] = false;
                }
                if (d < u[i]) {
                    second[i] = u[i];
                    u[i] = d;
                    first[i] = c;
                    firstCertified = certified;
                } else if (d < second[i]) {
                    second[i] = d;
                }
            }
            bounded[i] = bounded[i] && firstCertified;
        }
    }
    for (std::size_t i = 0; i < n; ++i) {
        Vec3d q(x[i], y[i], z[i]);
        // Outside every term, the nearest term's distance is the distance to the union; inside,
        // so is the deciding term's as long as no other term comes within it (its foot point
        // then lies outside the others: they are 1-Lipschitz). Also beyond the range asked for.
        const bool settled = leadKeepsDistance(u[i], second[i], 0.0) || -u[i] >= query.far;
        out.surface[i] = false;
        if (!allOk[i] || settled) {
            out.distance[i] = rho * u[i];
            out.ok[i] = bounded[i] && settled;
            if (query.feet && !terms.foot(first[i], i, q)) out.ok[i] = false;
        } else {
            double depth;
            out.ok[i] = terms.nearestInside(i, u[i], depth, q);
            out.distance[i] = rho * -depth;
            // Not proven the nearest, but found on the surface: at least as near as that.
            out.surface[i] = !out.ok[i] && depth < query.far;
        }
        out.x[i] = q[0];
        out.y[i] = q[1];
        out.z[i] = q[2];
        if (out.ok[i]) continue;
        // A child's point of its surface (its distance not certified) that lies outside every
        // other term, within the tolerance, is a point of the node's surface too: the lattice
        // search's answer is no farther (a shell's blend, whose sharp edge its sheets found).
        const Vec3d p(x[i], y[i], z[i]);
        for (std::size_t c = 0; c < terms.size(); ++c) {
            Vec3d s;
            if (!terms.surfacePoint(c, i, s)) continue;
            const double d = (s - p).length();
            if ((out.surface[i] && d >= std::abs(out.distance[i])) || !(d < query.far)) continue;
            bool on = true;
            for (std::size_t o = 0; o < terms.size() && on; ++o) {
                on = o == c || terms.sign(o) * children[o]->value(s) >= -query.tolerance;
            }
            if (!on) continue;
            out.surface[i] = true;
            out.distance[i] = std::copysign(d, out.distance[i]);
            out.x[i] = s[0], out.y[i] = s[1], out.z[i] = s[2];
        }
    }
}

} // namespace

void Csg::footPoints(const double* x, const double* y, const double* z, const double* values,
                     std::size_t n, const FootQuery& query, FootPoints& out) const
{
    if (mChildren.size() == 1) {
        mChildren[0]->footPoints(x, y, z, values, n, query, out);
        return;
    }
    bool exact = !query.feet;
    for (const auto& c : mChildren) exact = exact && c->isExactSdf();
    if (!exact) {
        csgFootPoints(mChildren, mOp, x, y, z, n, query, out);
        return;
    }
    // Children that are all exact distances: where the node is outside every term (rho f > 0;
    // a union's outside, an intersection's or a difference's inside) its value is the distance
    // (the lead rule with the deciding term >= 0), and no child need be evaluated again there.
    // Only the other points go through the terms.
    const double rho = mOp == Op::Union ? 1.0 : -1.0;
    std::size_t idx[kMaxBatch], m = 0;
    double sx[kMaxBatch], sy[kMaxBatch], sz[kMaxBatch];
    for (std::size_t i = 0; i < n; ++i) { // without branches: m moves on for the others
        out.x[i] = x[i];
        out.y[i] = y[i];
        out.z[i] = z[i];
        out.distance[i] = values[i];
        const bool done = rho * values[i] > 0.0;
        out.ok[i] = done;
        idx[m] = i;
        sx[m] = x[i], sy[m] = y[i], sz[m] = z[i];
        m += !done;
    }
    if (m == 0) return;
    if (mOp == Op::Union && !mSpheres.empty()) {
        // A union of spheres: the next term after the deciding one from its rows in one
        // vectorized pass, and the lead and far rules settle most inside points here, without
        // the terms' set-up (csgFootPoints decides them so too, from the same values).
        double second[kMaxBatch];
        sphereUnionSecond(mSpheres.data(), mChildren.size(), sx, sy, sz, m, second);
        std::size_t left = 0;
        for (std::size_t k = 0; k < m; ++k) {
            const std::size_t i = idx[k];
            const double u = values[i];
            const bool done = leadKeepsDistance(u, second[k], 0.0) || -u >= query.far;
            out.ok[i] = done; // its distance is u already
            idx[left] = i;
            sx[left] = sx[k], sy[left] = sy[k], sz[left] = sz[k];
            left += !done;
        }
        m = left;
        if (m == 0) return;
        // Then the deepest sphere's foot point, where it lies outside every other sphere: the
        // nearest point (CsgTerms::nearestInside()'s first candidate, the same arithmetic).
        double u[kMaxBatch], qx[kMaxBatch], qy[kMaxBatch], qz[kMaxBatch], depth[kMaxBatch];
        for (std::size_t k = 0; k < m; ++k) u[k] = values[idx[k]];
        bool found[kMaxBatch];
        // The points found (depth and foot point) settled, the others compacted.
        auto settle = [&]() {
            std::size_t kept = 0;
            for (std::size_t k = 0; k < m; ++k) {
                const std::size_t i = idx[k];
                if (found[k]) {
                    out.distance[i] = -depth[k];
                    out.ok[i] = true;
                    out.x[i] = qx[k], out.y[i] = qy[k], out.z[i] = qz[k];
                }
                idx[kept] = i;
                sx[kept] = sx[k], sy[kept] = sy[k], sz[kept] = sz[k];
                kept += !found[k];
            }
            m = kept;
        };
        sphereUnionDeepestFeet(mSpheres.data(), mChildren.size(), sx, sy, sz, u, m,
                               query.tolerance, query.far, qx, qy, qz, depth, found);
        settle();
        if (m == 0) return;
        // Then the nearest of every candidate, in closed form, for the few spheres of a
        // pruned union (kMaxClosedFormSpheres).
        if (mChildren.size() <= kMaxClosedFormSpheres) {
            sphereUnionNearest(mChildren, sx, sy, sz, m, query.tolerance, query.far, qx, qy, qz,
                               depth, found);
            settle();
            if (m == 0) return;
        }
    }
    FootPoints sub;
    csgFootPoints(mChildren, mOp, sx, sy, sz, m, query, sub,
                  mOp == Op::Union && !mSpheres.empty());
    for (std::size_t k = 0; k < m; ++k) {
        const std::size_t i = idx[k];
        out.distance[i] = sub.distance[k];
        out.ok[i] = sub.ok[k];
        out.surface[i] = sub.surface[k];
        out.x[i] = sub.x[k], out.y[i] = sub.y[k], out.z[i] = sub.z[k];
    }
}

// GCC cannot see that the child reads only the n entries written below.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
void Transform::footPoints(const double* x, const double* y, const double* z,
                           const double* values, std::size_t n, const FootQuery& query,
                           FootPoints& out) const
{
    if (uniformScale() == 0.0 && mSurface) {
        // A non-uniform scale of a sphere, a quadric, a box, a capped cylinder or cone, a CSG
        // node, a blend, a transform, or an offset or shell with a shape of its own
        // (Offset::solid()): the same surface's foot points (a world quadric's, a rigidly moved
        // box's, the CSG's of a cone's quadric and cap planes or of a sheared box's planes, the
        // CSG's or the blend's of its children mapped, the offset shape's), from its own
        // values. Of an exact SDF child, a point that surface leaves uncertified (a degenerate
        // foot point deep inside) with |f| >= far is that far at least (the field is
        // 1-Lipschitz).
        double sv[kMaxBatch];
        mSurface->values(x, y, z, sv, n);
        mSurface->footPoints(x, y, z, sv, n, query, out);
        if (!mChild->isExactSdf()) return;
        for (std::size_t i = 0; i < n; ++i) {
            if (out.ok[i] || std::abs(values[i]) < query.far) continue;
            out.ok[i] = true;
            out.distance[i] = values[i];
            out.x[i] = x[i], out.y[i] = y[i], out.z[i] = z[i];
        }
        return;
    }
    if (uniformScale() == 0.0) {
        // A non-uniform scale is not a rigid motion: the field itself, by the smooth iteration.
        // Of a 1-Lipschitz child (an exact SDF) the field min(scale) child(q) is 1-Lipschitz (q
        // moves by at most 1 / min(scale) per unit of p): a point with |f| >= far is that far
        // at least, without iterating (Implicit::footPoints).
        Implicit::footPoints(x, y, z, values, n, query, out);
        return;
    }
    // Rigid motion and uniform scale: the child's foot points, mapped.
    double qx[kMaxBatch], qy[kMaxBatch], qz[kMaxBatch], local[kMaxBatch];
    toLocal(x, y, z, n, qx, qy, qz);
    for (std::size_t i = 0; i < n; ++i) local[i] = values[i] / mValueScale;
    FootQuery childQuery = query;
    childQuery.tolerance = query.tolerance / mValueScale;
    childQuery.far = query.far / mValueScale;
    mChild->footPoints(qx, qy, qz, local, n, childQuery, out);
    for (std::size_t i = 0; i < n; ++i) {
        out.distance[i] *= mValueScale;
        const Vec3d w = toWorld(Vec3d(out.x[i], out.y[i], out.z[i]));
        out.x[i] = w[0];
        out.y[i] = w[1];
        out.z[i] = w[2];
    }
}

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

} // namespace ivdb::implicit

namespace ivdb::implicit {

bool detail::convexSdf(const Implicit& f)
{
    if (dynamic_cast<const Sphere*>(&f) || dynamic_cast<const Box*>(&f) ||
        dynamic_cast<const RoundedBox*>(&f) || dynamic_cast<const CappedCone*>(&f)) {
        return true;
    }
    const auto* t = dynamic_cast<const Transform*>(&f);
    return t && t->uniformScale() > 0.0 && convexSdf(*t->child());
}

void detail::iterateUncertified(const Implicit& f, const double* x, const double* y,
                                const double* z, const double* values, std::size_t n,
                                const FootQuery& query, FootPoints& out, const double* gx,
                                const double* gy, const double* gz)
{
    std::size_t all = 0;
    for (std::size_t i = 0; i < n; ++i) all += out.ok[i] ? 0 : 1;
    if (all == n && gx) { // every point, in place (no copies)
        smoothFootPoints(f, x, y, z, values, gx, gy, gz, n, query, out);
        return;
    }
    std::size_t idx[kMaxBatch], m = 0;
    double sx[kMaxBatch], sy[kMaxBatch], sz[kMaxBatch], sv[kMaxBatch];
    double sgx[kMaxBatch], sgy[kMaxBatch], sgz[kMaxBatch];
    for (std::size_t i = 0; i < n; ++i) {
        if (out.ok[i]) continue;
        idx[m] = i;
        sx[m] = x[i], sy[m] = y[i], sz[m] = z[i], sv[m] = values[i];
        if (gx) sgx[m] = gx[i], sgy[m] = gy[i], sgz[m] = gz[i];
        ++m;
    }
    if (m == 0) return;
    FootPoints sub;
    if (!gx) f.gradients(sx, sy, sz, sgx, sgy, sgz, m);
    smoothFootPoints(f, sx, sy, sz, sv, sgx, sgy, sgz, m, query, sub);
    for (std::size_t k = 0; k < m; ++k) {
        const std::size_t i = idx[k];
        out.distance[i] = sub.distance[k];
        out.x[i] = sub.x[k], out.y[i] = sub.y[k], out.z[i] = sub.z[k];
        out.ok[i] = sub.ok[k];
        out.surface[i] = false;
    }
}

namespace {

/// Foot points on the level set {g = c} of g = s f, for an exact SDF f and signs s = +/-1 per
/// point (g is |f| for a shell): the point p moved by c - g(p) along grad g reaches g = c there
/// if the surface it lands on is that level set's nearest point, and since f is 1-Lipschitz no
/// point of the level set is nearer than |c - g(p)|. Certified where g at the landing point is c
/// within the tolerance (and, for a shell, f kept its sign); the rest are left uncertified.
void levelSetFeet(const Implicit& child, const double* x, const double* y, const double* z,
                  const double* childValues, const double* sign, double level, std::size_t n,
                  const FootQuery& query, FootPoints& out)
{
    double gx[kMaxBatch], gy[kMaxBatch], gz[kMaxBatch], lx[kMaxBatch], ly[kMaxBatch],
        lz[kMaxBatch], at[kMaxBatch];
    child.gradients(x, y, z, gx, gy, gz, n);
    for (std::size_t i = 0; i < n; ++i) {
        const double len = std::sqrt(gx[i] * gx[i] + gy[i] * gy[i] + gz[i] * gz[i]);
        const double g = sign[i] * childValues[i];
        out.distance[i] = g - level;
        // Beyond the range asked for only "farther" matters, and the value is a lower bound of
        // the distance (a grid shape's value is clamped to its band there, its gradient zero).
        out.ok[i] = std::abs(out.distance[i]) >= query.far ||
                    (len > 0.5 && len < 1.5 && sign[i] != 0.0);
        const double step = out.ok[i] ? (level - g) * sign[i] / len : 0.0;
        lx[i] = x[i] + step * gx[i];
        ly[i] = y[i] + step * gy[i];
        lz[i] = z[i] + step * gz[i];
    }
    child.values(lx, ly, lz, at, n);
    for (std::size_t i = 0; i < n; ++i) {
        out.x[i] = lx[i], out.y[i] = ly[i], out.z[i] = lz[i];
        if (!out.ok[i]) continue;
        if (std::abs(out.distance[i]) >= query.far) continue; // only "farther" is asked for
        out.ok[i] = std::abs(sign[i] * at[i] - level) <= query.tolerance &&
                    (sign[i] * at[i] >= 0.0 || level < 0.0);
    }
}

} // namespace

namespace {

/// The foot points of a node's solid as a shape of its own (Offset::solid(), Shell::solid()),
/// from that shape's values: the same surface and sign as the node's.
void solidFootPoints(const Implicit& solid, const double* x, const double* y, const double* z,
                     std::size_t n, const FootQuery& query, FootPoints& out)
{
    double own[kMaxBatch];
    solid.values(x, y, z, own, n);
    solid.footPoints(x, y, z, own, n, query, out);
}

} // namespace

void Offset::footPoints(const double* x, const double* y, const double* z, const double* values,
                        std::size_t n, const FootQuery& query, FootPoints& out) const
{
    if (mSolid) {
        // The shrunk (or grown) shape's own foot points, with this node's surface and sign.
        // Moving along the child's gradient reaches the shrunk surface near its sharp edges
        // only by the smooth iteration, which answered voxels up to 0.77 voxel too far there;
        // the grown surface of a union where the grown parts meet, likewise.
        return solidFootPoints(*mSolid, x, y, z, n, query, out);
    }
    if (!mChild->isExactSdf()) return Implicit::footPoints(x, y, z, values, n, query, out);
    double f[kMaxBatch], sign[kMaxBatch];
    for (std::size_t i = 0; i < n; ++i) f[i] = values[i] + mDistance, sign[i] = 1.0;
    levelSetFeet(*mChild, x, y, z, f, sign, mDistance, n, query, out);
    detail::iterateUncertified(*this, x, y, z, values, n, query, out);
}

void Shell::footPoints(const double* x, const double* y, const double* z, const double* values,
                       std::size_t n, const FootQuery& query, FootPoints& out) const
{
    if (mSolid) {
        // The difference of the child's solids at t/2 and -t/2: the CSG's foot points.
        return solidFootPoints(*mSolid, x, y, z, n, query, out);
    }
    if (!mChild->isExactSdf()) return Implicit::footPoints(x, y, z, values, n, query, out);
    double f[kMaxBatch], sign[kMaxBatch];
    mChild->values(x, y, z, f, n);
    if (mEroded) {
        // Two surfaces with exact distances: the outer, the child grown by t/2 (f - t/2, whose
        // feet the child's gradient reaches from anywhere), and the inner, the shrunk shape's
        // boundary (its own distances: its edges stay sharp). The nearer one, signed as the
        // shell: inside its material (within t/2 of the child's surface, outside the shrunk
        // shape) negative, in the hollow and beyond positive.
        double own[kMaxBatch];
        FootPoints inner;
        mEroded->values(x, y, z, own, n);
        mEroded->footPoints(x, y, z, own, n, query, inner);
        for (std::size_t i = 0; i < n; ++i) sign[i] = 1.0;
        levelSetFeet(*mChild, x, y, z, f, sign, mHalf, n, query, out);
        for (std::size_t i = 0; i < n; ++i) {
            if (f[i] >= 0.0) continue; // outside the child: the outer is nearer
            if (!inner.ok[i]) {
                out.ok[i] = false; // the inner one may be the nearer: left to the iteration
                continue;
            }
            const double toOuter = -out.distance[i]; // t/2 - f > 0, exact however it landed
            const double toInner = std::abs(inner.distance[i]);
            if (inner.distance[i] < 0.0 || toInner < toOuter) {
                // In the hollow (the outer is farther than the inner by t), or nearer the inner.
                out.distance[i] = inner.distance[i] < 0.0 ? toInner : -toInner;
                out.x[i] = inner.x[i], out.y[i] = inner.y[i], out.z[i] = inner.z[i];
                out.ok[i] = true;
            }
        }
        detail::iterateUncertified(*this, x, y, z, values, n, query, out);
        return;
    }
    for (std::size_t i = 0; i < n; ++i) sign[i] = f[i] > 0.0 ? 1.0 : f[i] < 0.0 ? -1.0 : 0.0;
    levelSetFeet(*mChild, x, y, z, f, sign, mHalf, n, query, out);
    detail::iterateUncertified(*this, x, y, z, values, n, query, out);
}

bool Blend::leadRuleApplies() const
{
    if (mChildren.size() > 64) return false;
    for (const auto& c : mChildren) {
        if (!c->isExactSdf()) return false;
    }
    return true;
}

namespace {

/// True if one of @a children is a shape whose value kinks inside (kinkPieces()), and at most
/// 64 (nearerFeet() tries each child's foot point).
bool anyChildKinks(const std::vector<Implicit::Ptr>& children)
{
    if (children.size() > 64) return false;
    std::vector<Piece> pieces;
    double round = 0.0;
    for (const auto& child : children) {
        if (kinkPieces(*child, pieces, round)) return true;
    }
    return false;
}

/// If f(@a q) is 0 or has the other sign than @a fp = f(@a p) (not 0): @a c, the far end of a
/// bisection of the segment from p to q (16 halvings), so that a point of the surface lies
/// between p and c, and |p - c| bounds the distance from above. False if f is NaN on the way.
bool surfaceBetween(const Implicit& f, const Vec3d& p, double fp, const Vec3d& q, Vec3d& c)
{
    if (fp == 0.0 || !(f.value(q) * fp <= 0.0)) return false;
    Vec3d lo = p, hi = q; // f(lo) has p's sign, f(hi) not
    for (int k = 0; k < 16; ++k) {
        const Vec3d mid = (lo + hi) * 0.5;
        const double v = f.value(mid) * fp;
        if (std::isnan(v)) return false;
        (v > 0.0 ? lo : hi) = mid;
    }
    c = hi;
    return true;
}

/// The hand-over's answer (BlendKernel::Handover): the blend's distance @a own moved the share
/// @a s of the way to the deciding child's @a child, but not across the surface. The child's
/// surface lies up to the tolerance from the blend's, so within that of the surface the ramp
/// could give the other sign than the blend's value (five voxels inside by up to 3e-4 voxel
/// answered outside: TestRasterize.DistanceBoundStoresEveryDistanceBound); there the blend's own
/// distance stays. The foot point stays the blend's: within the tolerance of the answer's
/// distance from the voxel.
inline double handedOver(double own, double child, double s)
{
    const double mixed = own + s * (child - own);
    return mixed * own > 0.0 ? mixed : own;
}

/// The least term rho t_c of a blend's @a nc rows of @a n terms at point @a i (@a first, of
/// child @a decider) and the next (@a second): the lead rule's two terms.
void leadingTerms(const double* terms, std::size_t nc, std::size_t n, std::size_t i, double rho,
                  double& first, double& second, std::size_t& decider)
{
    first = second = std::numeric_limits<double>::max();
    decider = 0;
    for (std::size_t c = 0; c < nc; ++c) {
        const double u = rho * terms[c * n + i]; // the child's distance in term form
        if (u < first) second = first, first = u, decider = c;
        else if (u < second) second = u;
    }
}

} // namespace

void Blend::childLeadFootPoints(const double* x, const double* y, const double* z,
                                const double* values, std::size_t n, const FootQuery& query,
                                FootPoints& out) const
{
    // The lead rule with the deciding child's own distance D (its foot points) in place of its
    // value, which for a child that is not an exact SDF only bounds it from below: where the
    // next term exceeds D by the lead, every point of the blend's surface within D of the point
    // lies where the blend is the deciding child within the blend's value tolerance, on the
    // side of the child where its term is positive, and a value that small puts the child's
    // surface within its distanceFactor() of that side times it; so the reach is taken at the
    // tolerance over the largest factor (mChildLeadFactor, docs/method.md#true-distances).
    // Elsewhere, the smooth iteration on the blended field, checked near a child's kinks as
    // in footPoints() (nearerFeet(): an offset of a box or a capped cone kinks where the shape
    // does, and an offset or a shell of a blend is a blend of its children's offsets), but
    // with the children's foot points alone for extra starts, and no Newton's method: on a
    // shell of a blend of a cone and a box those took 60% of the compute, and on 120 random
    // shrunk or shelled blends they moved the worst voxels little either way
    // (docs/performance.md#true-distances). A non-uniformly scaled capped cylinder in a blend:
    // its rims (edges, where the iteration cannot converge) far from the other child get the
    // scaled shape's own foot points.
    const std::size_t nc = mChildren.size();
    // The hand-over of feetFromRows(), at the tolerance over the factor.
    const BlendKernel::Handover handover =
        mKernel.handover(query.tolerance / mChildLeadFactor, nc);
    const double lead = handover.edge, start = handover.edge - handover.width;
    const double rho = mOp == Op::Union ? 1.0 : -1.0;
    auto termSign = [this](std::size_t c) {
        return mOp == Op::Difference && c > 0 ? -1.0 : 1.0;
    };
    const detail::BatchRows rows(nc * n);
    double* terms = rows.get();
    childRows(x, y, z, n, terms, nullptr);
    std::size_t decider[kMaxBatch];
    double second[kMaxBatch], handed[kMaxBatch]; // handed: the child's D in the ramp's zone
    bool candidate[kMaxBatch], led[kMaxBatch] = {}, inZone[kMaxBatch] = {};
    for (std::size_t i = 0; i < n; ++i) {
        double first;
        leadingTerms(terms, nc, n, i, rho, first, second[i], decider[i]);
        out.ok[i] = std::abs(values[i]) >= query.far; // 1-Lipschitz: that far at least
        out.distance[i] = values[i];
        out.x[i] = x[i], out.y[i] = y[i], out.z[i] = z[i];
        // D >= |value|: the rule with the value is necessary for the rule with D (and for the
        // zone below its edge).
        candidate[i] = !out.ok[i] && leadKeepsDistance(first, second[i], start);
    }
    // The child's distances in full up to where the blend's value can put a point it leads.
    FootQuery childQuery = query;
    childQuery.far = query.far + mKernel.swell(nc);
    for (std::size_t c = 0; c < nc; ++c) {
        std::size_t idx[kMaxBatch], m = 0;
        double cx[kMaxBatch], cy[kMaxBatch], cz[kMaxBatch], cv[kMaxBatch];
        for (std::size_t i = 0; i < n; ++i) {
            if (!candidate[i] || decider[i] != c) continue;
            idx[m] = i;
            cx[m] = x[i], cy[m] = y[i], cz[m] = z[i];
            cv[m++] = termSign(c) * terms[c * n + i]; // the child's own value
        }
        if (m == 0) continue;
        FootPoints feet;
        mChildren[c]->footPoints(cx, cy, cz, cv, m, childQuery, feet);
        for (std::size_t k = 0; k < m; ++k) {
            const std::size_t i = idx[k];
            const double d = termSign(c) * feet.distance[k]; // in the blend's sign
            if (!feet.ok[k] || !leadKeepsDistance(rho * d, second[i], start)) continue;
            if (!leadKeepsDistance(rho * d, second[i], lead)) {
                handed[i] = d;
                inZone[i] = true;
                continue;
            }
            out.distance[i] = d;
            out.ok[i] = true;
            out.x[i] = feet.x[k], out.y[i] = feet.y[k], out.z[i] = feet.z[k];
            led[i] = true;
        }
    }
    detail::iterateUncertified(*this, x, y, z, values, n, query, out);
    if (anyChildKinks(mChildren)) nearerFeet(x, y, z, values, n, query, terms, led, out, false);
    for (std::size_t i = 0; i < n && handover.width > 0.0; ++i) {
        if (!inZone[i] || !out.ok[i]) continue;
        const double margin = leadMargin(rho * handed[i], second[i]);
        out.distance[i] = handedOver(out.distance[i], handed[i],
                                     handoverRamp((margin - start) / handover.width));
    }
}

void Blend::footPoints(const double* x, const double* y, const double* z, const double* values,
                       std::size_t n, const FootQuery& query, FootPoints& out) const
{
    if (!leadRuleApplies()) {
        if (std::isfinite(mChildLeadFactor)) {
            return childLeadFootPoints(x, y, z, values, n, query, out);
        }
        // The smooth iteration, checked near a child's kinks (nearerFeet(), as in
        // childLeadFootPoints()).
        Implicit::footPoints(x, y, z, values, n, query, out);
        if (!anyChildKinks(mChildren)) return;
        const detail::BatchRows rows(mChildren.size() * n);
        childRows(x, y, z, n, rows.get(), nullptr);
        const bool led[kMaxBatch] = {};
        // The sheets' bounds need every child 1-Lipschitz (not a quadric's field).
        return nearerFeet(x, y, z, values, n, query, rows.get(), led, out, false,
                          isDistanceBound());
    }
    // With foot points asked for, the children's values and gradients once, for the lead rule
    // (the deciding child's gradient) and for the smooth iteration's start (the blend's
    // gradient from them). Without, the values alone: the points the lead and far rules
    // certify need no gradient.
    const std::size_t nc = mChildren.size();
    detail::BatchRows rows((query.feet ? 5 : 1) * nc * n);
    double *terms = rows.get(), *cg = query.feet ? terms + nc * n : nullptr;
    double* w = query.feet ? cg + 3 * nc * n : nullptr;
    childRows(x, y, z, n, terms, cg);
    feetFromRows(x, y, z, values, n, query, terms, cg, w, false, out);
}

void Blend::valuesAndFootPoints(const double* x, const double* y, const double* z, std::size_t n,
                                const FootQuery& query, double* values, FootPoints& out) const
{
    if (!leadRuleApplies()) {
        return Implicit::valuesAndFootPoints(x, y, z, n, query, values, out);
    }
    // values() and footPoints() from one evaluation of the children; the super-elliptic
    // kernel's exponentials serve the values and the weights (values()' bits: the same
    // operations in the same order). Without foot points asked for, the values alone, as in
    // footPoints().
    const std::size_t nc = mChildren.size();
    detail::BatchRows rows((query.feet ? 5 : 1) * nc * n);
    double *terms = rows.get(), *cg = query.feet ? terms + nc * n : nullptr;
    double* w = query.feet ? cg + 3 * nc * n : nullptr;
    childRows(x, y, z, n, terms, cg);
    const bool haveWeights = valuesFromRows(terms, n, values, w);
    feetFromRows(x, y, z, values, n, query, terms, cg, w, haveWeights, out);
}

void Blend::feetFromRows(const double* x, const double* y, const double* z, const double* values,
                         std::size_t n, const FootQuery& query, const double* terms,
                         const double* cg, double* w, bool haveWeights, FootPoints& out) const
{
    // Where the deciding child (of exact SDFs) leads the next by more than the blend's reach
    // and swell, the blend is that child within the tolerance, and so is its distance (the
    // lead rule). A blend of exact SDFs is 1-Lipschitz (its gradient is a convex combination
    // of the children's unit gradients, each signed), so |f| never exceeds the distance: where
    // |f| >= far, the point is that far at least, which is all that is asked there. Elsewhere,
    // the smooth iteration on the blended field.
    const std::size_t nc = mChildren.size();
    auto termSign = [this](std::size_t c) {
        return mOp == Op::Union ? 1.0 : mOp == Op::Intersection ? -1.0 : (c == 0 ? -1.0 : 1.0);
    };
    const double rho = mOp == Op::Union ? 1.0 : -1.0;
    const BlendKernel::Handover handover = mKernel.handover(query.tolerance, nc);
    const double lead = handover.edge;
    std::size_t decider[kMaxBatch];
    double first[kMaxBatch], second[kMaxBatch];
    bool led[kMaxBatch];
    bool anyBlended = false;
    for (std::size_t i = 0; i < n; ++i) {
        leadingTerms(terms, nc, n, i, rho, first[i], second[i], decider[i]);
        led[i] = leadKeepsDistance(first[i], second[i], lead);
        out.ok[i] = led[i] || std::abs(values[i]) >= query.far;
        anyBlended = anyBlended || !out.ok[i];
        out.distance[i] = led[i] ? rho * first[i] : values[i];
        out.x[i] = x[i], out.y[i] = y[i], out.z[i] = z[i];
    }
    if (query.feet) {
        for (std::size_t i = 0; i < n; ++i) {
            if (!led[i]) continue; // the far points need no foot point
            // The deciding child's own gradient, a unit vector for an exact SDF.
            const double* g = cg + 3 * decider[i] * n;
            const Vec3d grad(g[i], g[n + i], g[2 * n + i]);
            const double len = grad.length();
            if (!(len > 0.5 && len < 1.5)) {
                out.ok[i] = false;
                anyBlended = true;
                continue;
            }
            const double value = termSign(decider[i]) * rho * terms[decider[i] * n + i];
            const Vec3d q = Vec3d(x[i], y[i], z[i]) - grad * (value / len);
            out.x[i] = q[0], out.y[i] = q[1], out.z[i] = q[2];
        }
    }
    if (!anyBlended) return;
    if (!cg) {
        // Values only: the blend's gradients (gradients()' bits) at the points left alone.
        detail::iterateUncertified(*this, x, y, z, values, n, query, out);
    } else {
        double gx[kMaxBatch], gy[kMaxBatch], gz[kMaxBatch];
        gradientsFromRows(terms, cg, n, w, haveWeights, gx, gy, gz);
        detail::iterateUncertified(*this, x, y, z, values, n, query, out, gx, gy, gz);
    }
    nearerFeet(x, y, z, values, n, query, terms, led, out);
    // The hand-over: just inside the rule's edge a certified answer ramps to the deciding
    // child's distance, which the rule takes at the edge. Without the ramp the answers stepped
    // there by up to half the tolerance, which second differences see: the mean curvature of a
    // blend of two spheres (p = 20, voxel 0.0025) was 5.9% off in a ring of voxels.
    const double start = handover.edge - handover.width;
    for (std::size_t i = 0; i < n && handover.width > 0.0; ++i) {
        if (led[i] || !out.ok[i] || std::abs(values[i]) >= query.far) continue;
        const double margin = leadMargin(first[i], second[i]);
        if (margin <= start) continue;
        const double s = handoverRamp((margin - start) / handover.width);
        out.distance[i] = handedOver(out.distance[i], rho * first[i], s);
    }
}

void Blend::nearerFeet(const double* x, const double* y, const double* z, const double* values,
                       std::size_t n, const FootQuery& query, const double* terms,
                       const bool* led, FootPoints& out, bool allStarts, bool sheets) const
{
    const std::size_t nc = mChildren.size();
    auto own = [&](std::size_t c, std::size_t i) { // child c's own value at point i
        return (mOp == Op::Difference && c > 0 ? -1.0 : 1.0) * terms[c * n + i];
    };
    // The smooth iteration stops at a point q where p - q lies along the blend's gradient: the
    // nearest point of the surface where the field is smooth about p, but one of several where
    // a child's distance kinks within |p - q| of p, and there the nearest is often across the
    // kink (up to 0.44 voxel nearer, inside a box's smooth intersection with a sphere). Those
    // answers are uncertified, q a point of the surface all the same. Where the kink is one
    // child's, the blend's sheets there (sheetFeet()) certify most of them; the others go to
    // the lattice search, the faces within reach of the largest offering starts of their own
    // below.
    std::vector<std::vector<Piece>> pieces(nc);
    std::vector<double> rounds(nc, 0.0);
    bool kinked[kMaxBatch] = {}, anyKinked = false;
    for (std::size_t c = 0; c < nc; ++c) {
        if (!kinkPieces(*mChildren[c], pieces[c], rounds[c])) continue;
        for (std::size_t i = 0; i < n; ++i) {
            if (led[i] || std::abs(values[i]) >= query.far) continue;
            const double reach = out.ok[i] ? std::abs(out.distance[i]) : query.far;
            if (!piecesKinkWithin(pieces[c], Vec3d(x[i], y[i], z[i]), own(c, i) + rounds[c],
                                  reach + query.tolerance)) {
                continue;
            }
            kinked[i] = anyKinked = true;
            if (!out.ok[i]) continue;
            // A certified foot point is a point of the surface; a far answer (the first-order
            // estimate, no foot point) is not.
            out.ok[i] = false;
            out.surface[i] = out.x[i] != x[i] || out.y[i] != y[i] || out.z[i] != z[i];
        }
    }
    // Where the sheets certify the distance, nothing more is asked.
    bool done[kMaxBatch] = {};
    if (anyKinked && sheets) {
        sheetFeet(*this, x, y, z, values, n, query, terms, pieces, rounds, kinked, out, done);
    }
    // Other points of the surface: the smooth iteration from each child's own foot point,
    // p - f_c grad f_c (exact SDFs), which finds the part of the surface near that child's
    // nearest point, Newton's method where the rounds fail (a rim rounded tightly by the
    // blend). For the points left uncertified, they bound the lattice search's answer (a
    // capped cone's rim pointing at p, which the lattice's crossings around p missed by 0.2
    // voxel). A certified point can be one of two feet too where the two least terms tie
    // within the ball of its distance (their difference is 2-Lipschitz): outside a smooth
    // union, near the middle of its valley, one on either child's side (0.04 voxel apart).
    // Of two children, that is asked only where the foot point lies well to one side of
    // where the point is (the terms' difference moved by more than the distance, of at most
    // twice the distance it can move), and from the other child's foot point: near the
    // middle of a valley whose sides mirror each other the foot point is at its bottom.
    const double rho = mOp == Op::Union ? 1.0 : -1.0;
    auto term = [&](std::size_t c, double v) { // a child's value v as a term, union form
        return rho * (mOp == Op::Difference && c > 0 ? -v : v);
    };
    // The iteration from @a start, kept where it finds a point of the surface nearer than what
    // point i holds (a certified point stays certified; another becomes a surface point). It
    // starts where the segment from p to @a start crosses the surface (a child's foot point
    // lies on the child's surface, the blend's up to its swell away), and that crossing, a
    // point of the surface, bounds the distance: nearer than a certified answer by more than
    // the tolerance, it shows that answer to be a farther foot point. Outside a box smoothly
    // united with a torus, a voxel's nearest point lay on the box's edge, rounded by the blend
    // to a third of a voxel, which the iteration from the box's foot point (on the sharp edge)
    // did not reach: a certified answer 0.12 voxel too far.
    auto offer = [&](std::size_t i, const Vec3d& p, const Vec3d& start) {
        Vec3d from = start, c;
        if (surfaceBetween(*this, p, values[i], start, c)) {
            from = c;
            const double dc = (c - p).length();
            // Any nearer bound replaces a surface point's; a certified answer only falls if
            // the crossing is nearer by more than the tolerance it was certified within.
            if (!(out.ok[i] || out.surface[i]) ||
                dc < std::abs(out.distance[i]) - (out.ok[i] ? query.tolerance : 0.0)) {
                out.ok[i] = false;
                out.surface[i] = true;
                out.distance[i] = std::copysign(dc, values[i]);
                out.x[i] = c[0], out.y[i] = c[1], out.z[i] = c[2];
            }
        }
        Vec3d q;
        if (!smoothRefine(*this, p, from, query.tolerance, q) &&
            !(allStarts && newtonFootPoint(*this, p, from, query.tolerance, q))) {
            return;
        }
        const double d = (q - p).length();
        if ((out.ok[i] || out.surface[i]) && d >= std::abs(out.distance[i])) return;
        out.surface[i] = !out.ok[i];
        out.distance[i] = std::copysign(d, values[i]);
        out.x[i] = q[0], out.y[i] = q[1], out.z[i] = q[2];
    };
    // The points asked, in a first pass without branches (most are led, certified or far).
    bool asked[kMaxBatch];
    if (nc == 2) {
        for (std::size_t i = 0; i < n; ++i) {
            const bool valley = std::abs(terms[i] - terms[n + i]) < 2.0 * std::abs(out.distance[i]);
            asked[i] = !led[i] && !done[i] && std::abs(values[i]) < query.far &&
                       (!out.ok[i] || valley);
        }
    } else {
        for (std::size_t i = 0; i < n; ++i) {
            asked[i] = !led[i] && !done[i] && std::abs(values[i]) < query.far && !out.ok[i];
        }
    }
    for (std::size_t i = 0; i < n; ++i) {
        if (!asked[i]) continue;
        const Vec3d p(x[i], y[i], z[i]);
        std::size_t only = nc; // all children's starts
        if (out.ok[i]) {
            const double dist = std::abs(out.distance[i]);
            const double atP = rho * (terms[i] - terms[n + i]);
            const Vec3d q(out.x[i], out.y[i], out.z[i]);
            const double atQ = term(0, mChildren[0]->value(q)) - term(1, mChildren[1]->value(q));
            if (std::abs(atQ - atP) <= dist) continue;
            only = atQ < 0.0 ? 1 : 0; // the child that does not decide at q
        }
        for (std::size_t c = 0; c < nc; ++c) {
            if (only == nc || c == only) offer(i, p, p - mChildren[c]->gradient(p) * own(c, i));
        }
        if (!kinked[i] || !allStarts) continue;
        // Near a kink, from the foot of the perpendicular on each face within reach of the
        // largest (its plane's or its side's): the iteration stays on the sheet of the surface
        // that face makes, where the child's own foot point can lie on another.
        for (std::size_t c = 0; c < nc; ++c) {
            const double reach =
                (out.surface[i] ? std::abs(out.distance[i]) : query.far) + query.tolerance;
            double largest = 0.0;
            if (pieces[c].empty() ||
                !piecesKinkWithin(pieces[c], p, own(c, i) + rounds[c], reach, &largest)) {
                continue;
            }
            for (const Piece& piece : pieces[c]) {
                const double v = piece.value(p);
                if (v >= largest - 2.0 * reach) offer(i, p, p - piece.gradient(p) * v);
            }
        }
    }
}

bool Blend::mayKinkWithin(const Vec3d& p, double radius) const
{
    std::vector<Piece> pieces;
    for (const auto& child : mChildren) {
        if (child->mayKinkWithin(p, radius)) return true;
        pieces.clear();
        double round = 0.0;
        if (!kinkPieces(*child, pieces, round)) continue;
        if (piecesKinkWithin(pieces, p, child->value(p) + round, radius)) return true;
    }
    return false;
}

bool Csg::mayKinkWithin(const Vec3d& p, double radius) const
{
    for (const auto& child : mChildren) {
        if (child->mayKinkWithin(p, radius)) return true;
    }
    return false;
}

bool Transform::mayKinkWithin(const Vec3d& p, double radius) const
{
    const double least = std::min({mScale[0], mScale[1], mScale[2]});
    return mChild->mayKinkWithin(toLocal(p), radius / least);
}

} // namespace ivdb::implicit
