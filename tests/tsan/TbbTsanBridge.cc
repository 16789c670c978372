// SPDX-License-Identifier: Apache-2.0
// Tells ThreadSanitizer about oneTBB's synchronization, which it cannot see because Debian's
// libtbb is not instrumented. Without this, TSan reports TBB's own bookkeeping (task spawn and
// steal, the partitioner's fold_tree, parallel_reduce joins, reused task memory) as races with
// the caller; with it, a TSan run of the threaded suites is clean, and a real race in a parallel
// body is still reported (checked against deliberate races in parallel_for, parallel_reduce and
// task_group bodies).
//
// Built without sanitizers as libivdb_tbb_tsan.so and used by the TSan stage of
// scripts/sanitize.sh, in two roles:
//
// 1. An ITT "collector": libtbb loads the library named by INTEL_LIBITTNOTIFY64 and binds the
//    ITT functions it exports (by name; as an API-version-1 collector, only the groups listed in
//    INTEL_ITTNOTIFY_GROUPS, so that must be "sync"). TBB calls sync_releasing(p) where it
//    publishes (a spawned task, a finished child in fold_tree, a wait_context release) and
//    sync_acquired(p) where it takes over (before running each task, after a wait): exactly
//    TSan's release and acquire. The header half of these calls exists only when the program is
//    compiled with TBB_USE_PROFILING_TOOLS=2, which the TSan build defines everywhere.
// 2. An LD_PRELOAD shim over libtbb's small-object pool (r1::allocate / r1::deallocate): the pool
//    hands memory from the thread that freed it to the one that allocates it, through atomics
//    inside libtbb; release on free and acquire on allocate model that hand-over, so the next
//    task's constructor does not "race" with the previous owner.
//
// 3. Also an LD_PRELOAD shim over r1::execute_and_wait and r1::wait: the last finishing task
//    ends a wait by an atomic decrement of the wait_context's count, after its ITT release, and
//    the waiting thread sees the zero inside libtbb. Acquiring the count's address when the wait
//    returns pairs with that decrement, so the waiter may reuse the wait_context's stack memory.
//
// Every edge added is synchronization TBB really performs, so no real race is hidden.
#include <dlfcn.h>

#include <cstddef>
#include <cstdio>
#include <cstdlib>

#define IVDB_EXPORT extern "C" __attribute__((visibility("default")))

// From the TSan runtime linked into the instrumented program; weak, so that loading this library
// into another process does nothing.
extern "C" void __tsan_acquire(void* addr) __attribute__((weak));
extern "C" void __tsan_release(void* addr) __attribute__((weak));

namespace {

void acquire(void* p)
{
    if (p && __tsan_acquire) __tsan_acquire(p);
}

void release(void* p)
{
    if (p && __tsan_release) __tsan_release(p);
}

/// libtbb's own definition of a symbol this library interposes.
template<typename Fn>
Fn next(const char* symbol)
{
    void* fn = ::dlsym(RTLD_NEXT, symbol);
    if (!fn) {
        std::fprintf(stderr, "libivdb_tbb_tsan: cannot find %s in libtbb\n", symbol);
        std::abort();
    }
    return reinterpret_cast<Fn>(fn);
}

} // namespace

// ITT: the presence of __itt_api_version makes libtbb bind the functions below by name.
IVDB_EXPORT const char* __itt_api_version() { return "ivdb tbb-tsan bridge 1"; }
IVDB_EXPORT void __itt_sync_acquired(void* addr) { acquire(addr); }
IVDB_EXPORT void __itt_sync_releasing(void* addr) { release(addr); }
IVDB_EXPORT void __itt_sync_create(void*, const char*, const char*, int) {}
IVDB_EXPORT void __itt_sync_rename(void*, const char*) {}
IVDB_EXPORT void __itt_sync_destroy(void*) {}
IVDB_EXPORT void __itt_sync_prepare(void*) {}
IVDB_EXPORT void __itt_sync_cancel(void*) {}
IVDB_EXPORT void __itt_thread_set_name(const char*) {}
IVDB_EXPORT void __itt_thread_ignore() {}
IVDB_EXPORT void* __itt_stack_caller_create() { return nullptr; }
IVDB_EXPORT void __itt_stack_caller_destroy(void*) {}
IVDB_EXPORT void __itt_stack_callee_enter(void*) {}
IVDB_EXPORT void __itt_stack_callee_leave(void*) {}

