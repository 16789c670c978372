// SPDX-License-Identifier: Apache-2.0
#include <ivdb/io/AtomicFile.h>

#include "FileOutput.h"

#include <openvdb/Exceptions.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <ostream>
#include <system_error>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace ivdb::io {

namespace fs = std::filesystem;

namespace {

// The temporary files being written, for removePendingTemporaryFile(), which a signal handler
// calls: several at once when a sequence writes frames in parallel. Fixed slots and lock-free
// atomics only (no allocation, no lock), each slot's path guarded by a sequence number that is odd
// while the path is being copied in, so the handler never unlinks a half-copied name.
constexpr int kPendingSlots = 64;

struct PendingSlot
{
    std::atomic<bool> taken{false};   // owned by one writer
    std::atomic<unsigned> sequence{0}; // even: path stable; odd: being copied
    std::atomic<bool> live{false};    // path names a temporary file to remove
    char path[4096];
};
static_assert(std::atomic<unsigned>::is_always_lock_free && std::atomic<bool>::is_always_lock_free);

PendingSlot gPending[kPendingSlots];

/// The slot now holding @a tmp, or -1 (a path too long, or more than kPendingSlots files being
/// written at once: that file is then left behind by a signal, as by SIGKILL).
int setPending(const std::string& tmp)
{
    if (tmp.size() >= sizeof(gPending[0].path)) return -1;
    for (int i = 0; i < kPendingSlots; ++i) {
        PendingSlot& slot = gPending[i];
        if (slot.taken.exchange(true)) continue;
        slot.sequence.fetch_add(1);
        std::memcpy(slot.path, tmp.c_str(), tmp.size() + 1);
        slot.sequence.fetch_add(1);
        slot.live.store(true);
        return i;
    }
    return -1;
}

void clearPending(int i)
{
    if (i < 0) return;
    gPending[i].live.store(false);
    gPending[i].taken.store(false);
}

[[noreturn]] void ioError(const std::string& path, const std::string& what)
{
    OPENVDB_THROW(openvdb::IoError, path + ": " + what);
}

std::string folderOf(const std::string& path)
{
    const fs::path p(path);
    return p.has_parent_path() ? p.parent_path().string() : std::string(".");
}

} // namespace

void checkOutputPath(const std::string& path)
{
    if (path.empty()) ioError("(output)", "the output path is empty");
    std::error_code ec;
    if (fs::is_directory(path, ec)) ioError(path, "is a folder; give a file name such as out.vdb");
    if (fs::exists(path, ec) && !fs::is_regular_file(path, ec)) {
        ioError(path, "exists and is not a regular file (a device or a socket?); give a file path");
    }
    const std::string dir = folderOf(path);
    if (!fs::is_directory(dir, ec)) {
        ioError(path, "the folder '" + dir + "' does not exist; create it first");
    }
    if (::access(dir.c_str(), W_OK) != 0) {
        ioError(path, "the folder '" + dir + "' is not writable (" + std::strerror(errno) + ")");
    }
}

void removePendingTemporaryFile() noexcept
{
    for (PendingSlot& slot : gPending) {
        if (!slot.live.load()) continue;
        const unsigned before = slot.sequence.load();
        if (before % 2 != 0) continue;
        char path[sizeof(slot.path)];
        std::memcpy(path, slot.path, sizeof(path));
        path[sizeof(path) - 1] = '\0';
        if (slot.sequence.load() == before && slot.live.load()) ::unlink(path);
    }
}

void writeFileAtomically(const std::string& path,
                         const std::function<void(std::ostream&)>& write)
{
    checkOutputPath(path);
    static std::atomic<unsigned> counter{0};
    const fs::path target(path);
    const std::string tmp = (fs::path(folderOf(path)) /
        ("." + target.filename().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
         std::to_string(counter++))).string();
    // Cleared on every way out: the temporary file is renamed or removed by then.
    struct PendingGuard
    {
        int slot;
        ~PendingGuard() { clearPending(slot); }
    } pendingGuard{setPending(tmp)};
    try {
        const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
        if (fd < 0) ioError(path, std::string("cannot create a file there: ") + std::strerror(errno));
        struct FdGuard { int fd; ~FdGuard() { if (fd >= 0) ::close(fd); } } guard{fd};
        {
            FileOutputBuffer buffer(fd);
            std::ostream os(&buffer);
            os.exceptions(std::ios::badbit | std::ios::failbit);
            write(os);
            os.flush();
        }
        if (::fsync(fd) != 0) {
            ioError(path, std::string("cannot sync the written file: ") + std::strerror(errno));
        }
        guard.fd = -1;
        if (::close(fd) != 0) {
            ioError(path, std::string("cannot close the written file: ") + std::strerror(errno));
        }
        if (std::rename(tmp.c_str(), path.c_str()) != 0) {
            ioError(path, std::string("cannot rename the temporary file into place: ") +
                              std::strerror(errno));
        }
    } catch (const openvdb::IoError&) {
        std::remove(tmp.c_str());
        throw;
    } catch (const std::ios_base::failure& e) {
        // FileOutputBuffer's failures carry errno; the stream's own ones do not.
        const int err = e.code().category() == std::generic_category() ? e.code().value() : errno;
        std::remove(tmp.c_str());
        ioError(path, std::string("cannot write: ") + (err ? std::strerror(err) : "stream error") +
                          " (is the disk full?)");
    } catch (const std::exception& e) {
        std::remove(tmp.c_str());
        ioError(path, std::string("cannot write: ") + e.what());
    }
}

} // namespace ivdb::io
