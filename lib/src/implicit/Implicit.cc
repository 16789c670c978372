// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/Implicit.h>

#include <limits>

namespace ivdb::implicit {

BBoxd infiniteBox()
{
    const double inf = std::numeric_limits<double>::infinity();
    return BBoxd(Vec3d(-inf), Vec3d(inf));
}

BBoxd Implicit::boundingBoxBelow(double level) const
{
    const BBoxd box = boundingBox();
    if (level <= 0.0) return box;
    if (!isExactOutside() || !isFinite(box)) return infiniteBox();
    return BBoxd(box.min() - Vec3d(level), box.max() + Vec3d(level));
}

bool isFinite(const BBoxd& box)
{
    for (int i = 0; i < 3; ++i) {
        if (!std::isfinite(box.min()[i]) || !std::isfinite(box.max()[i])) return false;
    }
    return true;
}

void Implicit::values(const double* x, const double* y, const double* z, double* out,
                      std::size_t n) const
{
    for (std::size_t i = 0; i < n; ++i) out[i] = value(Vec3d(x[i], y[i], z[i]));
}

void Implicit::valuesAndGradients(const double* x, const double* y, const double* z,
                                  double* out, double* gx, double* gy, double* gz,
                                  std::size_t n) const
{
    values(x, y, z, out, n);
    gradients(x, y, z, gx, gy, gz, n);
}

void Implicit::valuesAndFootPoints(const double* x, const double* y, const double* z,
                                   std::size_t n, const FootQuery& query, double* values,
                                   FootPoints& out) const
{
    this->values(x, y, z, values, n);
    footPoints(x, y, z, values, n, query, out);
}

void Implicit::intervals(const double* cx, const double* cy, const double* cz, const Vec3d& half,
                         std::size_t n, double* lo, double* hi) const
{
    for (std::size_t i = 0; i < n; ++i) {
        const Vec3d c(cx[i], cy[i], cz[i]);
        const Interval iv = interval(BBoxd(c - half, c + half));
        lo[i] = iv.lo;
        hi[i] = iv.hi;
    }
}

Implicit::Ptr Implicit::prune(const BBoxd&) const
{
    return shared_from_this();
}

} // namespace ivdb::implicit
