// SPDX-License-Identifier: Apache-2.0
// The parallel .vdb reader: the file is mapped, its layout checked (which also finds where each
// leaf's voxel data starts), the grids' metadata, transforms and topology read by OpenVDB's own
// functions, and then every leaf's values on all threads: straight from the mapped bytes for
// full values with Blosc or no codec (decodeLeaf, OpenVDB's own decoding steps), else by
// OpenVDB's LeafNode::readBuffers, each task through its own stream over the mapped bytes.
//
// Why not OpenVDB's delayed loading: io::File copies files under 500 MB to a temporary file
// first, and then reads each leaf when first touched, through a lock and a new stream per leaf;
// every ivdb command touches every voxel (the value check alone does), so the whole grid is
// read anyway, and reading it here in one parallel pass is faster (docs/performance.md).
#include <ivdb/io/VdbFile.h>
#include <ivdb/io/VdbPieces.h>

#include "Cancel.h"
#include "FileMapping.h"
#include "Layout.h"

#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <openvdb/io/Compression.h>
#include <openvdb/io/File.h>
#include <openvdb/io/io.h>

#include <blosc.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <string>

#include <unistd.h>

namespace ivdb::io {

namespace fs = std::filesystem;

namespace {

[[noreturn]] void ioError(const std::string& path, const std::string& what)
{
    OPENVDB_THROW(openvdb::IoError, path + ": " + what);
}

/// The grid types whose leaves the layout check locates (GridLayout::leaves).
using WalkedGrids = openvdb::TypeList<openvdb::FloatGrid, openvdb::DoubleGrid, openvdb::Int32Grid,
                                      openvdb::Int64Grid, openvdb::Vec3IGrid, openvdb::Vec3SGrid,
                                      openvdb::Vec3DGrid>;

/// What every stream reading a grid's bytes must be tagged with.
struct StreamState
{
    openvdb::VersionId library;
    std::uint32_t fileVersion = 0, compression = 0;

