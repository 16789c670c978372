// SPDX-License-Identifier: Apache-2.0
// The layout check: every .vdb file is walked with bounds-checked reads before OpenVDB's reader
// sees it (see validateLayout in Layout.h).
#include "Layout.h"

#include "FileMapping.h"

#include <openvdb/Metadata.h>
#include <openvdb/io/Archive.h>
#include <openvdb/io/Compression.h>
#include <openvdb/io/DelayedLoadMetadata.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <sstream>
#include <vector>

namespace ivdb::io {

namespace {

[[noreturn]] void ioError(const std::string& path, const std::string& what)
{
    OPENVDB_THROW(openvdb::IoError, path + ": " + what);
}

/// Bounds-checked reads of the file's own layout, so that a truncated or corrupt file is refused
/// before OpenVDB's reader sees it (which accepts some truncations and allocates whatever length a
/// corrupt metadata field claims).
class LayoutReader
{
public:
    LayoutReader(const std::string& path, const FileMapping& file)
        : mPath(path), mFile(file), mData(file.data()), mSize(file.size()) {}

    std::uint64_t pos() const { return mPos; }

    void seek(std::uint64_t pos)
    {
        if (pos > mSize) corrupt("an offset points past the end of the file");
        mPos = pos;
        dropBehind();
    }

    /// Let the pages passed go from memory as the walk goes on (FileMapping::release).
    void releaseBehind() { mRelease = true; }

    void bytes(void* out, std::uint64_t n, std::uint64_t end)
    {
        if (n > end || end > mSize || mPos > end - n) {
            corrupt("it ends in the middle of a field (truncated?)");
        }
        std::memcpy(out, mData + mPos, n);
        mPos += n;
        dropBehind();
    }

    void skip(std::uint64_t n, std::uint64_t end)
    {
        if (n > end || mPos > end - n) corrupt("a field claims more bytes than the file holds");
        seek(mPos + n);
    }

    std::uint32_t u32(std::uint64_t end)
    {
        std::uint32_t v = 0;
        bytes(&v, sizeof(v), end);
        return v;
    }

    std::int64_t i64(std::uint64_t end)
    {
        std::int64_t v = 0;
        bytes(&v, sizeof(v), end);
        return v;
    }

    std::string str(std::uint64_t end)
    {
        const std::uint32_t n = u32(end);
        if (n > end - mPos || n > (1u << 20)) corrupt("a name claims more bytes than the file holds");
        std::string s(n, '\0');
        if (n) bytes(&s[0], n, end);
        return s;
    }

    /// A MetaMap: count, then (name, type name, byte count + value) per entry. Returns the entry
    /// count of its delayed-load table (type "__delayedload"), or -1 if it has none.
    std::int64_t metaMap(std::uint64_t end)
    {
        std::int64_t delayed = -1;
        const std::uint32_t count = u32(end);
        if (std::uint64_t(count) * 12 > end - mPos) corrupt("its metadata count is impossible");
        for (std::uint32_t i = 0; i < count; ++i) {
            const std::string name = str(end);
            const std::string type = str(end);
            const std::uint32_t bytes = u32(end);
            if (bytes > end - mPos) corrupt("a metadata value claims more bytes than the file holds");
            const std::uint64_t valueEnd = mPos + bytes;
            if (type == "__delayedload") {
                // An empty table (0 bytes) is what OpenVDB writes for a grid without leaves.
                mDelayedLoadAt = mPos - 4;
                delayed = bytes > 0 ? delayedLoad(valueEnd) : 0;
            } else if (type != "string") {
                fixedSizeValue(name, type, bytes, valueEnd);
            }
            seek(valueEnd);
        }
        return delayed;
    }

