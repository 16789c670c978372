// SPDX-License-Identifier: Apache-2.0
// The parallel .vdb writer: OpenVDB's file format, byte for byte as openvdb::io::File writes it
// (but the file's random UUID), with the leaf buffers compressed once, in parallel.
//
// io::File writes a grid on one thread: it compresses every leaf once to size its delayed-load
// table, then once more, one after another, to write it. Here each leaf is compressed once, by
// OpenVDB's own LeafNode::writeBuffers on a per-task stream, in parallel; the table's entries
// are read off the compressed bytes; and the bytes are streamed out in file order. Everything
// else of a grid's record (descriptor, metadata, transform, topology) is written by OpenVDB's own
// functions, in the order Archive::writeGrid writes it (Archive.cc:1360-1443 in 10.0.1).
#include <ivdb/io/VdbFile.h>
#include <ivdb/io/VdbPieces.h>

#include "Cancel.h"

#include <ivdb/io/AtomicFile.h>
#include <ivdb/util/System.h>

#include <openvdb/io/Archive.h>
#include <openvdb/io/Compression.h>
#include <openvdb/io/DelayedLoadMetadata.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/tree/LeafManager.h>

#include <blosc.h>

#include "BloscLz4.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <map>
#include <set>
#include <sstream>
#include <type_traits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#endif

