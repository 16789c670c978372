// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/Rasterize.h>

#include "Common.h"

#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Inputs.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <nlohmann/json.hpp>

#include <tbb/parallel_pipeline.h>
#include <tbb/task_group.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <map>
#include <mutex>
#include <sstream>

#if defined(__has_feature)
#if __has_feature(thread_sanitizer)
extern "C" void __tsan_acquire(void* addr);
extern "C" void __tsan_release(void* addr);
#define IVDB_TSAN_ACQUIRE(addr) __tsan_acquire(addr)
#define IVDB_TSAN_RELEASE(addr) __tsan_release(addr)
#endif
#endif
#ifndef IVDB_TSAN_ACQUIRE
#define IVDB_TSAN_ACQUIRE(addr) ((void)(addr))
#define IVDB_TSAN_RELEASE(addr) ((void)(addr))
#endif

namespace ivdb::jobs {

raster::RasterSettings sceneSettings(const scene::Scene& sc, const std::string& scenePath,
                                     std::optional<double> voxelSize,
                                     std::optional<double> halfWidth)
{
    raster::RasterSettings settings;
    if (voxelSize) {
        check(limits::kVoxelSize, *voxelSize);
        settings.voxelSize = *voxelSize;
    } else if (sc.voxelSize) {
        settings.voxelSize = *sc.voxelSize;
    } else {
        throw ParamError(param::kVoxelSize, "voxel_size is missing: add \"voxel_size\" to the "
                         "scene or give a voxel size", scenePath, ParamError::Kind::Missing);
    }
    settings.halfWidth = sc.halfWidth;
    if (halfWidth) {
        check(limits::kHalfWidth, *halfWidth);
        settings.halfWidth = *halfWidth;
    }
    settings.bounds = sc.bounds;
    settings.distance = sc.distanceBound ? raster::Distance::Bound : raster::Distance::Exact;
    return settings;
}

namespace {

/// The scene as rasterized, for the output's metadata: the overrides replace the file's values.
std::string sceneAsRasterized(const scene::Scene& sc, const raster::RasterSettings& settings)
{
    nlohmann::json scene = nlohmann::json::parse(sc.json);
    scene["voxel_size"] = settings.voxelSize;
    scene["half_width"] = settings.halfWidth;
    scene["distance"] = settings.distance == raster::Distance::Bound ? "bound" : "exact";
    return scene.dump();
}

} // namespace

void stampRaster(openvdb::GridBase& grid, const RasterizeOptions& opt, const scene::Scene& sc,
                 const raster::RasterSettings& settings, std::optional<int> frame)
{
    io::stampGrid(grid, opt.scene);
    grid.insertMeta("ivdb_scene", openvdb::StringMetadata(sceneAsRasterized(sc, settings)));
    grid.insertMeta("ivdb_sampling", openvdb::StringMetadata(
        settings.sampling == raster::Sampling::Dense ? "dense" : "sparse"));
    if (frame) grid.insertMeta("ivdb_frame", openvdb::Int32Metadata(*frame));
}

scene::Scene loadRasterScene(const RasterizeOptions& opt, std::optional<double> frame,
                             bool readInputs)
{
    // The overrides first: mesh and vdb nodes are built at them.
    if (opt.voxelSize) check(limits::kVoxelSize, *opt.voxelSize);
    if (opt.halfWidth) check(limits::kHalfWidth, *opt.halfWidth);
    return scene::loadScene(opt.scene, {opt.voxelSize, opt.halfWidth, frame, readInputs});
}

raster::RasterSettings rasterSettings(const scene::Scene& sc, const RasterizeOptions& opt)
{
    raster::RasterSettings settings = sceneSettings(sc, opt.scene, opt.voxelSize, opt.halfWidth);
    settings.sampling = opt.sampling;
    if (opt.distance) settings.distance = *opt.distance;
    settings.interrupter = opt.interrupter;
    return settings;
}

void withSceneErrors(const RasterizeOptions& opt, const std::function<void()>& step)
{
    try {
        step();
    } catch (const ParamError& e) {
        // A value the caller gave keeps its parameter (the caller words it); one from the
        // scene file is the file's, named by its key.
        const bool given = (e.param() == param::kVoxelSize.id && opt.voxelSize) ||
                           (e.param() == param::kHalfWidth.id && opt.halfWidth);
        if (given) throw;
        throw scene::SceneError(opt.scene + ": " + e.describe(e.param() + ":"));
    } catch (const openvdb::Exception& e) {
        // The shape's own problems (unbounded, too large) are the scene file's.
        OPENVDB_THROW(openvdb::RuntimeError, opt.scene + ": " + util::errorText(e));
    }
}

void throwNoVoxels(const RasterizeOptions& opt, const raster::RasterSettings& settings,
                   std::optional<int> frame)
{
    std::ostringstream os;
    os << opt.scene << (frame ? ": frame " + std::to_string(*frame) : std::string())
       << ": the surface has no voxels at voxel size " << settings.voxelSize
       << " (no zero crossing inside the bounds, or a shape smaller than a voxel): "
       << "check the shape and bounds, or use a smaller voxel size; nothing was written";
    OPENVDB_THROW(openvdb::RuntimeError, os.str());
}

namespace {

/// @a loadSeconds: the time it took to read the scene (its meshes and .vdb inputs included),
/// counted in the compute and total times.
RasterizeResult rasterizeScene(const RasterizeOptions& opt, const scene::Scene& sc,
                               std::optional<int> frame, double loadSeconds)
{
    Stopwatch clock;
    if (!opt.output.empty()) io::checkOutputPath(opt.output);
    RasterizeResult result;
    result.notes = sc.notes;
    result.settings = rasterSettings(sc, opt);
    raster::RasterSettings& settings = result.settings;
    settings.stats = &result.stats;
    withSceneErrors(opt, [&] { result.surface = raster::rasterize(sc.shape, settings); });
    result.computeSeconds = loadSeconds + clock.lap();
    result.activeVoxels = result.surface->activeVoxelCount();
    if (result.activeVoxels == 0) throwNoVoxels(opt, settings, frame);
    settings.stats = nullptr;
    result.gridBytes = result.surface->memUsage();
    stampRaster(*result.surface, opt, sc, settings, frame);
    if (opt.fog) result.density = detail::fogWithStamps(*result.surface);
    result.fileBytes = detail::writeGrids(opt.output, {result.surface, result.density}, opt.write);
    result.totalSeconds = loadSeconds + clock.total();
    return result;
}

} // namespace

RasterizeResult rasterize(const RasterizeOptions& opt)
{
    Stopwatch load;
    const scene::Scene sc = loadRasterScene(opt, std::nullopt, true);
    if (sc.animated) throwAnimated(opt);
    return rasterizeScene(opt, sc, std::nullopt, load.lap());
}

void throwAnimated(const RasterizeOptions& opt)
{
    throw ParamError(param::kFrames, opt.scene + " has keyed values (an animation): choose the "
                     "frames to write, with # in the output name where the frame number goes",
                     "", ParamError::Kind::Missing);
}

namespace {

/// Reports one sequence-wide percentage to the caller's interrupter while frames run: the
/// frames done plus this one's share.
class FrameProgress final: public util::Interrupter
{
public:
    FrameProgress(util::Interrupter* outer, std::function<std::size_t()> done, std::size_t count)
        : mOuter(outer), mDone(std::move(done)), mCount(count) {}
    void start(const char*) override {}
    void end() override {}
    bool wasInterrupted(int percent) override
    {
        const std::size_t share = percent < 0 ? 0 : std::size_t(percent);
        const int overall = int(std::min<std::size_t>(99, (mDone() * 100 + share) / mCount));
        return util::wasInterrupted(mOuter, percent < 0 ? -1 : overall);
    }

private:
    util::Interrupter* mOuter;
    std::function<std::size_t()> mDone;
    std::size_t mCount;
};

} // namespace

bool isWholeFrame(const std::string& path)
{
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) return false;
    try {
        for (const auto& g : io::readVdb(path)) {
            if (g->getName() == "surface" && g->getGridClass() == openvdb::GRID_LEVEL_SET) return true;
        }
    } catch (const openvdb::Exception&) {
    }
    return false;
}