// The small-object pool (oneTBB 2021, ABI r1), by mangled name:
//   void* r1::allocate(d1::small_object_pool*&, std::size_t)
//   void* r1::allocate(d1::small_object_pool*&, std::size_t, const d1::execution_data&)
//   void  r1::deallocate(d1::small_object_pool&, void*, std::size_t)
//   void  r1::deallocate(d1::small_object_pool&, void*, std::size_t, const d1::execution_data&)
IVDB_EXPORT void* _ZN3tbb6detail2r18allocateERPNS0_2d117small_object_poolEm(void** pool,
                                                                            std::size_t n)
{
    using Fn = void* (*)(void**, std::size_t);
    static const Fn fn = next<Fn>("_ZN3tbb6detail2r18allocateERPNS0_2d117small_object_poolEm");
    void* p = fn(pool, n);
    acquire(p);
    return p;
}

IVDB_EXPORT void*
_ZN3tbb6detail2r18allocateERPNS0_2d117small_object_poolEmRKNS2_14execution_dataE(
    void** pool, std::size_t n, const void* ed)
{
    using Fn = void* (*)(void**, std::size_t, const void*);
    static const Fn fn = next<Fn>(
        "_ZN3tbb6detail2r18allocateERPNS0_2d117small_object_poolEmRKNS2_14execution_dataE");
    void* p = fn(pool, n, ed);
    acquire(p);
    return p;
}

IVDB_EXPORT void _ZN3tbb6detail2r110deallocateERNS0_2d117small_object_poolEPvm(void* pool,
                                                                               void* p,
                                                                               std::size_t n)
{
    using Fn = void (*)(void*, void*, std::size_t);
    static const Fn fn = next<Fn>("_ZN3tbb6detail2r110deallocateERNS0_2d117small_object_poolEPvm");
    release(p);
    fn(pool, p, n);
}

IVDB_EXPORT void
_ZN3tbb6detail2r110deallocateERNS0_2d117small_object_poolEPvmRKNS2_14execution_dataE(
    void* pool, void* p, std::size_t n, const void* ed)
{
    using Fn = void (*)(void*, void*, std::size_t, const void*);
    static const Fn fn = next<Fn>(
        "_ZN3tbb6detail2r110deallocateERNS0_2d117small_object_poolEPvmRKNS2_14execution_dataE");
    release(p);
    fn(pool, p, n, ed);
}

// The waits (d1::wait_context: an 8-byte version word, then the std::atomic<uint64_t> count):
//   void r1::execute_and_wait(d1::task&, d1::task_group_context&, d1::wait_context&,
//                             d1::task_group_context&)
//   void r1::wait(d1::wait_context&, d1::task_group_context&)
namespace {

void acquireWaitContext(void* wait)
{
    acquire(wait);
    acquire(static_cast<char*>(wait) + 8);
}

} // namespace

IVDB_EXPORT void
_ZN3tbb6detail2r116execute_and_waitERNS0_2d14taskERNS2_18task_group_contextERNS2_12wait_contextES6_(
    void* task, void* taskContext, void* wait, void* waitContext)
{
    using Fn = void (*)(void*, void*, void*, void*);
    static const Fn fn = next<Fn>(
        "_ZN3tbb6detail2r116execute_and_waitERNS0_2d14taskERNS2_18task_group_contextERNS2_12wait_"
        "contextES6_");
    fn(task, taskContext, wait, waitContext);
    acquireWaitContext(wait);
}

IVDB_EXPORT void _ZN3tbb6detail2r14waitERNS0_2d112wait_contextERNS2_18task_group_contextE(
    void* wait, void* context)
{
    using Fn = void (*)(void*, void*);
    static const Fn fn =
        next<Fn>("_ZN3tbb6detail2r14waitERNS0_2d112wait_contextERNS2_18task_group_contextE");
    fn(wait, context);
    acquireWaitContext(wait);
}
