// ivdb bench: sparse against dense sampling (and OpenVDB's own route) over a sweep of
// resolutions; a CSV, a plot and a table.
//
// Every measurement runs in a child process (`ivdb bench-run`, hidden), so each gets a fresh
// heap and its own peak memory, and a crash or a refusal in one cannot take the sweep down.
#include "Cli.h"

#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/util/System.h>

#include <openvdb/tools/Composite.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <sstream>

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace ivdb::cli {

namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------------
// The measurement, in the child process.

struct RunOptions
{
    std::string scene, method, write;
    double voxelSize = 0.0;
    int reps = 3;
};

std::uint64_t residentMemory() // VmRSS, bytes
{
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line)) {
        if (line.rfind("VmRSS:", 0) == 0) return std::stoull(line.substr(6)) * 1024;
    }
    return 0;
}

// The spheres of a shape that is a sphere or a union (nested or not) of spheres: what a user of
// OpenVDB's own tools would build with createLevelSetSphere and csgUnion. Empty otherwise.
std::vector<const implicit::Sphere*> unionOfSpheres(const implicit::Implicit& shape)
{
    if (const auto* s = dynamic_cast<const implicit::Sphere*>(&shape)) return {s};
    std::vector<const implicit::Sphere*> out;
    if (const auto* c = dynamic_cast<const implicit::Csg*>(&shape)) {
        if (c->op() != implicit::Csg::Op::Union) return {};
        for (const auto& child : c->children()) {
            const auto more = unionOfSpheres(*child);
            if (more.empty()) return {};
            out.insert(out.end(), more.begin(), more.end());
        }
    }
    return out;
}

openvdb::FloatGrid::Ptr openvdbRoute(const std::vector<const implicit::Sphere*>& spheres,
                                     double voxelSize, double halfWidth)
{
    openvdb::FloatGrid::Ptr result;
    for (const implicit::Sphere* s : spheres) {
        auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            float(s->radius()), openvdb::Vec3f(s->center()), float(voxelSize), float(halfWidth));
        if (!result) result = g;
        else openvdb::tools::csgUnion(*result, *g);
    }
    return result;
}

int runBenchRun(const RunOptions& opt)
{
    const scene::Scene sc = scene::loadScene(opt.scene);
    raster::RasterSettings settings = sceneSettings(sc, opt.scene, opt.voxelSize, std::nullopt);
    settings.sampling = opt.method == "dense" ? raster::Sampling::Dense : raster::Sampling::Sparse;
    const auto spheres = unionOfSpheres(*sc.shape);
    if (opt.method == "openvdb" && spheres.empty()) {
        throw std::runtime_error(opt.scene + ": the openvdb method needs a sphere or a union of "
                                 "spheres");
    }
    const std::uint64_t before = residentMemory();
    std::vector<double> times;
    openvdb::FloatGrid::Ptr grid;
    // A first run under half a second is a warm-up (thread start, first-touch page faults), not
    // counted; a slower one counts, as the warm-up is then a small part of it.
    for (int r = 0; r < opt.reps; ++r) {
        grid.reset();
        const auto t0 = std::chrono::steady_clock::now();
        grid = opt.method == "openvdb" ? openvdbRoute(spheres, settings.voxelSize, settings.halfWidth)
                                       : raster::rasterize(sc.shape, settings);
        const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (r == 0 && times.empty() && t < 0.5) {
            times.push_back(-1.0); // the warm-up: run once more
            --r;
            continue;
        }
        times.push_back(t);
    }
    times.erase(std::remove(times.begin(), times.end(), -1.0), times.end());
    const std::uint64_t peak = util::peakResidentMemory();
    std::sort(times.begin(), times.end());
    std::uint64_t fileBytes = 0;
    if (!opt.write.empty()) {
        grid->setName("surface");
        io::writeVdb(opt.write, {grid}, openvdb::MetaMap());
        fileBytes = fs::file_size(opt.write);
        fs::remove(opt.write);
    }
    // One line for the parent: median and fastest time, peak and work memory, voxels, bytes.
    std::printf("%.6f %.6f %llu %llu %llu %llu %llu\n", times[times.size() / 2], times.front(),
                (unsigned long long)peak, (unsigned long long)(peak > before ? peak - before : 0),
                (unsigned long long)grid->activeVoxelCount(),
                (unsigned long long)grid->memUsage(), (unsigned long long)fileBytes);
    return 0;
}

