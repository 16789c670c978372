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

/// A frame's report as sent to rank 0 (no grids, no file name: rank 0 makes it from the
/// pattern). Notes may name files whose names are not UTF-8: such bytes are replaced.
std::string encodeReport(const jobs::FrameReport& f)
{
    const jobs::RasterizeResult& r = f.result;
    const nlohmann::json j{
        {"index", f.index}, {"frame", f.frame}, {"skipped", f.skipped},
        {"rank", f.rank}, {"peak", f.peakMemory}, {"voxels", r.activeVoxels},
        {"grid", r.gridBytes}, {"file", r.fileBytes}, {"compute", r.computeSeconds},
        {"total", r.totalSeconds}, {"notes", r.notes},
        {"stats", {r.stats.localDistances, r.stats.searchedDistances,
                   r.stats.approximateDistances, r.stats.sweptDistances}}};
    return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

jobs::FrameReport decodeReport(const std::string& text, std::size_t count,
                               const std::string& pattern)
{
    const nlohmann::json j = nlohmann::json::parse(text);
    jobs::FrameReport f;
    f.index = j.at("index");
    f.count = count;
    f.frame = j.at("frame");
    f.output = scene::frameFileName(pattern, f.frame);
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
    /// The frames of @a opt, whose nextFrame and onFrame are called on the making thread.
    explicit Maker(jobs::SequenceOptions opt) : mOpt(std::move(opt)) {}

    /// Start making them (once the callbacks' targets exist).
    void start()
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
        mAskSeen = false;
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
        bool asking = false;             ///< a new ask: answer() it (now or later)
        bool finished = false;           ///< the making thread is done (after the above)
        bool failed = false;             ///< ... on an error
    };

    /// Main thread: wait (up to @a wait, or for good) until there is something to do.
    Work next(std::optional<std::chrono::milliseconds> wait = std::nullopt)
    {
        std::unique_lock<std::mutex> lock(mMutex);
        const auto ready = [this] { return (mAsking && !mAskSeen) || !mOutbox.empty() || mFinished; };
        if (wait) mChanged.wait_for(lock, *wait, ready);
        else mChanged.wait(lock, ready);
        Work w;
        w.reports.swap(mOutbox);
        w.asking = mAsking && !mAskSeen;
        mAskSeen = mAskSeen || mAsking;
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
    bool mAsking = false, mAskSeen = false, mAnswered = false, mFinished = false;
    std::optional<std::size_t> mAnswer;
};

/// Rank 0's share-out: the frames in order, each to a rank that asks, until there are no more
/// or a rank failed; at most an equal share of the frames in flight on one rank at a time (a
/// rank with many threads asks for as many frames at once); the reports delivered in frame
/// order.
class Dispatcher
{
public:
    /// What a rank that asks gets.
    struct Answer
    {
        bool wait = false;                  ///< nothing yet: ask again once a frame is done
        std::optional<std::size_t> frame;   ///< else the frame, or none: no more
    };

    Dispatcher(std::size_t count, int ranks, std::function<void(const jobs::FrameReport&)> onFrame)
        : mCount(count), mCap(std::max<std::size_t>(1, (count + std::size_t(ranks) - 1) / std::size_t(ranks))),
          mInFlight(std::size_t(ranks), 0), mOnFrame(std::move(onFrame)) {}

    Answer take(int rank)
    {
        std::lock_guard<std::mutex> lock(mMutex);
        Answer a;
        if (mStopped || mNext >= mCount) return a;
        if (mInFlight[std::size_t(rank)] >= mCap) {
            a.wait = true;
            return a;
        }
        ++mInFlight[std::size_t(rank)];
        a.frame = mNext++;
        return a;
    }

    void stop()
    {
        std::lock_guard<std::mutex> lock(mMutex);
        mStopped = true;
    }

    void add(jobs::FrameReport report)
    {
        std::lock_guard<std::mutex> lock(mMutex);
        std::size_t& flying = mInFlight[std::size_t(report.rank)];
        flying -= flying > 0 ? 1 : 0;
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
    std::size_t mCount, mCap, mNext = 0, mDelivered = 0;
    std::vector<std::size_t> mInFlight;
    bool mStopped = false;
    std::atomic<std::size_t> mDone{0};
    std::function<void(const jobs::FrameReport&)> mOnFrame;
    std::mutex mMutex;
    std::map<std::size_t, jobs::FrameReport> mMade;
};

/// Rank 0's main thread: answer the ranks' asks (later, for a rank at its share in flight),
/// take their reports, deliver them in order, until every rank (this one's maker too) is done.
/// A failure here (out of memory, the caller's onFrame throwing) stops the handing out and the
/// delivering but not the serving, so that no rank waits for ever; it is returned, with its
/// text in @a message.
std::exception_ptr serve(MPI_Comm comm, Maker& maker, Dispatcher& dispatcher,
                         SequenceResult& result, const jobs::SequenceOptions& opt,
                         std::string& message)
{
    std::exception_ptr failure;
    const auto guarded = [&](auto&& step) {
        if (failure) return;
        failure = captured(step, message);
        if (failure) dispatcher.stop();
    };
    const std::string& pattern = opt.base.output;
    int open = sizeOf(comm) - 1;
    bool mine = true;
    std::deque<int> waiting; // ranks whose ask is not answered yet
    bool ownAsk = false;     // this rank's maker's
    const auto answer = [&](int rank) {
        if (util::wasInterrupted(opt.base.interrupter)) dispatcher.stop();
        const Dispatcher::Answer a = dispatcher.take(rank);
        if (a.wait) return false;
        const std::int64_t frame = a.frame ? std::int64_t(*a.frame) : -1;
        MPI_Send(&frame, 1, MPI_INT64_T, rank, kGive, comm);
        return true;
    };
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
                waiting.push_back(status.MPI_SOURCE);
            } else if (status.MPI_TAG == kReport) {
                guarded([&] { dispatcher.add(decodeReport(text, result.frames, pattern)); });
            } else if (status.MPI_TAG == kDone) {
                if (text != "0") dispatcher.stop();
                --open;
            }
        }
        for (std::size_t k = waiting.size(); k-- > 0;) {
            const int rank = waiting.front();
            waiting.pop_front();
            if (!answer(rank)) waiting.push_back(rank);
        }
        if (mine) {
            const Maker::Work w = maker.next(std::chrono::milliseconds(busy ? 0 : 2));
            for (const std::string& r : w.reports) {
                guarded([&] { dispatcher.add(decodeReport(r, result.frames, pattern)); });
            }
            ownAsk = ownAsk || w.asking;
            if (ownAsk) {
                if (util::wasInterrupted(opt.base.interrupter)) dispatcher.stop();
                const Dispatcher::Answer a = dispatcher.take(0);
                if (!a.wait) {
                    maker.answer(a.frame);
                    ownAsk = false;
                }
            }
            if (w.failed) dispatcher.stop();
            if (w.finished) mine = false;
        } else if (!busy) {
            std::this_thread::sleep_for(std::chrono::milliseconds(2));
        }
        guarded([&] { dispatcher.deliver(result); });
    }
    guarded([&] { dispatcher.deliver(result, true); }); // what was made before a failure
    return failure;
}

