// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/Blend.h>
#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/Modifiers.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/implicit/Quadric.h>

#include <openvdb/Exceptions.h>

#include "../util/Simd.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <sstream>

namespace ivdb::implicit {

Transform::Transform(Ptr child, const Vec3d& translate, const Vec3d& rotateDeg,
                     const Vec3d& scale)
    : mChild(std::move(child)), mTranslate(translate), mScale(scale)
{
    if (!mChild) OPENVDB_THROW(openvdb::ValueError, "transform has no child");
    for (int i = 0; i < 3; ++i) {
        if (!std::isfinite(translate[i]) || !std::isfinite(rotateDeg[i])) {
            OPENVDB_THROW(openvdb::ValueError, "transform translate and rotate_deg must be finite");
        }
        if (!(scale[i] > 0.0) || !std::isfinite(scale[i])) {
            std::ostringstream os;
            os << "transform scale must be > 0 and finite, got " << scale[i];
            OPENVDB_THROW(openvdb::ValueError, os.str());
        }
    }
    const double d2r = M_PI / 180.0;
    const double cx = std::cos(rotateDeg[0] * d2r), sx = std::sin(rotateDeg[0] * d2r);
    const double cy = std::cos(rotateDeg[1] * d2r), sy = std::sin(rotateDeg[1] * d2r);
    const double cz = std::cos(rotateDeg[2] * d2r), sz = std::sin(rotateDeg[2] * d2r);
    // R = Rz * Ry * Rx
    const double r[3][3] = {
        {cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx},
        {sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx},
        {-sy, cy * sx, cy * cx}};
    std::copy(&r[0][0], &r[0][0] + 9, &mRot[0][0]);
    mValueScale = std::min(scale[0], std::min(scale[1], scale[2]));
    prepareSurface();
}

Transform::Transform(Ptr child, const Transform& like)
    : mChild(std::move(child)), mTranslate(like.mTranslate), mScale(like.mScale),
      mValueScale(like.mValueScale)
{
    std::copy(&like.mRot[0][0], &like.mRot[0][0] + 9, &mRot[0][0]);
    prepareSurface();
}

Transform::Transform(Ptr child, const Transform& like, Ptr surface)
    : mChild(std::move(child)), mTranslate(like.mTranslate), mScale(like.mScale),
      mValueScale(like.mValueScale), mSurface(std::move(surface))
{
    std::copy(&like.mRot[0][0], &like.mRot[0][0] + 9, &mRot[0][0]);
}

Transform::Transform(Ptr child, const Transform& like, bool)
    : mChild(std::move(child)), mTranslate(like.mTranslate), mScale(1.0), mValueScale(1.0)
{
    std::copy(&like.mRot[0][0], &like.mRot[0][0] + 9, &mRot[0][0]);
}

namespace {

/// The child-space quadric of the infinite cone (or cylinder) through @a c's rims, negative
/// inside.
Mat4 coneQuadric(const CappedCone& c)
{
    // With w = q - a, s = u . w and r(s) = r_a + k s (k = (r_b - r_a) / L):
    // |w|^2 - s^2 - r(s)^2 = w^T (I - (1 + k^2) u u^T) w - 2 r_a k s - r_a^2, negative inside.
    const Vec3d& a = c.a();
    const Vec3d& u = c.axis();
    const double ra = c.radiusA(), k = (c.radiusB() - ra) / c.length();
    double m[3][3];
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) m[i][j] = (i == j ? 1.0 : 0.0) - (1.0 + k * k) * u[i] * u[j];
    }
    Mat4 q{};
    double aAa = 0.0;
    for (int i = 0; i < 3; ++i) {
        const double ai = m[i][0] * a[0] + m[i][1] * a[1] + m[i][2] * a[2];
        for (int j = 0; j < 3; ++j) q[i][j] = m[i][j];
        q[i][3] = q[3][i] = -ai - ra * k * u[i];
        aAa += a[i] * ai;
    }
    q[3][3] = aAa + 2.0 * ra * k * u.dot(a) - ra * ra;
    return q;
}

