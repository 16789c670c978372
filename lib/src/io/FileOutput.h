// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <cstdint>
#include <streambuf>
#include <vector>

namespace ivdb::io {

/// @brief A buffered stream buffer over a file descriptor (positioned writes: pwrite); blocks
/// of a megabyte or more go to the file without a copy.
/// @details A failed write throws std::ios_base::failure carrying errno (ENOSPC, EFBIG, ...), so
/// the message names the cause; an std::ostream over this buffer with exceptions(badbit) passes
/// it on unchanged. (Writing the leaves' buffers from several threads at once gains nothing on
/// ext4, which serializes writes to one file on the inode's lock.)
class FileOutputBuffer: public std::streambuf
{
public:
    /// @param fd  an open, writable file descriptor; not closed here
    explicit FileOutputBuffer(int fd);

protected:
    int_type overflow(int_type c) override;
    std::streamsize xsputn(const char* s, std::streamsize n) override;
    int sync() override;
    pos_type seekoff(off_type off, std::ios_base::seekdir dir, std::ios_base::openmode) override;
    pos_type seekpos(pos_type pos, std::ios_base::openmode mode) override;

private:
    /// Write @a size bytes at @a offset, bypassing the buffer. @throw std::ios_base::failure
    void writeAt(const char* bytes, std::uint64_t size, std::uint64_t offset) const;
    void flushBuffer();
    /// Start the kernel writing back what has been written so far, every few megabytes
    /// (sync_file_range, which does not wait for it): the fsync that ends a write then finds
    /// most of the file on disk, the disk having worked while the rest was compressed.
    void startWriteback();

    int mFd;
    std::uint64_t mBufferStart = 0; ///< the file offset of the buffer's first byte
    std::uint64_t mEnd = 0;         ///< one past the furthest byte written
    std::uint64_t mWrittenBack = 0; ///< bytes [0, this) are being written back
    std::vector<char> mBuffer;
};

} // namespace ivdb::io
