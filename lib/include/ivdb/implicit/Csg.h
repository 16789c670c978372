// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/CsgOp.h>
#include <ivdb/implicit/Implicit.h>

#include <array>
#include <vector>

namespace ivdb::implicit {

/// @brief Sharp CSG over any number of children (docs/method.md#csg).
/// @details Union = min, intersection = max, difference = max(A, -B1, -B2, ...). The result is
/// not an exact distance near creases, so the rasterizer re-distances it. prune() drops the
/// children that cannot decide the result inside a box, which keeps a union of many shapes
/// cheap per voxel (libfive's and Fidget's per-region simplification).
class Csg final: public Implicit
{
public:
    using Op = CsgOp;

    /// @throw openvdb::ValueError if @a children is empty or holds a null pointer
    Csg(Op op, std::vector<Ptr> children);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    /// The children's foot points: outside every term (or where the deciding term leads the
    /// next by its own depth) the nearest; near a crease inside, the nearest of the children's
    /// foot points and the points of the creases of two children that lie outside the others.
    void footPoints(const double* x, const double* y, const double* z, const double* values,
                    std::size_t n, const FootQuery& query, FootPoints& out) const override;
    Interval interval(const BBoxd& box) const override;
    BBoxd boundingBox() const override;
    BBoxd boundingBoxBelow(double level) const override;
    bool isExactSdf() const override;
    /// A union of shapes exact outside is the distance outside it.
    bool isExactOutside() const override;
    /// Min and max of 1-Lipschitz children are 1-Lipschitz.
    bool isDistanceBound() const override;
    /// Where any child may.
    bool mayKinkWithin(const Vec3d& p, double radius) const override;
    /// The children's largest (min and max change no faster than their fastest argument).
    double lipschitzBound() const override;
    /// 1 outside a union, inside an intersection or a difference, where the children's are 1
    /// (a difference's subtracted children's outside); infinity elsewhere.
    double distanceFactor(bool outside) const override;
    Ptr prune(const BBoxd& box) const override;
    std::string typeName() const override;

    Op op() const { return mOp; }
    const std::vector<Ptr>& children() const { return mChildren; }

private:
    /// Each child's interval over @a box into @a lo, @a hi (as the child's own interval()).
    void childIntervals(const BBoxd& box, double* lo, double* hi) const;

    Op mOp;
    std::vector<Ptr> mChildren;
    /// When every child is a sphere: their centres' x, y, z and radii, 4 rows of one value per
    /// child, so their intervals (the descent's and prune()'s most frequent call for a union of
    /// many spheres) come from one loop that vectorizes. Empty otherwise.
    std::vector<double> mSpheres;
};

/// @brief The lead of the deciding term @a first over the next, @a second, in a union of
/// distances, as the lead rule measures it: second - first less twice the deciding term's depth
/// inside (max(0, -first)).
inline double leadMargin(double first, double second)
{
    return second - first - 2.0 * (first < 0.0 ? -first : 0.0);
}

/// @brief The lead rule of unions of distances (docs/method.md#true-distances): with the two
/// smallest terms @a first <= @a second of a union of exact (or 1-Lipschitz lower-bound)
/// distances at a point, the deciding term's value is the distance to the union's surface
/// unless a surface within @a reach of the crease can be nearer: true when the lead
/// (leadMargin()) is at least @a reach. Sharp CSG uses reach 0; the grid blend its blend's
/// reach (the blended surface leaves the sharp one only there); the scene blend hands over to
/// the deciding term below its edge (BlendKernel::Handover).
inline bool leadKeepsDistance(double first, double second, double reach)
{
    return leadMargin(first, second) >= reach;
}

/// @brief Rigid motion and scale of a child: p = R S q + t, with R = Rz Ry Rx.
/// @details The value is min(scale) * child(q): an exact SDF stays exact under uniform scale,
/// and a non-uniform scale keeps the sign and the Lipschitz bound (then it is re-distanced).
class Transform final: public Implicit
{
public:
    /// @param rotateDeg  rotations about x, then y, then z (fixed axes), in degrees
    /// @throw openvdb::ValueError if a scale component is <= 0 or any input is not finite
    Transform(Ptr child, const Vec3d& translate, const Vec3d& rotateDeg, const Vec3d& scale);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    /// The child's batch at the mapped points, its gradients mapped back as gradient() maps
    /// them (the same bits).
    void gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                   double* gz, std::size_t n) const override;
    void valuesAndGradients(const double* x, const double* y, const double* z, double* out,
                            double* gx, double* gy, double* gz, std::size_t n) const override;
    /// Rigid motion and uniform scale: the child's foot points mapped back. A non-uniform scale
    /// of a sphere or a quadric is a quadric, of a box a box with scaled sides, of a capped
    /// cylinder or cone the intersection of a quadric and two planes, of a CSG node the CSG of
    /// its children transformed, of a blend the blend of its children transformed (its
    /// sharpness over min(scale), or its width times it), of an offset or shell with a shrunk
    /// shape that shape's (or the
    /// difference of the shell's two solids): that surface's foot points (Quadric::footPoints;
    /// the box's, exact, under the rigid motion; Csg::footPoints); of any other child, the
    /// smooth iteration on this node's own field (of an exact SDF, only where |f| < far: the
    /// field is 1-Lipschitz, so |f| >= far is far enough).
    void footPoints(const double* x, const double* y, const double* z, const double* values,
                    std::size_t n, const FootQuery& query, FootPoints& out) const override;
    Interval interval(const BBoxd& box) const override;
    /// The child's intervals over the boxes' images (one size: the centres mapped, the half
    /// sizes through |S^-1 R^T|), in one batch.
    void intervals(const double* cx, const double* cy, const double* cz, const Vec3d& half,
                   std::size_t n, double* lo, double* hi) const override;
    BBoxd boundingBox() const override;
    BBoxd boundingBoxBelow(double level) const override;
    bool isExactSdf() const override;
    bool isExactOutside() const override;
    /// Of a 1-Lipschitz child, at any scale (the point moves by at most 1 / min(scale) in the
    /// child's space per unit in the world's).
    bool isDistanceBound() const override { return mChild->isDistanceBound(); }
    /// The child's: min(scale) times the child's rate along a move of at most 1 / min(scale).
    double lipschitzBound() const override { return mChild->lipschitzBound(); }
    /// The child's, times max(scale) / min(scale) for a non-uniform scale.
    double distanceFactor(bool outside) const override;
    /// The surface footPoints() answers for a non-uniform scale, where that is a world quadric
    /// or an exact SDF (a box moved rigidly).
    Ptr sameSurface() const override;
    /// The child's, at the child-space point, over the radius over min(scale).
    bool mayKinkWithin(const Vec3d& p, double radius) const override;
    Ptr prune(const BBoxd& box) const override;
    std::string typeName() const override { return "transform"; }

