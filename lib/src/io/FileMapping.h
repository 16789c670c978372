// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <cstdint>
#include <istream>
#include <streambuf>
#include <string>

namespace ivdb::io {

/// @brief A file mapped read-only into memory, for the layout check and the parallel reader:
/// every thread reads its own part through its own MemoryStream, with no copy and no lock.
/// @note The file must not be truncated while mapped (reading a page past its new end raises
/// SIGBUS), as with OpenVDB's own mapped reader.
class FileMapping
{
public:
    /// @throw openvdb::IoError naming @a path if it cannot be opened or mapped
    explicit FileMapping(const std::string& path);
    ~FileMapping();
    FileMapping(const FileMapping&) = delete;
    FileMapping& operator=(const FileMapping&) = delete;

    const char* data() const { return mData; }
    std::uint64_t size() const { return mSize; }

    /// Let the whole pages of [from, to) go from this process's resident memory: they stay in
    /// the page cache, and reading them again maps them back. For a reader that needs only
    /// part of a file after passing over all of it (io::PartialGrid).
    void release(std::uint64_t from, std::uint64_t to) const;

private:
    const char* mData = nullptr;
    std::uint64_t mSize = 0;
};

/// @brief A read-only, seekable stream buffer over bytes in memory; positions count from
/// @a begin. Reading past @a end fails the stream as a file's end does.
class MemoryBuffer: public std::streambuf
{
public:
    MemoryBuffer(const char* begin, std::uint64_t size);

protected:
    pos_type seekoff(off_type off, std::ios_base::seekdir dir, std::ios_base::openmode) override;
    pos_type seekpos(pos_type pos, std::ios_base::openmode) override;
    std::streamsize xsgetn(char* out, std::streamsize n) override;
};

/// @brief An std::istream over bytes in memory (MemoryBuffer).
class MemoryStream: public std::istream
{
public:
    MemoryStream(const char* begin, std::uint64_t size): std::istream(nullptr), mBuffer(begin, size)
    {
        rdbuf(&mBuffer);
    }

private:
    MemoryBuffer mBuffer;
};

} // namespace ivdb::io