std::vector<int> sequenceFrames(const SequenceOptions& opt)
{
    const RasterizeOptions& base = opt.base;
    const scene::Scene first = loadRasterScene(base, std::nullopt, false);
    if (!first.animated) {
        throw ParamError(param::kFrames, "are for animated scenes, and " + base.scene + " has "
                         "no keyed value: nothing moves from frame to frame (docs/scene-format.md"
                         "#animation)");
    }
    if (!opt.frames && !first.frames) {
        throw ParamError(param::kFrames, base.scene + " gives no \"frames\": choose the frames "
                         "to write", "", ParamError::Kind::Missing);
    }
    const std::vector<int> frames = (opt.frames ? *opt.frames : *first.frames).frames();
    if (base.output.empty()) return frames;
    if (frames.size() > 1 && !scene::hasFrameField(base.output)) {
        throw ParamError(param::kOutput, "needs # where the frame number goes (out_####.vdb) "
                         "for " + std::to_string(frames.size()) + " frames, got '" + base.output + "'");
    }
    io::checkOutputPath(scene::frameFileName(base.output, frames.front()));
    // Every frame's values are checked before any file is written.
    for (int f : frames) sceneSettings(loadRasterScene(base, f, false), base.scene, base.voxelSize, base.halfWidth);
    return frames;
}

