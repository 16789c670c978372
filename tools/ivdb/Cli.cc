#include "Cli.h"

#include <ivdb/levelset/Fog.h>

#include <ivdb/Version.h>
#include <ivdb/diff/Differential.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/util/System.h>

#include <openvdb/openvdb.h>

#include <tbb/global_control.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <optional>

#include <unistd.h>

namespace ivdb::cli {

namespace {

// Signals. SIGINT, SIGTERM and SIGHUP end a run promptly and leave no partial output:
// - while an operation polls its interrupter (Progress, between start() and end()), the first
//   signal only sets gInterrupted; the operation stops through OpenVDB's interrupter mechanism
//   and run() returns 128 + the signal;
// - at any other moment (reading, writing, operations without an interrupter), and for a second
//   signal, the handler removes the temporary output being written and ends the process at once.
std::atomic<bool> gInterrupted{false};
volatile std::sig_atomic_t gCooperative = 0;
volatile std::sig_atomic_t gSignal = 0;

[[noreturn]] void exitOnSignal(int sig)
{
    io::removePendingTemporaryFile();
    static const char msg[] = "ivdb: error: interrupted; nothing was written\n";
    [[maybe_unused]] const ssize_t n = ::write(2, msg, sizeof(msg) - 1);
    ::_exit(128 + sig);
}

extern "C" void onSignal(int sig)
{
    gSignal = sig;
    if (gCooperative && !gInterrupted.load()) {
        gInterrupted = true;
        return;
    }
    exitOnSignal(sig);
}

void installSignalHandlers()
{
    struct sigaction sa {};
    sa.sa_handler = onSignal;
    sigemptyset(&sa.sa_mask);
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) ::sigaction(sig, &sa, nullptr);
    // A file-size limit (ulimit -f) then fails the write with EFBIG, reported like a full disk,
    // instead of killing the process mid-file.
    std::signal(SIGXFSZ, SIG_IGN);
}

} // namespace

Progress::Progress(std::string label): mLabel(std::move(label)), mTerminal(::isatty(2) == 1) {}

Progress::~Progress()
{
    gCooperative = 0;
}

void Progress::start(const char*)
{
    mLastPercent = -1;
    gCooperative = 1;
}

void Progress::end()
{
    if (mTerminal && mLastPercent >= 0) std::fprintf(stderr, "\r\033[K");
    mLastPercent = -1;
    gCooperative = 0;
    // A signal that came after the operation's last poll: nothing is being written yet.
    if (gInterrupted.load()) exitOnSignal(gSignal);
}

bool Progress::wasInterrupted(int percent)
{
    int last = mLastPercent.load();
    // Only the thread that moves the percentage forward prints it.
    if (mTerminal && percent > last && mLastPercent.compare_exchange_strong(last, percent)) {
        std::fprintf(stderr, "\r%s: %3d%%", mLabel.c_str(), percent);
        std::fflush(stderr);
    }
    return gInterrupted.load();
}

raster::RasterSettings sceneSettings(const scene::Scene& sc, const std::string& scenePath,
                                     std::optional<double> voxelSize,
                                     std::optional<double> halfWidth)
{
    raster::RasterSettings settings;
    if (voxelSize) {
        if (!(*voxelSize > 0.0) || !std::isfinite(*voxelSize)) {
            throw std::runtime_error("--voxel-size must be > 0 and finite, got " +
                                     util::formatNumber(*voxelSize));
        }
        settings.voxelSize = *voxelSize;
    } else if (sc.voxelSize) {
        settings.voxelSize = *sc.voxelSize;
    } else {
        throw std::runtime_error(scenePath + ": voxel_size is missing: add \"voxel_size\" to the "
                                 "scene or pass --voxel-size");
    }
    settings.halfWidth = sc.halfWidth;
    if (halfWidth) {
        if (!(*halfWidth >= 1.0 && *halfWidth <= raster::kMaxHalfWidth)) {
            throw std::runtime_error("--half-width must be in [1, " +
                                     util::formatNumber(raster::kMaxHalfWidth) + "] voxels, got " +
                                     util::formatNumber(*halfWidth));
        }
        settings.halfWidth = *halfWidth;
    }
    settings.bounds = sc.bounds;
    settings.distance = sc.distanceBound ? raster::Distance::Bound : raster::Distance::Exact;
    return settings;
}

void warn(const std::string& what)
{
    std::cerr << "ivdb: warning: " << what << std::endl;
}

openvdb::FloatGrid::Ptr readLevelSet(const std::string& path, const std::string& grid)
{
    const openvdb::GridBase::Ptr g = io::selectGrid(io::readVdb(path), path, grid);
    diff::checkLevelSet(*g, path + ": grid '" + g->getName() + "'");
    io::checkGridValues(*g, path);
    return openvdb::gridPtrCast<openvdb::FloatGrid>(g);
}

void stampGrid(openvdb::GridBase& grid, const std::string& source)
{
    grid.setCreator(std::string("ivdb ") + kVersion); // Houdini shows it as vdb_creator
    grid.insertMeta("ivdb_version", openvdb::StringMetadata(kVersion));
    grid.insertMeta("ivdb_source", openvdb::StringMetadata(source));
}

void writeOutput(const std::string& path, const openvdb::GridCPtrVec& grids)
{
    openvdb::MetaMap fileMeta;
    fileMeta.insertMeta("creator", openvdb::StringMetadata(std::string("ivdb ") + kVersion));
    io::writeVdb(path, grids, fileMeta);
}

