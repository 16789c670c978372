// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <functional>
#include <ostream>
#include <string>

namespace ivdb::io {

/// @brief Fail early, before a long computation, if @a path cannot become an output file: its
/// folder must exist and be writable, and @a path must not be a folder.
/// @throw openvdb::IoError naming the path and the reason
void checkOutputPath(const std::string& path);

/// @brief Write a file atomically: @a write fills a stream on a temporary file in @a path's
/// folder (`.NAME.tmp-PID-N`), which is then flushed, synced and renamed over @a path. A failure
/// (a full disk, an exception from @a write) removes the temporary file and leaves @a path as it
/// was. Stream errors throw inside @a write (the stream has exceptions enabled). Every writer of
/// the library (.vdb, meshes, images, CSV) goes through here.
/// @throw openvdb::IoError naming the path and the reason
void writeFileAtomically(const std::string& path,
                         const std::function<void(std::ostream&)>& write);

/// @brief Remove the temporary files that writeFileAtomically is writing now, if any (several
/// threads may be writing files at once).
/// @details Async-signal-safe (lock-free atomics and unlink): for a signal handler that is about
/// to end the process, so that an interrupted write leaves nothing behind.
void removePendingTemporaryFile() noexcept;

} // namespace ivdb::io