namespace ivdb::io {

const std::vector<std::string>& compressionNames()
{
    static const std::vector<std::string> names{"blosc", "zip", "none"};
    return names;
}

std::uint32_t compressionFlags(Compression c)
{
    // Active-value (mask) compression always: lossless, and what every OpenVDB writer does.
    switch (c) {
    case Compression::Blosc: return openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK;
    case Compression::Zip: return openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK;
    case Compression::None: break;
    }
    return openvdb::io::COMPRESS_ACTIVE_MASK;
}

namespace {

using openvdb::GridBase;
using GridsWithLeafTables = openvdb::NumericGridTypes::Append<openvdb::Vec3GridTypes>;

/// OpenVDB's archive, for the pieces of its writer that are protected: the file header, and the
/// grids this writer leaves to it (types without delayed-load tables, instances).
class ArchiveParts: public openvdb::io::Archive
{
public:
    explicit ArchiveParts(std::uint32_t flags) { setCompression(flags); }
    void header(std::ostream& os) const { writeHeader(os, /*seekable=*/true); }
    void grid(openvdb::io::GridDescriptor& gd, const GridBase::ConstPtr& g, std::ostream& os) const
    {
        writeGrid(gd, g, os, /*seekable=*/true);
    }
    void instance(openvdb::io::GridDescriptor& gd, const GridBase::ConstPtr& g, std::ostream& os) const
    {
        writeGridInstance(gd, g, os, /*seekable=*/true);
    }
};

/// A stream buffer that appends to a string (no copies, unlike std::ostringstream's str()).
class StringSink: public std::streambuf
{
public:
    explicit StringSink(std::string& s): mString(s) {}

protected:
    int_type overflow(int_type c) override
    {
        if (!traits_type::eq_int_type(c, traits_type::eof())) mString.push_back(char(c));
        return traits_type::not_eof(c);
    }
    std::streamsize xsputn(const char* p, std::streamsize n) override
    {
        mString.append(p, std::size_t(n));
        return n;
    }
    pos_type seekoff(off_type off, std::ios_base::seekdir dir, std::ios_base::openmode) override
    {
        // Only tellp().
        return off == 0 && dir == std::ios_base::cur ? pos_type(off_type(mString.size()))
                                                     : pos_type(off_type(-1));
    }

private:
    std::string& mString;
};

/// The compressed buffers of a run of leaves, in file order, with each leaf's delayed-load entry.
struct LeafChunk
{
    std::string bytes;
    std::vector<std::int8_t> masks;   // MaskCompress code per leaf
    std::vector<std::int64_t> sizes;  // the value block's bytes (with its int64 prefix) per leaf
};

/// Bit k set where @a v[k] (k < 64) equals neither @a a nor @a b (NaN equals nothing): SSE2
/// compares of four floats at a time where available, which the compiler does not find itself.
inline openvdb::Index64 notEqualBits(const float* v, float a, float b)
{
    openvdb::Index64 bits = 0;
#if defined(__SSE2__)
    const __m128 va = _mm_set1_ps(a), vb = _mm_set1_ps(b);
    for (int k = 0; k < 64; k += 4) {
        const __m128 x = _mm_loadu_ps(v + k);
        const __m128 neither = _mm_and_ps(_mm_cmpneq_ps(x, va), _mm_cmpneq_ps(x, vb));
        bits |= openvdb::Index64(_mm_movemask_ps(neither)) << k;
    }
#else
    for (int k = 0; k < 64; ++k) bits |= openvdb::Index64(!(v[k] == a) & !(v[k] == b)) << k;
#endif
    return bits;
}

/// The same for vec3s values: a voxel is set where its vector differs from both @a a and @a b
/// in some component (branch-free; vectors compare exactly, component by component).
inline openvdb::Index64 notEqualBits(const openvdb::Vec3s* v, const openvdb::Vec3s& a,
                                     const openvdb::Vec3s& b)
{
    openvdb::Index64 bits = 0;
    for (int k = 0; k < 64; ++k) {
        const openvdb::Vec3s& x = v[k];
        // != is !(==) for floats, NaN included; ints and |, not ||, keep it branch-free.
        const int notA = int(x[0] != a[0]) | int(x[1] != a[1]) | int(x[2] != a[2]);
        const int notB = int(x[0] != b[0]) | int(x[1] != b[1]) | int(x[2] != b[2]);
        bits |= openvdb::Index64(notA & notB) << k;
    }
    return bits;
}

/// The active ones of 64 values (bit k of @a word set: value k active), appended in order at
/// @a out + @a count; returns the new count. Stores may reach up to 7 values beyond the new
/// count, never beyond out + count + 64.
template<typename ValueT>
openvdb::Index compactWord(const ValueT* src, openvdb::Index64 word, ValueT* out, openvdb::Index count)
{
    // Branch-free: every value is stored, and the next store overwrites it unless its voxel is
    // active (no chain of bit scans).
    for (openvdb::Index k = 0; k < 64; ++k) {
        out[count] = src[k];
        count += openvdb::Index((word >> k) & 1);
    }
    return count;
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
/// For each 8-bit mask, the positions of its set bits in order (then zeros): the permutation
/// that packs 8 floats' active ones to the front.
struct PackTable
{
    alignas(32) std::int32_t lanes[256][8] = {};
    constexpr PackTable()
    {
        for (int m = 0; m < 256; ++m) {
            int n = 0;
            for (int b = 0; b < 8; ++b) {
                if (m & (1 << b)) lanes[m][n++] = b;
            }
        }
    }
};
constexpr PackTable kPackTable;

/// compactWord() for floats with AVX2: 8 values a step, packed by a permutation from the table
/// and stored whole (about ten times fewer instructions than the loop over values).
__attribute__((target("avx2,popcnt")))
openvdb::Index compactWordAvx2(const float* src, openvdb::Index64 word, float* out, openvdb::Index count)
{
    for (int g = 0; g < 8; ++g) {
        const unsigned m = unsigned(word >> (8 * g)) & 0xffu;
        const __m256 v = _mm256_loadu_ps(src + 8 * g);
        const __m256i lanes = _mm256_load_si256(reinterpret_cast<const __m256i*>(kPackTable.lanes[m]));
        _mm256_storeu_ps(out + count, _mm256_permutevar8x32_ps(v, lanes));
        count += openvdb::Index(__builtin_popcount(m));
    }
    return count;
}

inline bool hasAvx2()
{
    static const bool yes = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("popcnt");
    return yes;
}

inline openvdb::Index compactWord(const float* src, openvdb::Index64 word, float* out, openvdb::Index count)
{
    if (hasAvx2()) return compactWordAvx2(src, word, out, count);
    return compactWord<float>(src, word, out, count);
}
#endif

inline bool hasNaN(float v) { return std::isnan(v); }
inline bool hasNaN(const openvdb::Vec3s& v)
{
    return std::isnan(v[0]) || std::isnan(v[1]) || std::isnan(v[2]);
}

/// The value types whose inactive values are counted a word of 64 voxels at a time.
template<typename ValueT>
inline constexpr bool kWordCompare = std::is_same_v<ValueT, float> ||
                                     std::is_same_v<ValueT, openvdb::Vec3s>;

/// Writes one grid of type GridT (one of the seven types with delayed-load tables).
template<typename GridT>
class GridWriter
{
public:
    using TreeT = typename GridT::TreeType;
    using LeafT = typename TreeT::LeafNodeType;
    using ValueT = typename GridT::ValueType;

    GridWriter(const GridT& grid, std::uint32_t archiveFlags, std::uint64_t bufferLimit)
        : mGrid(grid), mTree(grid.tree()), mFlags(archiveFlags), mBufferLimit(bufferLimit),
          mHalf(grid.saveFloatAsHalf()), mLeaves(mTree)
    {
        // The grid's own flags: zip is never used for level sets and fog volumes.
        mGridFlags = archiveFlags;
        if (grid.getGridClass() == openvdb::GRID_LEVEL_SET ||
            grid.getGridClass() == openvdb::GRID_FOG_VOLUME) {
            mGridFlags &= ~openvdb::io::COMPRESS_ZIP;
        }
    }

    /// The grid's record after its descriptor: flags, metadata, transform, topology, buffers.
    /// @a blockPos receives the stream position where the buffers start.
    void write(std::ostream& os, std::int64_t& blockPos)
    {
        const std::size_t n = mLeaves.leafCount();
        // Hold every leaf's compressed bytes if they fit (a bound: the uncompressed values),
        // else find the table's sizes first and compress again while streaming.
        const double bound = double(n) * double(LeafT::NodeMaskType::memUsage() + 1 + LeafT::SIZE * sizeof(ValueT) + 8);
        const bool holdAll = bound <= double(mBufferLimit);
        // While the leaves are compressed, one task serializes the transform and topology and
        // computes the statistics io::File adds (a shallow copy's metadata): serial work that
        // would otherwise wait for the compression.
        auto copy = openvdb::ConstPtrCast<GridBase>(mGrid.copyGrid());
        std::string head;
        tbb::task_group side;
        side.run([&] {
            StringSink sink(head);
            std::ostream hs(&sink);
            hs.copyfmt(os); // the stream state OpenVDB's writers read (compression, background)
            openvdb::io::setDataCompression(hs, mGridFlags);
            mGrid.writeTransform(hs);
            mGrid.writeTopology(hs);
            copy->addStatsMetadata();
            copy->insertMeta("file_compression",
                             openvdb::StringMetadata(openvdb::io::compressionToString(mGridFlags)));
        });
        std::vector<LeafChunk> chunks;
        try {
            if (holdAll) chunks = compress(0, n);
        } catch (...) {
            side.wait();
            throw;
        }
        side.wait();
        openvdb::io::DelayedLoadMetadata table;
        if (n > 0) {
            table.resizeMask(n);
            if (hasSizes()) table.resizeCompressedSize(n);
            std::size_t index = 0;
            auto record = [&](const LeafChunk& c) {
                for (std::size_t k = 0; k < c.masks.size(); ++k, ++index) {
                    table.setMask(index, c.masks[k]);
                    if (hasSizes()) table.setCompressedSize(index, c.sizes[k]);
                }
            };
            if (holdAll) {
                for (const auto& c : chunks) record(c);
            } else {
                for (std::size_t b = 0; b < n; b += kStreamLeaves) {
                    for (const auto& c : compress(b, std::min(n, b + kStreamLeaves))) record(c);
                }
            }
        }
        const auto w = [&os](const void* p, std::size_t len) {
            os.write(static_cast<const char*>(p), std::streamsize(len));
        };
        openvdb::io::setDataCompression(os, mGridFlags);
        w(&mGridFlags, sizeof(mGridFlags));
        copy->insertMeta("file_delayed_load", table);
        copy->writeMeta(os);
        w(head.data(), head.size());
        blockPos = std::int64_t(os.tellp());
        if (holdAll) {
            for (const auto& c : chunks) w(c.bytes.data(), c.bytes.size());
        } else {
            for (std::size_t b = 0; b < n; b += kStreamLeaves) {
                for (const auto& c : compress(b, std::min(n, b + kStreamLeaves))) {
                    w(c.bytes.data(), c.bytes.size());
                }
            }
        }
    }

    /// Every leaf encoded, held at once (a run of a grid's leaves: encodeLeafRun).
    LeafRun encode() const
    {
        LeafRun out;
        const std::size_t n = mLeaves.leafCount();
        std::vector<LeafChunk> chunks = compress(0, n);
        out.pieces.reserve(chunks.size());
        out.codes.reserve(n);
        if (hasSizes()) out.sizes.reserve(n);
        for (auto& c : chunks) {
            out.pieces.push_back(std::move(c.bytes));
            out.codes.insert(out.codes.end(), c.masks.begin(), c.masks.end());
            out.sizes.insert(out.sizes.end(), c.sizes.begin(), c.sizes.end());
        }
        // The masks, active voxels and their box, in parallel, a word at a time.
        out.masks.resize(n);
        struct Sums
        {
            std::uint64_t active = 0;
            openvdb::CoordBBox box;
        };
        std::vector<Sums> sums((n + kTaskLeaves - 1) / kTaskLeaves);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, sums.size(), 1),
                          [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t c = r.begin(); c != r.end(); ++c) {
                for (std::size_t i = c * kTaskLeaves; i < std::min(n, (c + 1) * kTaskLeaves); ++i) {
                    const LeafT& leaf = mLeaves.leaf(i);
                    out.masks[i] = leaf.valueMask();
                    sums[c].active += leaf.onVoxelCount();
                    expandByActive(sums[c].box, leaf.valueMask(), leaf.origin());
                }
            }
        });
        for (const Sums& s : sums) {
            out.activeVoxels += s.active;
            out.activeBox.expand(s.box);
        }
        return out;
    }

