// ivdb blend: super-elliptic blended CSG of level sets from .vdb files.
#include "Cli.h"

#include <ivdb/Version.h>
#include <ivdb/diff/Differential.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/ops/Blend.h>
#include <ivdb/util/System.h>

#include <chrono>
#include <cmath>
#include <cstdio>

namespace ivdb::cli {

namespace {

struct BlendOptions
{
    std::string op, output, grid;
    std::vector<std::string> inputs;
    double p = 0.0, tolerance = 0.05;
    bool quiet = false;
    bool fog = false;
};

int runBlend(const BlendOptions& opt)
{
    const auto t0 = std::chrono::steady_clock::now();
    if (!(opt.p >= 0.1 && opt.p <= 1000.0)) {
        throw std::runtime_error("-p must be in [0.1, 1000] (larger is sharper; the blend reaches "
                                 "about ln(2)/p world units from the crease), got " +
                                 util::formatNumber(opt.p));
    }
    if (!(opt.tolerance > 0.0) || !std::isfinite(opt.tolerance)) {
        throw std::runtime_error("--tolerance must be > 0 voxels, got " +
                                 util::formatNumber(opt.tolerance));
    }
    if (opt.inputs.size() < 2) {
        throw std::runtime_error("blend " + opt.op + " needs at least two input files, got " +
                                 std::to_string(opt.inputs.size()));
    }
    io::checkOutputPath(opt.output);
    std::vector<openvdb::FloatGrid::Ptr> grids;
    for (const std::string& path : opt.inputs) grids.push_back(readLevelSet(path, opt.grid));
    const auto t1 = std::chrono::steady_clock::now();
    ops::BlendSettings settings;
    settings.p = opt.p;
    settings.tolerance = opt.tolerance;
    Progress progress("blend");
    settings.interrupter = &progress;
    std::vector<std::string> notes;
    auto result = ops::blendInPlace(csgOp(opt.op), grids, settings, &notes);
    printNotes(notes);
    if (result->activeVoxelCount() == 0) {
        warn("the result has no surface (the inputs do not overlap as this operation needs); "
             "the level set written is empty");
    }
    const auto t2 = std::chrono::steady_clock::now();
    std::string sources;
    for (const auto& p : opt.inputs) sources += (sources.empty() ? "" : " ") + p;
    stampGrid(*result, "blend " + opt.op + " p=" + util::formatNumber(opt.p) + " " + sources);
    writeOutput(opt.output, withFog(result, opt.fog));
    const auto t3 = std::chrono::steady_clock::now();
    if (!opt.quiet) {
        std::printf("blend %s p=%s of %zu level sets: %llu active voxels, read %.3f s, blend "
                    "%.3f s, total %.3f s -> %s\n",
                    opt.op.c_str(), util::formatNumber(opt.p).c_str(), opt.inputs.size(),
                    (unsigned long long)result->activeVoxelCount(),
                    std::chrono::duration<double>(t1 - t0).count(),
                    std::chrono::duration<double>(t2 - t1).count(),
                    std::chrono::duration<double>(t3 - t0).count(), opt.output.c_str());
    }
    return 0;
}

} // namespace

void addBlend(CLI::App& app, Action& action)
{
    auto opt = std::make_shared<BlendOptions>();
    CLI::App* cmd = app.add_subcommand("blend",
        "Super-elliptic blended CSG of level sets (seed eqs. 12-15): union f = -(1/p) "
        "ln(exp(-p fA) + exp(-p fB)), intersection the same with -p, difference the intersection "
        "with -fB. The blend rounds the crease within about ln(2)/p world units. Each input's band "
        "is first extended as far as p needs, and the result is re-distanced into a narrow band "
        "'surface'");
    cmd->add_option("op", opt->op, "union | intersection | difference")
        ->required()
        ->check(CLI::IsMember({"union", "intersection", "difference"}));
    cmd->add_option("inputs", opt->inputs, "Two or more input .vdb files")->required();
    cmd->add_option("-o,--output", opt->output, "Output .vdb file (written atomically)")->required();
    cmd->add_option("-p", opt->p, "Sharpness p in [0.1, 1000], 1/world units (larger is sharper)")
        ->required();
    cmd->add_option("--tolerance", opt->tolerance,
                    "Error allowed on the surface from the bands' limited reach, in voxels")
        ->capture_default_str();
    cmd->add_option("--grid", opt->grid, "Grid name in every input (default: each file's first "
                                         "level set)");
    addFogFlag(*cmd, opt->fog);
    cmd->add_flag("-q,--quiet", opt->quiet, "Do not print the summary line");
    cmd->callback([&action, opt]() { action = [opt]() { return runBlend(*opt); }; });
}

} // namespace ivdb::cli
