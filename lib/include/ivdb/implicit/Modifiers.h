// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>

namespace ivdb::implicit {

/// @brief A shape grown (or shrunk) by a distance: f - d.
/// @details For an exact-distance child and d > 0 the value is the distance outside the grown
/// shape and a lower bound of it inside (where two parts of the grown surface meet it is not
/// the distance), so the rasterizer finds the distances (docs/method.md#true-distances).
class Offset final: public Implicit
{
public:
    /// @throw openvdb::ValueError if @a child is null or @a distance is not finite
    Offset(Ptr child, double distance);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    void gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                   double* gz, std::size_t n) const override;
    /// For an exact SDF child: the point moved along the child's gradient onto the offset
    /// surface, certified where it lands there (then nothing nearer can be: the child is
    /// 1-Lipschitz); elsewhere (a sharp edge shrunk, a medial axis grown) the smooth iteration.
    void footPoints(const double* x, const double* y, const double* z, const double* values,
                    std::size_t n, const FootQuery& query, FootPoints& out) const override;
    Interval interval(const BBoxd& box) const override;
    /// The child's box, grown by d > 0 when the child is exact outside; the solid's (solid())
    /// for a grown child that is not; else unbounded.
    BBoxd boundingBox() const override;
    BBoxd boundingBoxBelow(double level) const override;
    bool isExactSdf() const override { return false; }
    /// Grown (d >= 0) from a shape exact outside: f - d is the distance outside.
    bool isExactOutside() const override;
    /// Of an exact SDF child: 1 outside it grown and inside it shrunk (f - d is the distance
    /// there), and inside a convex solid grown; outside a box shrunk sqrt(3) (a sphere's or a
    /// rounded box's smaller one, 1); else infinity.
    double distanceFactor(bool outside) const override;
    bool isDistanceBound() const override { return mChild->isDistanceBound(); }
    double lipschitzBound() const override { return mChild->lipschitzBound(); }
    /// The solid's where there is one (its foot points are this node's), else the child's.
    bool mayKinkWithin(const Vec3d& p, double radius) const override
    {
        return (mSolid ? mSolid : mChild)->mayKinkWithin(p, radius);
    }
    Ptr prune(const BBoxd& box) const override;
    std::string typeName() const override { return "offset"; }

    const Ptr& child() const { return mChild; }
    double distance() const { return mDistance; }
    /// @brief The offset's solid {child <= d} as a shape of its own where one is known, else
    /// null: its foot points are this node's. Shrunk (d < 0): erodedShape() (a box's smaller
    /// box, a CSG node's parts shrunk...). Grown (d > 0) from a child that is not an exact SDF
    /// (whose gradient does not lead to the grown surface): dilatedShape() (a CSG node's parts
    /// grown...).
    const Ptr& solid() const { return mSolid; }

private:
    Ptr mChild;
    double mDistance;
    Ptr mSolid;
};

/// @brief A hollow shell of a shape, of thickness t centred on its surface: |f| - t/2.
/// @details The shell's surfaces are the child's offset by t/2 outwards and inwards. The value is
/// the distance outside the shell for an exact-distance child, and a lower bound inside it.
class Shell final: public Implicit
{
public:
    /// @throw openvdb::ValueError if @a child is null or @a thickness is not > 0 and finite
    Shell(Ptr child, double thickness);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    void gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                   double* gz, std::size_t n) const override;
    /// As Offset's, on whichever of the two offset surfaces lies on the point's side.
    void footPoints(const double* x, const double* y, const double* z, const double* values,
                    std::size_t n, const FootQuery& query, FootPoints& out) const override;
    Interval interval(const BBoxd& box) const override;
    /// The child's box grown by t/2 when the child is exact outside, else the solid's (solid()),
    /// else unbounded.
    BBoxd boundingBox() const override;
    BBoxd boundingBoxBelow(double level) const override;
    bool isExactSdf() const override { return false; }
    /// For an exact SDF child: both of the shell's surfaces are offsets of the child's.
    bool isExactOutside() const override { return mChild->isExactSdf(); }
    bool isDistanceBound() const override { return mChild->isDistanceBound(); }
    double lipschitzBound() const override { return mChild->lipschitzBound(); }
    /// The solid's where there is one (its foot points are this node's), else the child's.
    bool mayKinkWithin(const Vec3d& p, double radius) const override
    {
        return (mSolid ? mSolid : mChild)->mayKinkWithin(p, radius);
    }
    Ptr prune(const BBoxd& box) const override;
    std::string typeName() const override { return "shell"; }

    const Ptr& child() const { return mChild; }
    double thickness() const { return 2.0 * mHalf; }
    /// @brief The inner surface's solid (the child shrunk by t/2) as an exact SDF where one is
    /// known (erodedShape()), else null.
    const Ptr& eroded() const { return mEroded; }
    /// @brief Of a child that is not an exact SDF (a CSG node): the shell's solid, the child's
    /// solid at t/2 less its solid at -t/2 (dilatedShape(), erodedShape()), where both are
    /// known; else null. Its foot points are this node's.
    const Ptr& solid() const { return mSolid; }

private:
    Ptr mChild;
    double mHalf; // t/2
    Ptr mEroded, mSolid;
};

/// @brief The solid {child <= -delta}, @a delta > 0 (of an exact SDF, its points at least
/// delta inside), as a shape with exact foot points where one is known: a sphere's smaller
/// sphere, a box's smaller box, a rounded box's smaller rounded box (or, shrunk by more than its
/// radius, its inner box shrunk), a capped cylinder's or cone's shorter and thinner one, a CSG
/// node's parts at that level (its value is their min or max: a union's or intersection's parts
/// shrunk, a difference's first part shrunk and the others grown, dilatedShape()), and such a
/// shape's rigid motion or uniform scale the shrunk shape moved; null otherwise, or where
/// nothing (or a cone's tip) is left.
Implicit::Ptr erodedShape(const Implicit::Ptr& child, double delta);

/// @brief The solid {child <= delta}, @a delta > 0 (of an exact SDF, the points within delta of
/// it), as a shape with exact foot points where one is known: a sphere's larger sphere, a box's
/// rounded box, a CSG node's parts at that level (a union's or intersection's parts grown, a
/// difference's first part grown and the others shrunk), and such a shape's rigid motion or
/// uniform scale; null otherwise.
Implicit::Ptr dilatedShape(const Implicit::Ptr& child, double delta);

} // namespace ivdb::implicit
