// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>
#include <ivdb/jobs/Rasterize.h>

#include <openvdb/openvdb.h>

#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace ivdb::jobs {

/// @brief A brute-force distance to a shape's surface that trusts nothing but the shape's
/// values: not its gradient, its bounds or its foot points.
/// @details distance() grows a sphere of @a directions points (a Fibonacci lattice) about p, a
/// step at a time, until one of its points has the other sign than p, then bisects the radius
/// between the last two steps. A point of the surface lies on the segment from p to that
/// point, so the surface is no farther than the radius found. The sphere's gaps (about
/// sqrt(4 pi / directions) radians) can put that point beyond the nearest surface point where
/// the other side is small near it (a convex corner seen from outside), so caps of finer
/// directions about the points that reached are searched again, three levels each 4.5 times
/// finer. The surface may still be nearer by what the steps and the gaps miss: a feature
/// thinner than a step, or narrower than the gaps.
class SurfaceSearch
{
public:
    using Vec3d = openvdb::Vec3d;

    /// @param directions  points on each sphere (at least 1)
    SurfaceSearch(const implicit::Implicit& shape, int directions);

    /// @brief The least radius, within step / 2^20, at which a sphere about @a p (or a cap of
    /// the refinement) first holds a point of the other sign than @a p, stepping by @a step up
    /// to @a reach; infinity if none within @a reach; 0 if p is on the surface.
    /// @throw openvdb::ValueError unless @a step > 0 and @a reach >= 0 are finite
    double distance(const Vec3d& p, double step, double reach) const;

    const std::vector<Vec3d>& directions() const { return mDirections; }

private:
    const implicit::Implicit& mShape;
    std::vector<Vec3d> mDirections;
};

/// @brief What checkDistances() does: compare a level set's values with brute-force distances
/// (SurfaceSearch) to its scene's surface at sampled band voxels.
struct CheckDistancesOptions
{
    /// The scene (raster.scene) and, without an input, how it is rasterized (its voxel size,
    /// half width and distance overrides; these must be unset with an input). Its interrupter
    /// reports the search's progress too; its output is not used.
    RasterizeOptions raster;
    /// The level set checked, FILE.vdb[:GRID] (without GRID the file's first level set); empty:
    /// the scene rasterized.
    std::string input;
    std::size_t samples = 200;    ///< band voxels checked (all of them if fewer)
    int directions = 20000;       ///< points on each sphere of the search
    std::uint64_t seed = 1;       ///< which voxels are sampled
    /// Only voxels within whose distance the shape may kink (Implicit::mayKinkWithin): where a
    /// local search for the nearest point can settle on one that is not.
    bool nearKinks = false;
};

/// @brief One sampled voxel.
struct CheckedVoxel
{
    openvdb::Coord ijk;
    openvdb::Vec3d world;    ///< its centre
    double value = 0.0;      ///< the level set's, world units
    /// SurfaceSearch::distance() from the centre, world units, searched up to a voxel beyond
    /// the value's magnitude (infinity: no surface point that near)
    double searched = std::numeric_limits<double>::infinity();
    /// The value's sign is the shape's there, or the value and the distance found sum to at
    /// most 0.001 voxel (a voxel that near the surface may have either sign; 0 counts as either)
    bool signAgrees = true;
};

struct CheckDistancesResult
{
    double voxelSize = 0.0;
    std::uint64_t activeVoxels = 0;
    /// Band voxels that could be sampled: active, not clamped to the background, and near a
    /// kink if CheckDistancesOptions::nearKinks
    std::uint64_t candidates = 0;
    double reachVoxels = 1.0;             ///< how far beyond |value| each search looked
    double stepVoxels = 0.05;             ///< the search's radius step
    std::vector<CheckedVoxel> voxels;     ///< the samples, farthest first (by error())
    double seconds = 0.0;                 ///< rasterizing (if done) and searching

    /// @brief (|value| - searched) / voxel size of @a v: positive where the value is farther
    /// than a surface point the search found (certainly too far by at least that), negative
    /// where it is nearer (-infinity: no surface point within the reach).
    double error(const CheckedVoxel& v) const;
    /// @brief Sampled voxels more than @a voxels farther than the surface.
    std::size_t fartherThan(double voxels) const;
    /// @brief Sampled voxels more than @a voxels nearer than the surface the search found.
    std::size_t nearerThan(double voxels) const;
    std::size_t signMismatches() const;
};

/// @brief Check a level set against brute-force distances to its scene's surface (a keyed
/// scene's at its start frame).
/// @throw scene::SceneError for a bad scene; ParamError for a bad setting ("samples",
/// "directions", or a rasterizing one, which an input also refuses); openvdb::IoError or
/// ParamError ("grid") for an input that cannot be read, openvdb::ValueError for one with
/// values that are not finite; openvdb::RuntimeError when the
/// rasterized surface has no voxel, or on interruption. Nothing is written.
CheckDistancesResult checkDistances(const CheckDistancesOptions& options);

} // namespace ivdb::jobs
