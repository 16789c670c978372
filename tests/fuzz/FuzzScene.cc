// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: a scene file's text through the parser, then the shape through every
// evaluator (point, batch, gradient, interval, prune) and a coarse rasterization.
//
// Invalid scenes must end in scene::SceneError (any other exception is a bug: the CLI would print
// a message that does not name the field). On a valid scene, the checks that cannot fail for a
// correct evaluator abort, so libFuzzer records the input as a crash:
//   - the batch evaluator agrees with the point evaluator;
//   - a box's interval contains the value at the box's corners and centre (pruning relies on it).
#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace {

using ivdb::implicit::BBoxd;
using ivdb::implicit::Vec3d;

[[noreturn]] void fail(const char* what, const Vec3d& p, double a, double b)
{
    std::fprintf(stderr, "FuzzScene: %s at (%g, %g, %g): %.17g vs %.17g\n", what, p[0], p[1], p[2],
                 a, b);
    std::abort();
}

bool close(double a, double b)
{
    if (std::isnan(a) || std::isnan(b)) return std::isnan(a) == std::isnan(b);
    if (std::isinf(a) || std::isinf(b)) return a == b;
    return std::abs(a - b) <= 1e-9 * std::max({1.0, std::abs(a), std::abs(b)});
}

/// The box the checks sample: the shape's bounds (or the scene's), clipped to [-100, 100]^3.
BBoxd sampleBox(const ivdb::scene::Scene& sc)
{
    BBoxd box = sc.bounds ? *sc.bounds : sc.shape->boundingBox();
    const double lim = 100.0;
    for (int a = 0; a < 3; ++a) {
        double lo = std::max(-lim, std::min(lim, box.min()[a]));
        double hi = std::max(-lim, std::min(lim, box.max()[a]));
        if (!(lo < hi)) { lo = -1.0; hi = 1.0; }
        box.min()[a] = lo;
        box.max()[a] = hi;
    }
    return box;
}

void checkEvaluators(const ivdb::scene::Scene& sc)
{
    const auto& f = *sc.shape;
    const BBoxd box = sampleBox(sc);
    constexpr int n = 5;
    std::vector<double> xs, ys, zs;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j)
            for (int k = 0; k < n; ++k) {
                const Vec3d t(i / double(n - 1), j / double(n - 1), k / double(n - 1));
                const Vec3d p = box.min() + (box.max() - box.min()) * t;
                xs.push_back(p[0]); ys.push_back(p[1]); zs.push_back(p[2]);
            }
    std::vector<double> batch(xs.size());
    f.values(xs.data(), ys.data(), zs.data(), batch.data(), xs.size());
    for (size_t i = 0; i < xs.size(); ++i) {
        const Vec3d p(xs[i], ys[i], zs[i]);
        const double v = f.value(p);
        if (!close(v, batch[i])) fail("batch value differs from point value", p, batch[i], v);
        (void)f.gradient(p);
    }
    // Intervals over the eight octants of the box and the box itself.
    const Vec3d c = box.getCenter();
    std::vector<BBoxd> boxes{box};
    for (int o = 0; o < 8; ++o) {
        Vec3d lo, hi;
        for (int a = 0; a < 3; ++a) {
            const bool upper = (o >> a) & 1;
            lo[a] = upper ? c[a] : box.min()[a];
            hi[a] = upper ? box.max()[a] : c[a];
        }
        boxes.emplace_back(lo, hi);
    }
    for (const BBoxd& b : boxes) {
        const auto iv = f.interval(b);
        const double slack = 1e-9 * std::max({1.0, std::abs(iv.lo), std::abs(iv.hi)});
        for (int corner = 0; corner < 9; ++corner) {
            Vec3d p = b.getCenter();
            if (corner < 8) {
                for (int a = 0; a < 3; ++a) p[a] = ((corner >> a) & 1) ? b.max()[a] : b.min()[a];
            }
            const double v = f.value(p);
            if (std::isnan(v) || std::isnan(iv.lo) || std::isnan(iv.hi)) continue;
            if (v < iv.lo - slack || v > iv.hi + slack) fail("interval misses the value", p, v, iv.lo);
        }
        (void)f.prune(b);
    }
}

/// Rasterize at a voxel size that puts at most 24 voxels across the sampled box.
void rasterizeCoarse(const ivdb::scene::Scene& sc)
{
    const BBoxd box = sampleBox(sc);
    const Vec3d ext = box.max() - box.min();
    ivdb::raster::RasterSettings s;
    s.voxelSize = std::max({ext[0], ext[1], ext[2]}) / 24.0;
    s.halfWidth = std::min(sc.halfWidth, 4.0);
    s.bounds = box;
    s.threaded = false;
    s.distance = sc.distanceBound ? ivdb::raster::Distance::Bound : ivdb::raster::Distance::Exact;
    try {
        (void)ivdb::raster::rasterize(sc.shape, s);
    } catch (const openvdb::Exception&) {
        // Refusals (no surface in the box, a bound scene that is not plain CSG) are fine.
    }
}

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    openvdb::initialize();
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size)
{
    if (size > 64 * 1024) return 0;
    const std::string text(reinterpret_cast<const char*>(data), size);
    ivdb::scene::Scene sc;
    try {
        sc = ivdb::scene::parseScene(text, "fuzz.json");
    } catch (const ivdb::scene::SceneError&) {
        return 0;
    }
    checkEvaluators(sc);
    rasterizeCoarse(sc);
    return 0;
}
