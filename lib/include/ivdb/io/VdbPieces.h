// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/io/VdbFile.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <string>
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

    /// Append @a next's entries (the run after this one); its pieces are not copied.
    void appendEntries(const LeafRun& next);
};

/// @brief Encode the leaves of @a run (a grid holding one run of a grid's leaves, with that
/// grid's background and class) as writeVdbStream() encodes them with @a options: compressed
/// in parallel, in file order.
LeafRun encodeLeafRun(const openvdb::FloatGrid& run, const WriteOptions& options);

/// @brief The bytes of a .vdb file that holds one float grid, up to its leaf buffers: the file
/// header (with a new UUID), @a fileMetadata, the grid's descriptor, compression flags,
/// metadata (with the statistics, compression and delayed-load table io::File adds), transform
/// and topology. Followed by the runs' bytes in order, it is the file writeVdbStream() writes
/// for the grid, byte for byte but the UUID.
/// @param skeleton  the grid but for its leaves: metadata, transform, nodes and tiles, with an
///                  active tile in a 128^3 node wherever the grid has a leaf
///                  (raster::RasterRuns::skeleton)
/// @param leaves    every leaf's entries in file order (the runs' joined; pieces unused)
/// @param bufferBytes  the runs' bytes, in total (their byteCount())
/// @throw openvdb::ValueError if @a leaves does not hold one entry per leaf of @a skeleton
std::string vdbFileHead(const openvdb::FloatGrid& skeleton, const LeafRun& leaves,
                        std::uint64_t bufferBytes, const openvdb::MetaMap& fileMetadata,
                        const WriteOptions& options);

} // namespace ivdb::io