/// The world image, under q = L p + l (@a m holds L = S^-1 R^T and l: the child-space map
/// [q 1] = M [p 1]), of the child-space half-space outward . (q - point) <= 0: the half-space
/// (L^T outward) . p < outward . (point - l), as its plane's exact SDF.
Implicit::Ptr capPlane(const Mat4& m, const Vec3d& point, const Vec3d& outward)
{
    Vec3d n;
    for (int j = 0; j < 3; ++j) n[j] = m[0][j] * outward[0] + m[1][j] * outward[1] + m[2][j] * outward[2];
    return makePlane(n, outward.dot(point - Vec3d(m[0][3], m[1][3], m[2][3])));
}

/// @a a times @a b.
Mat4 product(const Mat4& a, const Mat4& b)
{
    Mat4 out{};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            for (int k = 0; k < 4; ++k) out[i][j] += a[i][k] * b[k][j];
    return out;
}

/// Wraps a node in the transforms between the world and it (for a node under nested ones).
using Wrap = std::function<Implicit::Ptr(const Implicit::Ptr&)>;

/// The world surface and sign of @a node under the affine map @a m (world to node space, [q 1]
/// = m [p 1]; a transform's within another's, whose composition is no rotation and scale: a
/// shear) as a shape whose foot points are found directly, or null: a sphere's or quadric's
/// world quadric, a capped cylinder's or cone's quadric between its cap planes, a box's six
/// face planes intersected (a parallelepiped), a transform's child under both maps, a CSG
/// node's children so mapped (each other child @a wrap'ped, as it is: its own field), an
/// offset's or shell's solid. A blend's values matter, not only its surface: the blend of its
/// children wrapped, with its kernel rescaled by @a valueScale (the value's factor: the product
/// of the transforms' min(scale)), as in prepareSurface().
Implicit::Ptr affineSurface(const Implicit::Ptr& node, const Mat4& m, double valueScale,
                            const Wrap& wrap)
{
    const Implicit* f = node.get();
    if (const auto* t = dynamic_cast<const Transform*>(f)) {
        // A transform within another: their composition is an affine map, a shear where the
        // inner one rotates (no rotation and scale). The smooth iteration on the composed
        // field, not smooth at a box's edges, certified farther points inside a rotated box
        // scaled non-uniformly, and left thousands of voxels approximate.
        const Wrap inner = [&wrap, t](const Implicit::Ptr& k) { return wrap(t->moved(k)); };
        return affineSurface(t->child(), product(t->localMap(), m),
                             valueScale * t->valueScale(), inner);
    }
    if (const auto* s = dynamic_cast<const Sphere*>(f)) {
        // |q - c|^2 - r^2: the same surface and sign as the sphere's distance; the world
        // surface is that of M^T Q M.
        const Vec3d& c = s->center();
        const double r = s->radius();
        const Mat4 local = {{{1.0, 0.0, 0.0, -c[0]},
                             {0.0, 1.0, 0.0, -c[1]},
                             {0.0, 0.0, 1.0, -c[2]},
                             {-c[0], -c[1], -c[2], c.dot(c) - r * r}}};
        return std::make_shared<Quadric>(mapQuadric(local, m));
    }
    if (const auto* q = dynamic_cast<const Quadric*>(f)) {
        return std::make_shared<Quadric>(mapQuadric(q->matrix(), m));
    }
    if (const auto* c = dynamic_cast<const CappedCone*>(f)) {
        // The solid between the two cap planes within the cone (or cylinder) through the rim
        // circles: each maps to a surface whose foot points have closed forms (the world
        // quadric, and planes, exact SDFs), and their intersection's creases (the rims) are
        // the CSG's. The cone's other nappe lies beyond a cap. The smooth iteration on the
        // scaled field, not smooth at the rims, answered voxels more than a voxel off. A tip
        // (a radius of 0) is the quadric's singular point: near it some voxels outside are
        // still left to the lattice search (docs/method.md).
        const Vec3d b = c->a() + c->axis() * c->length();
        return std::make_shared<Csg>(
            Csg::Op::Intersection,
            std::vector<Implicit::Ptr>{std::make_shared<Quadric>(mapQuadric(coneQuadric(*c), m)),
                                       capPlane(m, c->a(), -c->axis()), capPlane(m, b, c->axis())});
    }
    if (const auto* b = dynamic_cast<const Box*>(f)) {
        std::vector<Implicit::Ptr> faces;
        const Vec3d half = b->size() * 0.5;
        for (int i = 0; i < 3; ++i) {
            Vec3d e(0.0);
            e[i] = 1.0;
            faces.push_back(capPlane(m, b->center() + e * half[i], e));
            faces.push_back(capPlane(m, b->center() - e * half[i], -e));
        }
        return std::make_shared<Csg>(Csg::Op::Intersection, std::move(faces));
    }
    if (const auto* c = dynamic_cast<const Csg*>(f)) {
        std::vector<Implicit::Ptr> parts;
        for (const Implicit::Ptr& k : c->children()) {
            const Implicit::Ptr part = affineSurface(k, m, valueScale, wrap);
            parts.push_back(part ? part : wrap(k));
        }
        return std::make_shared<Csg>(c->op(), std::move(parts));
    }
    if (const auto* b = dynamic_cast<const Blend*>(f)) {
        // Both kernels are homogeneous of degree 1 in the terms and 1/p (or k): s times a
        // blend of terms t is the blend of the terms s t with p / s (or k s). So the value, s
        // times the blend of the children's values, is the blend, so rescaled, of the children
        // transformed: the same field, whose children find their own foot points (a scaled
        // box's box, a capped cylinder's quadric between its caps) where one leads
        // (Blend::footPoints), with their distance factors for its lead rule. The smooth
        // iteration on the scaled field converged at the children's edges and rims to
        // farther points, and certified some of them.
        BlendKernel kernel = b->kernel();
        kernel.p /= valueScale;
        kernel.k *= valueScale;
        std::vector<Implicit::Ptr> parts;
        for (const Implicit::Ptr& k : b->children()) parts.push_back(wrap(k));
        return std::make_shared<Blend>(b->op(), kernel, std::move(parts));
    }
    const auto* offset = dynamic_cast<const Offset*>(f);
    const auto* shell = dynamic_cast<const Shell*>(f);
    if (const Implicit::Ptr solid = offset ? offset->solid() : shell ? shell->solid() : nullptr) {
        return affineSurface(solid, m, valueScale, wrap);
    }
    return nullptr;
}

} // namespace

