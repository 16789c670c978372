// SPDX-License-Identifier: Apache-2.0
#include "Distances.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

namespace ivdb::raster::detail {

using implicit::Vec3d;

namespace {

implicit::FootQuery footQuery(const DistanceSettings& s)
{
    implicit::FootQuery query;
    query.tolerance = s.tolerance;
    query.far = s.band; // no foot point is solved for beyond the band
    query.feet = false;
    return query;
}

/// The certified feet's distances, the lattice search for the others.
void finishDistances(const implicit::Implicit& f, const openvdb::Coord& origin,
                     const int* offsets, const double* values, std::size_t n,
                     const DistanceSettings& s, const implicit::FootPoints& feet, double* out,
                     DistanceCounts& counts)
{
    for (std::size_t i = 0; i < n; ++i) {
        if (feet.ok[i]) {
            out[i] = feet.distance[i];
            ++counts.local;
            continue;
        }
        bool certified = false;
        const int o = offsets[i];
        const openvdb::Coord ijk = origin.offsetBy(o >> 6, (o >> 3) & 7, o & 7);
        out[i] = searchDistance(f, ijk, values[i], s, certified);
        // A point of the surface the foot points found, though not proven the nearest, bounds
        // the answer: the lattice's crossings, unrefined, can be farther, and a refined one
        // nearer than every other crossing's can still be a farther foot point (a blend's, on
        // the other side of a valley, 0.09 voxel): then it was not the nearest after all.
        if (feet.surface[i] && std::abs(feet.distance[i]) < std::abs(out[i]) - s.tolerance) {
            out[i] = std::copysign(std::abs(feet.distance[i]), out[i]);
            certified = false;
        }
        ++(std::isnan(out[i]) ? counts.unknown : certified ? counts.searched : counts.approximate);
    }
}

/// A crossing of the surface on a lattice's edge: its distance from the query point, the point
/// (linear interpolation of the values along the edge) and the edge's two ends.
struct Crossing
{
    double dist = std::numeric_limits<double>::max();
    Vec3d point;
    int a = -1, b = -1;
};

/// The @a K crossings nearest to @a p of the edges of the lattice of @a side points a side
/// (points and values @a px, @a py, @a pz, @a v, index (i side + j) side + k), nearest first;
/// those not found keep dist max and a = -1.
template<std::size_t K>
std::array<Crossing, K> nearestCrossings(const double* px, const double* py, const double* pz,
                                         const double* v, int side, const Vec3d& p)
{
    std::array<Crossing, K> nearest;
    nearest.fill(Crossing{std::numeric_limits<double>::max(), p, -1, -1});
    const int stride[3] = {side * side, side, 1};
    for (int i = 0, a = 0; i < side; ++i) {
        for (int j = 0; j < side; ++j) {
            for (int k = 0; k < side; ++k, ++a) {
                const int at[3] = {i, j, k};
                for (int d = 0; d < 3; ++d) {
                    if (at[d] + 1 >= side) continue;
                    const int b = a + stride[d];
                    if ((v[a] > 0.0) == (v[b] > 0.0)) continue;
                    const double t = v[a] / (v[a] - v[b]);
                    const Vec3d c(px[a] + t * (px[b] - px[a]), py[a] + t * (py[b] - py[a]),
                                  pz[a] + t * (pz[b] - pz[a]));
                    const double dist = (c - p).length();
                    if (dist >= nearest.back().dist) continue;
                    nearest.back() = Crossing{dist, c, a, b};
                    std::sort(nearest.begin(), nearest.end(),
                              [](const Crossing& l, const Crossing& r) { return l.dist < r.dist; });
                }
            }
        }
    }
    return nearest;
}

/// The nearest to @a p of the surface points found on the lattice of step @a h (5 points a
/// side) centred at @a c: the shape's crossings of the lattice's edges (linear interpolation),
/// the nearest few bisected along their edges onto the surface (@a halvings times); @a found
/// false (and @a c) where no edge crosses.
Vec3d latticeSurfacePoint(const implicit::Implicit& f, const Vec3d& p, const Vec3d& c, double h,
                          int halvings, bool& found)
{
    constexpr int kFine = 5;
    constexpr int kCount = kFine * kFine * kFine;
    double px[kCount], py[kCount], pz[kCount], v[kCount];
    for (int i = 0, m = 0; i < kFine; ++i) {
        for (int j = 0; j < kFine; ++j) {
            for (int k = 0; k < kFine; ++k, ++m) {
                px[m] = c[0] + (i - kFine / 2) * h;
                py[m] = c[1] + (j - kFine / 2) * h;
                pz[m] = c[2] + (k - kFine / 2) * h;
            }
        }
    }
    f.values(px, py, pz, v, kCount);
    const auto nearest = nearestCrossings<3>(px, py, pz, v, kFine, p);
    found = nearest.front().a >= 0;
    Vec3d best = c;
    double bestDist = std::numeric_limits<double>::max();
    for (const Crossing& e : nearest) {
        if (e.a < 0) break;
        // Bisection between the two ends (of opposite signs).
        Vec3d lo(px[e.a], py[e.a], pz[e.a]), hi(px[e.b], py[e.b], pz[e.b]);
        const bool loPositive = v[e.a] > 0.0;
        for (int it = 0; it < halvings; ++it) {
            const Vec3d mid = 0.5 * (lo + hi);
            ((f.value(mid) > 0.0) == loPositive ? lo : hi) = mid;
        }
        const Vec3d q = 0.5 * (lo + hi);
        const double d = (q - p).length();
        if (d < bestDist) bestDist = d, best = q;
    }
    return best;
}

/// Voxel-sized cubes surfacePointNear() may walk on after the first, and how much nearer
/// (voxels) a cube's point must be than the last one's for another.
constexpr int kSurfaceWalks = 8;
constexpr double kWalkGain = 0.02;

/// A point of the surface near the lattice crossing @a c (of an edge whose refinement into a
/// foot point failed: a crease, a sharp rim, a sliver), the nearest to @a p found, and its
/// distance: latticeSurfacePoint() in the voxel-sized cube around @a c (steps of a quarter
/// voxel), walked on where the nearest point lies beyond it, then twice in a cube half as
/// large around the best point so far. A point of the surface (within its bisection's 1e-5
/// voxel), so never nearer than the surface, and within a few thousandths of a voxel of the
/// nearest one where that lies in the cubes. The crossing @a c itself, interpolated linearly
/// across a whole voxel where the field is far from linear, was up to 0.82 voxel too far
/// (TestTrueDistances.ApproximateDistancesAreSurfacePointsNearTheNearest). The walk: a sharp
/// tip or corner's crossings of the voxels' edges can lie a voxel or more back from its
/// nearest point, so while a cube's nearest point lies in its outer layer and is nearer than
/// the last one's by kWalkGain, a cube about it follows (a shrunk blended intersection of a
/// box and a cylinder was answered up to 1.2 voxels too far at its corners, 0.07 with it).
/// @a dist (|c - p|) where no edge crosses.
double surfacePointNear(const implicit::Implicit& f, const Vec3d& p, const Vec3d& c, double dx,
                        double dist)
{
    Vec3d centre = c;
    double best = std::numeric_limits<double>::max();
    // Each stage's bisection ends within 1e-5 voxel of the surface (2^-15 of a quarter voxel),
    // far below the tolerance, so that no point is nearer than the surface by more.
    // The first stage walks (above); the first cube's gain is over the crossing's distance.
    const double h = 0.25 * dx;
    double last = dist;
    for (int walk = 0; walk <= kSurfaceWalks; ++walk) {
        bool found = false;
        const Vec3d q = latticeSurfacePoint(f, p, centre, h, 15, found);
        if (!found) break;
        const double d = (q - p).length();
        if (d >= best) break;
        const Vec3d moved = q - centre;
        best = d, centre = q;
        const bool gained = d < last - kWalkGain * dx;
        last = d;
        if (!gained || std::max({std::abs(moved[0]), std::abs(moved[1]), std::abs(moved[2])}) < 1.5 * h) break;
    }
    if (best == std::numeric_limits<double>::max()) return dist;
    for (int stage = 1; stage < 3; ++stage) {
        bool found = false;
        const Vec3d q = latticeSurfacePoint(f, p, centre, std::ldexp(h, -stage), 15 - stage, found);
        if (!found) break;
        const double d = (q - p).length();
        if (d < best) best = d, centre = q;
    }
    return best;
}

} // namespace

void trueDistances(const implicit::Implicit& f, const openvdb::Coord& origin, const int* offsets,
                   const double* x, const double* y, const double* z, const double* values,
                   std::size_t n, const DistanceSettings& s, double* out, DistanceCounts& counts)
{
    implicit::FootPoints feet;
    f.footPoints(x, y, z, values, n, footQuery(s), feet);
    finishDistances(f, origin, offsets, values, n, s, feet, out, counts);
}

void valuesAndTrueDistances(const implicit::Implicit& f, const openvdb::Coord& origin,
                            const int* offsets, const double* x, const double* y,
                            const double* z, std::size_t n, const DistanceSettings& s,
                            double* values, double* out, DistanceCounts& counts)
{
    implicit::FootPoints feet;
    f.valuesAndFootPoints(x, y, z, n, footQuery(s), values, feet);
    finishDistances(f, origin, offsets, values, n, s, feet, out, counts);
}

double searchDistance(const implicit::Implicit& f, const openvdb::Coord& ijk, double value,
                      const DistanceSettings& s, bool& certified)
{
    const int r = s.searchRadius, side = 2 * r + 1;
    const std::size_t count = std::size_t(side) * side * side;
    // The lattice at the voxels' own coordinates, so its values are the grid's.
    std::vector<double> px(count), py(count), pz(count), v(count);
    for (int i = 0, m = 0; i < side; ++i) {
        for (int j = 0; j < side; ++j) {
            for (int k = 0; k < side; ++k, ++m) {
                px[m] = double(ijk.x() - r + i) * s.dx;
                py[m] = double(ijk.y() - r + j) * s.dx;
                pz[m] = double(ijk.z() - r + k) * s.dx;
            }
        }
    }
    for (std::size_t b = 0; b < count; b += implicit::kMaxBatch) {
        const std::size_t len = std::min(implicit::kMaxBatch, count - b);
        f.values(&px[b], &py[b], &pz[b], &v[b], len);
    }
    const Vec3d p(double(ijk.x()) * s.dx, double(ijk.y()) * s.dx, double(ijk.z()) * s.dx);
    // The nearest crossings of the lattice's edges (linear interpolation along the edge).
    constexpr std::size_t kKeep = 4;
    const auto nearest = nearestCrossings<kKeep>(px.data(), py.data(), pz.data(), v.data(), side, p);
    certified = false;
    if (nearest.front().a < 0) {
        // No crossing in the window: the surface is farther (more than r voxels along an axis).
        if (double(r) * s.dx < s.far) return std::numeric_limits<double>::quiet_NaN();
        certified = true;
        return std::copysign(double(r + 1) * s.dx, value > 0.0 ? 1.0 : -1.0);
    }
    // The nearest surface point among the crossings' foot points, or where a crossing's
    // refinement is not certified (a crease, a sharp rim, a singular point), the surface points
    // found near it.
    double best = std::numeric_limits<double>::max();
    std::array<bool, kKeep> refined{};
    for (std::size_t k = 0; k < kKeep; ++k) {
        const double dist = nearest[k].dist;
        const Vec3d& c = nearest[k].point;
        if (nearest[k].a < 0) break;
        Vec3d q;
        // Newton's method where the rounds fail only for a crossing nearer than the nearest
        // point certified so far (it costs seven gradients a step: a mesh's crossings took
        // most of the knot's compute with it on every crossing).
        const bool newton = !(certified && dist >= best);
        refined[k] = implicit::refineFootPoint(f, p, c, s.tolerance, q, newton);
        if (refined[k] && (q - p).length() < best) {
            best = (q - p).length();
            certified = true;
        }
    }
    // The crossings not refined: a point of the surface near each (surfacePointNear()), for
    // those nearer than the nearest certified point (else it stands, as it did against the
    // crossing itself) and less than a voxel farther than the best point so far (the search
    // moves a crossing by less). A surface point within the tolerance of the certified one is
    // that point (its bisection leaves it a little off); a nearer one shows the certified
    // point was not the nearest.
    const double bestCertified = best;
    for (std::size_t k = 0; k < kKeep; ++k) {
        const double dist = nearest[k].dist;
        if (nearest[k].a < 0) break;
        if (refined[k] || dist >= bestCertified || dist - s.dx >= best) continue;
        const double d = surfacePointNear(f, p, nearest[k].point, s.dx, dist);
        if (d < (certified ? best - s.tolerance : best)) {
            best = d;
            certified = false;
        }
    }
    return std::copysign(best, value > 0.0 ? 1.0 : -1.0);
}

} // namespace ivdb::raster::detail
