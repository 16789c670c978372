// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/GridShape.h>

#include <openvdb/Exceptions.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace ivdb::implicit {

namespace {

/// Added to a double of magnitude below 2^51 and taken away again, rounds it to an integer.
constexpr double kRound = 6755399441055744.0; // 1.5 * 2^52

// Unregistered: a registered accessor would lock the tree's registry on every call.
using Accessor = openvdb::tree::ValueAccessor<const openvdb::FloatTree, /*IsSafe=*/false>;

/// The Catmull-Rom weights of the samples at -1, 0, 1, 2 for a point at @a t in [0, 1), and
/// their derivatives.
void catmullRom(double t, double w[4], double dw[4])
{
    const double t2 = t * t, t3 = t2 * t;
    w[0] = 0.5 * (-t3 + 2.0 * t2 - t);
    w[1] = 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0);
    w[2] = 0.5 * (-3.0 * t3 + 4.0 * t2 + t);
    w[3] = 0.5 * (t3 - t2);
    dw[0] = 0.5 * (-3.0 * t2 + 4.0 * t - 1.0);
    dw[1] = 0.5 * (9.0 * t2 - 10.0 * t);
    dw[2] = 0.5 * (-9.0 * t2 + 8.0 * t + 1.0);
    dw[3] = 0.5 * (3.0 * t2 - 2.0 * t);
}

/// The tricubic Catmull-Rom interpolation of the voxels around index-space point @a q (C1, it
/// passes through every voxel's value), and its gradient per voxel if @a grad is not null.
/// A point of the lattice (within 1e-9 of integers: p = i dx, whatever p / dx rounds to) is
/// its voxel's value, and its gradient the central differences there.
double tricubic(const Accessor& acc, const Vec3d& q, Vec3d* grad)
{
    double f[3];
    int c[3];
    bool onLattice = true;
    for (int a = 0; a < 3; ++a) {
        // The nearest integer by adding and taking away 1.5 * 2^52 (callers keep |q| far below
        // 2^51: GridShape::far()), and the floor from it: std::round and std::floor are calls
        // on x86-64's baseline.
        const double r = (q[a] + kRound) - kRound;
        if (std::abs(q[a] - r) < 1e-9) {
            c[a] = int(r);
            f[a] = 0.0;
        } else {
            const double fl = r > q[a] ? r - 1.0 : r;
            c[a] = int(fl);
            f[a] = q[a] - fl;
            onLattice = false;
        }
    }
    const openvdb::Coord base{c[0], c[1], c[2]};
    if (onLattice && !grad) return acc.getValue(base);
    // The 4^3 samples, a row along z at a time: from the leaf's buffer, where the row lies in
    // one leaf (z is the buffer's fastest axis), else voxel by voxel (a tile or the background
    // holds it, or it crosses leaves).
    float samples[4][4][4];
    for (int i = 0; i < 4; ++i) {
        for (int j = 0; j < 4; ++j) {
            const openvdb::Coord row = base.offsetBy(i - 1, j - 1, -1);
            const openvdb::FloatTree::LeafNodeType* leaf =
                (row.z() & 7) <= 4 ? acc.probeConstLeaf(row) : nullptr;
            if (leaf) {
                const float* from = leaf->buffer().data() + leaf->coordToOffset(row);
                for (int k = 0; k < 4; ++k) samples[i][j][k] = from[k];
            } else {
                for (int k = 0; k < 4; ++k) samples[i][j][k] = acc.getValue(row.offsetBy(0, 0, k));
            }
        }
    }
    double w[3][4], dw[3][4];
    for (int a = 0; a < 3; ++a) catmullRom(f[a], w[a], dw[a]);
    // The weights are separable: the rows along z first (value and z derivative), then along y,
    // then along x, about a third of the multiplies of the 64 products of three weights.
    double vz[4][4], dz[4][4];
    for (int i = 0; i < 4; ++i) {
        for (int j = 0; j < 4; ++j) {
            const float* r = samples[i][j];
            vz[i][j] = w[2][0] * r[0] + w[2][1] * r[1] + w[2][2] * r[2] + w[2][3] * r[3];
            dz[i][j] = dw[2][0] * r[0] + dw[2][1] * r[1] + dw[2][2] * r[2] + dw[2][3] * r[3];
        }
    }
    double vy[4], vdy[4], vdz[4];
    for (int i = 0; i < 4; ++i) {
        vy[i] = w[1][0] * vz[i][0] + w[1][1] * vz[i][1] + w[1][2] * vz[i][2] + w[1][3] * vz[i][3];
        vdy[i] = dw[1][0] * vz[i][0] + dw[1][1] * vz[i][1] + dw[1][2] * vz[i][2] +
                 dw[1][3] * vz[i][3];
        vdz[i] = w[1][0] * dz[i][0] + w[1][1] * dz[i][1] + w[1][2] * dz[i][2] + w[1][3] * dz[i][3];
    }
    const double value = w[0][0] * vy[0] + w[0][1] * vy[1] + w[0][2] * vy[2] + w[0][3] * vy[3];
    if (grad) {
        *grad = Vec3d(dw[0][0] * vy[0] + dw[0][1] * vy[1] + dw[0][2] * vy[2] + dw[0][3] * vy[3],
                      w[0][0] * vdy[0] + w[0][1] * vdy[1] + w[0][2] * vdy[2] + w[0][3] * vdy[3],
                      w[0][0] * vdz[0] + w[0][1] * vdz[1] + w[0][2] * vdz[2] + w[0][3] * vdz[3]);
    }
    return value;
}

} // namespace