    /// OpenVDB reads a value of the standard fixed-size types by its type's size, whatever byte
    /// count the file gives (and a bool straight into a bool), so a count that differs would make
    /// it read everything after from the wrong place.
    void fixedSizeValue(const std::string& name, const std::string& type, std::uint32_t bytes,
                        std::uint64_t end)
    {
        static const std::pair<const char*, std::uint32_t> kSizes[] = {
            {"bool", 1}, {"int32", 4}, {"int64", 8}, {"float", 4}, {"double", 8}, {"vec2i", 8},
            {"vec2s", 8}, {"vec2d", 16}, {"vec3i", 12}, {"vec3s", 12}, {"vec3d", 24},
            {"vec4i", 16}, {"vec4s", 16}, {"vec4d", 32}, {"mat4s", 64}, {"mat4d", 128}};
        for (const auto& [known, size] : kSizes) {
            if (type != known) continue;
            if (bytes != size) {
                corrupt("metadata '" + name.substr(0, 64) + "' of type " + type + " holds " +
                        std::to_string(bytes) + " bytes instead of " + std::to_string(size));
            }
            if (type == "bool") {
                unsigned char value = 0;
                this->bytes(&value, 1, end);
                if (value > 1) corrupt("metadata '" + name.substr(0, 64) + "' is not a bool");
            }
            return;
        }
        // Any other type OpenVDB knows reads its value its own way, which this check cannot
        // follow; unknown types are read as raw bytes, by the byte count.
        if (openvdb::Metadata::isRegisteredType(type)) {
            corrupt("metadata '" + name.substr(0, 64) + "' has type '" + type.substr(0, 64) +
                    "', which ivdb does not read");
        }
    }

    /// io::DelayedLoadMetadata, which OpenVDB sizes by its entry count before reading anything
    /// else: the count, then a byte per leaf and an int64 per leaf (the latter may be absent,
    /// marked by 0xffffffff), each as a byte count and then raw (count 0) or blosc-compressed.
    std::uint32_t delayedLoad(std::uint64_t end)
    {
        const std::uint32_t count = u32(end);
        delayedLoadTable(count, 1, end, /*optional=*/false);
        delayedLoadTable(count, 8, end, /*optional=*/true);
        return count;
    }

    void delayedLoadTable(std::uint32_t count, std::uint64_t valueBytes, std::uint64_t end,
                          bool optional)
    {
        const std::uint32_t bytes = u32(end);
        if (optional && bytes == 0xffffffffu) return;
        if (bytes == 0) {
            skip(count * valueBytes, end);
            return;
        }
        // A blosc block: its header holds the raw size (bytes 4-7) and its own size (12-15).
        // (OpenVDB leaves tables under 48 bytes raw.)
        unsigned char header[16];
        if (bytes < sizeof(header)) corrupt("its delayed-load table is damaged");
        this->bytes(header, sizeof(header), end);
        std::uint32_t raw = 0, stored = 0;
        std::memcpy(&raw, header + 4, 4);
        std::memcpy(&stored, header + 12, 4);
        // OpenVDB pads tables under 128 bytes to 128 before compressing them.
        const std::uint64_t expected = count * valueBytes;
        if ((raw != expected && !(expected < 128 && raw == 128)) || stored != bytes) {
            corrupt("its delayed-load table is damaged (" + std::to_string(count) +
                    " entries, but a block of " + std::to_string(raw) + " bytes)");
        }
        skip(bytes - sizeof(header), end);
    }

    /// A transform: the map's type name, then its fields (all doubles, fixed in size per type).
    void transform(std::uint64_t end, const std::string& grid, int depth = 0)
    {
        const std::string type = str(end);
        if (type == "AffineMap" || type == "UnitaryMap") {
            skip(16 * 8, end);                      // Mat4d
        } else if (type == "ScaleMap" || type == "UniformScaleMap") {
            skip(5 * 3 * 8, end);                   // scale, voxel size and three inverses
        } else if (type == "ScaleTranslateMap" || type == "UniformScaleTranslateMap") {
            skip(6 * 3 * 8, end);                   // translation, then as ScaleMap
        } else if (type == "TranslationMap") {
            skip(3 * 8, end);
        } else if (type == "NonlinearFrustumMap" && depth == 0) {
            skip(2 * 3 * 8 + 2 * 8, end);           // bounding box, taper, depth
            transform(end, grid, depth + 1);        // its linear part
        } else {
            corrupt("grid '" + grid.substr(0, 64) + "' has a transform of unknown type '" +
                    type.substr(0, 64) + "'");
        }
    }

    /// Where the last delayed-load table read by metaMap() starts (its byte count).
    std::uint64_t delayedLoadAt() const { return mDelayedLoadAt; }

    /// Let OpenVDB read from @a pos (bytes this reader has checked), then come back to pos().
    template<typename ReadFn>
    void readWithOpenVdb(std::uint64_t pos, ReadFn&& read)
    {
        MemoryStream in(mData, mSize);
        in.seekg(std::streamoff(pos));
        read(static_cast<std::istream&>(in));
        if (!in) corrupt("it cannot be read to the end (truncated?)");
    }

