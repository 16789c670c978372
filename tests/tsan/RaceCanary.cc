// SPDX-License-Identifier: Apache-2.0
// A deliberate data race in parallel bodies (parallel_for, parallel_reduce, task_group), run by
// the TSan stage of scripts/sanitize.sh with tests/tsan/TbbTsanBridge.cc loaded: TSan must still
// report it, or the bridge (or a suppression) hides real races and the stage fails.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_group.h>

#include <cstdio>
#include <thread>

namespace {

long gShared = 0; // written by every task without synchronization

void racyBody()
{
    for (int i = 0; i < 1000; ++i) gShared = gShared + 1;
    std::this_thread::yield();
}

} // namespace

int main()
{
    tbb::parallel_for(tbb::blocked_range<int>(0, 64, 1),
                      [](const tbb::blocked_range<int>&) { racyBody(); });
    const long sum = tbb::parallel_reduce(
        tbb::blocked_range<int>(0, 64, 1), 0L,
        [](const tbb::blocked_range<int>& r, long acc) {
            racyBody();
            return acc + long(r.size());
        },
        [](long a, long b) { return a + b; });
    tbb::task_group group;
    for (int i = 0; i < 16; ++i) group.run([] { racyBody(); });
    group.wait();
    std::printf("RaceCanary: %ld %ld\n", sum, gShared);
    return 0;
}
