// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/Bench.h>

#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Rasterize.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/Process.h>
#include <ivdb/util/System.h>

#include <openvdb/tools/Composite.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

namespace ivdb::jobs {

namespace fs = std::filesystem;

const std::vector<std::string>& benchMethodNames()
{
    static const std::vector<std::string> names{"sparse", "dense", "openvdb"};
    return names;
}

namespace {

const std::string& nameOf(BenchMethod m) { return benchMethodNames()[size_t(m)]; }

// The spheres of a shape that is a sphere or a union (nested or not) of spheres: what a user of
// OpenVDB's own tools would build with createLevelSetSphere and csgUnion. Empty otherwise.
std::vector<const implicit::Sphere*> unionOfSpheres(const implicit::Implicit& shape)
{
    if (const auto* s = dynamic_cast<const implicit::Sphere*>(&shape)) return {s};
    std::vector<const implicit::Sphere*> out;
    if (const auto* c = dynamic_cast<const implicit::Csg*>(&shape)) {
        if (c->op() != implicit::CsgOp::Union) return {};
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

size_t primitiveCount(const implicit::Implicit& shape)
{
    if (const auto* c = dynamic_cast<const implicit::Csg*>(&shape)) {
        size_t n = 0;
        for (const auto& child : c->children()) n += primitiveCount(*child);
        return n;
    }
    return 1;
}

} // namespace

BenchMeasurement benchRun(const BenchRunOptions& opt)
{
    check(limits::kReps, opt.reps);
    const scene::Scene sc = scene::loadScene(opt.scene);
    raster::RasterSettings settings = sceneSettings(sc, opt.scene, opt.voxelSize);
    settings.sampling = opt.method == BenchMethod::Dense ? raster::Sampling::Dense
                                                         : raster::Sampling::Sparse;
    const auto spheres = unionOfSpheres(*sc.shape);
    if (opt.method == BenchMethod::OpenVdb && spheres.empty()) {
        throw ParamError(param::kMethod, "openvdb needs a sphere or a union of spheres", opt.scene);
    }
    const std::uint64_t before = util::residentMemory();
    std::vector<double> times;
    openvdb::FloatGrid::Ptr grid;
    bool warmedUp = false;
    // A first run under half a second is a warm-up (thread start, first-touch page faults), not
    // counted; a slower one counts, as the warm-up is then a small part of it.
    while (int(times.size()) < opt.reps) {
        grid.reset();
        const auto t0 = std::chrono::steady_clock::now();
        grid = opt.method == BenchMethod::OpenVdb
                   ? openvdbRoute(spheres, settings.voxelSize, settings.halfWidth)
                   : raster::rasterize(sc.shape, settings);
        const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (!warmedUp && times.empty() && t < 0.5) {
            warmedUp = true;
            continue;
        }
        times.push_back(t);
    }
    BenchMeasurement m;
    m.peakMemory = util::peakResidentMemory();
    m.workMemory = m.peakMemory > before ? m.peakMemory - before : 0;
    std::sort(times.begin(), times.end());
    m.medianSeconds = times[times.size() / 2];
    m.fastestSeconds = times.front();
    m.activeVoxels = grid->activeVoxelCount();
    m.gridBytes = grid->memUsage();
    if (!opt.write.empty()) {
        grid->setName("surface");
        io::writeVdb(opt.write, {grid}, openvdb::MetaMap());
        m.fileBytes = fs::file_size(opt.write);
        fs::remove(opt.write);
    }
    return m;
}

namespace {

// Dense sampling evaluates every primitive at every voxel: beyond this many evaluations a run
// takes minutes, so it is skipped and marked (kQuickDenseEvaluations in a quick sweep).
constexpr double kDenseEvaluations = 2e10, kQuickDenseEvaluations = 1e9;
// A dense run that would take more than this share of the available memory is skipped: the
// sweep's own process and the system need the rest, and a run that swaps measures nothing.
constexpr double kDenseMemoryShare = 0.6;

std::string writeScene(const fs::path& dir, const std::string& name, const std::string& json)
{
    const fs::path p = dir / (name + ".json");
    io::writeFileAtomically(p.string(), [&](std::ostream& f) { f << json; });
    return p.string();
}

// The default scenes: a sphere, the two-sphere union and 1000 random spheres in a union (fixed
// seed, so every run measures the same scene), each union twice: with true distances (the
// default distance mode: "_exact") and as min of the distances ("distance": "bound"), the
// values OpenVDB's csgUnion gives its route.
std::vector<std::pair<std::string, std::string>> defaultScenes(const fs::path& dir)
{
    std::vector<std::pair<std::string, std::string>> out;
    out.emplace_back("sphere", writeScene(dir, "sphere",
        R"({"shape": {"type": "sphere", "center": [0, 0, 0], "radius": 1}})"));
    const std::string two = R"("shape": {"type": "union", "children": [)"
        R"({"type": "sphere", "center": [-0.35, 0, 0], "radius": 0.6}, )"
        R"({"type": "sphere", "center": [0.35, 0, 0], "radius": 0.6}]}})";
    std::mt19937 rng(20261124);
    std::uniform_real_distribution<double> pos(-0.9, 0.9), rad(0.04, 0.1);
    std::ostringstream os;
    os << R"("shape": {"type": "union", "children": [)";
    for (int i = 0; i < 1000; ++i) {
        const double x = pos(rng), y = pos(rng), z = pos(rng), r = rad(rng);
        os << (i ? ", " : "") << R"({"type": "sphere", "center": [)" << x << ", " << y << ", " << z
           << R"(], "radius": )" << r << "}";
    }
    os << "]}}";
    for (const auto& [name, shape] : {std::pair<std::string, std::string>{"two_spheres", two},
                                      {"spheres_1000", os.str()}}) {
        out.emplace_back(name, writeScene(dir, name, R"({"distance": "bound", )" + shape));
        out.emplace_back(name + "_exact", writeScene(dir, name + "_exact", "{" + shape));
    }
    return out;
}

std::string csvField(const std::string& s)
{
    if (s.find_first_of(",\"\n") == std::string::npos) return s;
    std::string q = "\"";
    for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
}

void writeCsv(const std::string& path, const std::vector<BenchRow>& rows, int reps)
{
    io::writeFileAtomically(path, [&](std::ostream& f) {
        f << "scene,method,resolution,voxel_size,reps,time_s,time_min_s,peak_memory_bytes,"
             "work_memory_bytes,active_voxels,dense_voxels,grid_bytes,file_bytes,status\n";
        f.precision(9);
        for (const BenchRow& r : rows) {
            const BenchMeasurement& m = r.measurement;
            f << csvField(r.scene) << ',' << r.method << ',' << r.resolution << ',' << r.voxelSize
              << ',' << reps << ',' << m.medianSeconds << ',' << m.fastestSeconds << ','
              << m.peakMemory << ',' << m.workMemory << ',' << m.activeVoxels << ','
              << r.denseVoxels << ',' << m.gridBytes << ',' << m.fileBytes << ','
              << csvField(r.status) << '\n';
        }
    });
}

std::string ratio(double a, double b)
{
    return util::formatNumber(std::round(a / b * 10) / 10) + "x";
}

std::string benchTable(const std::vector<BenchRow>& rows,
                       const std::vector<std::pair<std::string, std::string>>& scenes,
                       const std::vector<int>& resolutions)
{
    auto find = [&](const std::string& scene, const std::string& method, int res) -> const BenchRow* {
        for (const BenchRow& r : rows) {
            if (r.scene == scene && r.method == method && r.resolution == res && r.status == "ok") return &r;
        }
        return nullptr;
    };
    auto cell = [](const BenchRow* r) {
        return r ? util::formatNumber(std::round(r->measurement.medianSeconds * 1e4) / 10) + " ms, " +
                       util::formatBytes(double(r->measurement.workMemory))
                 : std::string("-");
    };
    std::ostringstream os;
    os << "| scene | voxels across | active voxels | sparse | dense | openvdb | dense / sparse time "
          "| dense / sparse memory |\n|---|---|---|---|---|---|---|---|\n";
    for (const auto& [name, path] : scenes) {
        for (int res : resolutions) {
            const BenchRow* s = find(name, "sparse", res);
            const BenchRow* d = find(name, "dense", res);
            const BenchRow* o = find(name, "openvdb", res);
            os << "| " << name << " | " << res << " | " << (s ? s->measurement.activeVoxels : 0)
               << " | " << cell(s) << " | " << cell(d) << " | " << cell(o) << " | "
               << (s && d ? ratio(d->measurement.medianSeconds, s->measurement.medianSeconds) : "-")
               << " | "
               << (s && d && s->measurement.workMemory
                       ? ratio(double(d->measurement.workMemory), double(s->measurement.workMemory))
                       : "-")
               << " |\n";
        }
    }
    return os.str();
}

/// Why a dense run is skipped ("" when it runs).
std::string denseSkip(double denseBytes, std::uint64_t denseVoxels, size_t primitives, bool quick)
{
    const double available = double(util::availableMemory());
    if (available > 0.0 && denseBytes > kDenseMemoryShare * available) {
        return "skipped: needs " + util::formatBytes(denseBytes) + " of " +
               util::formatBytes(available) + " available";
    }
    const double evaluations = double(denseVoxels) * double(primitives);
    if (evaluations > (quick ? kQuickDenseEvaluations : kDenseEvaluations)) {
        return "skipped: " + util::formatNumber(evaluations) + " primitive evaluations";
    }
    return "";
}

/// The rows of one scene at one resolution: each method measured (or skipped).
void measureScene(const BenchOptions& opt, const std::string& name, const std::string& path,
                  const scene::Scene& sc, int res, double across, const fs::path& out,
                  std::vector<BenchRow>& rows)
{
    const bool spheres = !unionOfSpheres(*sc.shape).empty();
    const double dx = across / res;
    raster::RasterSettings s = sceneSettings(sc, path, dx);
    s.sampling = raster::Sampling::Dense;
    const double denseBytes = double(raster::denseMemoryEstimate(sc.shape, s));
    std::vector<BenchMethod> methods{BenchMethod::Sparse, BenchMethod::Dense};
    if (spheres) methods.push_back(BenchMethod::OpenVdb);
    for (BenchMethod method : methods) {
        BenchRow row;
        row.scene = name;
        row.method = nameOf(method);
        row.resolution = res;
        row.voxelSize = dx;
        row.denseVoxels = std::uint64_t(denseBytes / sizeof(float));
        if (method == BenchMethod::Dense) {
            const std::string skip = denseSkip(denseBytes, row.denseVoxels,
                                               primitiveCount(*sc.shape), opt.quick);
            if (!skip.empty()) row.status = skip;
        }
        if (row.status == "ok") {
            BenchRunOptions run;
            run.scene = path;
            run.method = method;
            run.voxelSize = dx;
            run.reps = opt.reps;
            run.write = (out / ("." + name + "_" + row.method + ".vdb")).string();
            try {
                row.measurement = opt.measure ? opt.measure(run) : benchRun(run);
            } catch (const std::exception& e) {
                row.status = "failed: " + util::errorText(e);
                std::error_code ec;
                fs::remove(run.write, ec);
            }
        }
        if (opt.onRow) opt.onRow(row);
        rows.push_back(row);
    }
}

} // namespace

BenchResult benchSweep(const BenchOptions& opt)
{
    check(limits::kReps, opt.reps);
    std::vector<int> resolutions = opt.resolutions;
    if (resolutions.empty()) {
        resolutions = opt.quick ? std::vector<int>{32, 64, 128}
                                : std::vector<int>{64, 100, 160, 256, 400, 640, 800};
    }
    for (int r : resolutions) check(limits::kResolution, r);
    const fs::path out(opt.out);
    std::error_code ec;
    fs::create_directories(opt.scenes.empty() ? out / "scenes" : out, ec);
    if (ec) OPENVDB_THROW(openvdb::IoError, opt.out + ": cannot create the folder: " + ec.message());
    BenchResult result;
    result.csvPath = (out / "bench.csv").string();
    if (!opt.plotScript.empty()) result.pngPath = (out / "bench.png").string();
    io::checkOutputPath(result.csvPath);
    if (!result.pngPath.empty()) io::checkOutputPath(result.pngPath);

    std::vector<std::pair<std::string, std::string>> scenes;
    if (opt.scenes.empty()) scenes = defaultScenes(out / "scenes");
    for (const auto& s : opt.scenes) scenes.emplace_back(fs::path(s).stem().string(), s);

    for (const auto& [name, path] : scenes) {
        const scene::Scene sc = scene::loadScene(path);
        const implicit::BBoxd box = sc.bounds ? *sc.bounds : sc.shape->boundingBox();
        const implicit::Vec3d ext = box.max() - box.min();
        const double across = std::max({ext.x(), ext.y(), ext.z()});
        if (!std::isfinite(across) || !(across > 0.0)) {
            throw scene::SceneError(path + ": the shape has no finite bounding box; give the "
                                    "scene \"bounds\"");
        }
        for (int res : resolutions) measureScene(opt, name, path, sc, res, across, out, result.rows);
    }
    writeCsv(result.csvPath, result.rows, opt.reps);
    result.table = benchTable(result.rows, scenes, resolutions);
    result.machine = util::machineInfo().describe();
    if (!result.pngPath.empty()) {
        const util::ProcessResult plot =
            util::runProcess({opt.python, opt.plotScript, result.csvPath, result.pngPath});
        if (plot.status != 0) {
            result.plotError = "plotting " + result.pngPath + " failed (" + opt.plotScript +
                               "): " + plot.err + "The CSV is written";
        }
        result.plotOutput = plot.out;
    }
    return result;
}

} // namespace ivdb::jobs