    /// Grow @a box by the active voxels of the leaf at @a origin with value mask @a mask (the
    /// box LeafNode::evalActiveBoundingBox finds): x from the first and last non-empty word
    /// (a word is an x slice), y and z from the bytes and bits of the words' union.
    static void expandByActive(openvdb::CoordBBox& box, const typename LeafT::NodeMaskType& mask,
                               const openvdb::Coord& origin)
    {
        static_assert(LeafT::DIM == 8, "a word of the mask is an x slice of 8 x 8 voxels");
        int x0 = -1, x1 = -1;
        std::uint64_t any = 0;
        for (int w = 0; w < 8; ++w) {
            const std::uint64_t word = mask.template getWord<std::uint64_t>(openvdb::Index(w));
            if (!word) continue;
            if (x0 < 0) x0 = w;
            x1 = w;
            any |= word;
        }
        if (!any) return;
        int y0 = 8, y1 = -1;
        std::uint32_t zs = 0;
        for (int y = 0; y < 8; ++y) {
            const std::uint32_t row = std::uint32_t((any >> (8 * y)) & 0xFFu);
            if (!row) continue;
            y0 = std::min(y0, y);
            y1 = y;
            zs |= row;
        }
        const int z0 = __builtin_ctz(zs), z1 = 31 - __builtin_clz(zs);
        box.expand(openvdb::CoordBBox(origin.offsetBy(x0, y0, z0), origin.offsetBy(x1, y1, z1)));
    }

private:
    /// Leaves compressed per task; and, when the buffers do not all fit, per streamed batch.
    static constexpr std::size_t kTaskLeaves = 64;
    static constexpr std::size_t kStreamLeaves = 16384;

    bool hasSizes() const
    {
        return (mFlags & (openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ZIP)) != 0;
    }

