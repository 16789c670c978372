// SPDX-License-Identifier: Apache-2.0
// True distances of shapes that are not exact SDFs, voxel by voxel and locally (internal to the
// rasterizer; docs/method.md#true-distances).
#pragma once

#include <ivdb/implicit/Implicit.h>

#include <openvdb/Types.h>

#include <cstdint>

namespace ivdb::raster::detail {

struct DistanceSettings
{
    double dx = 0.0;          ///< voxel size
    double band = 0.0;        ///< the band's half width: beyond it a voxel keeps only its sign
    double far = 0.0;         ///< the search's: beyond this a distance only needs to be "farther"
    double tolerance = 0.0;   ///< world units a certified distance may be off
    int searchRadius = 0;     ///< voxels: the half side of the lattice window of the search
};

/// How the distances of a batch were found.
struct DistanceCounts
{
    std::uint64_t local = 0;       ///< certified by the shape's own local method (footPoints)
    std::uint64_t searched = 0;    ///< by the lattice search, refined to a certified foot point
    std::uint64_t approximate = 0; ///< by the lattice search, a surface point not certified
    std::uint64_t unknown = 0;     ///< none: the surface is beyond the lattice window (NaN)

    DistanceCounts& operator+=(const DistanceCounts& o)
    {
        local += o.local;
        searched += o.searched;
        approximate += o.approximate;
        unknown += o.unknown;
        return *this;
    }
};

/// @brief Signed true distances of @a f at n <= kMaxBatch voxels of the leaf at @a origin (their
/// leaf offsets @a offsets, their points @a x, @a y, @a z) whose values are @a values: the
/// shape's own foot points (Implicit::footPoints) where they are certified, else the lattice
/// search (searchDistance), NaN where neither knows. A pure function of the points and the
/// node: the sparse and the dense path get the same numbers.
void trueDistances(const implicit::Implicit& f, const openvdb::Coord& origin, const int* offsets,
                   const double* x, const double* y, const double* z, const double* values,
                   std::size_t n, const DistanceSettings& s, double* out, DistanceCounts& counts);
/// @brief trueDistances() for points whose values are not known yet: they are computed into
/// @a values (value() at each point) with the foot points (Implicit::valuesAndFootPoints), the
/// same numbers as values() followed by the call above.
void valuesAndTrueDistances(const implicit::Implicit& f, const openvdb::Coord& origin,
                            const int* offsets, const double* x, const double* y,
                            const double* z, std::size_t n, const DistanceSettings& s,
                            double* values, double* out, DistanceCounts& counts);

/// @brief The last resort where no local method is certified (a singular point, a medial axis,
/// a thin feature, a corner of three surfaces): @a f on the voxel lattice around @a ijk (a cube
/// of side 2 searchRadius + 1), the surface's crossings of the lattice's edges, and the nearest
/// few refined to foot points (implicit::refineFootPoint), or where that is not certified,
/// points of the surface found near them on finer lattices (approximate). No crossing in the window: the
/// surface is farther than the window: distance +/- (searchRadius + 1) dx by the sign of
/// @a value when that is beyond far, else NaN (unknown: the band is wider than the window, and
/// the rasterizer re-distances such voxels by fast sweeping).
double searchDistance(const implicit::Implicit& f, const openvdb::Coord& ijk, double value,
                      const DistanceSettings& s, bool& certified);

} // namespace ivdb::raster::detail
