// SPDX-License-Identifier: Apache-2.0
// ivdb-mpi's sequences: the frames of a keyed scene handed out to the ranks as they become free.
// Each rank makes its frames as plain ivdb does (jobs::rasterizeSequence, several at once on its
// threads), one .vdb file each; rank 0 hands out the frames and reports them in frame order.
//
// MPI is called only from each rank's main thread (MPI_THREAD_FUNNELED): the frames are made on
// a thread of their own, which asks the main thread for its next frame and gives it its reports;
// the main thread carries those to rank 0 and back.
#include <ivdb/mpi/Rasterize.h>

#include "Common.h"

#include <ivdb/scene/Animation.h>
#include <ivdb/util/Params.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <thread>

namespace ivdb::mpi {

using namespace detail;

namespace {

// The messages between a rank's main thread and rank 0's.
enum Tag : int {
    kAsk = 1,    ///< a rank asks for a frame (no payload)
    kGive = 2,   ///< rank 0's answer: the frame's index, or -1 for none
    kReport = 3, ///< a frame done: its report (JSON)
    kDone = 4    ///< a rank's frames are all done: 0, or 1 if it failed
};

std::string encodeReport(const jobs::FrameReport& f)
{
    const jobs::RasterizeResult& r = f.result;
    const nlohmann::json j{
        {"index", f.index}, {"frame", f.frame}, {"output", f.output}, {"skipped", f.skipped},
        {"rank", f.rank}, {"peak", f.peakMemory}, {"voxels", r.activeVoxels},
        {"grid", r.gridBytes}, {"file", r.fileBytes}, {"compute", r.computeSeconds},
        {"total", r.totalSeconds}, {"notes", r.notes},
        {"stats", {r.stats.localDistances, r.stats.searchedDistances,
                   r.stats.approximateDistances, r.stats.sweptDistances}}};
    return j.dump();
}

jobs::FrameReport decodeReport(const std::string& text, std::size_t count)
{
    const nlohmann::json j = nlohmann::json::parse(text);
    jobs::FrameReport f;
    f.index = j.at("index");
    f.count = count;
    f.frame = j.at("frame");
    f.output = j.at("output");
    f.skipped = j.at("skipped");
    f.rank = j.at("rank");
    f.peakMemory = j.at("peak");
    jobs::RasterizeResult& r = f.result;
    r.activeVoxels = j.at("voxels");
    r.gridBytes = j.at("grid");
    r.fileBytes = j.at("file");
    r.computeSeconds = j.at("compute");
    r.totalSeconds = j.at("total");
    r.notes = j.at("notes").get<std::vector<std::string>>();
    const auto& s = j.at("stats");
    r.stats.localDistances = s.at(0);
    r.stats.searchedDistances = s.at(1);
    r.stats.approximateDistances = s.at(2);
    r.stats.sweptDistances = s.at(3);
    return f;
}

/// This rank's frames, made on a thread of their own; what that thread needs from the main
/// thread (a next frame, a report carried) waits here for it.
class Maker
{
public:
    /// Start making the frames of @a opt, with @a nextFrame and @a onFrame called on the
    /// making thread.
    Maker(jobs::SequenceOptions opt) : mOpt(std::move(opt))
    {
        mThread = std::thread([this] {
            mError = captured([this] { jobs::rasterizeSequence(mOpt); }, mMessage);
            std::lock_guard<std::mutex> lock(mMutex);
            mFinished = true;
            mChanged.notify_all();
        });
    }

    ~Maker()
    {
        if (mThread.joinable()) mThread.join();
    }

    /// Wait for the making thread to end; its error (null if none) and message.
    std::exception_ptr join(std::string& message)
    {
        mThread.join();
        message = mMessage;
        return mError;
    }

    /// Making thread: wait for the main thread's answer to ask().
    std::optional<std::size_t> ask()
    {
        std::unique_lock<std::mutex> lock(mMutex);
        mAsking = true;
        mChanged.notify_all();
        mChanged.wait(lock, [this] { return mAnswered; });
        mAnswered = false;
        return mAnswer;
    }

    /// Making thread: hand a report to the main thread.
    void report(std::string text)
    {
        std::lock_guard<std::mutex> lock(mMutex);
        mOutbox.push_back(std::move(text));
        mChanged.notify_all();
    }

    /// What the main thread has to do next.
    struct Work
    {
        std::deque<std::string> reports; ///< to send
        bool asking = false;             ///< then answer() a frame
        bool finished = false;           ///< the making thread is done (after the above)
        bool failed = false;             ///< ... on an error
    };