    /// Leaves [begin, end) compressed in parallel, in chunks of kTaskLeaves, by OpenVDB's own
    /// LeafNode::writeBuffers on a stream with the state Archive::writeGrid gives its stream.
    std::vector<LeafChunk> compress(std::size_t begin, std::size_t end) const
    {
        std::vector<LeafChunk> chunks((end - begin + kTaskLeaves - 1) / kTaskLeaves);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks.size(), 1),
                          [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t c = r.begin(); c != r.end(); ++c) {
                const std::size_t from = begin + c * kTaskLeaves;
                const std::size_t to = std::min(end, from + kTaskLeaves);
                chunks[c] = compressChunk(from, to);
            }
        });
        detail::throwIfCancelled("the write");
        return chunks;
    }

    /// What io::MaskCompress finds (its code and inactive values), with the same decisions, but
    /// visiting a word's inactive voxels through its set bits instead of an iterator.
    struct MaskInfo
    {
        std::int8_t metadata;
        ValueT inactiveVal[2];
    };

    static MaskInfo maskCompress(const typename LeafT::NodeMaskType& on, const ValueT* src,
                                 const ValueT& background)
    {
        namespace vio = openvdb::io;
        using openvdb::math::isExactlyEqual;
        MaskInfo r;
        r.inactiveVal[0] = r.inactiveVal[1] = background;
        int unique = 0;
        if constexpr (kWordCompare<ValueT>) {
            // Floats and vec3s: find the first two distinct inactive values and check that every
            // inactive value is one of them, a word of 64 voxels at a time (branch-free).
            unique = twoInactiveValues(on, src, r.inactiveVal);
            if (unique == kMoreThanTwo) unique = 3;
            if (unique == kNaN) unique = countInactiveValues(on, src, r.inactiveVal);
        } else {
            unique = countInactiveValues(on, src, r.inactiveVal);
        }
        const ValueT minusBg = openvdb::math::negative(background);

        ValueT* val = r.inactiveVal;
        r.metadata = vio::NO_MASK_OR_INACTIVE_VALS;
        if (unique == 1) {
            if (!isExactlyEqual(val[0], background)) {
                r.metadata = isExactlyEqual(val[0], minusBg) ? vio::NO_MASK_AND_MINUS_BG
                                                             : vio::NO_MASK_AND_ONE_INACTIVE_VAL;
            }
        } else if (unique == 2) {
            if (!isExactlyEqual(val[0], background) && !isExactlyEqual(val[1], background)) {
                r.metadata = vio::MASK_AND_TWO_INACTIVE_VALS;
            } else if (isExactlyEqual(val[1], background)) {
                r.metadata = isExactlyEqual(val[0], minusBg) ? vio::MASK_AND_NO_INACTIVE_VALS
                                                             : vio::MASK_AND_ONE_INACTIVE_VAL;
            } else if (isExactlyEqual(val[0], background)) {
                r.metadata = isExactlyEqual(val[1], minusBg) ? vio::MASK_AND_NO_INACTIVE_VALS
                                                             : vio::MASK_AND_ONE_INACTIVE_VAL;
                std::swap(val[0], val[1]);
            }
        } else if (unique > 2) {
            r.metadata = vio::NO_MASK_AND_ALL_VALS;
        }
        return r;
    }

    /// The number of distinct inactive values (counting stops at 3), with the first two in order
    /// in @a val, as io::MaskCompress counts them (exact equality), visiting a word's inactive
    /// voxels through its set bits.
    static int countInactiveValues(const typename LeafT::NodeMaskType& on, const ValueT* src,
                                   ValueT* val)
    {
        using openvdb::math::isExactlyEqual;
        int unique = 0;
        for (openvdb::Index w = 0; w < LeafT::NodeMaskType::WORD_COUNT && unique < 3; ++w) {
            for (openvdb::Index64 bits = ~on.template getWord<openvdb::Index64>(w); bits && unique < 3;
                 bits &= bits - 1) {
                const ValueT& v = src[w * 64 + openvdb::Index(openvdb::util::FindLowestOn(bits))];
                const bool seen = (unique > 0 && isExactlyEqual(v, val[0])) ||
                                  (unique > 1 && isExactlyEqual(v, val[1]));
                if (seen) continue;
                if (unique < 2) val[unique] = v;
                ++unique;
            }
        }
        return unique;
    }

    /// twoInactiveValues() found three or more distinct inactive values, or a NaN among the
    /// first two (each NaN counts as a value of its own; the per-voxel count decides then).
    static constexpr int kMoreThanTwo = -1, kNaN = -2;

    /// Bits of word @a w of @a src whose value is not @a a (NaN is never equal).
    static openvdb::Index64 differing(const ValueT* src, openvdb::Index w, const ValueT& a)
    {
        return notEqualBits(src + w * 64, a, a);
    }

    /// For float and vec3s leaves: the number of distinct inactive values (0, 1 or 2) with the first two in
    /// order in @a val, as countInactiveValues counts them; kMoreThanTwo if there are more; kNaN
    /// if one of the first two is NaN.
    static int twoInactiveValues(const typename LeafT::NodeMaskType& on, const ValueT* src, ValueT* val)
    {
        constexpr openvdb::Index kWords = LeafT::NodeMaskType::WORD_COUNT;
        const auto off = [&on](openvdb::Index w) { return ~on.template getWord<openvdb::Index64>(w); };
        openvdb::Index w = 0;
        while (w < kWords && !off(w)) ++w;
        if (w == kWords) return 0; // every voxel is active
        const ValueT a = src[w * 64 + openvdb::Index(openvdb::util::FindLowestOn(off(w)))];
        if (hasNaN(a)) return kNaN;
        val[0] = a;
        // The first inactive voxel (after the first) that is not a.
        for (; w < kWords; ++w) {
            const openvdb::Index64 hits = differing(src, w, a) & off(w);
            if (hits) break;
        }
        if (w == kWords) return 1;
        const openvdb::Index64 first = differing(src, w, a) & off(w);
        const ValueT b = src[w * 64 + openvdb::Index(openvdb::util::FindLowestOn(first))];
        if (hasNaN(b)) return kNaN;
        val[1] = b;
        // Every inactive voxel from there on is a or b (before it, all were a).
        for (; w < kWords; ++w) {
            if (notEqualBits(src + w * 64, a, b) & off(w)) return kMoreThanTwo;
        }
        return 2;
    }

    /// LeafNode::writeBuffers(os, false) of a leaf with active-value compression, written with
    /// loops over the masks' words instead of per-voxel bit tests: the same bytes (the tests
    /// compare whole files with io::File's), in about half the time before the codec. Half
    /// values and the other compressions go through OpenVDB's own writeBuffers.
    void writeLeaf(std::ostream& os, std::string& out, const LeafT& leaf) const
    {
        using MaskT = typename LeafT::NodeMaskType;
        namespace vio = openvdb::io;
        const MaskT& on = leaf.valueMask();
        on.save(os);
        const ValueT* src = leaf.buffer().data();
        const MaskInfo mc = maskCompress(on, src, mTree.background());
        const std::int8_t code = mc.metadata;
        os.write(reinterpret_cast<const char*>(&code), 1);
        if (code == vio::NO_MASK_AND_ONE_INACTIVE_VAL || code == vio::MASK_AND_ONE_INACTIVE_VAL ||
            code == vio::MASK_AND_TWO_INACTIVE_VALS) {
            os.write(reinterpret_cast<const char*>(&mc.inactiveVal[0]), sizeof(ValueT));
            if (code == vio::MASK_AND_TWO_INACTIVE_VALS) {
                os.write(reinterpret_cast<const char*>(&mc.inactiveVal[1]), sizeof(ValueT));
            }
        }
        if (code == vio::NO_MASK_AND_ALL_VALS) {
            writeValues(os, out, src, LeafT::SIZE);
            return;
        }
        ValueT active[LeafT::SIZE];
        openvdb::Index count = 0;
        const bool selection = code == vio::MASK_AND_NO_INACTIVE_VALS ||
                               code == vio::MASK_AND_ONE_INACTIVE_VAL ||
                               code == vio::MASK_AND_TWO_INACTIVE_VALS;
        MaskT select;
        for (openvdb::Index w = 0; w < MaskT::WORD_COUNT; ++w) {
            const openvdb::Index64 word = on.template getWord<openvdb::Index64>(w);
            count = compactWord(src + w * 64, word, active, count);
            if (!selection) continue;
            // The inactive voxels that hold the second inactive value.
            openvdb::Index64 pick = 0;
            if constexpr (kWordCompare<ValueT>) {
                pick = ~notEqualBits(src + w * 64, mc.inactiveVal[1], mc.inactiveVal[1]) & ~word;
            } else {
                for (openvdb::Index64 bits = ~word; bits; bits &= bits - 1) {
                    const openvdb::Index b = openvdb::Index(openvdb::util::FindLowestOn(bits));
                    if (openvdb::math::isExactlyEqual(src[w * 64 + b], mc.inactiveVal[1])) {
                        pick |= openvdb::Index64(1) << b;
                    }
                }
            }
            select.template getWord<openvdb::Index64>(w) = pick;
        }
        if (selection) select.save(os);
        writeValues(os, out, active, count);
    }

    /// io::writeData(os, values, count, flags): with Blosc, compressed straight into @a out (the
    /// string @a os appends to), as io::bloscToStream compresses (level 9, byte shuffle of 4-byte
    /// words, LZ4, one block, one thread), without its temporary buffer and copy, and without
    /// LZ4's clearing of its table for every plane (detail::bloscLz4Compress).
    void writeValues(std::ostream& os, std::string& out, const ValueT* values, openvdb::Index count) const
    {
        if (!(mGridFlags & openvdb::io::COMPRESS_BLOSC)) {
            openvdb::io::writeData(os, values, count, mGridFlags);
            return;
        }
        const std::size_t bytes = std::size_t(count) * sizeof(ValueT);
        const std::size_t at = out.size();
        out.resize(at + 8 + bytes + BLOSC_MAX_OVERHEAD);
        const int stored = detail::bloscLz4Compress(values, bytes, &out[at + 8]);
        // Stored raw (minus its size first) when Blosc fails, as io::bloscToStream does.
        const std::int64_t size = stored > 0 ? std::int64_t(stored) : -std::int64_t(bytes);
        if (stored <= 0) std::memcpy(&out[at + 8], values, bytes);
        std::memcpy(&out[at], &size, sizeof(size));
        out.resize(at + 8 + (stored > 0 ? std::size_t(stored) : bytes));
    }

    LeafChunk compressChunk(std::size_t from, std::size_t to) const
    {
        LeafChunk out;
        // About twice what a level set's leaves take, so that a chunk rarely grows.
        out.bytes.reserve((to - from) * (LeafT::SIZE * sizeof(ValueT) / 2) + LeafT::SIZE * sizeof(ValueT) + 256);
        StringSink sink(out.bytes);
        std::ostream os(&sink);
        openvdb::io::setDataCompression(os, mGridFlags);
        openvdb::io::setGridBackgroundValuePtr(os, &mTree.background());
        std::vector<std::streamoff> ends;
        for (std::size_t i = from; i < to; ++i) {
            const LeafT& leaf = mLeaves.leaf(i);
            if (mHalf || !(mGridFlags & openvdb::io::COMPRESS_ACTIVE_MASK)) {
                leaf.writeBuffers(os, mHalf);
            } else {
                writeLeaf(os, out.bytes, leaf);
            }
            ends.push_back(os.tellp());
            // The delayed-load entry's mask code, as Archive's PopulateDelayedLoadMetadataOp
            // makes it: with active-value compression the stream holds it (read below).
            if (!(mGridFlags & openvdb::io::COMPRESS_ACTIVE_MASK)) {
                out.masks.push_back(std::int8_t(openvdb::io::MaskCompress<ValueT, typename LeafT::NodeMaskType>(
                    leaf.valueMask(), typename LeafT::NodeMaskType(), leaf.buffer().data(),
                    mTree.background()).metadata));
            }
        }
        if (mGridFlags & openvdb::io::COMPRESS_ACTIVE_MASK) {
            std::streamoff begin = 0;
            for (const std::streamoff end : ends) {
                out.masks.push_back(std::int8_t(out.bytes[std::size_t(
                    begin + std::streamoff(LeafT::NodeMaskType::memUsage()))]));
                begin = end;
            }
        }
        if (hasSizes()) {
            std::streamoff begin = 0;
            for (std::size_t k = 0; k < ends.size(); ++k) {
                out.sizes.push_back(valueBlockSize(mLeaves.leaf(from + k), out.masks[k], out.bytes,
                                                   begin, ends[k]));
                begin = ends[k];
            }
        }
        return out;
    }

    /// The bytes of a leaf's value block (int64 prefix included), as
    /// io::writeCompressedValuesSize() + 8 gives it, read off the leaf's written bytes.
    std::int64_t valueBlockSize(const LeafT& leaf, std::int8_t mask, const std::string& bytes,
                                std::streamoff begin, std::streamoff end) const
    {
        if ((mFlags & openvdb::io::COMPRESS_ZIP) && !(mGridFlags & openvdb::io::COMPRESS_ZIP)) {
            // The table is sized for the archive's zip, though the level set's data is not zipped.
            return 8 + std::int64_t(openvdb::io::writeCompressedValuesSize(
                leaf.buffer().data(), LeafT::SIZE, leaf.valueMask(), std::uint8_t(mask), mHalf, mFlags));
        }
        // Skip the value mask and the mask code, then the inactive values and the selection mask
        // the stream's own code implies.
        std::streamoff pos = begin + std::streamoff(LeafT::NodeMaskType::memUsage());
        namespace vio = openvdb::io;
        const int code = static_cast<unsigned char>(bytes[std::size_t(pos)]);
        pos += 1;
        if (code == vio::NO_MASK_AND_ONE_INACTIVE_VAL || code == vio::MASK_AND_ONE_INACTIVE_VAL) {
            pos += sizeof(ValueT);
        } else if (code == vio::MASK_AND_TWO_INACTIVE_VALS) {
            pos += 2 * sizeof(ValueT);
        }
        if (code == vio::MASK_AND_NO_INACTIVE_VALS || code == vio::MASK_AND_ONE_INACTIVE_VAL ||
            code == vio::MASK_AND_TWO_INACTIVE_VALS) {
            pos += std::streamoff(LeafT::NodeMaskType::memUsage());
        }
        // Half values with no active voxel write nothing, not even the prefix; the table says 8.
        if (pos == end) return 8;
        std::int64_t prefix = 0;
        std::memcpy(&prefix, bytes.data() + pos, sizeof(prefix));
        return 8 + (prefix < 0 ? -prefix : prefix);
    }

    const GridT& mGrid;
    const TreeT& mTree;
    const std::uint32_t mFlags;
    std::uint32_t mGridFlags = 0;
    const std::uint64_t mBufferLimit;
    const bool mHalf;
    openvdb::tree::LeafManager<const TreeT> mLeaves;
};