    [[noreturn]] void corrupt(const std::string& why) const
    {
        ioError(mPath, "not a valid .vdb file: " + why);
    }

private:
    /// With releaseBehind(): every 64 MB walked forward, let the pages behind go.
    void dropBehind()
    {
        constexpr std::uint64_t kChunk = std::uint64_t(64) << 20;
        if (!mRelease || mPos < mReleased + kChunk) return;
        mFile.release(mReleased, mPos);
        mReleased = mPos;
    }

    std::string mPath;
    const FileMapping& mFile;
    const char* mData;
    std::uint64_t mSize, mPos = 0, mDelayedLoadAt = 0;
    bool mRelease = false;
    std::uint64_t mReleased = 0;
};

/// What the root node's records of a tree type look like ("Tree_float_5_4_3", with an optional
/// "_HalfFloat"); valueBytes is 0 for a value type not listed here, whose records are not checked.
struct TreeLayout
{
    std::uint64_t valueBytes = 0;
    std::uint64_t halfBytes = 0; // a value as half floats ("_HalfFloat" grids of real values)
    bool boolValues = false; // values are C++ bools, so a byte other than 0 or 1 is invalid
    bool half = false;       // the grid stores its real values as half floats
    int rootChildLog2 = 0;   // log2 of the root's children's width in voxels
    /// Node widths (log2) from the root's children down to plain leaves, when the whole topology
    /// is checked: the standard 5-4-3 trees of plain (not bool, mask or point) values.
    std::vector<int> nodeLog2;
};

TreeLayout treeLayout(const std::string& gridType)
{
    TreeLayout layout;
    std::vector<std::string> parts;
    std::istringstream in(gridType);
    for (std::string part; std::getline(in, part, '_');) parts.push_back(part);
    if (parts.size() < 3 || parts[0] != "Tree") return layout;
    static const std::pair<const char*, std::uint64_t> kSizes[] = {
        {"bool", 1}, {"mask", 1}, {"half", 2}, {"float", 4}, {"double", 8}, {"int32", 4},
        {"int64", 8}, {"uint32", 4}, {"ptdataidx32", 4}, {"ptdataidx64", 8}, {"vec2i", 8},
        {"vec2s", 8}, {"vec2d", 16}, {"vec3i", 12}, {"vec3s", 12}, {"vec3d", 24}};
    for (const auto& [name, bytes] : kSizes) {
        if (parts[1] == name) layout.valueBytes = bytes;
    }
    layout.boolValues = parts[1] == "bool";
    static const std::pair<const char*, std::uint64_t> kHalfSizes[] = {
        {"float", 2}, {"double", 2}, {"vec2s", 4}, {"vec2d", 4}, {"vec3s", 6}, {"vec3d", 6}};
    for (const auto& [name, bytes] : kHalfSizes) {
        if (parts[1] == name) layout.halfBytes = bytes;
    }
    std::vector<int> log2;
    for (std::size_t i = 2; i < parts.size(); ++i) {
        if (parts[i] == "HalfFloat" && i + 1 == parts.size()) {
            layout.half = true;
            continue;
        }
        if (parts[i].empty() || parts[i].size() > 2 ||
            parts[i].find_first_not_of("0123456789") != std::string::npos) {
            return TreeLayout();
        }
        log2.push_back(std::stoi(parts[i]));
        layout.rootChildLog2 += log2.back();
    }
    if (layout.rootChildLog2 == 0 || layout.rootChildLog2 > 30) return TreeLayout();
    static const char* const kPlain[] = {"float", "double", "int32", "int64", "vec3i", "vec3s",
                                         "vec3d"};
    const bool plain = std::find(std::begin(kPlain), std::end(kPlain), parts[1]) != std::end(kPlain);
    if (plain && log2 == std::vector<int>{5, 4, 3}) layout.nodeLog2 = log2;
    return layout;
}

/// Bits set in a node mask read as 64-bit words.
std::uint64_t countOn(const std::vector<std::uint64_t>& words)
{
    std::uint64_t n = 0;
    for (std::uint64_t word: words) n += std::uint64_t(__builtin_popcountll(word));
    return n;
}

/// Walks a tree's topology as OpenVDB 10 reads it (InternalNode::readTopology,
/// io::readCompressedValues, LeafNode::readTopology), with every count checked against the
/// bytes before the grid's voxel data. OpenVDB reads on past the end of a damaged topology and
/// allocates a node for every bit its (then unread) masks hold: a 28 kB file took 24 GB.
class TopologyWalker
{
public:
    TopologyWalker(LayoutReader& in, const TreeLayout& layout, std::uint32_t compression,
                   std::uint64_t end, const std::string& where)
        : mIn(in), mLayout(layout), mCompression(compression), mEnd(end), mWhere(where) {}

