// ivdb csg: sharp union, intersection or difference of level sets from .vdb files.
#include "Cli.h"

#include <ivdb/Version.h>
#include <ivdb/diff/Differential.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/ops/Csg.h>

#include <chrono>
#include <cstdio>

namespace ivdb::cli {

namespace {

struct CsgOptions
{
    std::string op, output, grid;
    std::vector<std::string> inputs;
    bool quiet = false;
    bool fog = false;
};

int runCsg(const CsgOptions& opt)
{
    const auto t0 = std::chrono::steady_clock::now();
    if (opt.inputs.size() < 2) {
        throw std::runtime_error("csg " + opt.op + " needs at least two input files, got " +
                                 std::to_string(opt.inputs.size()));
    }
    io::checkOutputPath(opt.output);
    std::vector<openvdb::FloatGrid::Ptr> grids;
    for (const std::string& path : opt.inputs) grids.push_back(readLevelSet(path, opt.grid));
    const auto t1 = std::chrono::steady_clock::now();
    std::vector<std::string> notes;
    // In place: the inputs are not needed afterwards.
    auto result = ops::csgInPlace(csgOp(opt.op), grids, &notes);
    printNotes(notes);
    if (result->activeVoxelCount() == 0) {
        warn("the result has no surface (the inputs do not overlap as this operation needs); "
             "the level set written is empty");
    }
    const auto t2 = std::chrono::steady_clock::now();
    std::string sources;
    for (const auto& p : opt.inputs) sources += (sources.empty() ? "" : " ") + p;
    stampGrid(*result, "csg " + opt.op + " " + sources);
    writeOutput(opt.output, withFog(result, opt.fog));
    const auto t3 = std::chrono::steady_clock::now();
    if (!opt.quiet) {
        std::printf("csg %s of %zu level sets: %llu active voxels, read %.3f s, combine %.3f s, "
                    "total %.3f s -> %s\n",
                    opt.op.c_str(), grids.size(), (unsigned long long)result->activeVoxelCount(),
                    std::chrono::duration<double>(t1 - t0).count(),
                    std::chrono::duration<double>(t2 - t1).count(),
                    std::chrono::duration<double>(t3 - t0).count(), opt.output.c_str());
    }
    return 0;
}

} // namespace

void addCsg(CLI::App& app, Action& action)
{
    auto opt = std::make_shared<CsgOptions>();
    CLI::App* cmd = app.add_subcommand("csg",
        "Sharp CSG of level sets (union = min, intersection = max, difference = max(A, -B): A "
        "minus each following input); inputs of another voxel size or transform are resampled "
        "onto the finest one. Writes the level set 'surface'");
    cmd->add_option("op", opt->op, "union | intersection | difference")
        ->required()
        ->check(CLI::IsMember({"union", "intersection", "difference"}));
    cmd->add_option("inputs", opt->inputs, "Two or more input .vdb files")->required();
    cmd->add_option("-o,--output", opt->output, "Output .vdb file (written atomically)")->required();
    cmd->add_option("--grid", opt->grid, "Grid name in every input (default: each file's first "
                                         "level set)");
    addFogFlag(*cmd, opt->fog);
    cmd->add_flag("-q,--quiet", opt->quiet, "Do not print the summary line");
    cmd->callback([&action, opt]() { action = [opt]() { return runCsg(*opt); }; });
}

} // namespace ivdb::cli