/// The unique names Archive::write gives the grids (GridDescriptor::addSuffix): a name shared by
/// several grids, or empty, gets "\x1e" and the lowest number not yet taken.
std::vector<std::string> uniqueNames(const openvdb::GridCPtrVec& grids)
{
    std::map<std::string, int> count;
    for (const auto& g : grids) ++count[g->getName()];
    std::set<std::string> taken;
    std::vector<std::string> out;
    for (const auto& g : grids) {
        std::string name = g->getName();
        if (name.empty() || count[name] > 1) name = openvdb::io::GridDescriptor::addSuffix(name, 0);
        for (int n = 1; taken.count(name); ++n) {
            name = openvdb::io::GridDescriptor::addSuffix(g->getName(), n);
        }
        taken.insert(name);
        out.push_back(name);
    }
    return out;
}

/// One grid's record: the descriptor, then the record, then the descriptor's three offsets
/// patched in (as Archive::writeGrid does; the output is a file).
template<typename GridT>
void writeTypedGrid(std::ostream& os, const std::string& name, const GridT& grid,
                    std::uint32_t flags, std::uint64_t bufferLimit)
{
    openvdb::io::GridDescriptor gd(name, grid.type(), grid.saveFloatAsHalf());
    gd.writeHeader(os);
    const std::streamoff offsets = os.tellp();
    gd.writeStreamPos(os); // zeros for now
    gd.setGridPos(std::int64_t(os.tellp()));
    std::int64_t blockPos = 0;
    GridWriter<GridT>(grid, flags, bufferLimit).write(os, blockPos);
    gd.setBlockPos(blockPos);
    gd.setEndPos(std::int64_t(os.tellp()));
    os.seekp(offsets);
    gd.writeStreamPos(os);
    gd.seekToEnd(os);
}

} // namespace