    void tag(std::istream& is) const
    {
        openvdb::io::setVersion(is, library, fileVersion);
        openvdb::io::setDataCompression(is, compression);
    }
};

/// Throw for a leaf's voxel data that does not hold what it claims.
[[noreturn]] void damagedLeaf(const std::string& what)
{
    OPENVDB_THROW(openvdb::IoError, "a leaf's voxel data is damaged (" + what + ")");
}

/// One leaf's voxel data read straight from the mapped bytes [@a p, @a end), as
/// LeafNode::readBuffers and io::readCompressedValues read it from a stream (value mask, how the
/// inactive values are stored, the active values through Blosc or raw), with the blocks checked
/// as StreamGuards.cc checks OpenVDB's own reads; the inactive values are rebuilt a word of 64
/// voxels at a time instead of a bit test per voxel. For full (not half) values with active-value
/// compression and Blosc or no codec: the files OpenVDB and ivdb write by default.
template<typename LeafT>
void decodeLeaf(LeafT& leaf, const char* p, const char* end, std::uint32_t compression,
                const typename LeafT::ValueType& background)
{
    namespace vio = openvdb::io;
    using ValueT = typename LeafT::ValueType;
    using MaskT = typename LeafT::NodeMaskType;
    constexpr openvdb::Index kWords = MaskT::WORD_COUNT;
    const auto take = [&p, end](void* out, std::size_t n) {
        if (std::size_t(end - p) < n) damagedLeaf("it ends early");
        std::memcpy(out, p, n);
        p += n;
    };
    MaskT& on = leaf.getValueMask();
    for (openvdb::Index w = 0; w < kWords; ++w) take(&on.template getWord<openvdb::Index64>(w), 8);
    std::int8_t how = 0;
    take(&how, 1);
    ValueT inactive1 = background;
    ValueT inactive0 = how == vio::NO_MASK_OR_INACTIVE_VALS ? background
                                                            : openvdb::math::negative(background);
    if (how == vio::NO_MASK_AND_ONE_INACTIVE_VAL || how == vio::MASK_AND_ONE_INACTIVE_VAL ||
        how == vio::MASK_AND_TWO_INACTIVE_VALS) {
        take(&inactive0, sizeof(ValueT));
        if (how == vio::MASK_AND_TWO_INACTIVE_VALS) take(&inactive1, sizeof(ValueT));
    }
    MaskT select;
    if (how == vio::MASK_AND_NO_INACTIVE_VALS || how == vio::MASK_AND_ONE_INACTIVE_VAL ||
        how == vio::MASK_AND_TWO_INACTIVE_VALS) {
        for (openvdb::Index w = 0; w < kWords; ++w) {
            take(&select.template getWord<openvdb::Index64>(w), 8);
        }
    }
    const openvdb::Index count = how == vio::NO_MASK_AND_ALL_VALS ? LeafT::SIZE : on.countOn();
    ValueT* dest = leaf.buffer().data();
    ValueT active[LeafT::SIZE + 1];
    ValueT* values = count == LeafT::SIZE ? dest : active;
    const std::size_t bytes = std::size_t(count) * sizeof(ValueT);
    if (compression & vio::COMPRESS_BLOSC) {
        std::int64_t block = 0;
        take(&block, sizeof(block));
        if (block <= 0) {
            if (std::uint64_t(-(block + 1)) + 1 != bytes) damagedLeaf("a raw block of the wrong size");
            take(values, bytes);
        } else {
            if (std::uint64_t(block) > bytes + bytes / 100 + 1024 || end - p < block ||
                block < BLOSC_MIN_HEADER_LENGTH) {
                damagedLeaf("a compressed block of " + std::to_string(block) + " bytes for " +
                            std::to_string(bytes));
            }
            std::uint32_t raw = 0, stored = 0;
            std::memcpy(&raw, p + 4, 4);
            std::memcpy(&stored, p + 12, 4);
            if (raw != bytes || std::int64_t(stored) != block ||
                blosc_decompress_ctx(p, values, bytes, 1) != int(bytes)) {
                damagedLeaf("a compressed block that does not decompress to its values");
            }
            p += block;
        }
    } else {
        take(values, bytes);
    }
    if (values == dest) return;
    // The inactive values: the first, or the second where the selection mask says so.
    active[count] = ValueT(); // read (and not used) past the last active value
    openvdb::Index next = 0;
    for (openvdb::Index w = 0; w < kWords; ++w) {
        const openvdb::Index64 word = on.template getWord<openvdb::Index64>(w);
        const openvdb::Index64 second = select.template getWord<openvdb::Index64>(w);
        for (openvdb::Index k = 0; k < 64; ++k) {
            const bool isOn = (word >> k) & 1;
            const ValueT& off = ((second >> k) & 1) ? inactive1 : inactive0;
            dest[w * 64 + k] = isOn ? active[next] : off;
            next += openvdb::Index(isOn);
        }
    }
}

/// The grid's leaves in file order, one for each voxel data block the layout check found.
template<typename GridT>
std::vector<typename GridT::TreeType::LeafNodeType*>
leavesInFileOrder(GridT& grid, const GridLayout& layout)
{
    std::vector<typename GridT::TreeType::LeafNodeType*> leaves;
    leaves.reserve(layout.leaves.size());
    grid.tree().getNodes(leaves);
    if (leaves.size() != layout.leaves.size()) {
        OPENVDB_THROW(openvdb::IoError, "grid '" + grid.getName() + "' has " +
                      std::to_string(leaves.size()) + " leaves where its voxel data has " +
                      std::to_string(layout.leaves.size()));
    }
    return leaves;
}

/// The voxel data of @a all (leavesInFileOrder()), or of the leaves @a only picks (indices
/// into @a all), in parallel: each task reads a run of consecutive leaves through its own
/// stream, so no state is shared but the (read-only) mapping.
template<typename GridT>
void readLeaves(GridT& grid, const std::vector<typename GridT::TreeType::LeafNodeType*>& all,
                const GridLayout& layout, const FileMapping& file, const StreamState& state,
                const std::vector<std::uint64_t>* only = nullptr)
{
    using LeafT = typename GridT::TreeType::LeafNodeType;
    std::vector<LeafT*> picked;
    std::vector<std::uint64_t> offsets;
    if (only) {
        for (std::uint64_t i : *only) {
            picked.push_back(all[i]);
            offsets.push_back(layout.leaves[i]);
        }
    }
    const std::vector<LeafT*>& leaves = only ? picked : all;
    const std::vector<std::uint64_t>& at = only ? offsets : layout.leaves;
    namespace vio = openvdb::io;
    const bool half = grid.saveFloatAsHalf();
    const auto& background = grid.tree().background();
    // The common case is decoded here; half floats and zip go through OpenVDB's readBuffers.
    const bool direct = !half && (state.compression & vio::COMPRESS_ACTIVE_MASK) &&
                        !(state.compression & vio::COMPRESS_ZIP);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size(), 64),
                      [&](const tbb::blocked_range<std::size_t>& r) {
        if (direct) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) {
                decodeLeaf(*leaves[i], file.data() + at[i], file.data() + file.size(),
                           state.compression, background);
            }
            return;
        }
        MemoryStream is(file.data(), file.size());
        state.tag(is);
        vio::setGridBackgroundValuePtr(is, &background);
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            is.seekg(std::streamoff(at[i]));
            leaves[i]->readBuffers(is, half);
            if (!is) {
                OPENVDB_THROW(openvdb::IoError, "grid '" + grid.getName() + "' ends inside the "
                              "voxel data of a leaf");
            }
        }
    });
    detail::throwIfCancelled("reading grid '" + grid.getName() + "'");
}

