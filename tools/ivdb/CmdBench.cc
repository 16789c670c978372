// SPDX-License-Identifier: Apache-2.0
// ivdb bench: sparse against dense sampling (and OpenVDB's own route) over a sweep of
// resolutions; a CSV, a plot and a table (jobs::benchSweep).
//
// Every measurement runs in a child process (`ivdb bench-run`, hidden), so each gets a fresh
// heap and its own peak memory, and a crash or a refusal in one cannot take the sweep down.
#include "Cli.h"

#include <ivdb/jobs/Bench.h>
#include <ivdb/util/Process.h>
#include <ivdb/util/System.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>

namespace ivdb::cli {

namespace {

struct BenchRunArgs
{
    jobs::BenchRunOptions job;
    std::string method;
};

// One line for the parent: median and fastest time, peak and work memory, voxels, bytes.
int runBenchRun(BenchRunArgs& a)
{
    a.job.method = enumOf<jobs::BenchMethod>(a.method, jobs::benchMethodNames());
    const jobs::BenchMeasurement m = jobs::benchRun(a.job);
    std::printf("%.6f %.6f %llu %llu %llu %llu %llu\n", m.medianSeconds, m.fastestSeconds,
                (unsigned long long)m.peakMemory, (unsigned long long)m.workMemory,
                (unsigned long long)m.activeVoxels, (unsigned long long)m.gridBytes,
                (unsigned long long)m.fileBytes);
    return 0;
}

// The parent's side of bench-run: the measurement in a child process.
jobs::BenchMeasurement measureInChild(const std::string& self, const jobs::BenchRunOptions& run)
{
    std::ostringstream dx;
    dx.precision(17);
    dx << run.voxelSize;
    const util::ProcessResult p = util::runProcess(
        {self, "bench-run", run.scene, "--method", jobs::benchMethodNames()[size_t(run.method)],
         "--voxel-size", dx.str(), "--reps", std::to_string(run.reps), "--write", run.write});
    jobs::BenchMeasurement m;
    unsigned long long peak, work, active, gridBytes, fileBytes;
    if (p.status != 0 || std::sscanf(p.out.c_str(), "%lf %lf %llu %llu %llu %llu %llu",
                                     &m.medianSeconds, &m.fastestSeconds, &peak, &work, &active,
                                     &gridBytes, &fileBytes) != 7) {
        if (p.status < 0) throw std::runtime_error("signal " + std::to_string(-p.status));
        std::string why = p.err.empty() ? "no output" : p.err;
        while (!why.empty() && why.back() == '\n') why.pop_back();
        // The child's own "ivdb: error: " prefix would be repeated inside the row's status.
        const std::string prefix = "ivdb: error: ";
        if (why.rfind(prefix, 0) == 0) why.erase(0, prefix.size());
        throw std::runtime_error(why);
    }
    m.peakMemory = peak;
    m.workMemory = work;
    m.activeVoxels = active;
    m.gridBytes = gridBytes;
    m.fileBytes = fileBytes;
    return m;
}

// The plot script: IVDB_PLOT_SCRIPT, else the installed copy beside the binary
// (PREFIX/share/ivdb), else the source tree's.
std::string plotScript(const std::string& self)
{
    if (const char* env = std::getenv("IVDB_PLOT_SCRIPT")) return env;
    const std::filesystem::path installed =
        std::filesystem::path(self).parent_path().parent_path() / "share" / "ivdb" / "plot_bench.py";
    std::error_code ec;
    return std::filesystem::exists(installed, ec) ? installed.string() : IVDB_PLOT_SCRIPT;
}

std::string python()
{
    if (const char* env = std::getenv("IVDB_PYTHON")) return env;
    return std::filesystem::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
}

struct BenchArgs
{
    jobs::BenchOptions job;
    bool noPlot = false;
};

int runBench(BenchArgs& a)
{
    const std::string self = util::executablePath();
    a.job.measure = [self](const jobs::BenchRunOptions& run) { return measureInChild(self, run); };
    a.job.onRow = [](const jobs::BenchRow& row) {
        if (row.status == "ok") {
            std::fprintf(stderr, "  %-14s %-8s %5d voxels across: %8.3f s, %s\n", row.scene.c_str(),
                         row.method.c_str(), row.resolution, row.measurement.medianSeconds,
                         util::formatBytes(double(row.measurement.workMemory)).c_str());
        } else {
            std::fprintf(stderr, "  %-14s %-8s %5d voxels across: %s\n", row.scene.c_str(),
                         row.method.c_str(), row.resolution, row.status.c_str());
        }
    };
    if (!a.noPlot) {
        a.job.plotScript = plotScript(self);
        a.job.python = python();
    }
    const jobs::BenchResult r = jobs::benchSweep(a.job);
    std::printf("Machine: %s.\n\n%s\ncsv: %s\n", r.machine.c_str(), r.table.c_str(),
                r.csvPath.c_str());
    if (!r.plotError.empty()) {
        throw std::runtime_error(r.plotError + ". Install python3-matplotlib (./scripts/deps.sh), "
                                 "or pass --no-plot");
    }
    if (!r.pngPath.empty()) {
        std::fputs(r.plotOutput.c_str(), stdout);
        std::printf("plot: %s\n", r.pngPath.c_str());
    }
    return 0;
}

} // namespace

void addBench(CLI::App& app, Action& action)
{
    auto a = std::make_shared<BenchArgs>();
    Command cmd(app, "bench",
        "Sparse vs dense sampling (and OpenVDB's createLevelSetSphere + csgUnion for sphere "
        "scenes) over a sweep of resolutions: DIR/bench.csv, DIR/bench.png and a table");
    cmd.add("--scene", a->job.scenes,
            "Scene file (repeat for more); default: a sphere, a two-sphere union and 1000 random "
            "spheres in a union, each union with true distances (NAME_exact) and as min of the "
            "distances (\"distance\": \"bound\")");
    cmd.add("--resolutions", a->job.resolutions,
            "Voxels across the shape's largest side, comma-separated; default "
            "64,100,160,256,400,640,800 (32,64,128 with --quick)", &param::kResolutions)
        ->delimiter(',');
    cmd.add("--out", a->job.out, "Output folder (created)")->capture_default_str();
    cmd.add("--reps", a->job.reps, "Runs per measurement (the median is reported)", &param::kReps)
        ->capture_default_str();
    cmd.flag("--quick", a->job.quick, "A small sweep that finishes in well under a minute");
    cmd.flag("--no-plot", a->noPlot, "Write the CSV and the table only");
    cmd.onRun(action, [a]() { return runBench(*a); });

    auto run = std::make_shared<BenchRunArgs>();
    Command child(app, "bench-run", "");
    child.app().group(""); // hidden: one measurement, run by `ivdb bench` in a child process
    child.add("scene", run->job.scene)->required();
    child.add("--method", run->method)->check(CLI::IsMember(jobs::benchMethodNames()))->required();
    child.add("--voxel-size", run->job.voxelSize)->required();
    child.add("--reps", run->job.reps);
    child.add("--write", run->job.write);
    child.onRun(action, [run]() { return runBenchRun(*run); });
}

} // namespace ivdb::cli