void Transform::prepareSurface()
{
    // A rigid motion and uniform scale maps the child's own foot points (footPoints()); only a
    // non-uniform scale needs another route.
    if (uniformScale() > 0.0) return;
    const Mat4 m = localMap();
    // An offset or shell with a solid of its own (Offset::solid(): a shrunk box, capped cylinder
    // or cone is a smaller one, a CSG node's is the CSG of its parts offset; Shell::solid(): the
    // difference of a CSG node's solids at t/2 and -t/2): the surface is that solid's, mapped by
    // its route below (a box's scaled box, a capped cone's quadric between its caps, a CSG's).
    const auto* offset = dynamic_cast<const Offset*>(mChild.get());
    const auto* shell = dynamic_cast<const Shell*>(mChild.get());
    if (const Ptr solid = offset ? offset->solid() : shell ? shell->solid() : nullptr) {
        const std::shared_ptr<Transform> t(new Transform(solid, *this));
        mSurface = t->mSurface;
        return;
    }
    if (shell && shell->eroded()) {
        // The shell's solid is the child grown by t/2 less the child shrunk by t/2 (a smaller
        // box, capped cylinder or cone), each mapped with its own route: the smaller shape's
        // below, exact; the grown one (rounded, smooth) the smooth iteration's. Inside, the
        // inner surface's sharp edges were left to the smooth iteration, which answered voxels
        // over a voxel off.
        std::vector<Ptr> parts;
        for (const Ptr& k : {Ptr(std::make_shared<Offset>(shell->child(), 0.5 * shell->thickness())),
                             shell->eroded()}) {
            const std::shared_ptr<Transform> t(new Transform(k, *this));
            parts.push_back(t->mSurface ? t->mSurface : Ptr(t));
        }
        mSurface = std::make_shared<Csg>(Csg::Op::Difference, std::move(parts));
        return;
    }
    if (const auto* b = dynamic_cast<const Box*>(mChild.get())) {
        // The scale acts along the box's own axes: the box with centre S c and sides S size,
        // moved rigidly, an exact SDF.
        const Vec3d c = b->center(), size = b->size();
        const Vec3d sc(c[0] * mScale[0], c[1] * mScale[1], c[2] * mScale[2]);
        const Vec3d ss(size[0] * mScale[0], size[1] * mScale[1], size[2] * mScale[2]);
        try {
            mSurface = Ptr(new Transform(std::make_shared<Box>(sc, ss), *this, true));
        } catch (const openvdb::ValueError&) {
            // Sides that overflow, say: the smooth iteration instead.
        }
        return;
    }
    if (const auto* c = dynamic_cast<const Csg*>(mChild.get())) {
        // Sets commute with the map: the CSG of the children transformed has this node's
        // surface and sign, and each child may stand for its own surface (a box's scaled box,
        // an exact SDF; a sphere's quadric): a CSG node's surface and sign depend on its
        // children's only. Its foot points come from those children's and their creases, where
        // the smooth iteration on this node's field, not smooth at the creases, answered some
        // voxels a voxel off.
        std::vector<Ptr> moved;
        moved.reserve(c->children().size());
        for (const Ptr& k : c->children()) {
            const std::shared_ptr<Transform> t(new Transform(k, *this));
            moved.push_back(t->mSurface ? t->mSurface : Ptr(t));
        }
        mSurface = std::make_shared<Csg>(c->op(), std::move(moved));
        return;
    }
    // Any other child: its surface under the map, where it has a route (affineSurface()).
    try {
        mSurface = affineSurface(mChild, m, mValueScale, [this](const Ptr& k) { return moved(k); });
    } catch (const std::exception&) {
        // Not a usable quadric or plane (an overflow, say), a sharpness beyond the blend's
        // limits: the smooth iteration instead.
    }
}