// ---------------------------------------------------------------------------------------------
// The sweep, in the parent.

struct BenchOptions
{
    std::vector<std::string> scenes;
    std::vector<int> resolutions;
    std::string out = "bench";
    bool quick = false, noPlot = false;
    int reps = 3;
};

struct Row
{
    std::string scene, method, status = "ok";
    int resolution = 0;
    double voxelSize = 0.0, time = 0.0, timeMin = 0.0;
    std::uint64_t peak = 0, work = 0, active = 0, denseVoxels = 0, gridBytes = 0, fileBytes = 0;
};

// Dense sampling evaluates every primitive at every voxel: beyond this many evaluations a run
// takes minutes, so it is skipped and marked (1e9 with --quick).
constexpr double kDenseEvaluationBudget = 2e10;

std::string selfPath()
{
    std::error_code ec;
    const fs::path p = fs::read_symlink("/proc/self/exe", ec);
    if (ec) throw std::runtime_error("cannot find the ivdb binary (/proc/self/exe): " + ec.message());
    return p.string();
}

// Run @a args, capturing stdout (and stderr into @a err). Returns the exit status (-signal when
// killed by one).
int spawnCapture(const std::vector<std::string>& args, std::string& out, std::string& err)
{
    int outPipe[2], errPipe[2];
    if (pipe(outPipe) != 0 || pipe(errPipe) != 0) throw std::runtime_error("pipe failed");
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, outPipe[1], 1);
    posix_spawn_file_actions_adddup2(&actions, errPipe[1], 2);
    posix_spawn_file_actions_addclose(&actions, outPipe[0]);
    posix_spawn_file_actions_addclose(&actions, errPipe[0]);
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    pid_t pid = 0;
    const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    close(outPipe[1]);
    close(errPipe[1]);
    if (rc != 0) {
        close(outPipe[0]);
        close(errPipe[0]);
        throw std::runtime_error("cannot run " + args[0] + ": " + std::strerror(rc));
    }
    // The child writes one short line to stdout; stderr may be longer: read both to the end.
    auto drain = [](int fd, std::string& s) {
        char buf[4096];
        ssize_t n;
        while ((n = read(fd, buf, sizeof(buf))) > 0) s.append(buf, size_t(n));
        close(fd);
    };
    drain(errPipe[0], err);
    drain(outPipe[0], out);
    int status = 0;
    waitpid(pid, &status, 0);
    if (WIFSIGNALED(status)) return -WTERMSIG(status);
    return WEXITSTATUS(status);
}

std::string writeScene(const fs::path& dir, const std::string& name, const std::string& json)
{
    const fs::path p = dir / (name + ".json");
    std::ofstream f(p);
    f << json;
    if (!f) throw std::runtime_error(p.string() + ": cannot write");
    return p.string();
}

