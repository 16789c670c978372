// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace ivdb::jobs {

/// @brief How a benchmark builds the level set: the sparse or the dense rasterizer, or OpenVDB's
/// own route (createLevelSetSphere per sphere, csgUnion; for scenes that are a sphere or a union
/// of spheres).
enum class BenchMethod { Sparse, Dense, OpenVdb };

/// @brief "sparse", "dense", "openvdb", in the order of the enum.
const std::vector<std::string>& benchMethodNames();

/// @brief One measurement: a scene at one voxel size by one method.
struct BenchRunOptions
{
    std::string scene;
    BenchMethod method = BenchMethod::Sparse;
    double voxelSize = 0.0;
    int reps = 3;       ///< limits::kReps; a first run under half a second is an extra warm-up
    std::string write;  ///< write the grid here to measure the file's size (then remove it)
};

struct BenchMeasurement
{
    double medianSeconds = 0.0, fastestSeconds = 0.0;
    std::uint64_t peakMemory = 0;   ///< the process's peak resident memory
    std::uint64_t workMemory = 0;   ///< the peak less the memory resident before the runs
    std::uint64_t activeVoxels = 0, gridBytes = 0, fileBytes = 0;
};

/// @brief Run one measurement in this process. Peak memory is the process's: run each
/// measurement in a fresh process for a fair figure (as benchSweep's caller can).
/// @throw ParamError or scene::SceneError for bad options or scenes
BenchMeasurement benchRun(const BenchRunOptions& options);

/// @brief One row of a sweep: a measurement, or why there is none.
struct BenchRow
{
    std::string scene, method, status = "ok"; ///< status: "ok", "skipped: ..." or "failed: ..."
    int resolution = 0;
    double voxelSize = 0.0;
    std::uint64_t denseVoxels = 0; ///< voxels of the dense path's array at this voxel size
    BenchMeasurement measurement;
};

/// @brief What benchSweep() does: sparse against dense sampling (and OpenVDB's route for
/// spheres) over a sweep of resolutions, into DIR/bench.csv, a table and DIR/bench.png.
struct BenchOptions
{
    std::vector<std::string> scenes;  ///< empty: a sphere, two spheres and 1000 spheres
    std::vector<int> resolutions;     ///< voxels across; empty: the default sweep
    std::string out = "bench";        ///< the output folder (created)
    bool quick = false;               ///< a small sweep
    int reps = 3;
    /// Runs one measurement (default: benchRun here). A measurement that throws becomes a
    /// "failed: <what>" row. The CLI runs each in a child process instead.
    std::function<BenchMeasurement(const BenchRunOptions&)> measure;
    /// Told of each row as it is measured (progress), or null.
    std::function<void(const BenchRow&)> onRow;
    /// The plot: `python plotScript CSV PNG` (matplotlib); empty plotScript: no plot.
    std::string plotScript, python = "python3";
};

struct BenchResult
{
    std::vector<BenchRow> rows;
    std::string csvPath, pngPath; ///< pngPath empty without a plot
    std::string table;            ///< a Markdown table of the sweep
    std::string machine;          ///< where it ran (util::MachineInfo::describe())
    std::string plotOutput;       ///< what the plot script printed
    std::string plotError;        ///< why the plot failed (matplotlib missing?), or empty
};

/// @throw ParamError for bad resolutions or reps; openvdb::IoError for an output folder that
/// cannot be written. A failed plot is reported in BenchResult::plotError, not thrown.
BenchResult benchSweep(const BenchOptions& options);

} // namespace ivdb::jobs