GridShape::GridShape(openvdb::FloatGrid::ConstPtr grid, std::string name)
    : mGrid(std::move(grid)), mName(std::move(name))
{
    if (!mGrid) OPENVDB_THROW(openvdb::ValueError, mName + " shape has no grid");
    const openvdb::math::Transform& xform = mGrid->transform();
    mDx = xform.voxelSize()[0];
    const openvdb::math::Transform::Ptr lattice =
        openvdb::math::Transform::createLinearTransform(mDx);
    if (!(xform == *lattice)) {
        OPENVDB_THROW(openvdb::ValueError, mName + " shape's grid must have voxel centres at "
                      "integer multiples of its voxel size (resample it first)");
    }
    mInvDx = 1.0 / mDx;
    mBackground = double(mGrid->background());
    const openvdb::CoordBBox active = mGrid->evalActiveVoxelBoundingBox();
    if (active.empty()) {
        mBox = BBoxd(Vec3d(0.0), Vec3d(0.0));
        mIndexLo = Vec3d(1.0); // every point far
        mIndexHi = Vec3d(-1.0);
    } else {
        // Every node the tree stores (inside tiles too); beyond them it holds its background.
        openvdb::CoordBBox stored;
        mGrid->tree().getIndexRange(stored);
        mIndexLo = Vec3d(stored.min().x(), stored.min().y(), stored.min().z()) - Vec3d(3.0);
        mIndexHi = Vec3d(stored.max().x(), stored.max().y(), stored.max().z()) + Vec3d(3.0);
        const openvdb::Coord lo = active.min().offsetBy(-1), hi = active.max().offsetBy(1);
        mBox = BBoxd(Vec3d(lo.x(), lo.y(), lo.z()) * mDx, Vec3d(hi.x(), hi.y(), hi.z()) * mDx);
    }
    for (auto leaf = mGrid->tree().cbeginLeaf(); leaf; ++leaf) {
        const float* v = leaf->buffer().data();
        const auto [lo, hi] = std::minmax_element(v, v + leaf->SIZE);
        const openvdb::Coord cell = leaf->origin() >> 3;
        mLeafMin.setValue(cell, *lo);
        mLeafMax.setValue(cell, *hi);
    }
}

bool GridShape::far(const Vec3d& q) const
{
    // Beyond the tree's nodes (and the interpolation's reach) the grid holds only its outside
    // background: a test that also keeps huge coordinates out of the integer conversions.
    return !(q[0] >= mIndexLo[0] && q[0] <= mIndexHi[0] && q[1] >= mIndexLo[1] &&
             q[1] <= mIndexHi[1] && q[2] >= mIndexLo[2] && q[2] <= mIndexHi[2]);
}

double GridShape::value(const Vec3d& p) const
{
    const Vec3d q = p * mInvDx;
    if (far(q)) return mBackground;
    const Accessor acc(mGrid->tree());
    return clamp(tricubic(acc, q, nullptr));
}

Vec3d GridShape::gradient(const Vec3d& p) const
{
    const Vec3d q = p * mInvDx;
    if (far(q)) return Vec3d(0.0);
    const Accessor acc(mGrid->tree());
    Vec3d g;
    tricubic(acc, q, &g);
    return g * mInvDx; // per voxel to per world unit
}

void GridShape::values(const double* x, const double* y, const double* z, double* out,
                       std::size_t n) const
{
    const Accessor acc(mGrid->tree());
    for (std::size_t i = 0; i < n; ++i) {
        const Vec3d q = Vec3d(x[i], y[i], z[i]) * mInvDx;
        out[i] = far(q) ? mBackground : clamp(tricubic(acc, q, nullptr));
    }
}

void GridShape::valuesAndGradients(const double* x, const double* y, const double* z, double* out,
                                   double* gx, double* gy, double* gz, std::size_t n) const
{
    // values() and gradients() from one interpolation a point: values()' sums off the lattice;
    // on it values() reads the voxel, which these weights (0 and 1) give exactly, up to the sign
    // of a zero.
    const Accessor acc(mGrid->tree());
    for (std::size_t i = 0; i < n; ++i) {
        const Vec3d q = Vec3d(x[i], y[i], z[i]) * mInvDx;
        Vec3d g(0.0);
        out[i] = far(q) ? mBackground : clamp(tricubic(acc, q, &g));
        gx[i] = g[0] * mInvDx;
        gy[i] = g[1] * mInvDx;
        gz[i] = g[2] * mInvDx;
    }
}