namespace {

/// The frames of one sequence being made: each frame made on its own, reported in frame order.
class Sequence
{
public:
    Sequence(const SequenceOptions& opt, std::vector<int> frames)
        : mOpt(opt), mFrames(std::move(frames)) {}

    std::size_t size() const { return mFrames.size(); }

    /// Make (or, resuming, skip) frame @a i and keep its report for deliver().
    void make(std::size_t i)
    {
        if (i >= mFrames.size()) { // a frame source that checked another sequence
            OPENVDB_THROW(openvdb::RuntimeError, "frame " + std::to_string(i + 1) + " of a sequence "
                          "of " + std::to_string(mFrames.size()) + " frames: " + mOpt.base.scene +
                          " changed while its frames were being made");
        }
        FrameReport report;
        report.frame = mFrames[i];
        report.index = i;
        report.count = mFrames.size();
        report.output = mOpt.base.output.empty()
            ? std::string() : scene::frameFileName(mOpt.base.output, report.frame);
        report.skipped = mOpt.resume && !report.output.empty() && isWholeFrame(report.output);
        if (!report.skipped) {
            FrameProgress progress(mOpt.base.interrupter, framesDone(), mFrames.size());
            RasterizeOptions one = mOpt.base;
            one.output = report.output;
            one.interrupter = mOpt.base.interrupter ? &progress : nullptr;
            Stopwatch load;
            const scene::Scene sc = loadRasterScene(one, report.frame, true);
            report.result = rasterizeScene(one, sc, report.frame, load.lap());
            // A written frame is in its file: frames that wait for an earlier one to be reported
            // keep no grid, so a sequence holds only the frames being made.
            if (!report.output.empty()) {
                report.result.surface.reset();
                report.result.density.reset();
            }
        }
        report.peakMemory = util::peakResidentMemory();
        ++mDone;
        std::lock_guard<std::mutex> lock(mMutex);
        mMade.emplace(i, std::move(report));
    }

    /// The frames finished so far: the sequence's (when shared), else this one's.
    std::function<std::size_t()> framesDone() const
    {
        if (mOpt.framesDone) return mOpt.framesDone;
        return [this] { return mDone.load(); };
    }

    /// Report every made frame whose predecessors are reported (all of them if @a all, or if
    /// frames come from nextFrame), one caller at a time so the reports come in frame order.
    void deliver(bool all = false)
    {
        std::lock_guard<std::mutex> delivering(mDeliver);
        for (;;) {
            FrameReport report;
            {
                std::lock_guard<std::mutex> lock(mMutex);
                auto it = mMade.begin();
                if (it == mMade.end() || (!all && !mOpt.nextFrame && it->first != mNext)) return;
                report = std::move(it->second);
                mMade.erase(it);
                mNext = report.index + 1;
            }
            ++(report.skipped ? mResult.skipped : mResult.written);
            if (mOpt.onFrame) mOpt.onFrame(report);
        }
    }

