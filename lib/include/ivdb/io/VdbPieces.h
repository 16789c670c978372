// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/io/VdbFile.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace ivdb::io {

/// @brief A run of a float grid's leaves as a .vdb file stores them, and what the file's grid
/// record says of them: the pieces processes that each hold a run of the leaves write of one
/// file (ivdb-mpi), the buffers at their offsets and the record's head once.
struct LeafRun
{
    using Mask = openvdb::FloatTree::LeafNodeType::NodeMaskType;

    /// The leaves' buffers, in file order, byte for byte as writeVdbStream() writes them, in
    /// pieces of a few dozen leaves (as they were compressed: no copy into one string).
    std::vector<std::string> pieces;
    /// Per leaf, in file order: the delayed-load table's compression code and value-block size
    /// (sizes are empty without a codec), and the value mask the topology stores.
    std::vector<std::int8_t> codes;
    std::vector<std::int64_t> sizes;
    std::vector<Mask> masks;
    std::uint64_t activeVoxels = 0;
    openvdb::CoordBBox activeBox; ///< of the active voxels; empty if none

    /// The pieces' bytes, in total.
    std::uint64_t byteCount() const;

    /// Append @a next's entries and masks (the run after this one); its pieces are not copied.
    void appendEntries(const LeafRun& next);
};

/// @brief Encode the leaves of @a run (a grid holding one run of a grid's leaves, with that
/// grid's background and class) as writeVdbStream() encodes them with @a options: compressed
/// in parallel, in file order.
LeafRun encodeLeafRun(const openvdb::FloatGrid& run, const WriteOptions& options);
LeafRun encodeLeafRun(const openvdb::Vec3SGrid& run, const WriteOptions& options);

/// @brief The parts of a .vdb file that are not leaf buffers, as vdbFileHead() makes them: per
/// grid, its head (descriptor, record and topology; the first grid's starts with the file's
/// header), with every leaf's value mask left zero in the topology, and where the masks go (each
/// process writes its own leaves' masks there). Each grid's buffers follow its head.
struct FileHead
{
    /// The leaves of one 128^3 node: their masks lie one after another from @a offset (from
    /// the file's start).
    struct MaskRun
    {
        std::uint64_t firstLeaf = 0, leaves = 0, offset = 0;
    };

    struct Grid
    {
        std::uint64_t at = 0;          ///< where the head starts in the file
        std::uint64_t size = 0;        ///< the head's length
        /// The head (size bytes; a process that only writes leaves may leave it empty).
        std::string bytes;
        std::vector<MaskRun> maskRuns; ///< in file order; they cover every leaf of the grid once
        /// Where the grid's leaf buffers start: right after its head.
        std::uint64_t buffersAt() const { return at + size; }
    };

    std::vector<Grid> grids;     ///< in file order
    std::uint64_t fileBytes = 0; ///< the whole file's, buffers included

    /// The writes that put the masks of leaves [first, first + masks.size()) of grid @a grid in
    /// place: (offset, bytes) pairs, one per mask run they touch.
    std::vector<std::pair<std::uint64_t, std::string>>
    maskWrites(std::size_t grid, std::uint64_t first, const std::vector<LeafRun::Mask>& masks) const;

    /// A stretch of the head's bytes.
    struct Part
    {
        std::uint64_t offset;
        const char* data;
        std::uint64_t size;
    };

    /// The parts of the heads that are not masks: what the process that writes the heads
    /// writes, so that no byte is written twice.
    std::vector<Part> nonMaskParts() const;

    /// Copy the masks of leaves [first, first + masks.size()) of grid @a grid into its head.
    void putMasks(std::size_t grid, std::uint64_t first, const std::vector<LeafRun::Mask>& masks);
};

/// @brief Per 128^3 node (by origin), the leaf-sized tiles that are active in the grid itself.
/// A skeleton's active tiles in 128^3 nodes stand for its leaves; a grid that has active tiles
/// of its own there (a fog volume's inside) keeps them inactive in its skeleton, with their
/// values, and lists them here.
using ActiveTiles =
    std::map<openvdb::Coord,
             openvdb::FloatTree::RootNodeType::ChildNodeType::ChildNodeType::NodeMaskType>;

