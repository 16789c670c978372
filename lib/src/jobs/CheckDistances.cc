// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/CheckDistances.h>

#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Inputs.h>
#include <ivdb/jobs/Rasterize.h>
#include <ivdb/util/Params.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <random>
#include <string>

namespace ivdb::jobs {

namespace {

using Vec3d = openvdb::Vec3d;

/// Points a sphere's batch evaluates at once.
constexpr int kBatch = 256;
/// Halvings of the radius after the stepping (a step over 2^20).
constexpr int kHalvings = 20;
/// Refinement: levels of caps, points in each, caps at most per level, and a cap's angle in
/// gaps of the directions it refines (the first cap's, of the whole sphere's).
constexpr int kCapLevels = 3;
constexpr int kCapPoints = 400;
constexpr std::size_t kMaxCaps = 16;
constexpr double kCapSpread = 2.5;
/// Voxels within which of the surface a value may have either sign.
constexpr double kSignSlack = 1e-3;
/// The golden angle, radians: consecutive spiral points that never line up.
const double kGolden = M_PI * (3.0 - std::sqrt(5.0));

} // namespace

SurfaceSearch::SurfaceSearch(const implicit::Implicit& shape, int directions): mShape(shape)
{
    check(limits::kDirections, directions);
    // A Fibonacci lattice: equal areas, no pole clustering.
    for (int i = 0; i < directions; ++i) {
        const double z = 1.0 - 2.0 * (i + 0.5) / directions, r = std::sqrt(1.0 - z * z);
        mDirections.emplace_back(r * std::cos(kGolden * i), r * std::sin(kGolden * i), z);
    }
}

double SurfaceSearch::distance(const Vec3d& p, double step, double reach) const
{
    if (!(step > 0.0) || !std::isfinite(step) || !(reach >= 0.0) || !std::isfinite(reach)) {
        OPENVDB_THROW(openvdb::ValueError, "a surface search needs a finite step > 0 and a finite "
                      "reach >= 0, got step " + std::to_string(step) + " and reach " +
                      std::to_string(reach));
    }
    const double own = mShape.value(p);
    if (own == 0.0) return 0.0;
    const bool inside = own < 0.0;
    double x[kBatch], y[kBatch], z[kBatch], v[kBatch];
    // True if the sphere of @a radius about p holds a point of the other sign in one of
    // @a dirs; with @a hits, each such direction is added to it (else the first one ends it).
    auto reaches = [&](const std::vector<Vec3d>& dirs, double radius, std::vector<Vec3d>* hits) {
        bool found = false;
        const int n = int(dirs.size());
        for (int first = 0; first < n; first += kBatch) {
            const int count = std::min(kBatch, n - first);
            for (int k = 0; k < count; ++k) {
                const Vec3d q = p + dirs[first + k] * radius;
                x[k] = q[0], y[k] = q[1], z[k] = q[2];
            }
            mShape.values(x, y, z, v, count);
            for (int k = 0; k < count; ++k) {
                if ((v[k] < 0.0) == inside) continue;
                if (!hits) return true;
                found = true;
                hits->push_back(dirs[first + k]);
            }
        }
        return found;
    };
    // The least radius in (lo, hi] at which @a dirs reach, bisected (they reach at hi).
    auto bisect = [&](const std::vector<Vec3d>& dirs, double lo, double hi) {
        for (int k = 0; k < kHalvings; ++k) {
            const double mid = 0.5 * (lo + hi);
            (reaches(dirs, mid, nullptr) ? hi : lo) = mid;
        }
        return hi;
    };

    // The whole sphere, a step at a time.
    const std::uint64_t steps = std::uint64_t(std::ceil(reach / step));
    double lo = 0.0, hi = 0.0;
    for (std::uint64_t k = 1;; ++k) {
        hi = k >= steps ? reach : double(k) * step;
        if (reaches(mDirections, hi, nullptr)) break;
        if (k >= steps) return std::numeric_limits<double>::infinity();
        lo = hi;
    }
    hi = bisect(mDirections, lo, hi);

    // The sphere's gaps let the first point of the other sign lie beyond the nearest surface
    // point: by about the distance times the gap where the other side is a sharp corner's
    // small region. Caps of finer directions about those that reached search again, each
    // level's gaps 1/4.5 of the last's.
    std::vector<Vec3d> centers, cap;
    reaches(mDirections, hi, &centers);
    double spread = kCapSpread * std::sqrt(4.0 * M_PI / double(mDirections.size()));
    for (int level = 0; level < kCapLevels && !centers.empty(); ++level) {
        if (centers.size() > kMaxCaps) {
            // Evenly among them: they lie in one or a few clusters.
            std::vector<Vec3d> kept;
            for (std::size_t i = 0; i < kMaxCaps; ++i) kept.push_back(centers[i * centers.size() / kMaxCaps]);
            centers.swap(kept);
        }
        cap.clear();
        for (const Vec3d& c : centers) {
            // A frame about c, and a spiral of equal areas over the cap of angle spread.
            const Vec3d u = (std::abs(c[0]) < 0.9 ? Vec3d(1, 0, 0) : Vec3d(0, 1, 0)).cross(c).unitSafe();
            const Vec3d w = c.cross(u);
            cap.push_back(c);
            for (int i = 0; i < kCapPoints; ++i) {
                const double rho = spread * std::sqrt((i + 0.5) / kCapPoints), phi = kGolden * i;
                cap.push_back(c * std::cos(rho) + (u * std::cos(phi) + w * std::sin(phi)) * std::sin(rho));
            }
        }
        // Down a step at a time while the cap reaches (at most to p), then bisect the last step.
        double capHi = hi, capLo = std::max(0.0, hi - step);
        while (capLo > 0.0 && reaches(cap, capLo, nullptr)) {
            capHi = capLo;
            capLo = std::max(0.0, capLo - step);
        }
        hi = bisect(cap, capLo, capHi);
        centers.clear();
        reaches(cap, hi, &centers);
        spread *= kCapSpread * std::sqrt(M_PI / kCapPoints);
    }
    return hi;
}

double CheckDistancesResult::error(const CheckedVoxel& v) const
{
    if (std::isinf(v.searched)) return -std::numeric_limits<double>::infinity();
    return (std::abs(v.value) - v.searched) / voxelSize;
}

std::size_t CheckDistancesResult::fartherThan(double limit) const
{
    return std::size_t(std::count_if(voxels.begin(), voxels.end(),
                                      [&](const CheckedVoxel& v) { return error(v) > limit; }));
}

std::size_t CheckDistancesResult::nearerThan(double limit) const
{
    return std::size_t(std::count_if(voxels.begin(), voxels.end(),
                                      [&](const CheckedVoxel& v) { return error(v) < -limit; }));
}

std::size_t CheckDistancesResult::signMismatches() const
{
    return std::size_t(std::count_if(voxels.begin(), voxels.end(),
                                      [](const CheckedVoxel& v) { return !v.signAgrees; }));
}

namespace {

/// The band voxels of @a grid that may be sampled, in the tree's order: active, not clamped to
/// the background, and (if @a nearKinks) where @a shape may kink within the value's distance.
std::vector<openvdb::Coord> candidateVoxels(const openvdb::FloatGrid& grid,
                                            const implicit::Implicit& shape, bool nearKinks)
{
    using LeafT = openvdb::FloatTree::LeafNodeType;
    std::vector<const LeafT*> leaves;
    for (auto it = grid.tree().cbeginLeaf(); it; ++it) leaves.push_back(it.getLeaf());
    const float background = std::abs(grid.background());
    const double dx = grid.voxelSize()[0];
    std::vector<std::vector<openvdb::Coord>> perLeaf(leaves.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& range) {
        for (std::size_t l = range.begin(); l != range.end(); ++l) {
            for (auto it = leaves[l]->cbeginValueOn(); it; ++it) {
                const float value = std::abs(*it);
                if (value >= background) continue;
                const openvdb::Coord c = it.getCoord();
                if (nearKinks && !shape.mayKinkWithin(grid.indexToWorld(c), value + 0.5 * dx)) continue;
                perLeaf[l].push_back(c);
            }
        }
    });
    std::vector<openvdb::Coord> all;
    for (const auto& coords : perLeaf) all.insert(all.end(), coords.begin(), coords.end());
    // Active tiles hold no distances worth sampling (a band has none); they are skipped.
    return all;
}

/// @a count of @a items chosen by @a seed (a partial Fisher-Yates shuffle with the generator's
/// raw draws, the same on every platform), the rest dropped.
void sample(std::vector<openvdb::Coord>& items, std::size_t count, std::uint64_t seed)
{
    if (items.size() <= count) return;
    std::mt19937_64 rng(seed);
    for (std::size_t i = 0; i < count; ++i) {
        std::swap(items[i], items[i + std::size_t(rng() % (items.size() - i))]);
    }
    items.resize(count);
}

} // namespace

