// SPDX-License-Identifier: Apache-2.0
// ivdb csg and ivdb blend: sharp, super-elliptic blended or smooth CSG of level sets from .vdb
// files.
#include "Cli.h"

#include <ivdb/jobs/Combine.h>

#include <cstdio>

namespace ivdb::cli {

namespace {

struct CombineArgs
{
    jobs::CombineOptions job;
    std::string compression = "blosc";
    std::string op;
    std::optional<double> p, k;
    bool quiet = false;
};

int runCombine(CombineArgs& a, bool blend)
{
    a.job.write.compression = enumOf<io::Compression>(a.compression, io::compressionNames());
    a.job.op = *implicit::csgOpFromString(a.op);
    if (blend) {
        a.job.p = a.p;
        a.job.k = a.k;
    }
    std::optional<Progress> progress;
    if (blend) {
        progress.emplace("blend");
        a.job.interrupter = &*progress;
    }
    const jobs::CombineResult r = jobs::combine(a.job);
    printNotes(r.notes, r.warnings);
    if (!a.quiet) {
        const std::string what = combineLabel(a.op, a.job);
        std::printf("%s of %zu level sets: %llu active voxels, read %.3f s, %s %.3f s, total "
                    "%.3f s -> %s\n",
                    what.c_str(), a.job.inputs.size(), (unsigned long long)r.surface->activeVoxelCount(),
                    r.readSeconds, blend ? "blend" : "combine", r.computeSeconds, r.totalSeconds,
                    a.job.output.c_str());
    }
    return 0;
}

/// The options csg and blend share.
std::shared_ptr<CombineArgs> addCombineOptions(Command& cmd)
{
    auto a = std::make_shared<CombineArgs>();
    addCombineInputs(cmd, a->job, a->op, a->compression);
    addFogFlag(cmd, a->job.fog);
    addQuietFlag(cmd, a->quiet);
    return a;
}

} // namespace

void addCsg(CLI::App& app, Action& action)
{
    Command cmd(app, "csg",
        "Sharp CSG of level sets (union = min, intersection = max, difference = max(A, -B): A "
        "minus each following input); inputs of another voxel size or transform are resampled "
        "onto the finest one. Writes the level set 'surface'");
    auto a = addCombineOptions(cmd);
    cmd.onRun(action, [a]() { return runCombine(*a, false); });
}

void addBlend(CLI::App& app, Action& action)
{
    Command cmd(app, "blend",
        "Blended CSG of level sets. With -p, super-elliptic: union f = -(1/p) ln(exp(-p fA) + "
        "exp(-p fB)), intersection the same with -p, difference the intersection with -fB; it "
        "rounds the crease within about ln(2)/p world units. With -k, the smooth minimum of width "
        "k: union min(fA, fB) - h^2 k/4 with h = max(k - |fA - fB|, 0)/k, intersection max + "
        "h^2 k/4; it changes the sharp result only where the inputs are within k. Each input's "
        "band is first extended as far as p or k needs around the crease, where each voxel the "
        "blend changes gets its distance to the blended surface; the result is a narrow band "
        "'surface'");
    auto a = addCombineOptions(cmd);
    addBlendOptions(cmd, a->p, a->k, a->job.tolerance);
    cmd.onRun(action, [a]() { return runCombine(*a, true); });
}

} // namespace ivdb::cli
