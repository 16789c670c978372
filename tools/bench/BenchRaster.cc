// SPDX-License-Identifier: Apache-2.0
// Micro-benchmarks: each ivdb kernel beside OpenVDB's equivalent, in the same binary and run.
// Run on demand: build/bin/ivdb_bench [--benchmark_filter=...]; not part of the test suite.
#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/implicit/Quadric.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/levelset/Dilate.h>
#include <ivdb/ops/Blend.h>
#include <ivdb/ops/Csg.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/util/System.h>

#include <ivdb/diff/Differential.h>

#include <openvdb/io/File.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/GridOperators.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/Morphology.h>

#include <benchmark/benchmark.h>

#include "../HugePages.h"


#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <string>
#include <unistd.h>
#include <vector>

using namespace ivdb;

namespace {

// A sphere of radius 1 at voxel size 1 / radiusVoxels, half width 3 (the reference
// case is radius 400 voxels, voxel size 0.0025).
raster::RasterSettings sphereSettings(int radiusVoxels, raster::Sampling s)
{
    raster::RasterSettings r;
    r.voxelSize = 1.0 / radiusVoxels;
    r.halfWidth = 3.0;
    r.sampling = s;
    return r;
}

void setCounters(benchmark::State& state, const openvdb::FloatGrid& g)
{
    state.counters["active_voxels"] = double(g.activeVoxelCount());
    state.counters["grid_MB"] = double(g.memUsage()) / 1e6;
}

void BM_Rasterize_Sparse(benchmark::State& state)
{
    const int r = int(state.range(0));
    auto sphere = std::make_shared<implicit::Sphere>(implicit::Vec3d(0.0), 1.0);
    const auto s = sphereSettings(r, raster::Sampling::Sparse);
    openvdb::FloatGrid::Ptr g;
    for (auto _ : state) {
        g = raster::rasterize(sphere, s);
        benchmark::DoNotOptimize(g.get());
    }
    setCounters(state, *g);
}

void BM_Rasterize_Dense(benchmark::State& state)
{
    const int r = int(state.range(0));
    auto sphere = std::make_shared<implicit::Sphere>(implicit::Vec3d(0.0), 1.0);
    const auto s = sphereSettings(r, raster::Sampling::Dense);
    openvdb::FloatGrid::Ptr g;
    for (auto _ : state) {
        g = raster::rasterize(sphere, s);
        benchmark::DoNotOptimize(g.get());
    }
    setCounters(state, *g);
    state.counters["samples_MB"] = double(raster::denseMemoryEstimate(sphere, s)) / 1e6;
}

void BM_OpenVDB_CreateLevelSetSphere(benchmark::State& state)
{
    const int r = int(state.range(0));
    openvdb::FloatGrid::Ptr g;
    for (auto _ : state) {
        g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            1.0f, openvdb::Vec3f(0.0f), 1.0f / float(r), 3.0f);
        benchmark::DoNotOptimize(g.get());
    }
    setCounters(state, *g);
}

// A non-distance shape: the same sphere as a quadric, rasterized and re-distanced.
void BM_Rasterize_QuadricSphere(benchmark::State& state)
{
    const int r = int(state.range(0));
    auto q = implicit::makeEllipsoid(implicit::Vec3d(0.0), implicit::Vec3d(1.0));
    const auto s = sphereSettings(r, raster::Sampling::Sparse);
    openvdb::FloatGrid::Ptr g;
    for (auto _ : state) {
        g = raster::rasterize(q, s);
        benchmark::DoNotOptimize(g.get());
    }
    setCounters(state, *g);
}

openvdb::FloatGrid::Ptr benchSphere(int radiusVoxels)
{
    static std::map<int, openvdb::FloatGrid::Ptr> cache;
    auto& g = cache[radiusVoxels];
    if (!g) {
        g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            1.0f, openvdb::Vec3f(0.0f), 1.0f / float(radiusVoxels), 3.0f);
    }
    return g;
}