    SequenceResult& result() { return mResult; }

private:
    const SequenceOptions& mOpt;
    std::vector<int> mFrames;
    std::atomic<std::size_t> mDone{0};
    std::mutex mMutex, mDeliver;
    std::map<std::size_t, FrameReport> mMade;
    std::size_t mNext = 0;
    SequenceResult mResult;
};

/// oneTBB builds a pipeline's filters on the calling thread, hands them to its workers and
/// hands the finished pipeline back, all inside libtbb, which ThreadSanitizer does not see (the
/// library is not instrumented): a worker's first read of a filter's captures looks like a race
/// with their construction, and the caller's next use of that stack memory like a race with the
/// workers. give() before the pipeline, Body at the top of each filter body and collect() after
/// it tell TSan of both hand-overs (no-ops otherwise), each on its own address so that no edge
/// goes from one body to another: races inside the bodies are still reported
/// (tests/tsan/RaceCanary.cc). Static, so that a body reaches it without reading a capture.
struct FilterHandOver
{
    char toWorkers = 0, toCaller = 0;
    void give() { IVDB_TSAN_RELEASE(&toWorkers); }
    void collect() { IVDB_TSAN_ACQUIRE(&toCaller); }
    struct Body
    {
        Body();
        ~Body();
    };
} gFilterHandOver;

FilterHandOver::Body::Body() { IVDB_TSAN_ACQUIRE(&gFilterHandOver.toWorkers); }
FilterHandOver::Body::~Body() { IVDB_TSAN_RELEASE(&gFilterHandOver.toCaller); }

/// How many frames may be made at once: @a given if > 0, else as many as there are threads,
/// while that many of the first frame's peak memory (@a frameBytes) fits the memory budget.
std::size_t framesInFlight(int given, std::uint64_t frameBytes)
{
    if (given > 0) return std::size_t(given);
    const std::size_t threads = tbb::this_task_arena::max_concurrency();
    const double fit = util::memoryBudget() / double(std::max<std::uint64_t>(frameBytes, 1));
    return std::max<std::size_t>(1, std::min<std::size_t>(threads, std::size_t(std::max(fit, 1.0))));
}

} // namespace

SequenceResult rasterizeSequence(const SequenceOptions& opt)
{
    Stopwatch clock;
    check(limits::kParallelFrames, opt.parallelFrames);
    Sequence seq(opt, sequenceFrames(opt));
    util::InterruptScope scope(opt.base.interrupter, "rasterize frames");
    // The frames in order, or from the caller's source. Called by one stage at a time; atomic
    // because libtbb, which TSan does not see, orders that stage's runs on different threads.
    std::atomic<std::size_t> next{0};
    const auto nextFrame = [&]() -> std::optional<std::size_t> {
        if (util::wasInterrupted(opt.base.interrupter)) return std::nullopt;
        if (opt.nextFrame) return opt.nextFrame();
        const std::size_t i = next++;
        return i < seq.size() ? std::optional<std::size_t>(i) : std::nullopt;
    };
    // A frame's serial stretches (reading the scene, opening, syncing and renaming its file)
    // leave cores idle, so several frames run at once (docs/performance.md#sequences); the
    // first runs alone to measure their memory.
    const std::uint64_t before = util::residentMemory();
    const std::optional<std::size_t> first = nextFrame();
    if (first) {
        seq.make(*first);
        seq.deliver();
    }
    const std::uint64_t frameBytes = util::peakResidentMemory() - std::min(before, util::peakResidentMemory());
    try {
        const auto frames =
            tbb::make_filter<void, std::size_t>(tbb::filter_mode::serial_in_order,
                [&](tbb::flow_control& fc) -> std::size_t {
                    const FilterHandOver::Body body;
                    const std::optional<std::size_t> i = nextFrame();
                    if (!i) fc.stop();
                    return i.value_or(0);
                }) &
            tbb::make_filter<std::size_t, void>(tbb::filter_mode::parallel, [&](std::size_t i) {
                const FilterHandOver::Body body;
                // Each frame in a context of its own: when another frame fails, the pipeline is
                // cancelled, and a cancelled context's parallel loops skip their work silently;
                // this frame finishes (or stops at the interrupter) on its own.
                // Reports are delivered (and their grids freed) in that context too: OpenVDB
                // frees a tree's nodes in a parallel loop, which a cancelled pipeline would skip,
                // leaking them.
                tbb::task_group_context isolated(tbb::task_group_context::isolated);
                tbb::task_group frame(isolated);
                frame.run_and_wait([&] {
                    seq.make(i);
                    seq.deliver();
                });
            });
        gFilterHandOver.give();
        if (first) tbb::parallel_pipeline(framesInFlight(opt.parallelFrames, frameBytes), frames);
        gFilterHandOver.collect();
    } catch (...) {
        gFilterHandOver.collect();
        seq.deliver(true); // the frames that were written before the failure
        throw;
    }
    seq.deliver(true);
    util::checkInterrupt(opt.base.interrupter);
    scope.end();
    SequenceResult result = seq.result();
    result.totalSeconds = clock.total();
    return result;
}

} // namespace ivdb::jobs
