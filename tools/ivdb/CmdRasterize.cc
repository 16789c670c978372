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
    std::string sampling = "sparse", distance, frames;
    bool resume = false, quiet = false;
    int parallelFrames = 0;
};

void printSummary(const std::string& what, const jobs::RasterizeResult& r, const std::string& output)
{
    std::printf("%s: %llu active voxels, grid %s, file %s, peak memory %s, compute %.3f s, "
                "total %.3f s -> %s\n",
                what.c_str(), (unsigned long long)r.activeVoxels,
                util::formatBytes(double(r.gridBytes)).c_str(),
                util::formatBytes(double(r.fileBytes)).c_str(),
                util::formatBytes(double(util::peakResidentMemory())).c_str(),
                r.computeSeconds, r.totalSeconds, output.c_str());
    const raster::RasterStats& st = r.stats;
    if (st.searchedDistances + st.approximateDistances + st.sweptDistances > 0) {
        std::printf("  true distances: %llu voxels by foot points, %llu by the lattice search "
                    "(%llu of them approximate), %llu by fast sweeping\n",
                    (unsigned long long)st.localDistances,
                    (unsigned long long)(st.searchedDistances + st.approximateDistances),
                    (unsigned long long)st.approximateDistances,
                    (unsigned long long)st.sweptDistances);
    }
    std::fflush(stdout);
}

/// A keyed scene's frames: one summary line per frame, one progress line across them.
int runSequence(RasterizeArgs& a, Progress& progress)
{
    jobs::SequenceOptions seq;
    seq.base = a.job;
    if (!a.frames.empty()) seq.frames = scene::parseFrameRange(a.frames);
    seq.resume = a.resume;
    seq.parallelFrames = a.parallelFrames;
    std::size_t done = 0;
    seq.onFrame = [&](const jobs::FrameReport& f) {
        progress.clearLine();
        printNotes(f.result.notes);
        ++done;
        setInterruptedNote(std::to_string(done) + " of " + std::to_string(f.count) + " frames "
                           "are written whole, the frames being made were not written; "
                           "--resume carries on");
        if (a.quiet) return;
        const std::string what = a.job.scene + " frame " + std::to_string(f.frame);
        if (f.skipped) std::printf("%s: already written, skipped -> %s\n", what.c_str(), f.output.c_str());
        else printSummary(what, f.result, f.output);
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
    if (!a.distance.empty()) {
        a.job.distance = a.distance == "bound" ? raster::Distance::Bound : raster::Distance::Exact;
    }
    Progress progress("rasterize " + a.job.scene);
    a.job.interrupter = &progress;
    if (!a.frames.empty() || a.resume || a.parallelFrames != 0 || scene::hasFrameField(a.job.output)) {
        return runSequence(a, progress);
    }
    const jobs::RasterizeResult r = jobs::rasterize(a.job);
    printNotes(r.notes);
    if (!a.quiet) printSummary(a.job.scene, r, a.job.output);
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
    cmd.add("--frames", a->frames, "Frames of a keyed scene to write, A-B[:STEP] or A (default: "
            "the scene's \"frames\"); one .vdb per frame", &param::kFrames);
    cmd.flag("--resume", a->resume, "Skip frames whose file already reads as a whole frame");
    cmd.add("--parallel-frames", a->parallelFrames, "Frames made at once, in [0, 1024]; 0: as "
            "many as there are threads, while their memory fits", &param::kParallelFrames)
        ->capture_default_str();
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