void BM_Gradient(benchmark::State& state)
{
    auto phi = benchSphere(int(state.range(0)));
    for (auto _ : state) benchmark::DoNotOptimize(diff::gradient(*phi).get());
}

void BM_OpenVDB_Gradient(benchmark::State& state)
{
    auto phi = benchSphere(int(state.range(0)));
    for (auto _ : state) benchmark::DoNotOptimize(openvdb::tools::gradient(*phi).get());
}

// Both gradients alternately in each iteration, each timed on its own: with the memory of the
// previous outputs reused by both, this measures the stencils rather than first-touch page faults
// (which Google Benchmark's separate loops charge unevenly: see the README).
void BM_GradientAlternating(benchmark::State& state)
{
    auto phi = benchSphere(int(state.range(0)));
    double ours = 0.0, ref = 0.0;
    int n = 0;
    for (auto _ : state) {
        const auto t0 = std::chrono::steady_clock::now();
        auto a = diff::gradient(*phi);
        const auto t1 = std::chrono::steady_clock::now();
        a.reset();
        const auto t2 = std::chrono::steady_clock::now();
        auto b = openvdb::tools::gradient(*phi);
        const auto t3 = std::chrono::steady_clock::now();
        b.reset();
        if (n++ > 0) { // the first round warms the memory
            ours += std::chrono::duration<double, std::milli>(t1 - t0).count();
            ref += std::chrono::duration<double, std::milli>(t3 - t2).count();
        }
    }
    if (n > 1) {
        state.counters["ivdb_ms"] = ours / (n - 1);
        state.counters["openvdb_ms"] = ref / (n - 1);
    }
}

void BM_MeanCurvature(benchmark::State& state)
{
    auto phi = benchSphere(int(state.range(0)));
    for (auto _ : state) {
        benchmark::DoNotOptimize(diff::curvature(*phi, diff::Curvature::Mean).get());
    }
}

void BM_OpenVDB_MeanCurvature(benchmark::State& state)
{
    auto phi = benchSphere(int(state.range(0)));
    for (auto _ : state) benchmark::DoNotOptimize(openvdb::tools::meanCurvature(*phi).get());
}

// Two overlapping spheres of radius r voxels (centres +/- 0.35 of the radius apart).
std::pair<openvdb::FloatGrid::Ptr, openvdb::FloatGrid::Ptr> benchPair(int r)
{
    static std::map<int, std::pair<openvdb::FloatGrid::Ptr, openvdb::FloatGrid::Ptr>> cache;
    auto& p = cache[r];
    if (!p.first) {
        p.first = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            1.0f, openvdb::Vec3f(-0.35f, 0.0f, 0.0f), 1.0f / float(r), 3.0f);
        p.second = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            1.0f, openvdb::Vec3f(0.35f, 0.0f, 0.0f), 1.0f / float(r), 3.0f);
    }
    return p;
}

void BM_CsgUnion(benchmark::State& state)
{
    // In place, as `ivdb csg` runs it; the copies of the inputs are not timed, nor is freeing
    // them (as below): the last round's grids are replaced while the timing is paused. Freed
    // within the timing, they were 23 of the 40 ms at radius 400, on both sides of a ratio.
    auto [a, b] = benchPair(int(state.range(0)));
    std::vector<openvdb::FloatGrid::Ptr> in;
    for (auto _ : state) {
        state.PauseTiming();
        in = {a->deepCopy(), b->deepCopy()};
        state.ResumeTiming();
        benchmark::DoNotOptimize(ops::csgInPlace(ops::CsgOp::Union, in).get());
    }
}

void BM_OpenVDB_CsgUnion(benchmark::State& state)
{
    auto [a, b] = benchPair(int(state.range(0)));
    openvdb::FloatGrid::Ptr ca, cb;
    for (auto _ : state) {
        state.PauseTiming();
        ca = a->deepCopy();
        cb = b->deepCopy();
        state.ResumeTiming();
        openvdb::tools::csgUnion(*ca, *cb);
        benchmark::DoNotOptimize(ca.get());
    }
}

