// SPDX-License-Identifier: Apache-2.0
#include "FileMapping.h"

#include <openvdb/Exceptions.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

namespace ivdb::io {

FileMapping::FileMapping(const std::string& path)
{
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        OPENVDB_THROW(openvdb::IoError, path + ": cannot open: " + std::strerror(errno));
    }
    struct stat st = {};
    if (::fstat(fd, &st) != 0) {
        const int err = errno;
        ::close(fd);
        OPENVDB_THROW(openvdb::IoError, path + ": cannot get the file size: " + std::strerror(err));
    }
    mSize = std::uint64_t(st.st_size);
    if (mSize > 0) {
        void* p = ::mmap(nullptr, mSize, PROT_READ, MAP_PRIVATE, fd, 0);
        if (p == MAP_FAILED) {
            const int err = errno;
            ::close(fd);
            OPENVDB_THROW(openvdb::IoError, path + ": cannot map the file into memory: " +
                          std::strerror(err));
        }
        mData = static_cast<const char*>(p);
        // Read ahead: the reader goes through most of the file, in large parts at once.
        ::madvise(p, mSize, MADV_WILLNEED);
    }
    ::close(fd);
}

void FileMapping::release(std::uint64_t from, std::uint64_t to) const
{
    const std::uint64_t page = std::uint64_t(::sysconf(_SC_PAGESIZE));
    to = std::min(to, mSize);
    const std::uint64_t a = (from + page - 1) / page * page, b = to / page * page;
    if (mData && b > a) ::madvise(const_cast<char*>(mData) + a, b - a, MADV_DONTNEED);
}

FileMapping::~FileMapping()
{
    if (mData) ::munmap(const_cast<char*>(mData), mSize);
}

MemoryBuffer::MemoryBuffer(const char* begin, std::uint64_t size)
{
    char* b = const_cast<char*>(begin); // never written: the buffer has no put area
    setg(b, b, b + size);
}

MemoryBuffer::pos_type MemoryBuffer::seekoff(off_type off, std::ios_base::seekdir dir,
                                             std::ios_base::openmode)
{
    off_type base = 0;
    if (dir == std::ios_base::cur) base = gptr() - eback();
    else if (dir == std::ios_base::end) base = egptr() - eback();
    const off_type target = base + off;
    if (target < 0 || target > egptr() - eback()) return pos_type(off_type(-1));
    setg(eback(), eback() + target, egptr());
    return pos_type(target);
}

MemoryBuffer::pos_type MemoryBuffer::seekpos(pos_type pos, std::ios_base::openmode mode)
{
    return seekoff(off_type(pos), std::ios_base::beg, mode);
}

std::streamsize MemoryBuffer::xsgetn(char* out, std::streamsize n)
{
    const std::streamsize count = std::min<std::streamsize>(n, egptr() - gptr());
    if (count > 0) {
        std::memcpy(out, gptr(), std::size_t(count));
        setg(eback(), gptr() + count, egptr()); // (gbump takes an int)
    }
    return count;
}

} // namespace ivdb::io