    /// Main thread: wait (up to @a wait, or for good) until there is something to do.
    Work next(std::optional<std::chrono::milliseconds> wait = std::nullopt)
    {
        std::unique_lock<std::mutex> lock(mMutex);
        const auto ready = [this] { return mAsking || !mOutbox.empty() || mFinished; };
        if (wait) mChanged.wait_for(lock, *wait, ready);
        else mChanged.wait(lock, ready);
        Work w;
        w.reports.swap(mOutbox);
        w.asking = mAsking;
        w.finished = mFinished && !mAsking;
        w.failed = w.finished && mError;
        return w;
    }

    /// Main thread: answer the making thread's ask().
    void answer(std::optional<std::size_t> frame)
    {
        std::lock_guard<std::mutex> lock(mMutex);
        mAsking = false;
        mAnswer = frame;
        mAnswered = true;
        mChanged.notify_all();
    }

private:
    jobs::SequenceOptions mOpt;
    std::thread mThread;
    std::exception_ptr mError;
    std::string mMessage;
    std::mutex mMutex;
    std::condition_variable mChanged;
    std::deque<std::string> mOutbox;
    bool mAsking = false, mAnswered = false, mFinished = false;
    std::optional<std::size_t> mAnswer;
};

/// Rank 0's share-out: the frames in order, each to the first rank that asks, until there are
/// no more or a rank failed; the reports delivered in frame order.
class Dispatcher
{
public:
    Dispatcher(std::size_t count, std::function<void(const jobs::FrameReport&)> onFrame)
        : mCount(count), mOnFrame(std::move(onFrame)) {}

    std::optional<std::size_t> take()
    {
        std::lock_guard<std::mutex> lock(mMutex);
        if (mStopped || mNext >= mCount) return std::nullopt;
        return mNext++;
    }

    void stop()
    {
        std::lock_guard<std::mutex> lock(mMutex);
        mStopped = true;
    }

    void add(jobs::FrameReport report)
    {
        std::lock_guard<std::mutex> lock(mMutex);
        ++mDone;
        mMade.emplace(report.index, std::move(report));
    }

    std::size_t done() const { return mDone.load(); }

    /// Main thread: report the frames whose predecessors are reported (all of them if @a all).
    void deliver(SequenceResult& result, bool all = false)
    {
        for (;;) {
            jobs::FrameReport report;
            {
                std::lock_guard<std::mutex> lock(mMutex);
                auto it = mMade.begin();
                if (it == mMade.end() || (!all && it->first != mDelivered)) return;
                report = std::move(it->second);
                mMade.erase(it);
                mDelivered = report.index + 1;
            }
            ++(report.skipped ? result.skipped : result.written);
            if (!report.skipped) {
                const std::size_t r = std::size_t(report.rank);
                ++result.rankFrames[r];
                // The kernel updates a process's high-water mark lazily: it can read lower
                // at the end than when a frame was done.
                result.rankPeakMemory[r] = std::max(result.rankPeakMemory[r], report.peakMemory);
            }
            if (mOnFrame) mOnFrame(report);
        }
    }

private:
    std::size_t mCount, mNext = 0, mDelivered = 0;
    bool mStopped = false;
    std::atomic<std::size_t> mDone{0};
    std::function<void(const jobs::FrameReport&)> mOnFrame;
    std::mutex mMutex;
    std::map<std::size_t, jobs::FrameReport> mMade;
};

/// Rank 0's main thread: answer the ranks' asks, take their reports, deliver them in order,
/// until every rank (this one's maker too) is done.
void serve(MPI_Comm comm, Maker& maker, Dispatcher& dispatcher, SequenceResult& result,
           util::Interrupter* interrupter)
{
    int open = sizeOf(comm) - 1;
    bool mine = true;
    while (open > 0 || mine) {
        bool busy = false;
        int flag = 0;
        MPI_Status status;
        MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, comm, &flag, &status);
        if (flag) {
            busy = true;
            int bytes = 0;
            MPI_Get_count(&status, MPI_CHAR, &bytes);
            std::string text(std::size_t(bytes), '\0');
            MPI_Recv(text.data(), bytes, MPI_CHAR, status.MPI_SOURCE, status.MPI_TAG, comm,
                     MPI_STATUS_IGNORE);
            if (status.MPI_TAG == kAsk) {
                if (util::wasInterrupted(interrupter)) dispatcher.stop();
                const std::optional<std::size_t> frame = dispatcher.take();
                const std::int64_t answer = frame ? std::int64_t(*frame) : -1;
                MPI_Send(&answer, 1, MPI_INT64_T, status.MPI_SOURCE, kGive, comm);
            } else if (status.MPI_TAG == kReport) {
                dispatcher.add(decodeReport(text, result.frames));
            } else if (status.MPI_TAG == kDone) {
                if (text != "0") dispatcher.stop();
                --open;
            }
        }
        if (mine) {
            const Maker::Work w = maker.next(std::chrono::milliseconds(busy ? 0 : 2));
            for (const std::string& r : w.reports) dispatcher.add(decodeReport(r, result.frames));
            if (w.asking) maker.answer(dispatcher.take());
            if (w.failed) dispatcher.stop();
            if (w.finished) mine = false;
        } else if (!busy) {
            std::this_thread::sleep_for(std::chrono::milliseconds(2));
        }
        dispatcher.deliver(result);
    }
}

/// Another rank's main thread: carry its maker's asks and reports to rank 0 until it is done.
void carry(MPI_Comm comm, Maker& maker)
{
    for (;;) {
        const Maker::Work w = maker.next();
        for (const std::string& r : w.reports) {
            MPI_Send(r.data(), int(r.size()), MPI_CHAR, 0, kReport, comm);
        }
        if (w.asking) {
            MPI_Send(nullptr, 0, MPI_CHAR, 0, kAsk, comm);
            std::int64_t answer = -1;
            MPI_Recv(&answer, 1, MPI_INT64_T, 0, kGive, comm, MPI_STATUS_IGNORE);
            maker.answer(answer < 0 ? std::nullopt : std::optional<std::size_t>(std::size_t(answer)));
        }
        if (w.finished) return;
    }
}

} // namespace

