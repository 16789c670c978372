// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Interval.h>

#include <openvdb/math/BBox.h>
#include <openvdb/math/Vec3.h>

#include <cstddef>
#include <limits>
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

/// @brief What footPoints() is asked for.
struct FootQuery
{
    /// World units: a point reported as certified has a distance within this of the true one.
    double tolerance = 1e-6;
    /// World units: a point farther than this from the surface only needs to be reported as
    /// farther (its sign and a distance >= far; no foot point).
    double far = 1.0;
    /// False: only the distances are needed, a node may leave the foot points at the query
    /// points where finding them would cost more.
    bool feet = true;
};

/// @brief Signed distances and the surface points they are measured to, for a batch of points.
struct FootPoints
{
    double distance[kMaxBatch];   ///< signed distance to the surface, negative inside
    double x[kMaxBatch], y[kMaxBatch], z[kMaxBatch]; ///< the foot point (the closest surface point)
    bool ok[kMaxBatch];           ///< certified; false: no local method worked at this point
    /// Where not ok: true if (x, y, z) is a point of the surface all the same (a CSG's nearest
    /// candidate where not every candidate could be found), so |distance| is at least as far as
    /// the true distance; false where nothing is known of it.
    bool surface[kMaxBatch] = {};
};

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
    /// @brief Gradients at @a n <= kMaxBatch points: the same as gradient() at each point.
    virtual void gradients(const double* x, const double* y, const double* z, double* gx,
                           double* gy, double* gz, std::size_t n) const;
    /// @brief values() and gradients() at once, bit for bit theirs. The default calls both;
    /// nodes whose two share work (a blend's children and exponentials) override it.
    virtual void valuesAndGradients(const double* x, const double* y, const double* z,
                                    double* out, double* gx, double* gy, double* gz,
                                    std::size_t n) const;
    /// @brief True signed distances to the surface at @a n <= kMaxBatch points, found locally,
    /// with their foot points (docs/method.md#true-distances).
    /// @details @a values are value() at the points. An exact SDF returns its values and the
    /// points moved along its unit gradient. Other smooth shapes take Newton steps onto the
    /// surface along the gradient, each followed by a move of the point along the tangent plane
    /// towards the foot of the perpendicular from the query point, until both are converged
    /// far below the tolerance (so the distances are a smooth function of the point: curvature
    /// from their second differences stays smooth), and certify the result when it lies on the
    /// surface and the query point on its normal (within the tolerance), and the distance
    /// agrees with the first-order estimate f / |grad f| within 25%. CSG nodes override it
    /// (exact children, the crease between two children).
    /// Points where no local method is certified (a singular point, a medial axis, a thin
    /// feature) get ok = false and the first-order estimate as their distance.
    virtual void footPoints(const double* x, const double* y, const double* z,
                            const double* values, std::size_t n, const FootQuery& query,
                            FootPoints& out) const;
    /// @brief values() into @a values, then footPoints() at the same points: the same bits as
    /// the two calls. The default makes them; nodes whose foot points start from the same
    /// evaluations as their values (a blend's children) override it to evaluate once.
    virtual void valuesAndFootPoints(const double* x, const double* y, const double* z,
                                     std::size_t n, const FootQuery& query, double* values,
                                     FootPoints& out) const;
    /// @brief An interval that contains f(p) for every p in @a box.
    virtual Interval interval(const BBoxd& box) const = 0;
    /// @brief Intervals over @a n <= kMaxBatch boxes of one size: box i is the centre (cx[i],
    /// cy[i], cz[i]) +/- @a half, and [lo[i], hi[i]] contains f(p) for every p in it.
    /// @details The default calls interval() per box; nodes override it with loops the compiler
    /// can vectorize (the rasterizer tests the 64 groups of 2^3 voxels of a leaf in one call).
    virtual void intervals(const double* cx, const double* cy, const double* cz,
                           const Vec3d& half, std::size_t n, double* lo, double* hi) const;
    /// @brief A box outside which the shape has no inside points (infiniteBox() if unbounded).
    virtual BBoxd boundingBox() const = 0;
    /// @brief A box holding every point where value() < @a level (for a level of 0 or less,
    /// boundingBox()): by default the box grown by the level where the value is the distance
    /// outside (isExactOutside()), else infiniteBox(). Offsets, shells and blends, which grow
    /// their children's surfaces, ask their children for it; a transform, a CSG node and those
    /// pass it on, so a non-uniformly scaled child in a blend is bounded too.
    virtual BBoxd boundingBoxBelow(double level) const;
    /// @brief True if value() is the exact signed Euclidean distance to the surface.
    virtual bool isExactSdf() const = 0;
    /// @brief True if value() is the exact distance wherever it is positive (outside): exact
    /// SDFs, unions of such, shapes grown from them. Where this holds, the shape's inside lies
    /// within a distance d of the points where value() < d, which bounds grown shapes.
    virtual bool isExactOutside() const { return isExactSdf(); }
    /// @brief True if |value()| never exceeds the distance to the surface: value() is
    /// 1-Lipschitz (exact SDFs; CSG nodes, blends, offsets and shells of such, and their
    /// transforms, a non-uniform scale's value being min(scale) times its child's). Where this
    /// holds, a point with |value()| >= d is at least d from the surface.
    virtual bool isDistanceBound() const { return isExactSdf(); }
    /// @brief Where isDistanceBound(): a bound on how fast value() changes between the points
    /// the rasterizer samples, per unit of length. 1 for exact SDFs and the nodes that keep it;
    /// more for an interpolated grid (GridShape), whose values are distances at its voxels but
    /// whose interpolation between them can change faster. The rasterizer skips a group of
    /// voxels from the value at its centre only by this bound.
    virtual double lipschitzBound() const { return 1.0; }
    /// @brief A factor K such that every point where value() is positive (@a outside) or
    /// negative (else) lies within K |value()| of the surface: 1 for exact SDFs, for a union's
    /// outside and an intersection's or difference's inside where their children's are 1 (the
    /// min or max is then the distance there); K max(scale) / min(scale) for a non-uniform
    /// scale of a child with factor K (the scaled field is min(scale) times the child's, and a
    /// local distance grows by at most max(scale)); a rigid motion or uniform scale keeps the
    /// child's. Infinity where none is known. A blend takes a child's own distances where that
    /// child leads the others far enough, by a margin that grows with K (Blend::footPoints).
    virtual double distanceFactor(bool outside) const
    {
        (void)outside;
        return isExactSdf() ? 1.0 : std::numeric_limits<double>::infinity();
    }
    /// @brief A shape with this one's surface and sign whose true distances are found more
    /// directly (a non-uniformly scaled sphere's or quadric's world quadric, a scaled box's box
    /// moved rigidly), or null. Its values differ (a distance, or another field): the rasterizer
    /// takes it where it stores distances, not where it stores this shape's own values.
    virtual Ptr sameSurface() const { return nullptr; }
    /// @brief True if the field may have a kink (its gradient jumping) within @a radius of
    /// @a p that a local foot-point iteration cannot see past: then a point q where p - q lies
    /// along the gradient can be one of several such points, not the nearest. A blend of
    /// children whose distances kink inside them (a box's or a capped cone's, where the
    /// nearest face changes) says so near those kinks; the nodes above it pass the question
    /// on. False by default (smooth fields; CSG nodes find their creases' points themselves).
    virtual bool mayKinkWithin(const Vec3d& p, double radius) const
    {
        (void)p;
        (void)radius;
        return false;
    }
    /// @brief A node equal to this one at every point of @a box, possibly simpler
    /// (a union drops children that cannot be the minimum there).
    virtual Ptr prune(const BBoxd& box) const;
    /// @brief The node's scene-file type name ("sphere", "union", ...).
    virtual std::string typeName() const = 0;

    /// @brief True if the shape has a finite bounding box.
    bool isBounded() const { return isFinite(boundingBox()); }
};

/// @brief The foot point of @a p on the surface of @a f near @a start (a point on or near the
/// surface), by the smooth iteration of Implicit::footPoints started at @a start instead of at
/// the projection of @a p; where that does not converge (a surface that curves tightly for the
/// distance, kappa d > 1: a blend's rounded edge), by Newton's method on the nearest point's
/// conditions (q - p + lambda grad f(q) = 0, f(q) = 0; the Hessian from differences of the
/// gradient), certified only at a nearest point along the surface, unless @a newton is false.
/// @return true, with @a q, if certified: q on the surface and p on its normal within @a tol
bool refineFootPoint(const Implicit& f, const Vec3d& p, const Vec3d& start, double tol, Vec3d& q,
                     bool newton = true);

} // namespace ivdb::implicit