CheckDistancesResult checkDistances(const CheckDistancesOptions& opt)
{
    Stopwatch clock;
    check(limits::kSamples, double(opt.samples));
    check(limits::kDirections, opt.directions);
    RasterizeOptions ro = opt.raster;
    ro.output.clear();
    openvdb::FloatGrid::Ptr grid;
    if (!opt.input.empty()) {
        if (ro.voxelSize || ro.halfWidth || ro.distance) {
            const Param& p = ro.voxelSize ? param::kVoxelSize
                             : ro.halfWidth ? param::kHalfWidth : param::kDistance;
            throw ParamError(p, "applies only when the scene is rasterized, not to an input grid (" +
                             opt.input + ")");
        }
        const io::GridRef ref = io::GridRef::parse(opt.input);
        grid = readLevelSet(ref.file, ref.grid);
        ro.voxelSize = grid->voxelSize()[0];
    }
    const scene::Scene sc = loadRasterScene(ro, std::nullopt, true);
    raster::RasterSettings settings = rasterSettings(sc, ro);
    if (!grid) {
        withSceneErrors(ro, [&] { grid = raster::rasterize(sc.shape, settings); });
        if (grid->activeVoxelCount() == 0) throwNoVoxels(ro, settings);
    }
    const implicit::Implicit::Ptr shape = raster::clipToBounds(sc.shape, settings);

    CheckDistancesResult result;
    result.voxelSize = grid->voxelSize()[0];
    result.activeVoxels = grid->activeVoxelCount();
    std::vector<openvdb::Coord> coords = candidateVoxels(*grid, *shape, opt.nearKinks);
    result.candidates = coords.size();
    sample(coords, opt.samples, opt.seed);

    const SurfaceSearch search(*shape, opt.directions);
    const double dx = result.voxelSize;
    result.voxels.resize(coords.size());
    auto acc = grid->getConstAccessor();
    for (std::size_t i = 0; i < coords.size(); ++i) {
        CheckedVoxel& v = result.voxels[i];
        v.ijk = coords[i];
        v.world = grid->indexToWorld(v.ijk);
        v.value = acc.getValue(v.ijk);
    }
    util::InterruptScope scope(ro.interrupter, "searching for the surface");
    std::atomic<std::size_t> done{0};
    std::atomic<bool> cancelled{false};
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, coords.size(), 1), [&](const auto& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
            if (cancelled) return;
            CheckedVoxel& v = result.voxels[i];
            const double own = shape->value(v.world);
            v.searched = search.distance(v.world, result.stepVoxels * dx,
                                         std::abs(v.value) + result.reachVoxels * dx);
            // A wrong sign is off by the value and the distance together: within kSignSlack
            // of the surface (float values, another evaluation order) either sign is taken.
            v.signAgrees = own == 0.0 || v.value == 0.0 || (own < 0.0) == (v.value < 0.0) ||
                           std::abs(v.value) + v.searched <= kSignSlack * dx;
            const std::size_t n = ++done;
            if (util::wasInterrupted(ro.interrupter, int(100 * n / coords.size()))) cancelled = true;
        }
    });
    if (cancelled) util::throwInterrupted();
    std::stable_sort(result.voxels.begin(), result.voxels.end(),
                     [&](const CheckedVoxel& a, const CheckedVoxel& b) { return result.error(a) > result.error(b); });
    result.seconds = clock.total();
    return result;
}

} // namespace ivdb::jobs