// Grid blend of the same pair, in place as `ivdb blend` runs it (copies untimed, as for the
// sharp union above); p = range(1). p = 1000 needs a 2-voxel band extension at radius 100 and a
// 3-voxel one at radius 400; p = 80 at radius 100 and 320 at radius 400 a 6-voxel one (twice the
// band of 3), the limit for the 5x target.
void BM_BlendUnion(benchmark::State& state)
{
    const int r = int(state.range(0));
    auto [a, b] = benchPair(r);
    ops::BlendSettings s;
    s.p = double(state.range(1));
    std::vector<std::string> notes;
    std::vector<openvdb::FloatGrid::Ptr> in;
    for (auto _ : state) {
        state.PauseTiming();
        in = {a->deepCopy(), b->deepCopy()};
        notes.clear();
        state.ResumeTiming();
        benchmark::DoNotOptimize(ops::blendInPlace(ops::CsgOp::Union, in, s, &notes).get());
    }
    const double reach = (ops::blendReach(s.p, s.tolerance / r) + std::log(2.0) / s.p) * r;
    state.counters["extension_voxels"] = std::ceil(3.0 + reach) + 1.0 - 3.0;
    if (!notes.empty()) state.SetLabel(notes.front());
}

// The grid blend's compute over the sharp union's, paired: each iteration times the sharp union
// and then the blend of the same pair (p = range(1)), each on fresh copies made and freed untimed,
// so that the machine's load, which moves the separate benchmarks above by 20% from minute to
// minute, weighs on both sides of each ratio alike. Counters: the median of the iterations'
// ratios (issue 17's target is 5) and each side's median, over 15 pairs; the time reported is
// the blend's.
void BM_BlendOverSharp(benchmark::State& state)
{
    auto [a, b] = benchPair(int(state.range(0)));
    ops::BlendSettings s;
    s.p = double(state.range(1));
    std::vector<double> sharp, blend, ratio;
    std::vector<std::string> notes;
    for (auto _ : state) {
        std::vector<openvdb::FloatGrid::Ptr> in{a->deepCopy(), b->deepCopy()};
        const auto t0 = std::chrono::steady_clock::now();
        auto u = ops::csgInPlace(ops::CsgOp::Union, in);
        const auto t1 = std::chrono::steady_clock::now();
        benchmark::DoNotOptimize(u.get());
        u.reset();
        in = {a->deepCopy(), b->deepCopy()};
        notes.clear();
        const auto t2 = std::chrono::steady_clock::now();
        auto g = ops::blendInPlace(ops::CsgOp::Union, in, s, &notes);
        const auto t3 = std::chrono::steady_clock::now();
        benchmark::DoNotOptimize(g.get());
        g.reset();
        in.clear();
        const double ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
        const double mb = std::chrono::duration<double, std::milli>(t3 - t2).count();
        state.SetIterationTime(mb / 1000.0);
        sharp.push_back(ms);
        blend.push_back(mb);
        ratio.push_back(mb / ms);
    }
    auto median = [](std::vector<double> v) {
        std::sort(v.begin(), v.end());
        return v.empty() ? 0.0 : v.size() % 2 ? v[v.size() / 2]
                                               : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
    };
    state.counters["ratio"] = median(ratio);
    state.counters["sharp_ms"] = median(sharp);
    state.counters["blend_ms"] = median(blend);
}

// Growing the band of one sphere of the pair (radius 100 voxels) by range(0) voxels, corners
// included, as the grid blend grows its masks: levelset::dilatedBox against OpenVDB's repeated
// one-voxel dilation (the same voxels; tests/levelset/TestDilate.cc).
openvdb::MaskTree benchBandMask()
{
    openvdb::MaskTree mask;
    mask.topologyUnion(benchPair(100).first->tree());
    return mask;
}

