// SPDX-License-Identifier: Apache-2.0
// Guards around two functions of OpenVDB 10's reader (libopenvdb), which this program's own
// definitions interpose by name (same versioned symbols; the dynamic linker binds both our calls
// and libopenvdb's to the executable's definition).
//
// io::bloscFromStream and io::unzipFromStream read an int64 byte count, and a count <= 0 means
// that -count raw bytes follow. OpenVDB copies those -count bytes into the destination before it
// checks them against the destination's size, so a damaged count overflows the heap (found by
// the fuzz_vdb target: a write of 12756 bytes into a 6878-byte buffer); a positive count is
// allocated as it is (a damaged one asked for 37 PB, also found by fuzz_vdb). Here the count is
// checked first; a valid block is then handed to OpenVDB's own function, unchanged.
#include <openvdb/Exceptions.h>
#include <openvdb/version.h>
#include <openvdb/io/Compression.h>
#include <openvdb/io/DelayedLoadMetadata.h>

#include <dlfcn.h>

#include <cstdint>
#include <cstring>
#include <istream>
#include <string>

// The symbols below are OpenVDB 10.0's (CMakeLists.txt refuses other releases at configure time).
static_assert(OPENVDB_LIBRARY_MAJOR_VERSION_NUMBER == 10 && OPENVDB_LIBRARY_MINOR_VERSION_NUMBER == 0,
              "lib/src/io/StreamGuards.cc interposes OpenVDB 10.0's reader functions by their "
              "mangled names: port it to this OpenVDB release");

namespace {

using ReadFn = void (*)(std::istream&, char*, size_t);

ReadFn original(const char* symbol)
{
    void* fn = ::dlsym(RTLD_NEXT, symbol);
    if (!fn) OPENVDB_THROW(openvdb::IoError, std::string("cannot find OpenVDB's ") + symbol);
    return reinterpret_cast<ReadFn>(fn);
}

/// Check the block's byte count (without consuming it), then let OpenVDB read the block.
void guardedRead(std::istream& is, char* data, size_t numBytes, ReadFn read, bool blosc)
{
    const std::istream::pos_type start = is.tellg();
    std::int64_t count = 0;
    is.read(reinterpret_cast<char*>(&count), sizeof(count));
    if (!is) OPENVDB_THROW(openvdb::IoError, "the file ends inside a compressed block's header");
    // Compressed, the block cannot be much larger than its values (blosc adds 16 bytes, zlib
    // 0.03% + 13); OpenVDB would allocate whatever a damaged count says before reading it.
    if (count > 0 && std::uint64_t(count) > numBytes + numBytes / 100 + 1024) {
        OPENVDB_THROW(openvdb::IoError, "a compressed block claims " + std::to_string(count) +
            " bytes for " + std::to_string(numBytes) + " bytes of values (the file is damaged)");
    }
    if (count > 0 && blosc) {
        // c-blosc 1 takes the block's sizes from its 16-byte header, not from the caller: a header
        // that claims more compressed bytes than the block holds makes it read past the block
        // (found by fuzz_vdb: a heap overflow in LZ4_decompress_safe).
        unsigned char header[16];
        is.read(reinterpret_cast<char*>(header), sizeof(header));
        std::uint32_t raw = 0, stored = 0;
        std::memcpy(&raw, header + 4, 4);
        std::memcpy(&stored, header + 12, 4);
        if (!is || std::uint64_t(stored) != std::uint64_t(count) || raw != numBytes) {
            OPENVDB_THROW(openvdb::IoError, "a compressed block's header does not match the "
                "block (" + std::to_string(count) + " bytes for " + std::to_string(numBytes) +
                " bytes of values)");
        }
    }
    if (count <= 0) {
        const std::uint64_t raw = std::uint64_t(-(count + 1)) + 1; // no overflow at INT64_MIN
        if (raw != numBytes) {
            OPENVDB_THROW(openvdb::IoError, "an uncompressed block claims " + std::to_string(raw) +
                " bytes where " + std::to_string(numBytes) + " were expected (the file is damaged)");
        }
    }
    is.seekg(start);
    read(is, data, numBytes);
}

} // namespace

namespace openvdb {
OPENVDB_USE_VERSION_NAMESPACE
namespace OPENVDB_VERSION_NAME {
namespace io {

void bloscFromStream(std::istream& is, char* data, size_t numBytes)
{
    static const ReadFn read = original("_ZN7openvdb5v10_02io15bloscFromStreamERSiPcm");
    guardedRead(is, data, numBytes, read, /*blosc=*/true);
}

void unzipFromStream(std::istream& is, char* data, size_t numBytes)
{
    static const ReadFn read = original("_ZN7openvdb5v10_02io15unzipFromStreamERSiPcm");
    guardedRead(is, data, numBytes, read, /*blosc=*/false);
}

} // namespace io
} // namespace OPENVDB_VERSION_NAME
} // namespace openvdb

// DelayedLoadMetadata's accessors assert (abort, in Debian's build) when a damaged file's leaf
// index is beyond the per-leaf tables (found by fuzz_vdb). These definitions take the place of
// libopenvdb's: the same accessors, with the index checked.
namespace openvdb {
OPENVDB_USE_VERSION_NAMESPACE
namespace OPENVDB_VERSION_NAME {
namespace io {

DelayedLoadMetadata::MaskType DelayedLoadMetadata::getMask(size_t index) const
{
    if (index >= mMask.size()) {
        OPENVDB_THROW(IoError, "leaf " + std::to_string(index) + " is beyond the file's " +
            std::to_string(mMask.size()) + " delayed-load entries (the file is damaged)");
    }
    return mMask[index];
}

DelayedLoadMetadata::CompressedSizeType DelayedLoadMetadata::getCompressedSize(size_t index) const
{
    if (index >= mCompressedSize.size()) {
        OPENVDB_THROW(IoError, "leaf " + std::to_string(index) + " is beyond the file's " +
            std::to_string(mCompressedSize.size()) + " delayed-load sizes (the file is damaged)");
    }
    return mCompressedSize[index];
}

} // namespace io
} // namespace OPENVDB_VERSION_NAME
} // namespace openvdb