/// @brief One grid of the file vdbFileHead() lays out.
struct HeadGrid
{
    /// The grid but for its leaves (a FloatGrid or a Vec3SGrid): metadata, transform, nodes and
    /// tiles, with an active tile in a 128^3 node wherever the grid has a leaf
    /// (raster::RasterRuns::skeleton, io::skeletonOf, io::leafSkeleton).
    openvdb::GridBase::ConstPtr skeleton;
    /// Every leaf's table entries, active voxels and box, in file order (the runs' joined;
    /// their masks and pieces are not used).
    const LeafRun* leaves = nullptr;
    std::uint64_t bufferBytes = 0; ///< the runs' bytes, in total (their byteCount())
    /// The grid's own active tiles in its 128^3 nodes, if any (its active tiles above those
    /// nodes are active in the skeleton).
    const ActiveTiles* activeTiles = nullptr;
};

/// @brief The parts of a .vdb file that holds @a grids (in order), up to and between their leaf
/// buffers: the file header (with a new UUID), @a fileMetadata, and per grid its descriptor,
/// compression flags, metadata (with the statistics, compression and delayed-load table
/// io::File adds), transform and topology, with the leaves' masks left to
/// FileHead::maskWrites. With the masks in place and each grid's runs' bytes in order at its
/// buffersAt(), it is the file writeVdbStream() writes for the grids, byte for byte but the
/// UUID.
/// @throw openvdb::ValueError if a grid's leaves do not hold one entry per leaf of its skeleton,
/// or a skeleton is neither a float nor a vec3s grid
FileHead vdbFileHead(const std::vector<HeadGrid>& grids, const openvdb::MetaMap& fileMetadata,
                     const WriteOptions& options);

/// @brief vdbFileHead() of one float grid.
FileHead vdbFileHead(const openvdb::FloatGrid& skeleton, const LeafRun& leaves,
                     std::uint64_t bufferBytes, const openvdb::MetaMap& fileMetadata,
                     const WriteOptions& options);

/// @brief The skeleton of a float grid whose nodes and tiles are @a grid's (its leaves may hold
/// no values: a topology read without them): a copy with each leaf an active tile.
openvdb::FloatGrid::Ptr skeletonOf(const openvdb::FloatGrid& grid);

/// @brief The skeleton of a grid of @a GridT with background @a background, no tiles, and a
/// leaf wherever @a topology has a leaf with active voxels: the grid a leaf-by-leaf operator
/// on @a topology's active voxels makes (diff::gradient, diff::curvature). The grid has
/// @a topology's transform and no metadata.
template<typename GridT>
typename GridT::Ptr leafSkeleton(const openvdb::FloatTree& topology,
                                 const openvdb::math::Transform& transform,
                                 const typename GridT::ValueType& background)
{
    auto grid = GridT::create(background);
    grid->setTransform(transform.copy());
    typename GridT::Accessor acc = grid->getAccessor();
    for (auto it = topology.cbeginLeaf(); it; ++it) {
        if (!it->getValueMask().isOff()) acc.addTile(1, it->origin(), background, true);
    }
    return grid;
}

/// @brief One float grid of a .vdb file read in part, as a process that holds a run of its
/// leaves reads it (ivdb-mpi): the grid's metadata, transform and whole topology (nodes, tiles
/// and every leaf's value mask: about 100 bytes a leaf), and the values of only the leaves
/// asked for.
class PartialGrid
{
public:
    using LeafT = openvdb::FloatTree::LeafNodeType;

    /// Map @a path, check its layout as readVdb() does, and read grid @a grid (empty: the first
    /// level set, as selectGrid() picks it from readVdb()'s grids) with no voxel values.
    /// @throw what readVdb() and selectGrid() throw; ParamError (the grid) if the grid is not a
    /// float grid
    PartialGrid(const std::string& path, const std::string& grid);
    ~PartialGrid();
    PartialGrid(const PartialGrid&) = delete;
    PartialGrid& operator=(const PartialGrid&) = delete;

    /// The grid. Its leaves hold no values but those load() read: read only those.
    const openvdb::FloatGrid::Ptr& grid() const;
    /// Every leaf, in file order (the order of the file's delayed-load table).
    const std::vector<LeafT*>& leaves() const;

    /// Read the values of the leaves @a indices (file order) in parallel.
    /// @throw openvdb::IoError naming the file if a leaf's voxel data is damaged
    void load(const std::vector<std::uint64_t>& indices);

    /// Let go of the file (its mapping, whose pages count as the process's memory): no more
    /// load() after this.
    void release();

    /// Check what checkGridValues() checks, on the background, the tiles and the leaves
    /// @a indices (which must have been loaded): every rank checks its own leaves.
    /// @throw openvdb::ValueError naming the file, the grid and a leaf that is not finite
    void checkValues(const std::vector<std::uint64_t>& indices) const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace ivdb::io
