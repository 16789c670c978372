// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>

#include <string>

namespace ivdb::implicit {

/// @brief Exact signed distance to a sphere: |p - c| - r.
class Sphere final: public Implicit
{
public:
    /// @throw openvdb::ValueError if @a radius <= 0 or any input is not finite
    Sphere(const Vec3d& center, double radius);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    void gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                   double* gz, std::size_t n) const override;
    /// One square root a point for both.
    void valuesAndGradients(const double* x, const double* y, const double* z, double* out,
                            double* gx, double* gy, double* gz, std::size_t n) const override;
    Interval interval(const BBoxd& box) const override;
    void intervals(const double* cx, const double* cy, const double* cz, const Vec3d& half,
                   std::size_t n, double* lo, double* hi) const override;
    BBoxd boundingBox() const override;
    bool isExactSdf() const override { return true; }
    std::string typeName() const override { return "sphere"; }

    const Vec3d& center() const { return mCenter; }
    double radius() const { return mRadius; }

private:
    Vec3d mCenter;
    double mRadius;
};

/// @brief Exact signed distance to an axis-aligned box given by its center and full size.
class Box final: public Implicit
{
public:
    /// @throw openvdb::ValueError if a size component is <= 0 or any input is not finite
    Box(const Vec3d& center, const Vec3d& size);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    Interval interval(const BBoxd& box) const override;
    BBoxd boundingBox() const override;
    bool isExactSdf() const override { return true; }
    std::string typeName() const override { return "box"; }

    const Vec3d& center() const { return mCenter; }
    /// The full edge lengths (twice the half sizes, exactly).
    Vec3d size() const { return mHalf * 2.0; }

private:
    Vec3d mCenter, mHalf;
};

/// @brief Exact signed distance to a ring torus around the z axis through @a center.
class Torus final: public Implicit
{
public:
    /// @throw openvdb::ValueError unless 0 < minorRadius < majorRadius
    Torus(const Vec3d& center, double majorRadius, double minorRadius);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    Interval interval(const BBoxd& box) const override;
    BBoxd boundingBox() const override;
    bool isExactSdf() const override { return true; }
    std::string typeName() const override { return "torus"; }

    double minorRadius() const { return mMinor; }

private:
    Vec3d mCenter;
    double mMajor, mMinor;
};

/// @brief Exact signed distance to a capsule: the points within @a radius of the segment ab.
class Capsule final: public Implicit
{
public:
    /// @throw openvdb::ValueError if @a radius <= 0 or any input is not finite (a == b is a
    /// sphere)
    Capsule(const Vec3d& a, const Vec3d& b, double radius);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    Interval interval(const BBoxd& box) const override;
    BBoxd boundingBox() const override;
    bool isExactSdf() const override { return true; }
    std::string typeName() const override { return "capsule"; }

    double radius() const { return mRadius; }

private:
    Vec3d mA, mAb;
    double mInvLen2, mRadius;
};

/// @brief Exact signed distance to an axis-aligned box of full edge lengths @a size whose edges
/// and corners are rounded with @a radius (the box of size - 2 radius grown by radius).
class RoundedBox final: public Implicit
{
public:
    /// @throw openvdb::ValueError unless 0 < radius <= min(size) / 2 and every input is finite
    RoundedBox(const Vec3d& center, const Vec3d& size, double radius);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    Interval interval(const BBoxd& box) const override;
    BBoxd boundingBox() const override;
    bool isExactSdf() const override { return true; }
    std::string typeName() const override { return "rounded_box"; }

    const Vec3d& center() const { return mCenter; }
    /// The full outer edge lengths.
    Vec3d size() const { return (mInner + Vec3d(mRadius)) * 2.0; }
    double radius() const { return mRadius; }

private:
    Vec3d mCenter, mInner; // mInner: half the size of the box before rounding
    double mRadius;
};

/// @brief Exact signed distance to the solid truncated cone between the points @a a and @a b,
/// of radius @a radiusA at a and @a radiusB at b (a capped cylinder when they are equal).
/// @details In the half-plane through the axis, at (distance from the axis, distance along it),
/// the solid is a trapezoid; the distance is the one to its three edges off the axis (the two
/// caps and the side).
class CappedCone final: public Implicit
{
public:
    /// @param name  the scene type, "capped_cone" or "capped_cylinder"
    /// @throw openvdb::ValueError if a == b, a radius is < 0, both are 0, or an input is not
    /// finite
    CappedCone(const Vec3d& a, const Vec3d& b, double radiusA, double radiusB,
               std::string name = "capped_cone");

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    Interval interval(const BBoxd& box) const override;
    BBoxd boundingBox() const override;
    bool isExactSdf() const override { return true; }
    std::string typeName() const override { return mName; }

    /// The end point a (radius radiusA()).
    const Vec3d& a() const { return mA; }
    /// The unit axis from a to b.
    const Vec3d& axis() const { return mAxis; }
    /// |b - a|.
    double length() const { return mLength; }
    double radiusA() const { return mRadiusA; }
    double radiusB() const { return mRadiusB; }

private:
    /// The signed distance, and in @a dir the unit direction of increase in (radial, axial)
    /// coordinates of the half-plane; @a radial the unit radial direction.
    double distance(const Vec3d& p, double dir[2], Vec3d& radial) const;

    Vec3d mA, mAxis, mPerp; // mAxis: unit a -> b; mPerp: a unit vector normal to it
    double mLength, mRadiusA, mRadiusB;
    std::string mName;
};

/// @brief Interval of a 1-Lipschitz function over @a box from its value at the box center:
/// f(center) -/+ half the box diagonal.
Interval lipschitzInterval(const Implicit& f, const BBoxd& box);

} // namespace ivdb::implicit
