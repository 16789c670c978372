// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>

#include <array>

namespace ivdb::implicit {

/// @brief A symmetric 4x4 matrix, row-major: Q[row][column].
using Mat4 = std::array<std::array<double, 4>, 4>;

/// @brief The general quadric f(p) = [p 1] Q [p 1]^T (docs/method.md#quadrics), negative inside.
/// @details Writing Q = [[A, b], [b^T, c]], f(p) = p^T A p + 2 b.p + c and the gradient is
/// 2 (A p + b) = 2 Q_sub [p 1]^T (docs/method.md#quadric-gradient). Quadric values are not distances (except for a
/// plane with a unit normal); the rasterizer re-distances them. The interval over a box uses the
/// centered form f(m) + g(m).d + d^T A d bounded term by term, which is exact for planes and
/// tightens quadratically as boxes shrink.
class Quadric final: public Implicit
{
public:
    /// @throw openvdb::ValueError if Q is not finite, not symmetric or all zero
    explicit Quadric(const Mat4& q);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    void gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                   double* gz, std::size_t n) const override;
    /// The foot point solves one equation in the Lagrange multiplier, in the eigenframe of A
    /// (docs/method.md#true-distances): Newton's method converges quadratically, to rounding.
    void footPoints(const double* x, const double* y, const double* z, const double* values,
                    std::size_t n, const FootQuery& query, FootPoints& out) const override;
    Interval interval(const BBoxd& box) const override;
    void intervals(const double* cx, const double* cy, const double* cz, const Vec3d& half,
                   std::size_t n, double* lo, double* hi) const override;
    /// Finite only when A is positive definite (an ellipsoid, or empty).
    BBoxd boundingBox() const override;
    /// True for a plane with a unit normal: then f is the exact signed distance.
    bool isExactSdf() const override { return mIsPlaneSdf; }
    std::string typeName() const override { return "quadric"; }

    const Mat4& matrix() const { return mQ; }
    /// @brief True if the inside {f < 0} is empty (A positive definite and f >= 0 at its center).
    bool isEmpty() const { return mIsEmpty; }

private:
    void prepareFootPoints();

    Mat4 mQ;
    BBoxd mBox;
    bool mIsPlaneSdf = false;
    bool mIsEmpty = false;
    // A = F diag(mEigen) F^T (F's columns the eigenvectors), and F^T b, for footPoints().
    double mFrame[3][3] = {}, mEigen[3] = {}, mLinear[3] = {};
    bool mHasFrame = false;
};

/// @brief The rotation (columns: images of local x, y, z) that takes +z onto @a axis by the
/// smallest angle. The local x and y axes of named quadrics are the first two columns.
/// @throw openvdb::ValueError if @a axis is zero or not finite
std::array<Vec3d, 3> frameFromAxis(const Vec3d& axis);

/// @brief Q of a quadric given in a local frame (origin @a origin, axes @a frame), in world space.
Mat4 placeQuadric(const Mat4& local, const Vec3d& origin, const std::array<Vec3d, 3>& frame);

/// @brief The world Q, M^T Q M (symmetrized), of the quadric @a local of local points q, where
/// [q 1] = M [p 1] for world points p (@a m, any affine map: its last row 0 0 0 1).
Mat4 mapQuadric(const Mat4& local, const Mat4& m);

/// @name Named quadrics: presets that produce a Q (all throw openvdb::ValueError on bad input)
/// @{
/// Half-space n.p < offset (stored with a unit normal, so it is an exact SDF).
Implicit::Ptr makePlane(const Vec3d& normal, double offset);
/// Infinite circular cylinder.
Implicit::Ptr makeCylinder(const Vec3d& center, const Vec3d& axis, double radius);
/// Axis-aligned ellipsoid with semi-axes @a radii.
Implicit::Ptr makeEllipsoid(const Vec3d& center, const Vec3d& radii);
/// Infinite double cone x^2 + y^2 = tan^2(halfAngle) z^2 in the frame of @a axis at @a apex.
Implicit::Ptr makeCone(const Vec3d& apex, const Vec3d& axis, double halfAngleDeg);
/// Paraboloid z = (x/a)^2 + (y/b)^2 (elliptic) or z = (x/a)^2 - (y/b)^2 (hyperbolic).
Implicit::Ptr makeParaboloid(const Vec3d& vertex, const Vec3d& axis, bool hyperbolic, double a,
                             double b);
/// Hyperboloid (x/a)^2 + (y/b)^2 - (z/c)^2 = 1 (one sheet) or = -1 (two sheets).
Implicit::Ptr makeHyperboloid(const Vec3d& center, const Vec3d& axis, bool twoSheets,
                              const Vec3d& radii);
/// @}

} // namespace ivdb::implicit