std::array<std::array<double, 4>, 4> Transform::localMap() const
{
    // M = [[S^-1 R^T, -S^-1 R^T t], [0 0 0 1]].
    Mat4 m{};
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) m[i][j] = mRot[j][i] / mScale[i];
        m[i][3] = -(m[i][0] * mTranslate[0] + m[i][1] * mTranslate[1] + m[i][2] * mTranslate[2]);
    }
    m[3][3] = 1.0;
    return m;
}

Vec3d Transform::toLocal(const Vec3d& p) const
{
    const double dx = p[0] - mTranslate[0], dy = p[1] - mTranslate[1], dz = p[2] - mTranslate[2];
    // q = S^-1 R^T (p - t)
    return Vec3d((mRot[0][0] * dx + mRot[1][0] * dy + mRot[2][0] * dz) / mScale[0],
                 (mRot[0][1] * dx + mRot[1][1] * dy + mRot[2][1] * dz) / mScale[1],
                 (mRot[0][2] * dx + mRot[1][2] * dy + mRot[2][2] * dz) / mScale[2]);
}

namespace {
/// Transform::toLocal() of @a n points, in its order of operations (so the same bits), as a
/// loop that vectorizes: @a r the rotation, @a t the translation, @a s the scale.
IVDB_VECTOR_CLONES
void mapToLocal(const double (&r)[3][3], const Vec3d& t, const Vec3d& s, const double* __restrict x,
                const double* __restrict y, const double* __restrict z, std::size_t n,
                double* __restrict qx, double* __restrict qy, double* __restrict qz)
{
    const double r00 = r[0][0], r01 = r[0][1], r02 = r[0][2], r10 = r[1][0], r11 = r[1][1],
                 r12 = r[1][2], r20 = r[2][0], r21 = r[2][1], r22 = r[2][2];
    const double t0 = t[0], t1 = t[1], t2 = t[2], s0 = s[0], s1 = s[1], s2 = s[2];
    for (std::size_t i = 0; i < n; ++i) {
        const double dx = x[i] - t0, dy = y[i] - t1, dz = z[i] - t2;
        qx[i] = (r00 * dx + r10 * dy + r20 * dz) / s0;
        qy[i] = (r01 * dx + r11 * dy + r21 * dz) / s1;
        qz[i] = (r02 * dx + r12 * dy + r22 * dz) / s2;
    }
}
} // namespace

