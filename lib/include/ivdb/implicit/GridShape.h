// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>

#include <openvdb/openvdb.h>

#include <algorithm>
#include <string>

namespace ivdb::implicit {

/// @brief A narrow-band level set as a shape: a mesh's signed distance (scene type "mesh") or
/// a level set from a .vdb file ("vdb").
/// @details The grid's voxel centres are at integer multiples of its voxel size (the
/// rasterizer's lattice, so at the voxels of a raster of the same voxel size the value is the
/// grid's value, bit for bit). Between them the value is the tricubic Catmull-Rom
/// interpolation of the 64 voxels around the point, and the gradient its gradient: C1, so the
/// foot points and creases of CSG converge on it as on an analytic shape. Beyond the band the
/// value is the background, +/- the band's half width, by the grid's sign: a lower bound of
/// the distance's magnitude. The samples are distances, so the interpolation changes by at most
/// 4.06 per unit of length, which bounds it over a box.
class GridShape final: public Implicit
{
public:
    /// @param grid  a level set with a uniform scale transform and no translation (voxel size
    ///              dx, voxel (i, j, k) at (i, j, k) dx), its values within +/- its background
    /// @param name  the scene type, "mesh" or "vdb"
    /// @throw openvdb::ValueError for a null grid or another transform
    GridShape(openvdb::FloatGrid::ConstPtr grid, std::string name);

    double value(const Vec3d& p) const override;
    Vec3d gradient(const Vec3d& p) const override;
    void values(const double* x, const double* y, const double* z, double* out,
                std::size_t n) const override;
    void gradients(const double* x, const double* y, const double* z, double* gx, double* gy,
                   double* gz, std::size_t n) const override;
    void valuesAndGradients(const double* x, const double* y, const double* z, double* out,
                            double* gx, double* gy, double* gz, std::size_t n) const override;
    Interval interval(const BBoxd& box) const override;
    /// The band's active voxels' box, one voxel wider (a closed surface's inside is within it).
    BBoxd boundingBox() const override;
    /// Within the band; beyond it the value is a lower bound of the distance's magnitude.
    bool isExactSdf() const override { return true; }
    /// The interpolation's (interval()): its values between voxels can change faster than 1.
    double lipschitzBound() const override;
    std::string typeName() const override { return mName; }

    const openvdb::FloatGrid& grid() const { return *mGrid; }
    /// The band's half width, world units: values beyond it are clamped to it.
    double bandWidth() const { return mBackground; }

private:
    /// True if index-space point @a q is beyond every node the tree stores and the
    /// interpolation's reach: there the value is the background.
    bool far(const Vec3d& q) const;
    double clamp(double v) const { return std::max(-mBackground, std::min(mBackground, v)); }
    /// The range of the samples in index box [@a lo, @a hi]: every voxel's for a box of up to
    /// 21 voxels a side, else each leaf's (or tile's) smallest and largest value (wider).
    void sampleRange(const openvdb::Coord& lo, const openvdb::Coord& hi, double& min,
                     double& max) const;

    openvdb::FloatGrid::ConstPtr mGrid;
    std::string mName;
    double mDx, mInvDx, mBackground;
    BBoxd mBox;
    Vec3d mIndexLo, mIndexHi; // the tree's index range, grown by three voxels
    openvdb::FloatTree mLeafMin, mLeafMax; // each leaf's values' range, at (origin / 8)
};

} // namespace ivdb::implicit
