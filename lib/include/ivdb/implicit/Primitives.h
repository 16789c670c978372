// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>

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
    Interval interval(const BBoxd& box) const override;
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

private:
    Vec3d mCenter;
    double mMajor, mMinor;
};

/// @brief Interval of a 1-Lipschitz function over @a box from its value at the box center:
/// f(center) -/+ half the box diagonal.
Interval lipschitzInterval(const Implicit& f, const BBoxd& box);

} // namespace ivdb::implicit