void Transform::toLocal(const double* x, const double* y, const double* z, std::size_t n,
                        double* qx, double* qy, double* qz) const
{
    mapToLocal(mRot, mTranslate, mScale, x, y, z, n, qx, qy, qz);
}

Vec3d Transform::toWorld(const Vec3d& q) const
{
    const Vec3d s(q[0] * mScale[0], q[1] * mScale[1], q[2] * mScale[2]);
    Vec3d p;
    for (int i = 0; i < 3; ++i) {
        p[i] = mRot[i][0] * s[0] + mRot[i][1] * s[1] + mRot[i][2] * s[2] + mTranslate[i];
    }
    return p;
}

double Transform::value(const Vec3d& p) const
{
    return mValueScale * mChild->value(toLocal(p));
}

Vec3d Transform::gradient(const Vec3d& p) const
{
    // d/dp [s child(S^-1 R^T (p - t))] = s R S^-1 grad child
    const Vec3d g = mChild->gradient(toLocal(p));
    const Vec3d h(g[0] / mScale[0], g[1] / mScale[1], g[2] / mScale[2]);
    Vec3d out;
    for (int i = 0; i < 3; ++i) {
        out[i] = mValueScale * (mRot[i][0] * h[0] + mRot[i][1] * h[1] + mRot[i][2] * h[2]);
    }
    return out;
}

// GCC cannot see that the child reads only the n entries written below.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
void Transform::values(const double* x, const double* y, const double* z, double* out,
                       std::size_t n) const
{
    double qx[kMaxBatch], qy[kMaxBatch], qz[kMaxBatch];
    toLocal(x, y, z, n, qx, qy, qz);
    mChild->values(qx, qy, qz, out, n);
    for (std::size_t i = 0; i < n; ++i) out[i] *= mValueScale;
}

void Transform::worldGradients(const double* cx, const double* cy, const double* cz, double* gx,
                               double* gy, double* gz, std::size_t n) const
{
    // As gradient(): s R S^-1 grad child, in its order of operations.
    for (std::size_t i = 0; i < n; ++i) {
        const double h0 = cx[i] / mScale[0], h1 = cy[i] / mScale[1], h2 = cz[i] / mScale[2];
        gx[i] = mValueScale * (mRot[0][0] * h0 + mRot[0][1] * h1 + mRot[0][2] * h2);
        gy[i] = mValueScale * (mRot[1][0] * h0 + mRot[1][1] * h1 + mRot[1][2] * h2);
        gz[i] = mValueScale * (mRot[2][0] * h0 + mRot[2][1] * h1 + mRot[2][2] * h2);
    }
}

void Transform::gradients(const double* x, const double* y, const double* z, double* gx,
                          double* gy, double* gz, std::size_t n) const
{
    double qx[kMaxBatch], qy[kMaxBatch], qz[kMaxBatch];
    toLocal(x, y, z, n, qx, qy, qz);
    // The child's gradients into gx..gz, then mapped in place (each point reads only its own).
    mChild->gradients(qx, qy, qz, gx, gy, gz, n);
    worldGradients(gx, gy, gz, gx, gy, gz, n);
}

