// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Csg.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace ivdb::implicit {

/// @brief How a blended CSG combines its children's values: the super-elliptic blend of
/// sharpness p (docs/method.md#super-elliptic-blend) or the polynomial smooth minimum of width k
/// (docs/method.md#smooth-csg).
/// @details Both take the terms t_i: the children's values, negated for the ones a difference
/// subtracts. Both are monotone in every term, so a blend of intervals is an interval.
struct BlendKernel
{
    enum class Kind {
        SuperElliptic, ///< union -(1/p) ln sum exp(-p t_i); intersection (1/p) ln sum exp(p t_i)
        Polynomial     ///< union min(a, b) - h^2 k / 4, h = max(k - |a - b|, 0) / k, from the left
    };

    Kind kind = Kind::SuperElliptic;
    double p = 10.0; ///< SuperElliptic: sharpness, 1/world units
    double k = 0.0;  ///< Polynomial: width, world units

    /// @throw ParamError unless @a p is in limits::kBlendP
    static BlendKernel superElliptic(double p);
    /// @throw ParamError unless @a k is in limits::kSmoothK
    static BlendKernel polynomial(double k);

    /// @brief The blended value of the @a n terms @a t.
    double combine(CsgOp op, const double* t, std::size_t n) const;
    /// @brief The partial derivatives d f / d t_i of combine() into @a w (n values).
    void weights(CsgOp op, const double* t, std::size_t n, double* w) const;
    /// @brief How far (world units) a blended union's surface may lie beyond the sharp
    /// union's, for exact-distance terms: ln(n)/p, or (n - 1) k/4 for the smooth minimum.
    double swell(std::size_t n) const;
    /// @brief How far (world units) apart two terms may be and still change the result by more
    /// than @a toleranceWorld: ln(1 / (p tolerance)) / p, or exactly k for the smooth minimum.
    double reach(double toleranceWorld) const;
    /// @brief "p = 4" or "k = 0.1", for messages.
    std::string describe() const;

    /// @brief Where the lead rule hands over to the deciding term's distance
    /// (docs/method.md#the-lead-rules-hand-over), for @a n exact-distance terms and a distance
    /// tolerance @a toleranceWorld: the term's distance is the blend's within the tolerance
    /// where its lead (the next term less it, less twice its depth inside) is at least @a edge;
    /// over the @a width below the edge the answer ramps (handoverRamp()) from the blend's own
    /// distance to it. The smooth minimum's lead answers are exact: no ramp (width 0).
    struct Handover
    {
        double edge = 0.0;  ///< world units
        double width = 0.0; ///< world units
    };
    Handover handover(double toleranceWorld, std::size_t n) const;
};

/// @brief The hand-over's ramp (BlendKernel::Handover): 0 at @a u <= 0, 1 at @a u >= 1, the
/// quintic 6u^5 - 15u^4 + 10u^3 between, whose first and second derivatives are 0 at both ends,
/// so second differences across the zone see no step.
inline double handoverRamp(double u)
{
    u = std::min(std::max(u, 0.0), 1.0);
    return u * u * u * (u * (u * 6.0 - 15.0) + 10.0);
}

/// @brief The blended value of the signed terms @a t (children's values, negated for the ones a
/// difference subtracts): union -(1/p) ln sum exp(-p t_i), intersection and difference
/// (1/p) ln sum exp(p t_i), evaluated around the extreme term so that nothing overflows.
double blendTerms(Csg::Op op, double p, const double* t, std::size_t n);

/// @brief The polynomial smooth minimum of @a a and @a b with width @a k > 0:
/// min(a, b) - h^2 k / 4 with h = max(k - |a - b|, 0) / k. Equal to min(a, b) where the two
/// differ by k or more; C1 everywhere.
inline double smoothMin(double a, double b, double k)
{
    const double d = a - b, h = std::max(k - std::abs(d), 0.0) / k;
    return std::min(a, b) - h * h * k * 0.25;
}

/// @brief Blended CSG over any number of children: the super-elliptic blend (scene type
/// "blend") or the polynomial smooth minimum (scene type "smooth"); see BlendKernel.
/// @details The super-elliptic blend is a log-sum-exp around the extreme term, so no exp
/// overflows for any p in [0.1, 1000] and any finite values; it rounds the crease within about
/// ln(2)/p world units of it. The smooth minimum folds its children from the left and differs
/// from the sharp operation only where two terms are within k of each other. Neither is a
/// distance near the crease (|grad f| < 1 there), so the rasterizer finds the distances.
class Blend final: public Implicit
{
public:
    using Op = Csg::Op;

