// SPDX-License-Identifier: Apache-2.0
#include <ivdb/io/AtomicFile.h>

#include "FileOutput.h"

#include <openvdb/Exceptions.h>

#include <atomic>
#include <cerrno>
#include <csignal>
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

// The temporary file being written, for removePendingTemporaryFile() (a signal handler).
char gPendingPath[4096];
volatile std::sig_atomic_t gPendingSet = 0;

void setPending(const std::string& tmp)
{
    gPendingSet = 0;
    std::atomic_signal_fence(std::memory_order_seq_cst);
    if (tmp.size() >= sizeof(gPendingPath)) return;
    std::memcpy(gPendingPath, tmp.c_str(), tmp.size() + 1);
    std::atomic_signal_fence(std::memory_order_seq_cst);
    gPendingSet = 1;
}

void clearPending()
{
    gPendingSet = 0;
    std::atomic_signal_fence(std::memory_order_seq_cst);
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
    if (gPendingSet) ::unlink(gPendingPath);
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
    struct PendingGuard { ~PendingGuard() { clearPending(); } } pendingGuard;
    setPending(tmp);
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