void Transform::valuesAndGradients(const double* x, const double* y, const double* z,
                                   double* out, double* gx, double* gy, double* gz,
                                   std::size_t n) const
{
    double qx[kMaxBatch], qy[kMaxBatch], qz[kMaxBatch];
    toLocal(x, y, z, n, qx, qy, qz);
    mChild->valuesAndGradients(qx, qy, qz, out, gx, gy, gz, n);
    for (std::size_t i = 0; i < n; ++i) out[i] *= mValueScale;
    worldGradients(gx, gy, gz, gx, gy, gz, n);
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

namespace {
template<typename MapT>
BBoxd mapBox(const BBoxd& box, const MapT& map)
{
    BBoxd out(map(box.min()), map(box.min()));
    for (int c = 1; c < 8; ++c) {
        const Vec3d corner((c & 1) ? box.max()[0] : box.min()[0],
                           (c & 2) ? box.max()[1] : box.min()[1],
                           (c & 4) ? box.max()[2] : box.min()[2]);
        out.expand(map(corner));
    }
    return out;
}
} // namespace

Interval Transform::interval(const BBoxd& box) const
{
    const BBoxd local = mapBox(box, [this](const Vec3d& p) { return toLocal(p); });
    return mChild->interval(local) * mValueScale;
}

// GCC cannot see that the child reads only the n entries written below.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
void Transform::intervals(const double* cx, const double* cy, const double* cz, const Vec3d& half,
                          std::size_t n, double* lo, double* hi) const
{
    // The image of a box centre c +/- h under q = S^-1 R^T (p - t) lies in the box
    // q(c) +/- |S^-1 R^T| h, the box interval() maps its corners to.
    Vec3d localHalf;
    for (int i = 0; i < 3; ++i) {
        localHalf[i] = (std::abs(mRot[0][i]) * half[0] + std::abs(mRot[1][i]) * half[1] +
                        std::abs(mRot[2][i]) * half[2]) / mScale[i];
    }
    double qx[kMaxBatch], qy[kMaxBatch], qz[kMaxBatch];
    toLocal(cx, cy, cz, n, qx, qy, qz);
    mChild->intervals(qx, qy, qz, localHalf, n, lo, hi);
    for (std::size_t i = 0; i < n; ++i) {
        lo[i] *= mValueScale;
        hi[i] *= mValueScale;
    }
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

BBoxd Transform::boundingBox() const { return boundingBoxBelow(0.0); }

BBoxd Transform::boundingBoxBelow(double level) const
{
    // The value is mValueScale times the child's at the mapped point (the scale, or min(scale)
    // for a non-uniform one): below the level where the child's is below level / mValueScale.
    const BBoxd c = mChild->boundingBoxBelow(level / mValueScale);
    if (!isFinite(c)) return infiniteBox();
    return mapBox(c, [this](const Vec3d& q) { return toWorld(q); });
}

bool Transform::isExactOutside() const
{
    return mChild->isExactOutside() && uniformScale() > 0.0;
}

Implicit::Ptr Transform::moved(Ptr child) const { return Ptr(new Transform(std::move(child), *this)); }

double Transform::uniformScale() const
{
    return mScale[0] == mScale[1] && mScale[1] == mScale[2] ? mScale[0] : 0.0;
}

double Transform::distanceFactor(bool outside) const
{
    const double k = mChild->distanceFactor(outside);
    if (uniformScale() > 0.0) return k;
    return k * std::max({mScale[0], mScale[1], mScale[2]}) / mValueScale;
}

bool Transform::isExactSdf() const
{
    return mChild->isExactSdf() && uniformScale() > 0.0;
}

Implicit::Ptr Transform::sameSurface() const
{
    // Not the CSG surfaces (of children moved, or of a cone's quadric and caps): unmeasured
    // against the scaled field's own route.
    if (uniformScale() > 0.0 || !mSurface) return nullptr;
    if (mSurface->isExactSdf() || dynamic_cast<const Quadric*>(mSurface.get())) return mSurface;
    return nullptr;
}

Implicit::Ptr Transform::prune(const BBoxd& box) const
{
    const BBoxd local = mapBox(box, [this](const Vec3d& p) { return toLocal(p); });
    Ptr c = mChild->prune(local);
    if (c == mChild) return shared_from_this();
    // The surface pruned to the same box (a CSG drops the same children; others are kept),
    // rather than made anew for every box.
    return Ptr(new Transform(std::move(c), *this, mSurface ? mSurface->prune(box) : nullptr));
}

} // namespace ivdb::implicit
