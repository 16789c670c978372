// SPDX-License-Identifier: Apache-2.0
// ivdb rasterize: a scene file into a narrow-band level set .vdb.
#include "Cli.h"

#include <ivdb/jobs/Rasterize.h>
#include <ivdb/util/System.h>

#include <cstdio>

namespace ivdb::cli {

namespace {

struct RasterizeArgs
{
    jobs::RasterizeOptions job;
    std::string compression = "blosc";
    std::string sampling = "sparse", distance;
    SequenceArgs seq;
    bool quiet = false;
};

/// A keyed scene's frames: one summary line per frame, one progress line across them.
int runSequence(RasterizeArgs& a, Progress& progress)
{
    jobs::SequenceOptions seq = a.seq.options(a.job);
    std::size_t done = 0;
    seq.onFrame = [&](const jobs::FrameReport& f) {
        progress.clearLine();
        printFrame(a.job.scene, f, ++done, a.quiet);
    };
    const jobs::SequenceResult r = jobs::rasterizeSequence(seq);
    if (!a.quiet) {
        std::printf("%zu frames written, %zu skipped, total %.3f s\n", r.written, r.skipped,
                    r.totalSeconds);
    }
    return 0;
}

int runRasterize(RasterizeArgs& a)
{
    a.job.write.compression = enumOf<io::Compression>(a.compression, io::compressionNames());
    a.job.sampling = a.sampling == "dense" ? raster::Sampling::Dense : raster::Sampling::Sparse;
    applyDistance(a.job, a.distance);
    Progress progress("rasterize " + a.job.scene);
    a.job.interrupter = &progress;
    if (a.seq.wanted(a.job.output)) return runSequence(a, progress);
    const jobs::RasterizeResult r = jobs::rasterize(a.job);
    printNotes(r.notes);
    if (!a.quiet) printRasterSummary(a.job.scene, r, a.job.output, util::peakResidentMemory());
    return 0;
}

} // namespace

void addRasterize(CLI::App& app, Action& action)
{
    auto a = std::make_shared<RasterizeArgs>();
    Command cmd(app, "rasterize",
        "Rasterize a JSON scene into a narrow-band level set .vdb (grid 'surface')");
    cmd.add("scene", a->job.scene, "Scene file (JSON; see docs/scene-format.md)")->required();
    cmd.add("-o,--output", a->job.output, "Output .vdb file (written atomically); for a sequence, "
            "each run of # becomes the zero-padded frame number (out_####.vdb)", &param::kOutput)
        ->required();
    addSequenceOptions(cmd, a->seq);
    addRasterSettings(cmd, a->job, a->distance);
    cmd.add("--sampling", a->sampling,
            "sparse: interval-pruned, cost grows with the surface; dense: every voxel of the "
            "bounding box (the reference; refuses if it would not fit in memory)", &param::kSampling)
        ->check(CLI::IsMember({"sparse", "dense"}))
        ->capture_default_str();
    addWriteOptions(cmd, a->compression, a->job.write.half);
    addFogFlag(cmd, a->job.fog);
    addQuietFlag(cmd, a->quiet);
    cmd.onRun(action, [a]() { return runRasterize(*a); });
}

} // namespace ivdb::cli
