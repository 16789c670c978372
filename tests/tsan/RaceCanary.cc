// SPDX-License-Identifier: Apache-2.0
// Deliberate data races, one in each kind of TBB parallel body the library uses (parallel_for,
// parallel_reduce, task_group, parallel_pipeline), run by the TSan stage of scripts/sanitize.sh
// with tests/tsan/TbbTsanBridge.cc loaded: TSan must report every one of them (the script looks
// for each function's name), or the bridge (or a suppression) hides real races and the stage
// fails.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_group.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <thread>

namespace {

// Each written by the tasks of one kind without synchronization.
long gFor = 0, gReduce = 0, gGroup = 0, gPipeline = 0;

/// Waits (up to a second) until two tasks of a kind have arrived, so that two of them certainly
/// run at the same time; the unsynchronized writes come after it, so the atomic does not order
/// them.
void rendezvous(std::atomic<int>& arrived)
{
    arrived.fetch_add(1);
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(1);
    while (arrived.load() < 2 && std::chrono::steady_clock::now() < until) std::this_thread::yield();
}

std::atomic<int> gForArrived{0}, gReduceArrived{0}, gGroupArrived{0}, gPipelineArrived{0};

// noinline: each race's report names its own function.
__attribute__((noinline)) void racyFor()
{
    rendezvous(gForArrived);
    for (int i = 0; i < 1000; ++i) gFor = gFor + 1;
}

__attribute__((noinline)) void racyReduce()
{
    rendezvous(gReduceArrived);
    for (int i = 0; i < 1000; ++i) gReduce = gReduce + 1;
}

__attribute__((noinline)) void racyGroup()
{
    rendezvous(gGroupArrived);
    for (int i = 0; i < 1000; ++i) gGroup = gGroup + 1;
}

__attribute__((noinline)) void racyPipeline()
{
    rendezvous(gPipelineArrived);
    for (int i = 0; i < 1000; ++i) gPipeline = gPipeline + 1;
}

} // namespace

int main()
{
    tbb::parallel_for(tbb::blocked_range<int>(0, 64, 1),
                      [](const tbb::blocked_range<int>&) { racyFor(); });
    const long sum = tbb::parallel_reduce(
        tbb::blocked_range<int>(0, 64, 1), 0L,
        [](const tbb::blocked_range<int>& r, long acc) {
            racyReduce();
            return acc + long(r.size());
        },
        [](long a, long b) { return a + b; });
    tbb::task_group group;
    for (int i = 0; i < 16; ++i) group.run([] { racyGroup(); });
    group.wait();
    int next = 0;
    tbb::parallel_pipeline(4,
        tbb::make_filter<void, int>(tbb::filter_mode::serial_in_order,
            [&](tbb::flow_control& fc) {
                if (next == 64) fc.stop();
                return next++;
            }) &
        tbb::make_filter<int, void>(tbb::filter_mode::parallel, [](int) { racyPipeline(); }));
    std::printf("RaceCanary: %ld %ld %ld %ld %ld\n", sum, gFor, gReduce, gGroup, gPipeline);
    return 0;
}