void GridShape::gradients(const double* x, const double* y, const double* z, double* gx,
                          double* gy, double* gz, std::size_t n) const
{
    const Accessor acc(mGrid->tree());
    for (std::size_t i = 0; i < n; ++i) {
        const Vec3d q = Vec3d(x[i], y[i], z[i]) * mInvDx;
        Vec3d g(0.0);
        if (!far(q)) tricubic(acc, q, &g);
        gx[i] = g[0] * mInvDx;
        gy[i] = g[1] * mInvDx;
        gz[i] = g[2] * mInvDx;
    }
}

void GridShape::sampleRange(const openvdb::Coord& lo, const openvdb::Coord& hi, double& min,
                            double& max) const
{
    min = std::numeric_limits<double>::infinity();
    max = -min;
    const Accessor acc(mGrid->tree());
    openvdb::tree::ValueAccessor<const openvdb::FloatTree, false> minAcc(mLeafMin), maxAcc(mLeafMax);
    const openvdb::Coord ext = hi - lo;
    if (ext.x() <= 20 && ext.y() <= 20 && ext.z() <= 20) { // a leaf's box or so: every voxel
        // A row along z at a time, in runs within one leaf: from its buffer (z is its fastest
        // axis), or one value where a tile or the background holds the run.
        for (int x = lo.x(); x <= hi.x(); ++x) {
            for (int y = lo.y(); y <= hi.y(); ++y) {
                for (int z = lo.z(); z <= hi.z();) {
                    const openvdb::Coord at(x, y, z);
                    const int end = std::min(hi.z(), z | 7); // the run's last z in this leaf
                    if (const auto* leaf = acc.probeConstLeaf(at)) {
                        const float* v = leaf->buffer().data() + leaf->coordToOffset(at);
                        for (int k = 0; k <= end - z; ++k) {
                            min = std::min(min, double(v[k]));
                            max = std::max(max, double(v[k]));
                        }
                    } else {
                        const double v = acc.getValue(at);
                        min = std::min(min, v);
                        max = std::max(max, v);
                    }
                    z = end + 1;
                }
            }
        }
        return;
    }
    const openvdb::Coord a = lo >> 3, b = hi >> 3; // arithmetic shifts: floor division by 8
    for (int x = a.x(); x <= b.x(); ++x) {
        for (int y = a.y(); y <= b.y(); ++y) {
            for (int z = a.z(); z <= b.z(); ++z) {
                const openvdb::Coord cell(x, y, z);
                float l, h;
                if (minAcc.probeValue(cell, l)) {
                    h = maxAcc.getValue(cell);
                } else { // no leaf: a tile or the background holds the whole cell
                    l = h = acc.getValue(openvdb::Coord(x * 8, y * 8, z * 8));
                }
                min = std::min(min, double(l));
                max = std::max(max, double(h));
            }
        }
    }
}

double GridShape::lipschitzBound() const
{
    // The samples change by at most one voxel size per voxel along each axis, so each component
    // of the interpolation's gradient is at most 1.5 (Catmull-Rom's derivative) times 1.25^2
    // (the other axes' weights, negative lobes included), its length at most sqrt(3) times that.
    return std::sqrt(3.0) * 1.5 * 1.25 * 1.25;
}

Interval GridShape::interval(const BBoxd& box) const
{
    // The interpolation changes by at most lipschitzBound() per unit of length; the values are
    // clamped to the background.
    const double v = value(box.getCenter());
    // (With a margin for the samples' float rounding.)
    const double lipschitz = lipschitzBound();
    const double h = lipschitz * 0.5 * (box.max() - box.min()).length() * (1.0 + 1e-4) + 1e-5 * mDx;
    double lo = std::max(-mBackground, v - h), hi = std::min(mBackground, v + h);
    // Tighter for boxes of a few voxels: the interpolation reads the voxels from floor(q) - 1 to
    // floor(q) + 2 around each point q; its weights sum to 1, and their magnitudes to at most
    // 1.25 along each axis (the negative lobes sum to -1/8), so the value is within 1.25^3 times
    // the samples' half range of their middle. The samples' range comes from whole leaves.
    const Vec3d qlo = box.min() * mInvDx, qhi = box.max() * mInvDx;
    // Only for boxes of a few voxels and more (the descent's), where the Lipschitz bound is
    // loosest: for the tiny boxes of the distance searches it is as tight and cheaper.
    const double diagonal = (qhi - qlo).length();
    const bool small = diagonal >= 4.0 && diagonal <= 48.0 && std::abs(qlo[0]) < 1e9 &&
                       std::abs(qlo[1]) < 1e9 && std::abs(qlo[2]) < 1e9;
    if (small) {
        openvdb::Coord a, b;
        for (int i = 0; i < 3; ++i) {
            a[i] = int(std::floor(qlo[i])) - 1;
            b[i] = int(std::floor(qhi[i])) + 2;
        }
        double min, max;
        sampleRange(a, b, min, max);
        const double mid = 0.5 * (min + max);
        const double half = 0.5 * (max - min) * 1.953125 * (1.0 + 1e-9) + 1e-9 * mDx;
        lo = std::max(lo, mid - half);
        hi = std::min(hi, mid + half);
    }
    return {std::min(lo, hi), std::max(lo, hi)};
}

BBoxd GridShape::boundingBox() const { return mBox; }

} // namespace ivdb::implicit