openvdb::GridCPtrVec withFog(const openvdb::FloatGrid::Ptr& surface, bool fog)
{
    openvdb::GridCPtrVec grids{surface};
    if (fog) {
        openvdb::FloatGrid::Ptr density = levelset::fogFromLevelSet(*surface);
        for (const char* key : {"creator", "ivdb_version", "ivdb_source"}) {
            if (auto meta = (*surface)[key]) density->insertMeta(key, *meta);
        }
        grids.push_back(density);
    }
    return grids;
}

void addFogFlag(CLI::App& cmd, bool& fog)
{
    cmd.add_flag("--fog", fog,
                 "Also write a 'density' fog volume (0 outside, a ramp across the inside of the "
                 "band, 1 deeper inside) so Blender renders the file as a volume");
}

ops::CsgOp csgOp(const std::string& word)
{
    return word == "union" ? ops::CsgOp::Union
         : word == "intersection" ? ops::CsgOp::Intersection
                                  : ops::CsgOp::Difference;
}

// "LO,HI" with LO < HI, both finite.
std::pair<double, double> parseRange(const std::string& text)
{
    const auto comma = text.find(',');
    double lo = std::nan(""), hi = std::nan("");
    try {
        if (comma != std::string::npos) {
            size_t n1 = 0, n2 = 0;
            lo = std::stod(text.substr(0, comma), &n1);
            hi = std::stod(text.substr(comma + 1), &n2);
            if (n1 != comma || n2 != text.size() - comma - 1) lo = hi = std::nan("");
        }
    } catch (const std::exception&) {
        lo = hi = std::nan("");
    }
    if (!std::isfinite(lo) || !std::isfinite(hi)) {
        throw std::runtime_error("--range must be LO,HI (two finite numbers), got '" + text + "'");
    }
    if (!(lo < hi)) {
        throw std::runtime_error("--range needs LO < HI, got " + util::formatNumber(lo) + "," +
                                 util::formatNumber(hi));
    }
    return {lo, hi};
}

openvdb::GridBase::Ptr readColorGrid(const std::string& spec, bool withRange, bool withColormap)
{
    std::string path = spec, name;
    const auto colon = spec.rfind(':');
    if (!std::filesystem::exists(spec) && colon != std::string::npos) {
        path = spec.substr(0, colon);
        name = spec.substr(colon + 1);
    }
    const openvdb::GridPtrVec grids = io::readVdb(path);
    if (grids.empty()) throw std::runtime_error(path + ": the file holds no grid");
    openvdb::GridBase::Ptr g = name.empty() ? grids.front() : io::selectGrid(grids, path, name);
    if (g->isType<openvdb::Vec3SGrid>()) {
        if (withRange || withColormap) {
            throw std::runtime_error(path + ": grid '" + g->getName() + "' is a vector grid, "
                                     "coloured by direction: --colormap and --range apply to "
                                     "scalar grids only");
        }
    } else if (!g->isType<openvdb::FloatGrid>()) {
        throw std::runtime_error(path + ": grid '" + g->getName() + "' is a " + g->valueType() +
                                 " grid; --color-by needs a float (scalar) or vec3s (vector) grid");
    }
    io::checkGridValues(*g, path);
    return g;
}

void printNotes(const std::vector<std::string>& notes)
{
    for (const auto& n : notes) std::cerr << "ivdb: note: " << n << std::endl;
}

int run(int argc, char** argv)
{
    try {
        installSignalHandlers();
        openvdb::initialize();
        CLI::App app{"ivdb: implicit surfaces to sparse OpenVDB level sets", "ivdb"};
        app.require_subcommand(1);
        app.set_version_flag("--version", std::string("ivdb ") + ivdb::kVersion);
        std::optional<int> threads;
        app.add_option("--threads", threads, "Worker threads (default: all cores)")
            ->check(CLI::PositiveNumber);
        Action action;
        addRasterize(app, action);
        addInfo(app, action);
        addGradient(app, action);
        addCurvature(app, action);
        addCompareGradient(app, action);
        addCsg(app, action);
        addBlend(app, action);
        addMesh(app, action);
        addGlyphs(app, action);
        addRender(app, action);
        addBench(app, action);
        // CLI11 reports an unknown command only as "a subcommand is required": name it.
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            if (a == "--threads") { ++i; continue; }
            if (a.rfind("-", 0) == 0) continue;
            const auto subs = app.get_subcommands([&a](const CLI::App* c) { return c->get_name() == a; });
            if (subs.empty()) {
                std::cerr << "ivdb: error: unknown command '" << a
                          << "'; commands: rasterize, info, gradient, curvature, compare-gradient, csg, blend, mesh, glyphs, render, bench (run 'ivdb --help')" << std::endl;
                return 2;
            }
            break;
        }
        try {
            app.parse(argc, argv);
        } catch (const CLI::CallForHelp& e) {
            return app.exit(e);
        } catch (const CLI::CallForAllHelp& e) {
            return app.exit(e);
        } catch (const CLI::CallForVersion& e) {
            return app.exit(e);
        } catch (const CLI::ParseError& e) {
            std::cerr << "ivdb: error: " << e.what() << "\nRun 'ivdb --help' or 'ivdb COMMAND --help'."
                      << std::endl;
            return 2;
        }
        std::optional<tbb::global_control> limit;
        if (threads) limit.emplace(tbb::global_control::max_allowed_parallelism, size_t(*threads));
        return action ? action() : 2;
    } catch (const std::exception& e) {
        if (gInterrupted.load()) {
            std::cerr << "ivdb: error: interrupted; nothing was written" << std::endl;
            return 128 + gSignal;
        }
        std::cerr << "ivdb: error: " << util::errorText(e) << std::endl;
        return 1;
    } catch (...) {
        std::cerr << "ivdb: error: unknown failure" << std::endl;
        return 1;
    }
}

} // namespace ivdb::cli
