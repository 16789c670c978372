// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Csg.h>

#include <vector>

namespace ivdb::implicit {

/// @brief The blended value of the signed terms @a t (children's values, negated for the ones a
/// difference subtracts): union -(1/p) ln sum exp(-p t_i), intersection and difference
/// (1/p) ln sum exp(p t_i), evaluated around the extreme term so that nothing overflows.
double blendTerms(Csg::Op op, double p, const double* t, std::size_t n);

/// @brief Super-elliptic blended CSG (docs/method.md#super-elliptic-blend) over any number of children.
/// @details With the density D = exp(-f): union f = -(1/p) ln(sum exp(-p f_i)); intersection the
/// same with -p; difference = intersection of the first child with the others negated. Computed as
/// a log-sum-exp around the extreme term, so no exp overflows or underflows to -inf for any p in
/// [0.1, 1000] and any finite values. The blend rounds the crease within about ln(2)/p world
/// units of it; it is not a distance (|grad f| < 1 near the crease), so the rasterizer
/// re-distances it.
class Blend final: public Implicit
{
public:
    using Op = Csg::Op;

    /// @throw ParamError if @a p is not in limits::kBlendP; openvdb::ValueError if @a children
    /// is empty or holds a null pointer
    Blend(Op op, double p, std::vector<Ptr> children);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    void gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                   double* gz, std::size_t n) const override;
    /// Exact for a blend of exact intervals: the blend is monotone in every child.
    Interval interval(const BBoxd& box) const override;
    /// Union: the children's boxes grown by ln(n)/p when every child is an exact SDF (the blend
    /// reaches at most that far beyond them), else unbounded. Intersection, difference: within
    /// the sharp result.
    BBoxd boundingBox() const override;
    bool isExactSdf() const override { return false; }
    std::string typeName() const override;

    Op op() const { return mOp; }
    double sharpness() const { return mP; }

private:
    double combine(const double* terms, std::size_t n) const { return blendTerms(mOp, mP, terms, n); }

    Op mOp;
    double mP;
    std::vector<Ptr> mChildren;
};

} // namespace ivdb::implicit