// The default scenes: a sphere, the seed's two-sphere union (figure 1) and 1000 random spheres
// in a union (fixed seed, so every run measures the same scene). The unions store min of the
// distances ("distance": "bound"), the values OpenVDB's csgUnion gives the openvdb route.
std::vector<std::pair<std::string, std::string>> defaultScenes(const fs::path& dir)
{
    std::vector<std::pair<std::string, std::string>> out;
    out.emplace_back("sphere", writeScene(dir, "sphere",
        R"({"shape": {"type": "sphere", "center": [0, 0, 0], "radius": 1}})"));
    out.emplace_back("two_spheres", writeScene(dir, "two_spheres",
        R"({"distance": "bound", "shape": {"type": "union", "children": [)"
        R"({"type": "sphere", "center": [-0.35, 0, 0], "radius": 0.6}, )"
        R"({"type": "sphere", "center": [0.35, 0, 0], "radius": 0.6}]}})"));
    std::mt19937 rng(20261124);
    std::uniform_real_distribution<double> pos(-0.9, 0.9), rad(0.04, 0.1);
    std::ostringstream os;
    os << R"({"distance": "bound", "shape": {"type": "union", "children": [)";
    for (int i = 0; i < 1000; ++i) {
        const double x = pos(rng), y = pos(rng), z = pos(rng), r = rad(rng);
        os << (i ? ", " : "") << R"({"type": "sphere", "center": [)" << x << ", " << y << ", " << z
           << R"(], "radius": )" << r << "}";
    }
    os << "]}}";
    out.emplace_back("spheres_1000", writeScene(dir, "spheres_1000", os.str()));
    return out;
}

size_t primitiveCount(const implicit::Implicit& shape)
{
    if (const auto* c = dynamic_cast<const implicit::Csg*>(&shape)) {
        size_t n = 0;
        for (const auto& child : c->children()) n += primitiveCount(*child);
        return n;
    }
    return 1;
}

std::string plotScript()
{
    if (const char* env = std::getenv("IVDB_PLOT_SCRIPT")) return env;
    return IVDB_PLOT_SCRIPT;
}

std::string python()
{
    if (const char* env = std::getenv("IVDB_PYTHON")) return env;
    return fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
}

std::string csvField(const std::string& s)
{
    if (s.find_first_of(",\"\n") == std::string::npos) return s;
    std::string q = "\"";
    for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
}