/// One grid from its record on, as OpenVDB's Archive reads it (compression flags, metadata
/// without the delayed-load table, transform and, with @a topology, the topology, its leaves
/// holding no values yet); @a state takes the grid's compression flags.
openvdb::GridBase::Ptr readGridHead(const GridLayout& layout, const FileMapping& file,
                                    StreamState& state, bool topology)
{
    std::string type = layout.type;
    const std::string halfSuffix = "_HalfFloat";
    const bool half = type.size() > halfSuffix.size() &&
                      type.compare(type.size() - halfSuffix.size(), halfSuffix.size(), halfSuffix) == 0;
    if (half) type.resize(type.size() - halfSuffix.size());
    if (!openvdb::GridBase::isRegistered(type)) {
        OPENVDB_THROW(openvdb::IoError, "grid '" + layout.uniqueName + "' has type '" + type +
                      "', which this OpenVDB build does not know");
    }
    openvdb::GridBase::Ptr grid = openvdb::GridBase::createGrid(type);
    grid->setSaveFloatAsHalf(half);

    MemoryStream is(file.data(), file.size());
    is.seekg(std::streamoff(layout.start));
    is.read(reinterpret_cast<char*>(&state.compression), sizeof(state.compression));
    state.tag(is);
    grid->readMeta(is);
    // Only OpenVDB's delayed loading uses the table; a grid read from a file never keeps it.
    if ((*grid)[openvdb::GridBase::META_FILE_DELAYED_LOAD]) {
        grid->removeMeta(openvdb::GridBase::META_FILE_DELAYED_LOAD);
    }
    grid->readTransform(is);
    if (topology && layout.parent.empty()) {
        grid->readTopology(is);
        if (!is) OPENVDB_THROW(openvdb::IoError, "grid '" + layout.uniqueName + "' is truncated");
    }
    if (!is) OPENVDB_THROW(openvdb::IoError, "grid '" + layout.uniqueName + "' is truncated");
    return grid;
}