    /// A node of mLayout.nodeLog2[level]: an internal node, or a leaf at the last level.
    void node(std::size_t level)
    {
        const std::uint64_t count = std::uint64_t(1) << (3 * mLayout.nodeLog2[level]);
        const std::uint64_t maskBytes = count / 8;
        if (level + 1 == mLayout.nodeLog2.size()) {
            // A leaf's topology is its value mask; its active count sizes its values later.
            std::vector<std::uint64_t> mask(count / 64);
            mIn.bytes(mask.data(), maskBytes, mEnd);
            mLeafActive.push_back(std::uint16_t(countOn(mask)));
            ++mLeaves;
            return;
        }
        std::vector<std::uint64_t> children(count / 64), active(count / 64);
        mIn.bytes(children.data(), maskBytes, mEnd);
        mIn.bytes(active.data(), maskBytes, mEnd);
        const std::uint64_t childCount = countOn(children), activeCount = countOn(active);
        // Each child needs at least its own masks: refuse a count the bytes cannot hold before
        // descending (which would also be OpenVDB's allocation).
        const std::uint64_t childMaskBytes = (std::uint64_t(1) << (3 * mLayout.nodeLog2[level + 1])) / 8;
        values(count, activeCount, maskBytes);
        if (childCount * childMaskBytes > mEnd - mIn.pos()) {
            mIn.corrupt(mWhere + "has a node with " + std::to_string(childCount) +
                        " children, more than its bytes can hold");
        }
        for (std::size_t w = 0; w < children.size(); ++w) {
            for (std::uint64_t bits = children[w]; bits; bits &= bits - 1) node(level + 1);
        }
    }

    /// The leaves' voxel data, as LeafNode::readBuffers reads it from a stream: per leaf, its
    /// value mask, then its values.
    void leafBuffers()
    {
        const std::uint64_t count = std::uint64_t(1) << (3 * mLayout.nodeLog2.back());
        std::vector<std::uint64_t> mask(count / 64);
        for (std::uint64_t i = 0; i < mLeaves; ++i) {
            if (mOffsets) mOffsets->push_back(mIn.pos());
            mIn.bytes(mask.data(), count / 8, mEnd);
            values(count, countOn(mask), count / 8);
        }
    }

    /// The leaves' voxel data in a file with grid offsets, as OpenVDB passes over it when it
    /// opens the file with delayed loading (LeafNode::readBuffers, seeking): the value masks
    /// are the topology's; with a delayed-load @a table, each leaf's value-compression case
    /// and block size are the table's, and must match the file's own, which OpenVDB reads when
    /// the leaf is first touched.
    void seekableLeafBuffers(const openvdb::io::DelayedLoadMetadata* table)
    {
        namespace vio = openvdb::io;
        const std::uint64_t count = std::uint64_t(1) << (3 * mLayout.nodeLog2.back());
        const bool maskCompressed = (mCompression & vio::COMPRESS_ACTIVE_MASK) != 0;
        std::vector<std::uint64_t> mask(count / 64);
        for (std::uint64_t i = 0; i < mLeaves; ++i) {
            // The value mask is the topology's again: OpenVDB's delayed loading uses the
            // topology's and a full load this one, so they must agree on the values stored.
            if (mOffsets) mOffsets->push_back(mIn.pos());
            mIn.bytes(mask.data(), count / 8, mEnd);
            if (countOn(mask) != mLeafActive[i]) {
                mIn.corrupt(mWhere + "has a leaf whose value mask differs from its topology's");
            }
            Expect expect;
            if (!maskCompressed) {
                expect.how = vio::NO_MASK_AND_ALL_VALS; // OpenVDB skips the byte and assumes this
            } else if (table) {
                expect.how = table->getMask(i);
            }
            if (table && (mCompression & (vio::COMPRESS_BLOSC | vio::COMPRESS_ZIP))) {
                expect.blockBytes = table->getCompressedSize(i);
            }
            values(count, mLeafActive[i], count / 8, &expect);
        }
    }

    std::uint64_t leaves() const { return mLeaves; }