int runBench(const BenchOptions& opt)
{
    if (opt.reps < 1 || opt.reps > 100) {
        throw std::runtime_error("--reps must be in [1, 100], got " + std::to_string(opt.reps));
    }
    std::vector<int> resolutions = opt.resolutions;
    if (resolutions.empty()) {
        resolutions = opt.quick ? std::vector<int>{32, 64, 128}
                                : std::vector<int>{64, 100, 160, 256, 400, 640, 800};
    }
    for (int r : resolutions) {
        if (r < 8 || r > 4096) {
            throw std::runtime_error("--resolutions: each must be in [8, 4096] voxels across, got " +
                                     std::to_string(r));
        }
    }
    const fs::path out(opt.out);
    std::error_code ec;
    fs::create_directories(opt.scenes.empty() ? out / "scenes" : out, ec);
    if (ec) throw std::runtime_error(opt.out + ": cannot create the folder: " + ec.message());
    const std::string csvPath = (out / "bench.csv").string(), pngPath = (out / "bench.png").string();
    io::checkOutputPath(csvPath);
    if (!opt.noPlot) io::checkOutputPath(pngPath);

    std::vector<std::pair<std::string, std::string>> scenes;
    if (opt.scenes.empty()) scenes = defaultScenes(out / "scenes");
    for (const auto& s : opt.scenes) scenes.emplace_back(fs::path(s).stem().string(), s);

    const std::string self = selfPath();
    const double available = double(util::availableMemory());
    std::vector<Row> rows;
    for (const auto& [name, path] : scenes) {
        const scene::Scene sc = scene::loadScene(path);
        const bool spheres = !unionOfSpheres(*sc.shape).empty();
        const size_t primitives = primitiveCount(*sc.shape);
        const implicit::BBoxd box = sc.bounds ? *sc.bounds : sc.shape->boundingBox();
        const implicit::Vec3d ext = box.max() - box.min();
        const double across = std::max({ext.x(), ext.y(), ext.z()});
        if (!std::isfinite(across) || !(across > 0.0)) {
            throw std::runtime_error(path + ": the shape has no finite bounding box; give the "
                                     "scene \"bounds\"");
        }
        for (int res : resolutions) {
            const double dx = across / res;
            raster::RasterSettings s = sceneSettings(sc, path, dx, std::nullopt);
            s.sampling = raster::Sampling::Dense;
            const double denseBytes = double(raster::denseMemoryEstimate(sc.shape, s));
            const std::uint64_t denseVoxels = std::uint64_t(denseBytes / sizeof(float));
            std::vector<std::string> methods{"sparse", "dense"};
            if (spheres) methods.push_back("openvdb");
            for (const std::string& method : methods) {
                Row row;
                row.scene = name;
                row.method = method;
                row.resolution = res;
                row.voxelSize = dx;
                row.denseVoxels = denseVoxels;
                if (method == "dense" && available > 0.0 && denseBytes > 0.6 * available) {
                    row.status = "skipped: needs " + util::formatBytes(denseBytes) + " of " +
                                 util::formatBytes(available) + " available";
                } else if (method == "dense" && double(denseVoxels) * double(primitives) >
                                                    (opt.quick ? 1e9 : kDenseEvaluationBudget)) {
                    row.status = "skipped: " + util::formatNumber(double(denseVoxels) * primitives) +
                                 " primitive evaluations";
                }
                if (row.status == "ok") {
                    std::ostringstream dxText;
                    dxText.precision(17);
                    dxText << dx;
                    std::string sout, serr;
                    const std::string vdb = (out / ("." + name + "_" + method + ".vdb")).string();
                    const int rc = spawnCapture({self, "bench-run", path, "--method", method,
                                                 "--voxel-size", dxText.str(), "--reps",
                                                 std::to_string(opt.reps), "--write", vdb},
                                                sout, serr);
                    unsigned long long peak, work, active, gridBytes, fileBytes;
                    if (rc != 0 || std::sscanf(sout.c_str(), "%lf %lf %llu %llu %llu %llu %llu",
                                               &row.time, &row.timeMin, &peak, &work, &active,
                                               &gridBytes, &fileBytes) != 7) {
                        std::string why = serr.empty() ? "no output" : serr;
                        while (!why.empty() && why.back() == '\n') why.pop_back();
                        row.status = rc < 0 ? "failed: signal " + std::to_string(-rc)
                                            : "failed: " + why;
                        fs::remove(vdb, ec);
                    } else {
                        row.peak = peak;
                        row.work = work;
                        row.active = active;
                        row.gridBytes = gridBytes;
                        row.fileBytes = fileBytes;
                    }
                }
                if (row.status == "ok") {
                    std::fprintf(stderr, "  %-14s %-8s %5d voxels across: %8.3f s, %s\n",
                                 name.c_str(), method.c_str(), res, row.time,
                                 util::formatBytes(double(row.work)).c_str());
                } else {
                    std::fprintf(stderr, "  %-14s %-8s %5d voxels across: %s\n", name.c_str(),
                                 method.c_str(), res, row.status.c_str());
                }
                rows.push_back(row);
            }
        }
    }

    // The CSV, atomically.
    io::writeFileAtomically(csvPath, [&](std::ostream& f) {
        f << "scene,method,resolution,voxel_size,reps,time_s,time_min_s,peak_memory_bytes,"
             "work_memory_bytes,active_voxels,dense_voxels,grid_bytes,file_bytes,status\n";
        f.precision(9);
        for (const Row& r : rows) {
            f << csvField(r.scene) << ',' << r.method << ',' << r.resolution << ',' << r.voxelSize
              << ',' << opt.reps << ',' << r.time << ',' << r.timeMin << ',' << r.peak << ','
              << r.work << ',' << r.active << ',' << r.denseVoxels << ',' << r.gridBytes << ','
              << r.fileBytes << ',' << csvField(r.status) << '\n';
        }
    });

    // The table.
    auto find = [&](const std::string& scene, const std::string& method, int res) -> const Row* {
        for (const Row& r : rows) {
            if (r.scene == scene && r.method == method && r.resolution == res && r.status == "ok") return &r;
        }
        return nullptr;
    };
    std::printf("| scene | voxels across | active voxels | sparse | dense | openvdb | dense / sparse time "
                "| dense / sparse memory |\n|---|---|---|---|---|---|---|---|\n");
    for (const auto& [name, path] : scenes) {
        for (int res : resolutions) {
            const Row* s = find(name, "sparse", res);
            const Row* d = find(name, "dense", res);
            const Row* o = find(name, "openvdb", res);
            auto cell = [](const Row* r) {
                return r ? util::formatNumber(std::round(r->time * 1e4) / 10) + " ms, " +
                               util::formatBytes(double(r->work))
                         : std::string("-");
            };
            std::printf("| %s | %d | %llu | %s | %s | %s | %s | %s |\n", name.c_str(), res,
                        s ? (unsigned long long)s->active : 0ull, cell(s).c_str(), cell(d).c_str(),
                        cell(o).c_str(),
                        s && d ? (util::formatNumber(std::round(d->time / s->time * 10) / 10) + "x").c_str() : "-",
                        s && d && s->work ? (util::formatNumber(std::round(double(d->work) / double(s->work) * 10) / 10) + "x").c_str() : "-");
        }
    }
    std::printf("\ncsv: %s\n", csvPath.c_str());

    if (!opt.noPlot) {
        std::string sout, serr;
        const int rc = spawnCapture({python(), plotScript(), csvPath, pngPath}, sout, serr);
        if (rc != 0) {
            throw std::runtime_error("plotting " + pngPath + " failed (" + plotScript() + "): " +
                                     serr + "The CSV is written. Install python3-matplotlib "
                                     "(./scripts/deps.sh), or pass --no-plot");
        }
        std::fputs(sout.c_str(), stdout);
        std::printf("plot: %s\n", pngPath.c_str());
    }
    return 0;
}

} // namespace