/// One grid from its record on, then its voxel data in parallel.
openvdb::GridBase::Ptr readGridParallel(const GridLayout& layout, const FileMapping& file,
                                        StreamState state)
{
    openvdb::GridBase::Ptr grid = readGridHead(layout, file, state, true);
    if (layout.parent.empty()) {
        const bool known = grid->apply<WalkedGrids>([&](auto& g) {
            readLeaves(g, leavesInFileOrder(g, layout), layout, file, state);
        });
        if (!known) {
            OPENVDB_THROW(openvdb::IoError, "grid '" + layout.uniqueName + "' has type '" +
                          layout.type + "', which the parallel reader does not read");
        }
    }
    return grid;
}

/// Whether every grid's voxel data was located by the layout check.
bool readableInParallel(const FileLayout& layout)
{
    for (const GridLayout& g : layout.grids) {
        if (g.parent.empty() && !g.leavesWalked) return false;
    }
    return true;
}

/// The grids in the order OpenVDB's io::File::getGrids() gives them (from a file with grid
/// offsets sorted by name, then in file order; from a stream in file order), so that "the first
/// level set" means what it means to OpenVDB's own tools.
void sortAsOpenVdb(std::vector<std::pair<std::string, openvdb::GridBase::Ptr>>& grids,
                   const FileLayout& layout)
{
    if (!layout.hasGridOffsets) return;
    std::stable_sort(grids.begin(), grids.end(), [](const auto& a, const auto& b) {
        return a.first < b.first;
    });
}

openvdb::GridPtrVec readParallel(const std::string& path, const FileMapping& file,
                                 const FileLayout& layout)
{
    StreamState state;
    state.library = openvdb::VersionId(layout.libraryMajor, layout.libraryMinor);
    state.fileVersion = layout.fileVersion;
    std::map<std::string, openvdb::GridBase::Ptr> byUniqueName;
    std::vector<std::pair<std::string, openvdb::GridBase::Ptr>> grids;
    try {
        for (const GridLayout& g : layout.grids) {
            openvdb::GridBase::Ptr grid = readGridParallel(g, file, state);
            byUniqueName[g.uniqueName] = grid;
            grids.emplace_back(openvdb::io::GridDescriptor::stripSuffix(g.uniqueName), grid);
        }
    } catch (const std::exception& e) {
        ioError(path, "not a readable .vdb file: " + util::errorText(e));
    }
    // Grids that share a tree (instances) take their parent's.
    for (const GridLayout& g : layout.grids) {
        if (g.parent.empty()) continue;
        const auto parent = byUniqueName.find(g.parent);
        if (parent == byUniqueName.end()) {
            ioError(path, "not a valid .vdb file: grid '" + g.uniqueName + "' shares the tree "
                    "of a grid the file does not hold");
        }
        byUniqueName[g.uniqueName]->setTree(parent->second->baseTreePtr());
    }
    sortAsOpenVdb(grids, layout);
    openvdb::GridPtrVec result;
    for (auto& g : grids) result.push_back(g.second);
    return result;
}

/// OpenVDB's own reader, with delayed loading: for the grid types the layout check does not
/// walk to the leaves (bool, mask and point grids, and trees of other shapes).
openvdb::GridPtrVec readWithOpenVdb(const std::string& path)
{
    openvdb::GridPtrVecPtr grids;
    try {
        openvdb::io::File file(path);
        file.open(/*delayLoad=*/true);
        grids = file.getGrids();
        file.close();
    } catch (const std::exception& e) {
        ioError(path, "not a readable .vdb file: " + util::errorText(e));
    }
    return grids ? *grids : openvdb::GridPtrVec();
}

/// Refuse a path that is not a readable regular file, naming it.
void checkReadable(const std::string& path)
{
    detail::throwIfCancelled(path + ": reading");
    std::error_code ec;
    if (!fs::exists(path, ec)) ioError(path, "no such file");
    if (fs::is_directory(path, ec)) ioError(path, "is a folder, not a .vdb file");
    if (::access(path.c_str(), R_OK) != 0) {
        ioError(path, std::string("cannot read: ") + std::strerror(errno));
    }
    if (!fs::is_regular_file(path, ec)) ioError(path, "is not a regular file");
}

} // namespace