    /// Record where each leaf's voxel data starts in @a offsets.
    void recordOffsets(std::vector<std::uint64_t>* offsets) { mOffsets = offsets; }

    /// Where reading must stop from now on: the voxel data runs to the grid's end.
    void bound(std::uint64_t end) { mEnd = end; }

private:
    /// What OpenVDB's delayed-load pass takes from elsewhere than the value block itself.
    struct Expect
    {
        int how = -1;                // the value-compression case
        std::int64_t blockBytes = -1; // the compressed block's size, count included
    };

    /// A node's values, as io::readCompressedValues reads them.
    void values(std::uint64_t count, std::uint64_t activeCount, std::uint64_t maskBytes,
                const Expect* expect = nullptr)
    {
        namespace vio = openvdb::io;
        unsigned char how = 0; // which of the value-compression cases follows
        mIn.bytes(&how, 1, mEnd);
        if (how > vio::NO_MASK_AND_ALL_VALS) {
            mIn.corrupt(mWhere + "has a node whose values are stored in an unknown way (" +
                        std::to_string(int(how)) + ")");
        }
        if (expect && expect->how >= 0 && expect->how != how) {
            mIn.corrupt(mWhere + "has a leaf whose values are stored in one way (" +
                        std::to_string(int(how)) + ") where its delayed-load table says another (" +
                        std::to_string(expect->how) + ")");
        }
        if (how == vio::NO_MASK_AND_ONE_INACTIVE_VAL || how == vio::MASK_AND_ONE_INACTIVE_VAL) {
            mIn.skip(mLayout.valueBytes, mEnd);
        } else if (how == vio::MASK_AND_TWO_INACTIVE_VALS) {
            mIn.skip(2 * mLayout.valueBytes, mEnd);
        }
        if (how == vio::MASK_AND_NO_INACTIVE_VALS || how == vio::MASK_AND_ONE_INACTIVE_VAL ||
            how == vio::MASK_AND_TWO_INACTIVE_VALS) {
            mIn.skip(maskBytes, mEnd); // selection mask
        }
        std::uint64_t stored = count;
        if ((mCompression & vio::COMPRESS_ACTIVE_MASK) && how != vio::NO_MASK_AND_ALL_VALS) {
            stored = activeCount;
        }
        const bool half = mLayout.half && mLayout.halfBytes > 0;
        if (half && stored == 0) return; // OpenVDB's half reader reads nothing then
        const std::uint64_t bytes = stored * (half ? mLayout.halfBytes : mLayout.valueBytes);
        if (!(mCompression & (vio::COMPRESS_BLOSC | vio::COMPRESS_ZIP))) {
            mIn.skip(bytes, mEnd);
            return;
        }
        const std::int64_t block = mIn.i64(mEnd); // compressed bytes, or minus the raw bytes
        if (expect && expect->blockBytes >= 0) {
            const std::uint64_t actual = 8 + (block <= 0 ? std::uint64_t(-(block + 1)) + 1
                                                         : std::uint64_t(block));
            if (actual != std::uint64_t(expect->blockBytes)) {
                mIn.corrupt(mWhere + "has a leaf of " + std::to_string(actual) + " compressed "
                            "bytes where its delayed-load table says " +
                            std::to_string(expect->blockBytes));
            }
        }
        if (block <= 0) {
            const std::uint64_t raw = std::uint64_t(-(block + 1)) + 1;
            if (raw != bytes) {
                mIn.corrupt(mWhere + "has a value block of " + std::to_string(raw) +
                            " bytes where " + std::to_string(bytes) + " were expected");
            }
            mIn.skip(raw, mEnd);
        } else {
            if (std::uint64_t(block) > bytes + bytes / 100 + 1024) {
                mIn.corrupt(mWhere + "has a compressed block of " + std::to_string(block) +
                            " bytes for " + std::to_string(bytes) + " bytes of values");
            }
            mIn.skip(std::uint64_t(block), mEnd);
        }
    }