void writeVdbStream(std::ostream& os, const openvdb::GridCPtrVec& input,
                    const openvdb::MetaMap& fileMetadata, const WriteOptions& options)
{
    detail::throwIfCancelled("the write");
    const std::uint32_t flags = compressionFlags(options.compression);
    const std::uint64_t bufferLimit =
        options.bufferLimit ? options.bufferLimit : std::uint64_t(util::memoryBudget() / 4.0);
    openvdb::GridCPtrVec grids;
    for (const auto& g : input) {
        if (!g) continue;
        if (options.half && !g->saveFloatAsHalf()) {
            // Half floats on disk: a shallow copy flagged as OpenVDB flags it.
            auto copy = openvdb::ConstPtrCast<GridBase>(g->copyGrid());
            copy->setSaveFloatAsHalf(true);
            grids.push_back(copy);
        } else {
            grids.push_back(g);
        }
    }
    ArchiveParts archive(flags);
    openvdb::io::setDataCompression(os, flags);
    openvdb::io::setWriteGridStatsMetadata(os, true);
    archive.header(os);
    fileMetadata.writeMeta(os);
    const std::int32_t count = std::int32_t(grids.size());
    os.write(reinterpret_cast<const char*>(&count), sizeof(count));
    const std::vector<std::string> names = uniqueNames(grids);
    std::map<const openvdb::TreeBase*, std::pair<std::string, bool>> written; // tree -> name, half
    for (std::size_t i = 0; i < grids.size(); ++i) {
        const GridBase::ConstPtr& g = grids[i];
        const auto shared = written.find(&g->baseTree());
        if (shared != written.end() && shared->second.second == g->saveFloatAsHalf()) {
            // A grid that shares an earlier grid's tree: OpenVDB's instance record.
            openvdb::io::GridDescriptor gd(names[i], g->type(), g->saveFloatAsHalf());
            gd.setInstanceParentName(shared->second.first);
            archive.instance(gd, g, os);
        } else {
            written[&g->baseTree()] = {names[i], g->saveFloatAsHalf()};
            const bool typed = g->apply<GridsWithLeafTables>([&](const auto& typedGrid) {
                writeTypedGrid(os, names[i], typedGrid, flags, bufferLimit);
            });
            if (!typed) {
                openvdb::io::GridDescriptor gd(names[i], g->type(), g->saveFloatAsHalf());
                archive.grid(gd, g, os);
            }
        }
        openvdb::io::setDataCompression(os, flags);
    }
}

std::uint64_t LeafRun::byteCount() const
{
    std::uint64_t n = 0;
    for (const auto& p : pieces) n += p.size();
    return n;
}

void LeafRun::appendEntries(const LeafRun& next)
{
    codes.insert(codes.end(), next.codes.begin(), next.codes.end());
    sizes.insert(sizes.end(), next.sizes.begin(), next.sizes.end());
    masks.insert(masks.end(), next.masks.begin(), next.masks.end());
    activeVoxels += next.activeVoxels;
    activeBox.expand(next.activeBox);
}

namespace {

template<typename GridT>
LeafRun encodeRun(const GridT& run, const WriteOptions& options)
{
    typename GridT::ConstPtr grid = run.copy();
    if (options.half) {
        auto copy = openvdb::ConstPtrCast<GridT>(grid);
        copy->setSaveFloatAsHalf(true);
    }
    return GridWriter<GridT>(*grid, compressionFlags(options.compression),
                             std::numeric_limits<std::uint64_t>::max()).encode();
}

} // namespace

LeafRun encodeLeafRun(const openvdb::FloatGrid& run, const WriteOptions& options)
{
    return encodeRun(run, options);
}

LeafRun encodeLeafRun(const openvdb::Vec3SGrid& run, const WriteOptions& options)
{
    return encodeRun(run, options);
}

