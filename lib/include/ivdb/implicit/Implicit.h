// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Interval.h>

#include <openvdb/math/BBox.h>
#include <openvdb/math/Vec3.h>

#include <cstddef>
#include <memory>
#include <string>

namespace ivdb::implicit {

using Vec3d = openvdb::math::Vec3d;
using BBoxd = openvdb::math::BBox<Vec3d>;

/// @brief The largest batch that Implicit::values() accepts: one 8x8x8 leaf of points.
inline constexpr std::size_t kMaxBatch = 512;

/// @brief An infinite box, the bounding box of an unbounded shape.
BBoxd infiniteBox();
/// @brief True if every coordinate of @a box is finite.
bool isFinite(const BBoxd& box);

/// @brief An implicit function f: R^3 -> R, negative inside, zero on the surface.
/// @details Nodes are immutable and shared (a tree of Implicit::Ptr). Besides the value, a node
/// gives its analytic gradient, a conservative interval of its values over a box (what lets the
/// rasterizer skip empty space without holes), and its bounding box.
class Implicit: public std::enable_shared_from_this<Implicit>
{
public:
    using Ptr = std::shared_ptr<const Implicit>;

    virtual ~Implicit() = default;

    /// @brief Value at a world-space point.
    virtual double value(const Vec3d& p) const = 0;
    /// @brief Analytic gradient at a world-space point (where it is defined).
    virtual Vec3d gradient(const Vec3d& p) const = 0;
    /// @brief Values at @a n <= kMaxBatch points given as separate x, y and z arrays.
    /// @details Bit-for-bit the same as value() at each point; nodes override it with loops the
    /// compiler can vectorize, so a virtual call is paid per batch, not per point.
    virtual void values(const double* x, const double* y, const double* z, double* out,
                        std::size_t n) const;
    /// @brief An interval that contains f(p) for every p in @a box.
    virtual Interval interval(const BBoxd& box) const = 0;
    /// @brief A box outside which the shape has no inside points (infiniteBox() if unbounded).
    virtual BBoxd boundingBox() const = 0;
    /// @brief True if value() is the exact signed Euclidean distance to the surface.
    virtual bool isExactSdf() const = 0;
    /// @brief A node equal to this one at every point of @a box, possibly simpler
    /// (a union drops children that cannot be the minimum there).
    virtual Ptr prune(const BBoxd& box) const;
    /// @brief The node's scene-file type name ("sphere", "union", ...).
    virtual std::string typeName() const = 0;

    /// @brief True if the shape has a finite bounding box.
    bool isBounded() const { return isFinite(boundingBox()); }
};

} // namespace ivdb::implicit