void BM_DilateBox(benchmark::State& state)
{
    const openvdb::MaskTree mask = benchBandMask();
    for (auto _ : state) {
        benchmark::DoNotOptimize(levelset::dilatedBox(mask, int(state.range(0))).get());
    }
}

// The mask of the leaves of one sphere of the pair (radius 400 voxels: a voxel a leaf, as the
// grid blend finds its candidate leaves) grown by one leaf, on a MaskTree (range(0) = 0) and on
// a levelset::SmallMaskTree (1).
template<typename TreeT>
void dilateLeafMask(benchmark::State& state)
{
    const openvdb::FloatGrid::Ptr sphere = benchPair(400).first;
    TreeT mask;
    for (auto leaf = sphere->tree().cbeginLeaf(); leaf; ++leaf) mask.setValueOn(leaf->origin() >> 3);
    for (auto _ : state) benchmark::DoNotOptimize(levelset::dilatedBox(mask, 1).get());
    state.counters["leaves"] = double(mask.activeVoxelCount());
}

void BM_DilateLeafMask(benchmark::State& state)
{
    if (state.range(0) == 0) dilateLeafMask<openvdb::MaskTree>(state);
    else dilateLeafMask<levelset::SmallMaskTree>(state);
}

void BM_OpenVDB_Dilate(benchmark::State& state)
{
    const openvdb::MaskTree mask = benchBandMask();
    for (auto _ : state) {
        openvdb::MaskTree grown(mask);
        openvdb::tools::dilateActiveValues(grown, int(state.range(0)),
                                           openvdb::tools::NN_FACE_EDGE_VERTEX,
                                           openvdb::tools::EXPAND_TILES);
        benchmark::DoNotOptimize(grown.leafCount());
    }
}

} // namespace

BENCHMARK(BM_CsgUnion)->Arg(100)->Arg(200)->Arg(400)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OpenVDB_CsgUnion)->Arg(100)->Arg(200)->Arg(400)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_DilateBox)->Arg(3)->Arg(10)->Arg(30)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OpenVDB_Dilate)->Arg(3)->Arg(10)->Arg(30)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_DilateLeafMask)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_BlendUnion)->Args({100, 1000})->Args({200, 1000})->Args({400, 1000})->Args({100, 80})
    ->Args({200, 160})->Args({400, 320})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_BlendOverSharp)->Args({400, 1000})->Args({400, 320})->Unit(benchmark::kMillisecond)
    ->UseManualTime()->Iterations(15);
BENCHMARK(BM_GradientAlternating)->Arg(400)->Iterations(6)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Gradient)->Arg(400)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OpenVDB_Gradient)->Arg(400)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_MeanCurvature)->Arg(400)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OpenVDB_MeanCurvature)->Arg(400)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Rasterize_Sparse)->Arg(50)->Arg(100)->Arg(200)->Arg(400)->Arg(800)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OpenVDB_CreateLevelSetSphere)->Arg(50)->Arg(100)->Arg(200)->Arg(400)->Arg(800)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Rasterize_Dense)->Arg(50)->Arg(100)->Arg(200)->Arg(400)
    ->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1)->Repetitions(3)
    ->ReportAggregatesOnly(true);
BENCHMARK(BM_Rasterize_QuadricSphere)->Arg(100)->Arg(200)->Arg(400)
    ->Unit(benchmark::kMillisecond)->UseRealTime();

int main(int argc, char** argv)
{
    // Heap settings as `ivdb` runs with them (../HugePages.h: the launcher's tunables): restart
    // once with them, so that compute is timed as the commands compute. IVDB_HUGEPAGES=0 or a
    // GLIBC_TUNABLES naming glibc.malloc.hugetlb runs as given.
    if (ivdb::tools::askForHugePages()) execv("/proc/self/exe", argv);
    openvdb::initialize();
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