namespace {

/// An internal node's topology as InternalNode::writeTopology writes it, for a node whose
/// children are @a childMask and tiles the others (value mask @a valueMask): the masks, then the
/// values (zero where a child is) compressed as OpenVDB compresses them.
template<typename NodeT, typename ValueOf>
void writeNodeTable(std::ostream& os, const typename NodeT::NodeMaskType& childMask,
                    const typename NodeT::NodeMaskType& valueMask, ValueOf&& valueOf, bool toHalf)
{
    using ValueT = typename NodeT::ValueType;
    childMask.save(os);
    valueMask.save(os);
    std::unique_ptr<ValueT[]> values(new ValueT[NodeT::NUM_VALUES]);
    for (openvdb::Index i = 0; i < NodeT::NUM_VALUES; ++i) {
        values[i] = childMask.isOn(i) ? openvdb::zeroVal<ValueT>() : valueOf(i);
    }
    openvdb::io::writeCompressedValues(os, values.get(), NodeT::NUM_VALUES, valueMask, childMask,
                                       toHalf);
}

/// Tree::writeTopology of the grid @a skeleton stands for: its 128^3 nodes' active tiles are
/// leaves, of which there are @a leafCount; their value masks are written as zeros, and where
/// they go is recorded in @a runs (offsets from @a base, the stream's start in the file). The
/// grid's own active tiles in those nodes are @a ownTiles' (if any).
template<typename TreeT>
void writeSkeletonTopology(std::ostream& os, const TreeT& skeleton, std::uint64_t leafCount,
                           bool toHalf, std::uint64_t base, std::vector<FileHead::MaskRun>& runs,
                           const ActiveTiles* ownTiles)
{
    using ValueT = typename TreeT::ValueType;
    using Int2T = typename TreeT::RootNodeType::ChildNodeType;
    using Int1T = typename Int2T::ChildNodeType;
    const std::int32_t bufferCount = 1;
    os.write(reinterpret_cast<const char*>(&bufferCount), sizeof(bufferCount));
    const auto& root = skeleton.root();
    const ValueT& bg = root.background();
    const ValueT bgOut = toHalf ? openvdb::io::truncateRealToHalf(bg) : bg;
    os.write(reinterpret_cast<const char*>(&bgOut), sizeof(ValueT));
    openvdb::io::setGridBackgroundValuePtr(os, &bg);
    openvdb::Index tiles = 0;
    for (auto it = root.cbeginValueAll(); it; ++it) ++tiles;
    const openvdb::Index children = root.childCount();
    os.write(reinterpret_cast<const char*>(&tiles), sizeof(tiles));
    os.write(reinterpret_cast<const char*>(&children), sizeof(children));
    std::uint64_t next = 0;
    const LeafRun::Mask zero;
    if (tiles + children > 0) {
        for (auto it = root.cbeginValueAll(); it; ++it) {
            const openvdb::Coord o = it.getCoord();
            const ValueT v = *it;
            const bool active = it.isValueOn();
            os.write(reinterpret_cast<const char*>(o.asPointer()), 3 * sizeof(std::int32_t));
            os.write(reinterpret_cast<const char*>(&v), sizeof(v));
            os.write(reinterpret_cast<const char*>(&active), sizeof(active));
        }
        for (auto it2 = root.cbeginChildOn(); it2; ++it2) {
            const openvdb::Coord o = it2.getCoord();
            os.write(reinterpret_cast<const char*>(o.asPointer()), 3 * sizeof(std::int32_t));
            const Int2T& n2 = *it2;
            writeNodeTable<Int2T>(os, n2.getChildMask(), n2.getValueMask(),
                [&](openvdb::Index i) { return n2.getValue(n2.offsetToGlobalCoord(i)); }, toHalf);
            for (auto it1 = n2.cbeginChildOn(); it1; ++it1) {
                const Int1T& n1 = *it1;
                // The active tiles are the leaves: they become the child mask.
                const typename Int1T::NodeMaskType leaves = n1.getValueMask();
                typename Int1T::NodeMaskType active;
                if (ownTiles) {
                    const auto found = ownTiles->find(n1.origin());
                    if (found != ownTiles->end()) active = found->second;
                }
                if (!(leaves & active).isOff()) {
                    OPENVDB_THROW(openvdb::ValueError, "a skeleton lists an active tile where it "
                                  "has a leaf");
                }
                writeNodeTable<Int1T>(os, leaves, active,
                    [&](openvdb::Index i) { return n1.getValue(n1.offsetToGlobalCoord(i)); }, toHalf);
                const std::uint64_t count = leaves.countOn();
                if (count == 0) continue;
                runs.push_back({next, count, base + std::uint64_t(os.tellp())});
                for (std::uint64_t k = 0; k < count; ++k) zero.save(os);
                next += count;
            }
        }
    }
    if (next != leafCount) {
        OPENVDB_THROW(openvdb::ValueError, "the skeleton has " + std::to_string(next) +
                      " leaves, the runs " + std::to_string(leafCount));
    }
}

/// One grid's part of the head, from its descriptor on, starting at file offset @a at (the
/// stream @a os is the head's bytes so far, of which @a out is the string): writeTypedGrid's
/// steps, with the statistics and table from the runs' entries.
template<typename GridT>
void writeGridHead(std::ostream& os, std::string& out, std::uint64_t at, const std::string& name,
                   const GridT& grid, const LeafRun& leaves, std::uint64_t bufferBytes,
                   std::uint32_t flags, std::vector<FileHead::MaskRun>& runs,
                   const ActiveTiles* activeTiles)
{
    using LeafT = typename GridT::TreeType::LeafNodeType;
    const bool half = grid.saveFloatAsHalf();
    std::uint32_t gridFlags = flags;
    if (grid.getGridClass() == openvdb::GRID_LEVEL_SET ||
        grid.getGridClass() == openvdb::GRID_FOG_VOLUME) {
        gridFlags &= ~openvdb::io::COMPRESS_ZIP;
    }
    openvdb::io::GridDescriptor gd(name, grid.type(), half);
    gd.writeHeader(os);
    const std::size_t offsets = out.size();
    gd.writeStreamPos(os);
    gd.setGridPos(std::int64_t(at + out.size()));

    const std::size_t n = leaves.codes.size();
    std::string head;
    {
        StringSink hsink(head);
        std::ostream hs(&hsink);
        hs.copyfmt(os);
        openvdb::io::setDataCompression(hs, gridFlags);
        grid.writeTransform(hs);
        writeSkeletonTopology(hs, grid.tree(), n, half, 0, runs, activeTiles);
    }
    // The statistics io::File adds: the active voxels and their box, the grid's own active tiles'
    // included (those above the 128^3 nodes, and the listed ones in them).
    std::uint64_t activeVoxels = leaves.activeVoxels;
    openvdb::CoordBBox activeBox = leaves.activeBox;
    using ValueOnCIter = typename GridT::TreeType::ValueOnCIter;
    ValueOnCIter above = grid.tree().cbeginValueOn();
    above.setMaxDepth(ValueOnCIter::LEAF_DEPTH - 2);
    for (; above; ++above) {
        openvdb::CoordBBox box;
        above.getBoundingBox(box);
        activeVoxels += box.volume();
        activeBox.expand(box);
    }
    if (activeTiles) {
        for (const auto& [origin, mask] : *activeTiles) {
            for (auto on = mask.beginOn(); on; ++on) {
                using Int1T = typename GridT::TreeType::RootNodeType::ChildNodeType::ChildNodeType;
                openvdb::Coord local;
                Int1T::offsetToLocalCoord(on.pos(), local);
                const openvdb::Coord o = origin + (local << int(LeafT::TOTAL));
                activeVoxels += LeafT::SIZE;
                activeBox.expand(openvdb::CoordBBox::createCube(o, int(LeafT::DIM)));
            }
        }
    }
    auto meta = openvdb::ConstPtrCast<openvdb::GridBase>(grid.copyGrid());
    const auto leafBytes = LeafT(openvdb::Coord(), openvdb::zeroVal<typename GridT::ValueType>()).memUsage();
    meta->insertMeta(openvdb::GridBase::META_FILE_BBOX_MIN,
                     openvdb::Vec3IMetadata(activeBox.min().asVec3i()));
    meta->insertMeta(openvdb::GridBase::META_FILE_BBOX_MAX,
                     openvdb::Vec3IMetadata(activeBox.max().asVec3i()));
    meta->insertMeta(openvdb::GridBase::META_FILE_MEM_BYTES, openvdb::Int64Metadata(std::int64_t(
        grid.tree().memUsage() + n * leafBytes)));
    meta->insertMeta(openvdb::GridBase::META_FILE_VOXEL_COUNT,
                     openvdb::Int64Metadata(std::int64_t(activeVoxels)));
    meta->insertMeta("file_compression",
                     openvdb::StringMetadata(openvdb::io::compressionToString(gridFlags)));
    openvdb::io::DelayedLoadMetadata table;
    const bool sized = (flags & (openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ZIP)) != 0;
    if (sized && leaves.sizes.size() != n) {
        OPENVDB_THROW(openvdb::ValueError, "the runs' entries disagree: " + std::to_string(n) +
                      " codes, " + std::to_string(leaves.sizes.size()) + " sizes");
    }
    if (n > 0) {
        table.resizeMask(n);
        if (sized) table.resizeCompressedSize(n);
        for (std::size_t i = 0; i < n; ++i) {
            table.setMask(i, leaves.codes[i]);
            if (sized) table.setCompressedSize(i, leaves.sizes[i]);
        }
    }
    openvdb::io::setDataCompression(os, gridFlags);
    os.write(reinterpret_cast<const char*>(&gridFlags), sizeof(gridFlags));
    meta->insertMeta("file_delayed_load", table);
    meta->writeMeta(os);
    // The mask runs' offsets were from the record's start: now from the file's.
    const std::uint64_t headStart = at + out.size();
    for (auto& r : runs) r.offset += headStart;
    os.write(head.data(), std::streamsize(head.size()));
    const std::int64_t blockPos = std::int64_t(at + out.size());
    gd.setBlockPos(blockPos);
    gd.setEndPos(blockPos + std::int64_t(bufferBytes));
    // The descriptor's offsets, patched in as writeTypedGrid seeks back to write them.
    std::string pos;
    {
        StringSink psink(pos);
        std::ostream ps(&psink);
        gd.writeStreamPos(ps);
    }
    out.replace(offsets, pos.size(), pos);
    openvdb::io::setDataCompression(os, flags);
}

} // namespace