SequenceResult rasterizeSequence(MPI_Comm world, const jobs::SequenceOptions& opt)
{
    const auto start = Clock::now();
    const int rank = rankOf(world), size = sizeOf(world);
    SequenceResult result;
    result.ranks = size;
    result.rankFrames.assign(std::size_t(size), 0);
    result.rankPeakMemory.assign(std::size_t(size), 0);

    // Every rank checks the sequence (every frame's scene and settings) before any is made.
    std::vector<int> frames;
    collective(world, [&] {
        if (opt.base.sampling == raster::Sampling::Dense) {
            throw ParamError(param::kSampling, "dense is the one-process reference (plain ivdb); "
                             "ranks rasterize sparsely");
        }
        if (opt.base.output.empty()) {
            throw ParamError(param::kOutput, "is where the ranks write the frames: give a name "
                             "with # for the frame number", "", ParamError::Kind::Missing);
        }
        frames = jobs::sequenceFrames(opt);
    });
    result.frames = frames.size();

    MPI_Comm comm;
    MPI_Comm_dup(world, &comm);
    jobs::SequenceOptions mine = opt;
    std::optional<Dispatcher> dispatcher;
    std::optional<Maker> maker;
    if (rank == 0) {
        dispatcher.emplace(frames.size(), opt.onFrame);
        mine.nextFrame = [&] { return dispatcher->take(); };
        mine.framesDone = [&] { return dispatcher->done(); };
        mine.onFrame = [&](const jobs::FrameReport& f) { maker->report(encodeReport(f)); };
        maker.emplace(mine);
        serve(comm, *maker, *dispatcher, result, opt.base.interrupter);
    } else {
        mine.nextFrame = [&] { return maker->ask(); };
        mine.onFrame = [&](const jobs::FrameReport& f) {
            jobs::FrameReport sent = f;
            sent.rank = rank;
            maker->report(encodeReport(sent));
        };
        maker.emplace(mine);
        carry(comm, *maker);
    }
    std::string message;
    const std::exception_ptr error = maker->join(message);
    if (rank != 0) {
        const char done = error ? '1' : '0';
        MPI_Send(&done, 1, MPI_CHAR, 0, kDone, comm);
    } else {
        dispatcher->deliver(result, true); // what was made before a failure
    }
    MPI_Comm_free(&comm);

    const std::vector<std::uint64_t> peaks = gatherPeakMemory(world);
    for (std::size_t r = 0; r < peaks.size(); ++r) {
        result.rankPeakMemory[r] = std::max(result.rankPeakMemory[r], peaks[r]);
    }
    raiseTogether(world, error, message);
    double total = secondsSince(start);
    MPI_Allreduce(MPI_IN_PLACE, &total, 1, MPI_DOUBLE, MPI_MAX, world);
    result.totalSeconds = total;
    return result;
}

} // namespace ivdb::mpi
