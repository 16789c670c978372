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
        // an approximate answer: the lattice's crossings, unrefined, can be farther.
        if (!certified && feet.surface[i] && std::abs(feet.distance[i]) < std::abs(out[i])) {
            out[i] = std::copysign(std::abs(feet.distance[i]), out[i]);
        }
        ++(std::isnan(out[i]) ? counts.unknown : certified ? counts.searched : counts.approximate);
    }
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
    std::array<std::pair<double, Vec3d>, kKeep> nearest;
    nearest.fill({std::numeric_limits<double>::max(), p});
    auto index = [side](int i, int j, int k) { return (std::size_t(i) * side + j) * side + k; };
    for (int i = 0; i < side; ++i) {
        for (int j = 0; j < side; ++j) {
            for (int k = 0; k < side; ++k) {
                const std::size_t a = index(i, j, k);
                const int step[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
                for (const auto& d : step) {
                    const int ii = i + d[0], jj = j + d[1], kk = k + d[2];
                    if (ii >= side || jj >= side || kk >= side) continue;
                    const std::size_t b = index(ii, jj, kk);
                    if ((v[a] > 0.0) == (v[b] > 0.0)) continue;
                    const double t = v[a] / (v[a] - v[b]);
                    const Vec3d c(px[a] + t * (px[b] - px[a]), py[a] + t * (py[b] - py[a]),
                                  pz[a] + t * (pz[b] - pz[a]));
                    const double dist = (c - p).length();
                    if (dist >= nearest.back().first) continue;
                    nearest.back() = {dist, c};
                    std::sort(nearest.begin(), nearest.end(),
                              [](const auto& l, const auto& rr) { return l.first < rr.first; });
                }
            }
        }
    }
    certified = false;
    if (nearest.front().first == std::numeric_limits<double>::max()) {
        // No crossing in the window: the surface is farther (more than r voxels along an axis).
        if (double(r) * s.dx < s.far) return std::numeric_limits<double>::quiet_NaN();
        certified = true;
        return std::copysign(double(r + 1) * s.dx, value > 0.0 ? 1.0 : -1.0);
    }
    // The nearest surface point among the crossings' foot points (the crossing itself where
    // the refinement is not certified: a crease, a singular point).
    double best = std::numeric_limits<double>::max();
    for (const auto& [dist, c] : nearest) {
        if (dist == std::numeric_limits<double>::max()) break;
        Vec3d q;
        // Newton's method where the rounds fail only for a crossing nearer than the nearest
        // point certified so far (it costs seven gradients a step: a mesh's crossings took
        // most of the knot's compute with it on every crossing).
        const bool newton = !(certified && dist >= best);
        const bool ok = implicit::refineFootPoint(f, p, c, s.tolerance, q, newton);
        const double d = ok ? (q - p).length() : dist;
        if (d < best) {
            best = d;
            certified = ok;
        }
    }
    return std::copysign(best, value > 0.0 ? 1.0 : -1.0);
}

} // namespace ivdb::raster::detail
