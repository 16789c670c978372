// SPDX-License-Identifier: Apache-2.0
// .vdb writing and reading: ivdb's parallel writer and reader beside OpenVDB's io::File, on the
// same level-set sphere, in the same run. range(0): the radius in voxels (400: 12.06 M active
// voxels, a 54 MB file); range(1): threads for ivdb's side. The files stay in the page cache, so
// this measures the formats' work (compression, parsing, allocation), not the disk.
#include <ivdb/io/VdbFile.h>

#include <openvdb/io/File.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tree/LeafManager.h>

#include <benchmark/benchmark.h>

#include <tbb/global_control.h>

#include <cstdio>
#include <fstream>
#include <map>
#include <string>

#include <unistd.h>

namespace {

namespace io = ivdb::io;

openvdb::FloatGrid::Ptr sphere(int radiusVoxels)
{
    static std::map<int, openvdb::FloatGrid::Ptr> cache;
    auto& g = cache[radiusVoxels];
    if (!g) {
        g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            1.0f, openvdb::Vec3f(0.0f), 1.0f / float(radiusVoxels), 3.0f);
        g->setName("surface");
    }
    return g;
}

std::string tempPath(const char* what)
{
    return "/tmp/ivdb_bench_" + std::to_string(::getpid()) + "_" + what + ".vdb";
}

void setCounters(benchmark::State& state, const std::string& path)
{
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    state.counters["file_MB"] = double(in.tellg()) / 1e6;
}

/// ivdb's writer, to a stream (no fsync, as io::File::write).
void BM_WriteVdb(benchmark::State& state)
{
    auto g = sphere(int(state.range(0)));
    const std::string path = tempPath("write");
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism,
                                std::size_t(state.range(1)));
    for (auto _ : state) {
        std::ofstream os(path, std::ios::binary | std::ios::trunc);
        io::writeVdbStream(os, {g}, openvdb::MetaMap(), io::WriteOptions());
    }
    setCounters(state, path);
    std::remove(path.c_str());
}

/// ivdb's writer as the commands call it: a temporary file, fsync, rename.
void BM_WriteVdb_Atomic(benchmark::State& state)
{
    auto g = sphere(int(state.range(0)));
    const std::string path = tempPath("atomic");
    for (auto _ : state) io::writeVdb(path, {g});
    std::remove(path.c_str());
}

void BM_OpenVDB_FileWrite(benchmark::State& state)
{
    auto g = sphere(int(state.range(0)));
    const std::string path = tempPath("openvdb");
    for (auto _ : state) {
        openvdb::io::File f(path);
        f.write({g});
        f.close();
    }
    setCounters(state, path);
    std::remove(path.c_str());
}

/// The sphere as io::File writes it, once per process.
const std::string& sphereFile(int radiusVoxels)
{
    static std::map<int, std::string> files;
    std::string& path = files[radiusVoxels];
    if (path.empty()) {
        path = tempPath(("read" + std::to_string(radiusVoxels)).c_str());
        openvdb::io::File f(path);
        f.write({sphere(radiusVoxels)});
        f.close();
        std::atexit([] {
            for (const auto& [r, p] : files) std::remove(p.c_str());
        });
    }
    return path;
}

/// ivdb's reader: the layout check, then every leaf decompressed in parallel.
void BM_ReadVdb(benchmark::State& state)
{
    const std::string& path = sphereFile(int(state.range(0)));
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism,
                                std::size_t(state.range(1)));
    for (auto _ : state) {
        openvdb::GridPtrVec grids = io::readVdb(path);
        benchmark::DoNotOptimize(grids.front().get());
    }
}

/// io::File's full load (no delayed loading): every leaf read in turn.
void BM_OpenVDB_FileRead(benchmark::State& state)
{
    const std::string& path = sphereFile(int(state.range(0)));
    for (auto _ : state) {
        openvdb::io::File f(path);
        f.open(/*delayLoad=*/false);
        openvdb::GridPtrVec grids = *f.getGrids();
        f.close();
        benchmark::DoNotOptimize(grids.front().get());
    }
}

/// io::File with delayed loading, then every leaf touched on all threads: what reading through
/// OpenVDB and then running a parallel operator costs.
void BM_OpenVDB_FileReadDelayed(benchmark::State& state)
{
    const std::string& path = sphereFile(int(state.range(0)));
    for (auto _ : state) {
        openvdb::io::File f(path);
        f.open(/*delayLoad=*/true);
        auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(f.getGrids()->front());
        f.close();
        openvdb::tree::LeafManager<openvdb::FloatTree> leaves(grid->tree());
        leaves.foreach([](openvdb::FloatTree::LeafNodeType& leaf, std::size_t) {
            benchmark::DoNotOptimize(leaf.buffer().data());
        });
    }
}

} // namespace

BENCHMARK(BM_WriteVdb)->Args({400, 1})->Args({400, 2})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OpenVDB_FileWrite)->Arg(400)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_WriteVdb_Atomic)->Arg(400)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ReadVdb)->Args({400, 1})->Args({400, 2})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OpenVDB_FileRead)->Arg(400)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_OpenVDB_FileReadDelayed)->Arg(400)->Unit(benchmark::kMillisecond)->UseRealTime();
