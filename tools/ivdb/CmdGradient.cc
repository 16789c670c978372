// SPDX-License-Identifier: Apache-2.0
// ivdb gradient: the central-difference gradient of a level set (docs/method.md#discrete-gradient).
#include "Cli.h"

#include <ivdb/jobs/Differentiate.h>

#include <cstdio>

namespace ivdb::cli {

namespace {

struct GradientArgs
{
    jobs::GradientOptions job;
    std::string compression = "blosc";
    bool quiet = false;
};

int runGradient(GradientArgs& a)
{
    a.job.write.compression = enumOf<io::Compression>(a.compression, io::compressionNames());
    a.job.keepGrids = false; // the file is all the command wants
    const jobs::GradientResult r = jobs::gradient(a.job);
    if (!a.quiet) {
        std::printf("%s: gradient of '%s', step %d, %llu active voxels, read %.3f s, compute "
                    "%.3f s, total %.3f s -> %s\n",
                    a.job.input.c_str(), r.input->getName().c_str(), a.job.step,
                    (unsigned long long)r.activeVoxels, r.readSeconds,
                    r.computeSeconds, r.totalSeconds, a.job.output.c_str());
    }
    return 0;
}

} // namespace

void addGradient(CLI::App& app, Action& action)
{
    auto a = std::make_shared<GradientArgs>();
    Command cmd(app, "gradient",
        "Central-difference gradient of a level set: a covariant world-space Vec3SGrid "
        "'gradient' on the input's band");
    addGradientOptions(cmd, a->job, a->compression);
    addQuietFlag(cmd, a->quiet);
    cmd.onRun(action, [a]() { return runGradient(*a); });
}

} // namespace ivdb::cli