openvdb::GridPtrVec readVdb(const std::string& path)
{
    checkReadable(path);
    openvdb::GridPtrVec grids;
    {
        const FileMapping file(path);
        const FileLayout layout = validateLayout(path, file);
        // The layout was checked, so every byte either reader reads is in the file.
        if (readableInParallel(layout)) grids = readParallel(path, file, layout);
    }
    if (grids.empty()) grids = readWithOpenVdb(path);
    if (grids.empty()) ioError(path, "holds no grids");
    return grids;
}

struct PartialGrid::Impl
{
    std::string path;
    std::unique_ptr<FileMapping> file;
    FileLayout layout;
    std::size_t index = 0; // the grid's, in layout.grids
    StreamState state;
    openvdb::FloatGrid::Ptr grid;
    std::vector<LeafT*> leaves;
};

PartialGrid::PartialGrid(const std::string& path, const std::string& name)
    : mImpl(std::make_unique<Impl>())
{
    Impl& m = *mImpl;
    m.path = path;
    checkReadable(path);
    m.file = std::make_unique<FileMapping>(path);
    // The layout check walks the whole file; this process keeps only the pages it reads later.
    m.layout = validateLayout(path, *m.file, /*releaseBehind=*/true);
    m.state.library = openvdb::VersionId(m.layout.libraryMajor, m.layout.libraryMinor);
    m.state.fileVersion = m.layout.fileVersion;
    // The grids without their trees, in the order readVdb() gives them, to pick one as
    // selectGrid() picks it.
    std::vector<std::pair<std::string, openvdb::GridBase::Ptr>> heads;
    std::map<const openvdb::GridBase*, std::size_t> indexOf;
    try {
        for (std::size_t i = 0; i < m.layout.grids.size(); ++i) {
            StreamState state = m.state;
            auto g = readGridHead(m.layout.grids[i], *m.file, state, false);
            indexOf[g.get()] = i;
            heads.emplace_back(openvdb::io::GridDescriptor::stripSuffix(m.layout.grids[i].uniqueName), g);
        }
    } catch (const std::exception& e) {
        ioError(path, "not a readable .vdb file: " + util::errorText(e));
    }
    if (heads.empty()) ioError(path, "holds no grids");
    sortAsOpenVdb(heads, m.layout);
    openvdb::GridPtrVec grids;
    for (auto& h : heads) grids.push_back(h.second);
    const openvdb::GridBase::Ptr chosen = selectGrid(grids, path, name);
    if (!chosen->isType<openvdb::FloatGrid>()) {
        throw ParamError(param::kGrid, "grid '" + chosen->getName() + "' holds " +
                         chosen->valueType() + " values; this needs a float grid", path,
                         ParamError::Kind::Missing);
    }
    m.index = indexOf.at(chosen.get());
    const GridLayout& g = m.layout.grids[m.index];
    if (!g.parent.empty() || !g.leavesWalked) {
        ioError(path, "grid '" + chosen->getName() + "' shares another grid's tree or is not "
                "stored as a standard tree; re-save the file (ivdb convert IN.vdb -o OUT.vdb)");
    }
    try {
        m.grid = openvdb::gridPtrCast<openvdb::FloatGrid>(readGridHead(g, *m.file, m.state, true));
        m.leaves = leavesInFileOrder(*m.grid, g);
        m.file->release(0, m.file->size());
    } catch (const std::exception& e) {
        ioError(path, "not a readable .vdb file: " + util::errorText(e));
    }
}

PartialGrid::~PartialGrid() = default;

const openvdb::FloatGrid::Ptr& PartialGrid::grid() const { return mImpl->grid; }

