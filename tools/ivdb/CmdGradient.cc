// ivdb gradient: the central-difference gradient of a level set (seed eq. 9).
#include "Cli.h"

#include <ivdb/Version.h>
#include <ivdb/diff/Differential.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/util/System.h>

#include <chrono>
#include <cstdio>

namespace ivdb::cli {

namespace {

struct GradientOptions
{
    std::string input, output, grid;
    int step = 1;
    bool magnitude = false, withInput = false, quiet = false;
};

int runGradient(const GradientOptions& opt)
{
    const auto t0 = std::chrono::steady_clock::now();
    if (opt.step < 1 || opt.step > diff::kMaxStep) {
        throw std::runtime_error("--step must be in [1, " + std::to_string(diff::kMaxStep) +
                                 "] voxels, got " + std::to_string(opt.step));
    }
    io::checkOutputPath(opt.output);
    const auto phi = readLevelSet(opt.input, opt.grid);

    const auto t1 = std::chrono::steady_clock::now();
    auto grad = diff::gradient(*phi, opt.step);
    const auto t2 = std::chrono::steady_clock::now();

    const std::string source = opt.input + ":" + phi->getName();
    stampGrid(*grad, source);
    grad->insertMeta("ivdb_step_voxels", openvdb::Int32Metadata(opt.step));
    openvdb::GridCPtrVec out{grad};
    if (opt.magnitude) {
        auto mag = diff::magnitude(*grad);
        stampGrid(*mag, source);
        out.push_back(mag);
    }
    if (opt.withInput) out.push_back(phi);
    writeOutput(opt.output, out);
    const auto t3 = std::chrono::steady_clock::now();
    if (!opt.quiet) {
        std::printf("%s: gradient of '%s', step %d, %llu active voxels, read %.3f s, compute "
                    "%.3f s, total %.3f s -> %s\n",
                    opt.input.c_str(), phi->getName().c_str(), opt.step,
                    (unsigned long long)grad->activeVoxelCount(),
                    std::chrono::duration<double>(t1 - t0).count(),
                    std::chrono::duration<double>(t2 - t1).count(),
                    std::chrono::duration<double>(t3 - t0).count(), opt.output.c_str());
    }
    return 0;
}

} // namespace

void addGradient(CLI::App& app, Action& action)
{
    auto opt = std::make_shared<GradientOptions>();
    CLI::App* cmd = app.add_subcommand("gradient",
        "Central-difference gradient of a level set (seed eq. 9): a covariant world-space "
        "Vec3SGrid 'gradient' on the input's band");
    cmd->add_option("input", opt->input, "Input .vdb file")->required();
    cmd->add_option("-o,--output", opt->output, "Output .vdb file (written atomically)")->required();
    cmd->add_option("--step", opt->step,
                    "Difference step K in voxels: (phi(x+K) - phi(x-K)) / (2 K dx); in [1, 20]")
        ->capture_default_str();
    cmd->add_option("--grid", opt->grid, "Input grid name (default: the first level set)");
    cmd->add_flag("--magnitude", opt->magnitude, "Also write 'gradient_magnitude' (|gradient|)");
    cmd->add_flag("--with-input", opt->withInput, "Also copy the input grid into the output file");
    cmd->add_flag("-q,--quiet", opt->quiet, "Do not print the summary line");
    cmd->callback([&action, opt]() { action = [opt]() { return runGradient(*opt); }; });
}

} // namespace ivdb::cli