/// Another rank's main thread: carry its maker's asks and reports to rank 0 until it is done.
/// While an ask waits for rank 0's answer, the reports keep going (rank 0 may be waiting for
/// one of them to answer).
void carry(MPI_Comm comm, Maker& maker)
{
    std::optional<MPI_Request> asked;
    std::int64_t answer = -1;
    for (;;) {
        const Maker::Work w = maker.next(std::chrono::milliseconds(asked ? 2 : 50));
        for (const std::string& r : w.reports) {
            MPI_Send(r.data(), int(r.size()), MPI_CHAR, 0, kReport, comm);
        }
        if (w.asking && !asked) {
            MPI_Send(nullptr, 0, MPI_CHAR, 0, kAsk, comm);
            asked.emplace();
            MPI_Irecv(&answer, 1, MPI_INT64_T, 0, kGive, comm, &*asked);
        }
        if (asked) {
            int flag = 0;
            MPI_Test(&*asked, &flag, MPI_STATUS_IGNORE);
            if (flag) {
                asked.reset();
                maker.answer(answer < 0 ? std::nullopt
                                        : std::optional<std::size_t>(std::size_t(answer)));
            }
        }
        if (w.finished && !asked) return;
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
    Maker* maker = nullptr; // set before its thread starts
    if (rank == 0) {
        dispatcher.emplace(frames.size(), size, opt.onFrame);
        mine.nextFrame = [&]() { return maker->ask(); };
        mine.framesDone = [&] { return dispatcher->done(); };
        mine.onFrame = [&](const jobs::FrameReport& f) { maker->report(encodeReport(f)); };
    } else {
        mine.nextFrame = [&]() { return maker->ask(); };
        mine.onFrame = [&](const jobs::FrameReport& f) {
            jobs::FrameReport sent = f;
            sent.rank = rank;
            maker->report(encodeReport(sent));
        };
    }
    Maker making(mine);
    maker = &making;
    making.start();
    std::string message, served;
    std::exception_ptr failure;
    if (rank == 0) failure = serve(comm, making, *dispatcher, result, opt, served);
    else carry(comm, making);
    std::exception_ptr error = making.join(message);
    if (!error && failure) {
        error = failure;
        message = served;
    }
    if (rank != 0) {
        const char done = error ? '1' : '0';
        MPI_Send(&done, 1, MPI_CHAR, 0, kDone, comm);
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
