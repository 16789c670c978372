// SPDX-License-Identifier: Apache-2.0
// ivdb curvature: mean, Gaussian, principal curvatures or the Laplacian of a level set.
#include "Cli.h"

#include <ivdb/jobs/Differentiate.h>

#include <cstdio>

namespace ivdb::cli {

namespace {

struct CurvatureArgs
{
    jobs::CurvatureOptions job;
    std::string compression = "blosc";
    std::string method = "mean";
    bool quiet = false;
};

int runCurvature(CurvatureArgs& a)
{
    a.job.write.compression = enumOf<io::Compression>(a.compression, io::compressionNames());
    a.job.method = enumOf<jobs::CurvatureMethod>(a.method, jobs::curvatureMethodNames());
    a.job.keepGrids = false; // the file is all the command wants
    const jobs::CurvatureResult r = jobs::curvature(a.job);
    if (!a.quiet) {
        std::printf("%s: %s curvature of '%s', %llu active voxels, read %.3f s, compute %.3f s, "
                    "total %.3f s -> %s\n",
                    a.job.input.c_str(), a.method.c_str(), r.input->getName().c_str(),
                    (unsigned long long)r.activeVoxels, r.readSeconds,
                    r.computeSeconds, r.totalSeconds, a.job.output.c_str());
    }
    return 0;
}

} // namespace

void addCurvature(CLI::App& app, Action& action)
{
    auto a = std::make_shared<CurvatureArgs>();
    Command cmd(app, "curvature",
        "Curvature of a level set's iso-surfaces on its band, as a FloatGrid 'curvature' "
        "(principal: 'k1' and 'k2'). Conventions, in 1/world units: mean = (k1 + k2) / 2 (1/r on "
        "a sphere, as OpenVDB's meanCurvature); gaussian = k1 k2 (1/r^2); principal = k1 >= k2 "
        "(1/r each); laplacian = the Laplacian of phi, an approximation (2/r on a sphere's "
        "distance field)");
    addCurvatureOptions(cmd, a->job, a->method, a->compression);
    addQuietFlag(cmd, a->quiet);
    cmd.onRun(action, [a]() { return runCurvature(*a); });
}

} // namespace ivdb::cli
