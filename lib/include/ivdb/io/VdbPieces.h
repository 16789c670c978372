// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/io/VdbFile.h>

#include <openvdb/openvdb.h>

#include <cstdint>
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

/// @brief The start of a .vdb file that holds one float grid, up to its leaf buffers, as
/// vdbFileHead() makes it: the bytes, with every leaf's value mask left zero in the topology,
/// and where the masks go (each process writes its own leaves' masks there).
struct FileHead
{
    /// The leaves of one 128^3 node: their masks lie one after another from @a offset.
    struct MaskRun
    {
        std::uint64_t firstLeaf = 0, leaves = 0, offset = 0;
    };

    std::string bytes;
    std::vector<MaskRun> maskRuns; ///< in file order; they cover every leaf once

    /// The writes that put the masks of leaves [first, first + masks.size()) in place: (offset,
    /// bytes) pairs, one per mask run they touch.
    std::vector<std::pair<std::uint64_t, std::string>>
    maskWrites(std::uint64_t first, const std::vector<LeafRun::Mask>& masks) const;

    /// The parts of the head that are not masks, as (offset, length): what the process that
    /// writes the head writes, so that no byte is written twice.
    std::vector<std::pair<std::uint64_t, std::uint64_t>> nonMaskParts() const;

    /// Copy the masks of leaves [first, first + masks.size()) into bytes (one process).
    void putMasks(std::uint64_t first, const std::vector<LeafRun::Mask>& masks);
};

/// @brief The start of a .vdb file that holds one float grid, up to its leaf buffers: the file
/// header (with a new UUID), @a fileMetadata, the grid's descriptor, compression flags,
/// metadata (with the statistics, compression and delayed-load table io::File adds), transform
/// and topology, with the leaves' masks left to FileHead::maskWrites. With the masks in place
/// and followed by the runs' bytes in order, it is the file writeVdbStream() writes for the
/// grid, byte for byte but the UUID.
/// @param skeleton  the grid but for its leaves: metadata, transform, nodes and tiles, with an
///                  active tile in a 128^3 node wherever the grid has a leaf
///                  (raster::RasterRuns::skeleton)
/// @param leaves    every leaf's table entries, active voxels and box, in file order (the runs'
///                  joined; their masks and pieces are not used)
/// @param bufferBytes  the runs' bytes, in total (their byteCount())
/// @throw openvdb::ValueError if @a leaves does not hold one entry per leaf of @a skeleton
FileHead vdbFileHead(const openvdb::FloatGrid& skeleton, const LeafRun& leaves,
                     std::uint64_t bufferBytes, const openvdb::MetaMap& fileMetadata,
                     const WriteOptions& options);

} // namespace ivdb::io