    /// A super-elliptic blend of sharpness @a p.
    /// @throw ParamError if @a p is not in limits::kBlendP; openvdb::ValueError if @a children
    /// is empty or holds a null pointer
    Blend(Op op, double p, std::vector<Ptr> children);
    /// @throw openvdb::ValueError if @a children is empty or holds a null pointer
    Blend(Op op, const BlendKernel& kernel, std::vector<Ptr> children);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    void gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                   double* gz, std::size_t n) const override;
    /// The children evaluated once, and the super-elliptic kernel's exponentials shared by the
    /// value and the weights.
    void valuesAndGradients(const double* x, const double* y, const double* z, double* out,
                            double* gx, double* gy, double* gz, std::size_t n) const override;
    /// Exact SDF children: where the deciding child leads the next by the kernel's reach and
    /// swell (the lead rule, docs/method.md#true-distances), its distance and foot point; where
    /// |f| >= far, that (the blend is 1-Lipschitz, so the distance is at least |f|); the smooth
    /// iteration elsewhere.
    void footPoints(const double* x, const double* y, const double* z, const double* values,
                    std::size_t n, const FootQuery& query, FootPoints& out) const override;
    /// The children evaluated once for the values, the lead rule and the smooth iteration's
    /// start (exact SDF children); without foot points asked for, their values alone, and
    /// the gradients only at the points the lead and far rules leave.
    void valuesAndFootPoints(const double* x, const double* y, const double* z, std::size_t n,
                             const FootQuery& query, double* values,
                             FootPoints& out) const override;
    /// Exact for a blend of exact intervals: the blend is monotone in every child.
    Interval interval(const BBoxd& box) const override;
    void intervals(const double* cx, const double* cy, const double* cz, const Vec3d& half,
                   std::size_t n, double* lo, double* hi) const override;
    /// Union: the children's boxes grown by BlendKernel::swell() when every child is exact
    /// outside (the blend reaches at most that far beyond them), else unbounded. Intersection,
    /// difference: within the sharp result.
    BBoxd boundingBox() const override;
    BBoxd boundingBoxBelow(double level) const override;
    bool isExactSdf() const override { return false; }
    /// Of 1-Lipschitz children: both kernels' gradients are convex combinations of the
    /// children's (the weights d f / d t_i are >= 0 and sum to 1).
    bool isDistanceBound() const override;
    /// The children's largest (the gradient is a convex combination of theirs).
    double lipschitzBound() const override;
    /// Where a child's distance may kink within @a radius of @a p: a box's or a capped cone's
    /// (moved rigidly or scaled uniformly), inside it, where the two largest of its faces'
    /// values are within 2 radius of each other (the nearest face changes there); or where a
    /// child says so itself.
    bool mayKinkWithin(const Vec3d& p, double radius) const override;
    std::string typeName() const override;

    Op op() const { return mOp; }
    const BlendKernel& kernel() const { return mKernel; }
    const std::vector<Ptr>& children() const { return mChildren; }
    /// The super-elliptic sharpness p (kernel().p).
    double sharpness() const { return mKernel.p; }

private:
    /// The children's values at @a p as terms (negated where a difference subtracts them).
    void terms(const Vec3d& p, double* t) const;
    /// The children over a batch of @a n points as terms (term-major: a row of n per child,
    /// negated where a difference subtracts them) and, if @a cg is not null, their gradients
    /// (3 rows of n per child).
    void childRows(const double* x, const double* y, const double* z, std::size_t n,
                   double* terms, double* cg) const;
    /// The blend's gradients from childRows()' terms and gradients, with the weights d f / d t
    /// in @a w (a row of n per child): computed into it, or already there if @a haveWeights.
    void gradientsFromRows(const double* terms, const double* cg, std::size_t n, double* w,
                           bool haveWeights, double* gx, double* gy, double* gz) const;
    /// The blend's values from childRows()' terms (values()' bits) into @a values; true if the
    /// kernel gave the weights d f / d t with them, into @a w (the super-elliptic one does).
    bool valuesFromRows(const double* terms, std::size_t n, double* values, double* w) const;
    /// True if the foot points can use the lead rule: every child an exact SDF, at most 64.
    bool leadRuleApplies() const;
    /// footPoints() by the lead rule with the deciding child's own foot points (where
    /// mChildLeadFactor is finite), the smooth iteration elsewhere.
    void childLeadFootPoints(const double* x, const double* y, const double* z,
                             const double* values, std::size_t n, const FootQuery& query,
                             FootPoints& out) const;
    /// footPoints() from childRows()' @a terms and gradients @a cg; @a w holds the weights
    /// d f / d t if @a haveWeights, else is where they are computed. @a cg and @a w null (no
    /// foot points asked for): the children's values alone, and the blend's gradients found
    /// only where the lead and far rules leave points to iterate.
    void feetFromRows(const double* x, const double* y, const double* z, const double* values,
                      std::size_t n, const FootQuery& query, const double* terms,
                      const double* cg, double* w, bool haveWeights, FootPoints& out) const;
    /// For the points @a out leaves to the smooth iteration (not @a led by a child): its answers
    /// uncertified where a child may kink within their distance (mayKinkWithin()), then
    /// certified from the blend's sheets where the kink is one box's or capped cone's (the
    /// blend with one of its faces or edges in its place; if @a sheets: they need every child
    /// 1-Lipschitz, isDistanceBound()), and nearer points of the surface from each child's
    /// own foot point (and each face's, near a kink, if @a allStarts) where still not
    /// certified, and from the other child's where a certified foot point may be one of two;
    /// Newton's method where the iteration from a start fails only if @a allStarts.
    void nearerFeet(const double* x, const double* y, const double* z, const double* values,
                    std::size_t n, const FootQuery& query, const double* terms, const bool* led,
                    FootPoints& out, bool allStarts = true, bool sheets = true) const;

    Op mOp;
    BlendKernel mKernel;
    std::vector<Ptr> mChildren;
    /// The largest of the children's distanceFactor() on the side where their term is positive
    /// (outside for a union's children and a difference's subtracted ones, inside otherwise);
    /// infinity if a child is not 1-Lipschitz or has none: childLeadFootPoints()' margin.
    double mChildLeadFactor = 1.0;
};

} // namespace ivdb::implicit