const std::vector<PartialGrid::LeafT*>& PartialGrid::leaves() const { return mImpl->leaves; }

void PartialGrid::load(const std::vector<std::uint64_t>& indices)
{
    Impl& m = *mImpl;
    if (!m.file) OPENVDB_THROW(openvdb::ValueError, m.path + " was released");
    for (std::uint64_t i : indices) {
        if (i >= m.leaves.size()) {
            OPENVDB_THROW(openvdb::ValueError, "leaf " + std::to_string(i) + " of a grid of " +
                          std::to_string(m.leaves.size()));
        }
    }
    try {
        readLeaves(*m.grid, m.leaves, m.layout.grids[m.index], *m.file, m.state, &indices);
    } catch (const std::exception& e) {
        ioError(m.path, "not a readable .vdb file: " + util::errorText(e));
    }
}

void PartialGrid::release() { mImpl->file.reset(); }

void PartialGrid::checkValues(const std::vector<std::uint64_t>& indices) const
{
    const Impl& m = *mImpl;
    const std::string what = m.path + ": grid '" + m.grid->getName() + "'";
    const auto fail = [&](const std::string& where) {
        OPENVDB_THROW(openvdb::ValueError, what + " holds values that are not finite (NaN or "
            "infinity) " + where + "; the file is damaged or was written by a faulty tool, make "
            "it again");
    };
    const openvdb::Vec3d vs = m.grid->voxelSize();
    const openvdb::Vec3d origin = m.grid->transform().indexToWorld(openvdb::Vec3d(0.0));
    for (int a = 0; a < 3; ++a) {
        if (!std::isfinite(vs[a]) || !(vs[a] > 0.0) || !std::isfinite(origin[a])) {
            OPENVDB_THROW(openvdb::ValueError, what + " has an invalid transform; the file is "
                                                      "damaged, make it again");
        }
    }
    const auto& root = m.grid->tree().root();
    if (!std::isfinite(root.background())) fail("in its background");
    if (m.grid->getGridClass() == openvdb::GRID_LEVEL_SET && !(root.background() > 0.0f)) {
        OPENVDB_THROW(openvdb::ValueError, what + " is a level set with background " +
            util::formatNumber(root.background()) + "; a level set's background (the band's "
            "half width in world units) must be > 0, the file is damaged or not a level set");
    }
    const auto tile = [&](float v, const openvdb::Coord& at) {
        if (!std::isfinite(v)) {
            fail("in the tile at (" + std::to_string(at.x()) + ", " + std::to_string(at.y()) +
                 ", " + std::to_string(at.z()) + ")");
        }
    };
    for (auto it = root.cbeginValueAll(); it; ++it) tile(*it, it.getCoord());
    for (auto n2 = root.cbeginChildOn(); n2; ++n2) {
        for (auto it = n2->cbeginValueAll(); it; ++it) tile(*it, it.getCoord());
        for (auto n1 = n2->cbeginChildOn(); n1; ++n1) {
            for (auto it = n1->cbeginValueAll(); it; ++it) tile(*it, it.getCoord());
        }
    }
    std::atomic<std::uint64_t> bad{std::numeric_limits<std::uint64_t>::max()};
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, indices.size(), 64),
                      [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const float* v = m.leaves[indices[i]]->buffer().data();
            for (openvdb::Index k = 0; k < LeafT::SIZE; ++k) {
                if (!std::isfinite(v[k])) {
                    std::uint64_t seen = bad.load();
                    while (indices[i] < seen && !bad.compare_exchange_weak(seen, indices[i])) {}
                    break;
                }
            }
        }
    });
    if (bad.load() != std::numeric_limits<std::uint64_t>::max()) {
        const openvdb::Coord o = m.leaves[bad.load()]->origin();
        fail("in the leaf at (" + std::to_string(o.x()) + ", " + std::to_string(o.y()) + ", " +
             std::to_string(o.z()) + ")");
    }
}

} // namespace ivdb::io