void addBench(CLI::App& app, Action& action)
{
    auto opt = std::make_shared<BenchOptions>();
    CLI::App* cmd = app.add_subcommand("bench",
        "Sparse vs dense sampling (and OpenVDB's createLevelSetSphere + csgUnion for sphere "
        "scenes) over a sweep of resolutions: DIR/bench.csv, DIR/bench.png and a table");
    cmd->add_option("--scene", opt->scenes,
                    "Scene file (repeat for more); default: a sphere, the seed's two-sphere union "
                    "and 1000 random spheres in a union");
    cmd->add_option("--resolutions", opt->resolutions,
                    "Voxels across the shape's largest side, comma-separated; default "
                    "64,100,160,256,400,640,800 (32,64,128 with --quick)")
        ->delimiter(',');
    cmd->add_option("--out", opt->out, "Output folder (created)")->capture_default_str();
    cmd->add_option("--reps", opt->reps, "Runs per measurement (the median is reported)")
        ->capture_default_str();
    cmd->add_flag("--quick", opt->quick, "A small sweep that finishes in well under a minute");
    cmd->add_flag("--no-plot", opt->noPlot, "Write the CSV and the table only");
    cmd->callback([&action, opt]() { action = [opt]() { return runBench(*opt); }; });

    auto run = std::make_shared<RunOptions>();
    CLI::App* child = app.add_subcommand("bench-run", "");
    child->group(""); // hidden: one measurement, run by `ivdb bench` in a child process
    child->add_option("scene", run->scene)->required();
    child->add_option("--method", run->method)->check(CLI::IsMember({"sparse", "dense", "openvdb"}))
        ->required();
    child->add_option("--voxel-size", run->voxelSize)->required();
    child->add_option("--reps", run->reps);
    child->add_option("--write", run->write);
    child->callback([&action, run]() { action = [run]() { return runBenchRun(*run); }; });
}

} // namespace ivdb::cli