    LayoutReader& mIn;
    const TreeLayout& mLayout;
    std::uint32_t mCompression;
    std::uint64_t mEnd;
    std::string mWhere;
    std::uint64_t mLeaves = 0;
    std::vector<std::uint16_t> mLeafActive; // active voxels per leaf, in file order
    std::vector<std::uint64_t>* mOffsets = nullptr;
};

/// A grid's tree, from its root node on. OpenVDB reads the root's tile records without checking:
/// a tile's "active" flag goes straight into a bool (undefined behaviour for a byte other than 0
/// or 1), and a damaged tile count makes it read past its bytes. For the trees TreeLayout walks
/// (nodeLog2), then the whole topology and the voxel data (to @a gridEnd), with the leaf count
/// checked against the delayed-load table's (@a delayed, -1 without one).
void checkTree(LayoutReader& in, const TreeLayout& layout, std::uint32_t compression,
               std::uint64_t end, const std::string& grid, bool buffers, std::uint64_t gridEnd,
               std::int64_t delayed, GridLayout& out)
{
    const std::string where = "grid '" + grid.substr(0, 64) + "' ";
    in.skip(4, end); // buffer count
    std::vector<unsigned char> value(layout.valueBytes);
    in.bytes(value.data(), value.size(), end); // background
    if (layout.boolValues && value[0] > 1) in.corrupt(where + "has an invalid background");
    const std::uint32_t tiles = in.u32(end), children = in.u32(end);
    const std::uint64_t tileBytes = 12 + layout.valueBytes + 1;
    if (tiles * tileBytes + std::uint64_t(children) * 12 > end - in.pos()) {
        in.corrupt(where + "claims " + std::to_string(tiles) + " root tiles and " +
                   std::to_string(children) + " children, more than its bytes can hold");
    }
    const std::int64_t alignment = (std::int64_t(1) << layout.rootChildLog2) - 1;
    for (std::uint32_t i = 0; i < tiles; ++i) {
        std::int32_t origin[3];
        in.bytes(origin, sizeof(origin), end);
        in.bytes(value.data(), value.size(), end);
        unsigned char active = 0;
        in.bytes(&active, 1, end);
        if (active > 1 || (layout.boolValues && value[0] > 1) || (origin[0] & alignment) ||
            (origin[1] & alignment) || (origin[2] & alignment)) {
            in.corrupt(where + "has an invalid root tile record (number " + std::to_string(i) +
                       " of " + std::to_string(tiles) + ")");
        }
    }
    if (layout.nodeLog2.empty()) return;
    TopologyWalker walker(in, layout, compression, end, where);
    for (std::uint32_t i = 0; i < children; ++i) {
        std::int32_t origin[3];
        in.bytes(origin, sizeof(origin), end);
        if ((origin[0] & alignment) || (origin[1] & alignment) || (origin[2] & alignment)) {
            in.corrupt(where + "has a root child at an invalid origin (number " +
                       std::to_string(i) + " of " + std::to_string(children) + ")");
        }
        walker.node(0);
    }
    const std::int64_t leaves = std::int64_t(walker.leaves());
    if (delayed >= 0 && leaves != delayed) {
        in.corrupt(where + "has " + std::to_string(leaves) + " leaves but a delayed-load table "
                   "of " + std::to_string(delayed));
    }
    // The voxel data: OpenVDB reads on from where the topology ended.
    out.leaves.reserve(walker.leaves());
    walker.recordOffsets(&out.leaves);
    out.leavesWalked = true;
    if (buffers) {
        walker.leafBuffers();
        return;
    }
    openvdb::io::DelayedLoadMetadata table;
    if (delayed >= 0) {
        const std::uint64_t at = in.delayedLoadAt();
        in.readWithOpenVdb(at, [&table](std::istream& is) { table.read(is); });
    }
    walker.bound(gridEnd);
    walker.seekableLeafBuffers(delayed >= 0 ? &table : nullptr);
}

struct GridRecord
{
    std::string name, type;
    std::string parent; // the grid whose tree this one shares (so stores none), if any
    bool instance = false;
    std::int64_t grid = 0, block = 0, end = 0;
};

/// One grid's bytes, from its compression flags on: metadata, transform and (unless it shares
/// another grid's tree) the tree; with @a buffers, also its voxel data, which in a file without
/// grid offsets is the only way to find where the next grid starts.
GridLayout checkGrid(LayoutReader& in, const GridRecord& d, std::uint64_t end, bool buffers)
{
    const std::string where = "grid '" + d.name.substr(0, 64) + "' ";
    const std::uint64_t start = in.pos();
    GridLayout out;
    out.uniqueName = d.name;
    out.type = d.type;
    out.parent = d.parent;
    out.start = start;
    const std::uint32_t compression = in.u32(end);
    const std::int64_t delayed = in.metaMap(end);
    in.transform(end, d.name);
    if (d.instance) return out;
    const TreeLayout layout = treeLayout(d.type);
    if (buffers && layout.nodeLog2.empty()) {
        in.corrupt(where + "is of type '" + d.type.substr(0, 64) + "', which ivdb reads only "
                   "from a file with grid offsets (re-save it with OpenVDB's vdb_tool)");
    }
    // Every leaf stores at least a 64-byte value mask.
    if (delayed > 0 && std::uint64_t(delayed) * 64 > end - start) {
        in.corrupt(where + "has a delayed-load table of " + std::to_string(delayed) +
                   " leaves, more than its bytes can hold");
    }
    if (layout.valueBytes == 0) return out;
    checkTree(in, layout, compression, end, d.name, buffers, std::uint64_t(d.end), delayed, out);
    return out;
}

} // namespace

FileLayout validateLayout(const std::string& path, const FileMapping& file, bool releaseBehind)
{
    const std::uint64_t size = file.size();
    if (size == 0) ioError(path, "is empty, not a .vdb file");
    LayoutReader in(path, file);
    if (releaseBehind) in.releaseBehind();
    FileLayout result;
    std::int64_t magic = 0;
    if (size < 8) ioError(path, "is too short to be a .vdb file");
    in.bytes(&magic, 8, size);
    if (magic != openvdb::OPENVDB_MAGIC) ioError(path, "is not a .vdb file (no OpenVDB magic number)");
    const std::uint32_t version = in.u32(size);
    result.fileVersion = version;
    // Older layouts differ, and OpenVDB reads them with fewer checks still; files that old (from
    // before OpenVDB 1.0) can be brought up to date by re-saving them with OpenVDB.
    if (version < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION ||
        version > openvdb::OPENVDB_FILE_VERSION) {
        ioError(path, "is in OpenVDB file format " + std::to_string(version) + ", and ivdb reads "
                "formats " + std::to_string(openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION) +
                " to " + std::to_string(openvdb::OPENVDB_FILE_VERSION) + (version < 
                openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION ? " (re-save it with OpenVDB's "
                "vdb_tool: vdb_tool -read old.vdb -write new.vdb)" : " (a damaged file?)"));
    }
    result.libraryMajor = in.u32(size);
    result.libraryMinor = in.u32(size);
    char hasOffsets = 0;
    in.bytes(&hasOffsets, 1, size);
    result.hasGridOffsets = hasOffsets != 0;
    in.skip(36, size);      // UUID
    in.metaMap(size);       // file metadata
    const std::int32_t count = std::int32_t(in.u32(size));
    if (count <= 0) ioError(path, "holds no grids");
    if (std::uint64_t(count) * 36 > size - in.pos()) in.corrupt("its grid count is impossible");
    const auto readRecord = [&in, size]() {
        GridRecord d;
        d.name = in.str(size);
        d.type = in.str(size);
        d.parent = in.str(size);
        d.instance = !d.parent.empty();
        d.grid = in.i64(size);
        d.block = in.i64(size);
        d.end = in.i64(size);
        return d;
    };
    if (!hasOffsets) {
        // A stream (io::Stream's layout) saved to a file: each grid follows its record.
        for (std::int32_t i = 0; i < count; ++i) {
            result.grids.push_back(checkGrid(in, readRecord(), size, true));
        }
        return result;
    }
    std::vector<GridRecord> grids;
    for (std::int32_t i = 0; i < count; ++i) {
        GridRecord d = readRecord();
        const std::uint64_t header = in.pos();
        // A grid that shares another's tree has no voxel data, and no block offset.
        const std::int64_t block = d.instance ? d.end : d.block;
        if (d.grid < std::int64_t(header) || block < d.grid || d.end < block ||
            std::uint64_t(d.end) > size) {
            std::ostringstream os;
            os << "not a valid .vdb file: grid " << i << " ('" << d.name.substr(0, 64)
               << "') claims bytes " << d.grid << " to " << d.end << " but the file has " << size
               << " bytes (truncated?)";
            ioError(path, os.str());
        }
        d.block = block;
        grids.push_back(d);
        in.seek(std::uint64_t(d.end));
    }
    for (const GridRecord& d : grids) {
        in.seek(std::uint64_t(d.grid));
        result.grids.push_back(checkGrid(in, d, std::uint64_t(d.block), false));
    }
    return result;
}

} // namespace ivdb::io
