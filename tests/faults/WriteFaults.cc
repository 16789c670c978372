// SPDX-License-Identifier: Apache-2.0
// Write failures on demand, for the CLI tests: preloaded into an ivdb run (LD_PRELOAD), it makes
// the writes of ivdb's temporary output files (the hidden ".NAME.tmp-PID-N" that
// io::writeFileAtomically renames into place) fail the way a full or failing disk does, so the
// error paths run on every machine, without root or a tmpfs to fill.
//
// IVDB_FAULT chooses the fault (nothing happens without it):
//   enospc:N   once N bytes of a temporary file are written, pwrite fails with ENOSPC
//   eio:N      the same with EIO
//   zero:N     the same, but pwrite returns 0 (a device that takes nothing, no errno)
//   short:N    every pwrite writes at most N bytes (legal: the caller must loop)
//   fsync-eio  fsync of a temporary file fails with EIO
//   pause[:S[:H]]  the first S temporary files (default 0) are written normally; the first
//              pwrite of each later one waits (up to a minute) for a signal, and once H of them
//              (default 1) wait, the file named by IVDB_FAULT_MARK is created: a test signals a
//              run that is certainly in the middle of writing H outputs at once
// Other files (inputs, standard streams) are never touched.
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <mutex>
#include <set>
#include <string>

#include <dlfcn.h>
#include <fcntl.h>
#include <unistd.h>

namespace {

enum class Fault { None, Enospc, Eio, Zero, Short, FsyncEio, Pause };

struct Config
{
    Fault fault = Fault::None;
    long long bytes = 0;       // enospc, eio, zero, short: N; pause: S
    long long holdCount = 1;   // pause: H
};

Config readConfig()
{
    Config c;
    const char* v = std::getenv("IVDB_FAULT");
    if (!v) return c;
    const char* colon = std::strchr(v, ':');
    const std::size_t len = colon ? std::size_t(colon - v) : std::strlen(v);
    const auto is = [&](const char* name) { return std::strlen(name) == len && std::strncmp(v, name, len) == 0; };
    if (is("enospc")) c.fault = Fault::Enospc;
    else if (is("eio")) c.fault = Fault::Eio;
    else if (is("zero")) c.fault = Fault::Zero;
    else if (is("short")) c.fault = Fault::Short;
    else if (is("fsync-eio")) c.fault = Fault::FsyncEio;
    else if (is("pause")) c.fault = Fault::Pause;
    else {
        std::fprintf(stderr, "WriteFaults: unknown IVDB_FAULT '%s'\n", v);
        std::abort();
    }
    if (colon) c.bytes = std::atoll(colon + 1);
    if (const char* second = colon ? std::strchr(colon + 1, ':') : nullptr) c.holdCount = std::atoll(second + 1);
    return c;
}

const Config& config()
{
    static const Config c = readConfig();
    return c;
}

/// The path @a fd is open on ("" if unknown).
std::string pathOf(int fd)
{
    char link[64], target[4096];
    std::snprintf(link, sizeof(link), "/proc/self/fd/%d", fd);
    const ssize_t n = ::readlink(link, target, sizeof(target) - 1);
    return n > 0 ? std::string(target, std::size_t(n)) : std::string();
}

/// True if @a fd is one of ivdb's temporary output files.
bool isTemporaryOutput(int fd)
{
    return pathOf(fd).find(".tmp-") != std::string::npos;
}

std::atomic<long long> gWritten{0};
std::atomic<long long> gFiles{0}, gHeld{0}; // pause: temporary files seen, writes held

/// True the first time @a fd's file is written (by its path: a file descriptor is reused).
bool firstWrite(int fd)
{
    static std::mutex mutex;
    static std::set<std::string> seen;
    const std::string path = pathOf(fd);
    std::lock_guard<std::mutex> lock(mutex);
    return seen.insert(path).second;
}

using PwriteFn = ssize_t (*)(int, const void*, size_t, off_t);

ssize_t faultyPwrite(PwriteFn real, int fd, const void* buf, size_t count, off_t offset)
{
    const Config& c = config();
    if (c.fault == Fault::None || c.fault == Fault::FsyncEio || !isTemporaryOutput(fd)) {
        return real(fd, buf, count, offset);
    }
    switch (c.fault) {
    case Fault::Short:
        return real(fd, buf, count < size_t(c.bytes) ? count : size_t(c.bytes), offset);
    case Fault::Pause: {
        if (firstWrite(fd) && gFiles.fetch_add(1) >= c.bytes) {
            if (gHeld.fetch_add(1) + 1 == c.holdCount) {
                if (const char* mark = std::getenv("IVDB_FAULT_MARK")) {
                    const int m = ::open(mark, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
                    if (m >= 0) ::close(m);
                }
            }
            // A signal handler that returns (a cooperative interrupt) ends the wait early.
            for (int i = 0; i < 600; ++i) {
                const struct timespec tenth{0, 100000000L};
                if (::nanosleep(&tenth, nullptr) != 0) break;
            }
        }
        return real(fd, buf, count, offset);
    }
    default: {
        // Fail the write that would cross N bytes; the bytes before it are written.
        const long long before = gWritten.fetch_add((long long)count);
        if (before + (long long)count <= c.bytes) return real(fd, buf, count, offset);
        if (c.fault == Fault::Zero) return 0;
        errno = c.fault == Fault::Enospc ? ENOSPC : EIO;
        return -1;
    }
    }
}

template<typename Fn>
Fn next(const char* name)
{
    return reinterpret_cast<Fn>(::dlsym(RTLD_NEXT, name));
}

} // namespace

extern "C" {

ssize_t pwrite(int fd, const void* buf, size_t count, off_t offset)
{
    static const PwriteFn real = next<PwriteFn>("pwrite");
    return faultyPwrite(real, fd, buf, count, offset);
}

ssize_t pwrite64(int fd, const void* buf, size_t count, off_t offset)
{
    static const PwriteFn real = next<PwriteFn>("pwrite64");
    return faultyPwrite(real, fd, buf, count, offset);
}

int fsync(int fd)
{
    using FsyncFn = int (*)(int);
    static const FsyncFn real = next<FsyncFn>("fsync");
    if (config().fault == Fault::FsyncEio && isTemporaryOutput(fd)) {
        errno = EIO;
        return -1;
    }
    return real(fd);
}

} // extern "C"