    /// @brief The child-space point of world point @a p.
    Vec3d toLocal(const Vec3d& p) const;
    /// @brief toLocal() as a matrix M: [q 1] = M [p 1].
    std::array<std::array<double, 4>, 4> localMap() const;
    /// @brief The world point of child-space point @a q.
    Vec3d toWorld(const Vec3d& q) const;
    const Ptr& child() const { return mChild; }
    /// @brief The same map applied to @a child.
    Ptr moved(Ptr child) const;
    /// @brief The scale, if it is the same along every axis (distances scale by it); else 0.
    double uniformScale() const;
    /// @brief The factor of the child's value in this node's: the scale, or min(scale).
    double valueScale() const { return mValueScale; }

private:
    Transform(Ptr child, const Transform& like);
    /// As @a like, with @a child and @a surface for mSurface (prune(): the surface pruned).
    Transform(Ptr child, const Transform& like, Ptr surface);
    /// The rigid motion of @a like (its rotation and translation) with unit scale.
    Transform(Ptr child, const Transform& like, bool rigid);
    /// mSurface, where the scale is not uniform and the child is a sphere, a quadric, a box, a
    /// capped cylinder or cone, a CSG node, a blend, or an offset or shell with a shape of its
    /// own.
    void prepareSurface();
    /// toLocal() of @a n points, into @a qx, @a qy, @a qz.
    void toLocal(const double* x, const double* y, const double* z, std::size_t n, double* qx,
                 double* qy, double* qz) const;
    /// World gradients from the child's gradients @a cx, @a cy, @a cz (in place into gx...).
    void worldGradients(const double* cx, const double* cy, const double* cz, double* gx,
                        double* gy, double* gz, std::size_t n) const;

    Ptr mChild;
    Vec3d mTranslate, mScale;
    double mRot[3][3];   // R, row-major
    double mValueScale;  // min(scale)
    /// The same surface, with the same sign, as a shape footPoints() answers directly: a
    /// world-space Quadric (called as an Implicit: its batch functions are target clones), a
    /// rigidly moved Box, the intersection of a cone's world quadric and its caps' planes, or
    /// the CSG of the children transformed (or of their own such surfaces), or the blend of the
    /// children transformed (the same field); null unless prepareSurface() made one.
    Ptr mSurface;
};

} // namespace ivdb::implicit
