// SPDX-License-Identifier: Apache-2.0
#include "FileOutput.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <ios>
#include <system_error>

#include <fcntl.h>
#include <unistd.h>

namespace ivdb::io {

namespace {

constexpr std::size_t kBufferBytes = 1 << 20;
constexpr std::uint64_t kWritebackBytes = 8u << 20;

} // namespace

FileOutputBuffer::FileOutputBuffer(int fd): mFd(fd), mBuffer(kBufferBytes)
{
    setp(mBuffer.data(), mBuffer.data() + mBuffer.size());
}

void FileOutputBuffer::writeAt(const char* bytes, std::uint64_t size, std::uint64_t offset) const
{
    while (size > 0) {
        const ::ssize_t n = ::pwrite(mFd, bytes, std::size_t(std::min<std::uint64_t>(size, 1u << 30)),
                                     ::off_t(offset));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            throw std::ios_base::failure("write failed",
                                         std::error_code(n < 0 ? errno : ENOSPC, std::generic_category()));
        }
        bytes += n;
        size -= std::uint64_t(n);
        offset += std::uint64_t(n);
    }
}

void FileOutputBuffer::flushBuffer()
{
    const std::uint64_t n = std::uint64_t(pptr() - pbase());
    if (n > 0) writeAt(pbase(), n, mBufferStart);
    mBufferStart += n;
    mEnd = std::max(mEnd, mBufferStart);
    setp(mBuffer.data(), mBuffer.data() + mBuffer.size());
    startWriteback();
}

void FileOutputBuffer::startWriteback()
{
    if (mEnd < mWrittenBack + kWritebackBytes) return;
    // Advisory: a failure here shows in the fsync that ends the write.
    (void)::sync_file_range(mFd, ::off64_t(mWrittenBack), ::off64_t(mEnd - mWrittenBack),
                            SYNC_FILE_RANGE_WRITE);
    mWrittenBack = mEnd;
}

FileOutputBuffer::int_type FileOutputBuffer::overflow(int_type c)
{
    flushBuffer();
    if (!traits_type::eq_int_type(c, traits_type::eof())) {
        *pptr() = traits_type::to_char_type(c);
        pbump(1);
    }
    return traits_type::not_eof(c);
}

std::streamsize FileOutputBuffer::xsputn(const char* s, std::streamsize n)
{
    if (std::uint64_t(n) >= mBuffer.size()) {
        // Large blocks go straight to the file.
        flushBuffer();
        writeAt(s, std::uint64_t(n), mBufferStart);
        mBufferStart += std::uint64_t(n);
        mEnd = std::max(mEnd, mBufferStart);
        startWriteback();
        return n;
    }
    if (n > epptr() - pptr()) flushBuffer();
    std::memcpy(pptr(), s, std::size_t(n));
    pbump(int(n));
    return n;
}

int FileOutputBuffer::sync()
{
    flushBuffer();
    return 0;
}

FileOutputBuffer::pos_type FileOutputBuffer::seekoff(off_type off, std::ios_base::seekdir dir,
                                                     std::ios_base::openmode mode)
{
    const std::uint64_t here = mBufferStart + std::uint64_t(pptr() - pbase());
    if (dir == std::ios_base::cur && off == 0) return pos_type(off_type(here)); // tellp()
    flushBuffer();
    off_type base = 0;
    if (dir == std::ios_base::cur) base = off_type(here);
    else if (dir == std::ios_base::end) base = off_type(mEnd);
    return seekpos(pos_type(base + off), mode);
}

FileOutputBuffer::pos_type FileOutputBuffer::seekpos(pos_type pos, std::ios_base::openmode)
{
    if (off_type(pos) < 0) return pos_type(off_type(-1));
    flushBuffer();
    mBufferStart = std::uint64_t(off_type(pos));
    mEnd = std::max(mEnd, mBufferStart); // (bytes written past the buffer end there)
    return pos;
}

} // namespace ivdb::io