FileHead vdbFileHead(const std::vector<HeadGrid>& input, const openvdb::MetaMap& fileMetadata,
                     const WriteOptions& options)
{
    openvdb::GridCPtrVec grids;
    for (const HeadGrid& g : input) {
        if (!g.skeleton || !g.leaves) OPENVDB_THROW(openvdb::ValueError, "a grid without a skeleton or entries");
        auto copy = openvdb::ConstPtrCast<GridBase>(g.skeleton->copyGrid());
        if (options.half) copy->setSaveFloatAsHalf(true);
        grids.push_back(copy);
    }
    const std::uint32_t flags = compressionFlags(options.compression);
    const std::vector<std::string> names = uniqueNames(grids);
    FileHead result;
    std::uint64_t at = 0;
    for (std::size_t g = 0; g < grids.size(); ++g) {
        FileHead::Grid part;
        part.at = at;
        StringSink sink(part.bytes);
        std::ostream os(&sink);
        openvdb::io::setDataCompression(os, flags);
        openvdb::io::setWriteGridStatsMetadata(os, true);
        if (g == 0) {
            // writeVdbStream's steps for the file's start.
            ArchiveParts archive(flags);
            archive.header(os);
            fileMetadata.writeMeta(os);
            const std::int32_t count = std::int32_t(grids.size());
            os.write(reinterpret_cast<const char*>(&count), sizeof(count));
        }
        const HeadGrid& in = input[g];
        const bool typed = grids[g]->apply<openvdb::TypeList<openvdb::FloatGrid, openvdb::Vec3SGrid>>(
            [&](const auto& grid) {
                writeGridHead(os, part.bytes, at, names[g], grid, *in.leaves, in.bufferBytes, flags,
                              part.maskRuns, in.activeTiles);
            });
        if (!typed) {
            OPENVDB_THROW(openvdb::ValueError, "grid '" + grids[g]->getName() + "' is a " +
                          grids[g]->valueType() + " grid; the pieces are float or vec3s grids");
        }
        part.size = part.bytes.size();
        at = part.buffersAt() + in.bufferBytes;
        result.grids.push_back(std::move(part));
    }
    result.fileBytes = at;
    return result;
}

FileHead vdbFileHead(const openvdb::FloatGrid& skeleton, const LeafRun& leaves,
                     std::uint64_t bufferBytes, const openvdb::MetaMap& fileMetadata,
                     const WriteOptions& options)
{
    return vdbFileHead({HeadGrid{skeleton.copy(), &leaves, bufferBytes}}, fileMetadata, options);
}

openvdb::FloatGrid::Ptr skeletonOf(const openvdb::FloatGrid& grid)
{
    // A copy of a leaf that holds no values holds none either: the copy costs the topology.
    auto skeleton = grid.deepCopy();
    using Int1T = openvdb::FloatTree::RootNodeType::ChildNodeType::ChildNodeType;
    std::vector<Int1T*> nodes;
    skeleton->tree().getNodes(nodes);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nodes.size()),
                      [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            for (auto it = nodes[i]->beginChildOn(); it; ++it) {
                nodes[i]->addTile(it.pos(), 0.0f, true);
            }
        }
    });
    return skeleton;
}

std::vector<std::pair<std::uint64_t, std::string>>
FileHead::maskWrites(std::size_t grid, std::uint64_t first, const std::vector<LeafRun::Mask>& masks) const
{
    std::vector<std::pair<std::uint64_t, std::string>> out;
    if (masks.empty()) return out;
    if (grid >= grids.size()) {
        OPENVDB_THROW(openvdb::ValueError, "grid " + std::to_string(grid) + " of " +
                      std::to_string(grids.size()));
    }
    const std::vector<MaskRun>& maskRuns = grids[grid].maskRuns;
    const std::uint64_t end = first + masks.size();
    // The run holding leaf `first`: the last that starts at or before it.
    auto it = std::upper_bound(maskRuns.begin(), maskRuns.end(), first,
        [](std::uint64_t leaf, const MaskRun& r) { return leaf < r.firstLeaf; });
    if (it == maskRuns.begin() || end > maskRuns.back().firstLeaf + maskRuns.back().leaves) {
        OPENVDB_THROW(openvdb::ValueError, "leaves " + std::to_string(first) + " to " +
                      std::to_string(end) + " are not all in the head's topology");
    }
    const std::size_t size = LeafRun::Mask::memUsage();
    for (--it; it != maskRuns.end() && it->firstLeaf < end; ++it) {
        const std::uint64_t a = std::max(first, it->firstLeaf);
        const std::uint64_t b = std::min(end, it->firstLeaf + it->leaves);
        std::string bytes;
        bytes.reserve((b - a) * size);
        {
            StringSink sink(bytes);
            std::ostream os(&sink);
            for (std::uint64_t i = a; i < b; ++i) masks[i - first].save(os);
        }
        out.emplace_back(it->offset + (a - it->firstLeaf) * size, std::move(bytes));
    }
    return out;
}

std::vector<FileHead::Part> FileHead::nonMaskParts() const
{
    std::vector<Part> out;
    for (const Grid& g : grids) {
        std::uint64_t at = g.at;
        const auto add = [&](std::uint64_t from, std::uint64_t to) {
            if (to > from) out.push_back({from, g.bytes.data() + (from - g.at), to - from});
        };
        for (const MaskRun& r : g.maskRuns) {
            add(at, r.offset);
            at = r.offset + r.leaves * LeafRun::Mask::memUsage();
        }
        add(at, g.buffersAt());
    }
    return out;
}

void FileHead::putMasks(std::size_t grid, std::uint64_t first, const std::vector<LeafRun::Mask>& masks)
{
    for (const auto& [offset, data] : maskWrites(grid, first, masks)) {
        grids[grid].bytes.replace(offset - grids[grid].at, data.size(), data);
    }
}

void writeVdb(const std::string& path, const openvdb::GridCPtrVec& grids,
              const openvdb::MetaMap& fileMetadata, const WriteOptions& options)
{
    detail::throwIfCancelled(path + ": the write");
    writeFileAtomically(path, [&](std::ostream& os) {
        writeVdbStream(os, grids, fileMetadata, options);
    });
}

} // namespace ivdb::io
