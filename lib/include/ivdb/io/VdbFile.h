// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/io/AtomicFile.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <string>
#include <vector>

namespace ivdb::io {

/// @brief How voxel values are compressed on disk. Every choice also stores only the active
/// values where the inactive ones are the background (OpenVDB's "active values" compression).
enum class Compression {
    Blosc, ///< Blosc (LZ4, level 9, byte shuffle): OpenVDB's default, fast
    Zip,   ///< zlib: smaller, slower (OpenVDB leaves level sets and fog volumes unzipped)
    None   ///< no codec
};

/// @brief "blosc", "zip", "none", in the order of the enum.
const std::vector<std::string>& compressionNames();

/// @brief OpenVDB's archive compression flags for @a c (io::COMPRESS_*).
std::uint32_t compressionFlags(Compression c);

/// @brief How writeVdb() writes.
struct WriteOptions
{
    Compression compression = Compression::Blosc;
    /// Float, double and vector values as 16-bit halves on disk (grids flagged as
    /// saveFloatAsHalf, as OpenVDB and Houdini write them); values read back within half
    /// precision.
    bool half = false;
    /// Bytes of compressed leaf buffers held at once; 0: a quarter of util::memoryBudget().
    /// A grid whose buffers may need more is compressed twice (once to size the delayed-load
    /// table, once while streaming), as OpenVDB does.
    std::uint64_t bufferLimit = 0;
};

/// @brief Write @a grids in OpenVDB's file format to @a stream (seekable): the bytes
/// openvdb::io::File::write writes, but for the file's random UUID, with every leaf compressed
/// in parallel (TBB), once.
/// @details For each grid of the seven types with delayed-load tables (float, double, int32,
/// int64 and the three vec3 types): the grid's record (descriptor, compression flags,
/// metadata with the file_* statistics, compression and delayed-load table io::File adds,
/// transform, topology) by OpenVDB's own functions, then the leaf buffers, each written by
/// OpenVDB's LeafNode::writeBuffers on a per-task stream and streamed in file order. Other grid
/// types and grids sharing a tree are written by OpenVDB's Archive itself.
void writeVdbStream(std::ostream& stream, const openvdb::GridCPtrVec& grids,
                    const openvdb::MetaMap& fileMetadata, const WriteOptions& options);

/// @brief Write @a grids to @a path atomically (writeFileAtomically) with writeVdbStream().
/// @details The grids go to a temporary file in the same folder (`.NAME.tmp-PID-N`), which is
/// flushed, synced and renamed over @a path: a failure (a full disk, say) or a kill leaves
/// either the old file or the complete new one, never a partial or clobbered @a path. After an
/// error the temporary file is removed (the CLI's signal handler removes it too); only SIGKILL
/// during the write can leave it behind (hidden, named after the output and the process id).
/// Every stream error is checked, unlike io::File::write.
/// @throw openvdb::IoError naming the path and the reason
void writeVdb(const std::string& path, const openvdb::GridCPtrVec& grids,
              const openvdb::MetaMap& fileMetadata = openvdb::MetaMap(),
              const WriteOptions& options = WriteOptions());

/// @brief Read every grid of a .vdb file, whole, after checking the file's layout: the file is
/// mapped into memory and the leaves' voxel data decompressed on all threads (TBB), each leaf
/// by OpenVDB's own LeafNode::readBuffers, so the values are those OpenVDB's reader gives.
/// Grids of types whose leaves the layout check does not locate (bool, mask, points) are read
/// by OpenVDB's io::File with delayed loading.
/// @return the grids in the order io::File::getGrids() gives them (by name, then file order);
/// grids that share a tree in the file share it in memory
/// @throw openvdb::IoError naming the path if it is missing, a folder, not a .vdb file,
/// truncated or corrupt
openvdb::GridPtrVec readVdb(const std::string& path);

/// @brief The grid named @a name in @a grids, or the first level set when @a name is empty.
/// @param path  the file the grids came from, for messages
/// @throw ParamError (parameter "grid") naming the file, the grid and what the file holds
openvdb::GridBase::Ptr selectGrid(const openvdb::GridPtrVec& grids, const std::string& path,
                                  const std::string& name);

/// @brief A grid of a file, written FILE.vdb[:GRID]: a path that exists is taken whole, else
/// the text after the last ':' names the grid (empty: the file's first grid).
struct GridRef
{
    std::string file, grid;
    static GridRef parse(const std::string& text);
};

/// @brief Stamp @a grid as made by ivdb: the `creator` (Houdini shows it as vdb_creator),
/// `ivdb_version` and `ivdb_source` (@a source: what it was made from) metadata.
void stampGrid(openvdb::GridBase& grid, const std::string& source);

/// @brief The file metadata ivdb writes: `creator` set to this ivdb version.
openvdb::MetaMap fileStamp();

/// @brief writeVdb() with the file's `creator` metadata set to this ivdb version.
void writeVdbStamped(const std::string& path, const openvdb::GridCPtrVec& grids,
                     const WriteOptions& options = WriteOptions());

/// @brief Check a grid read from @a path before it is used: a finite, non-degenerate transform,
/// every value (background, tiles and voxels) finite for float, double and vector grids, and a
/// positive background for a level set. Threaded (OpenVDB's tools::Diagnose); with delayed
/// loading this is where the voxel buffers are first read, so damaged buffers show up here.
/// @throw openvdb::ValueError naming the file, the grid and what is wrong
void checkGridValues(const openvdb::GridBase& grid, const std::string& path);

/// @brief What `ivdb info` reports about a grid.
struct GridInfo
{
    std::string name, gridClass, valueType;
    openvdb::Vec3d voxelSize;
    std::uint64_t activeVoxels = 0, leafNodes = 0;
    openvdb::CoordBBox indexBox;   // of the active voxels; empty if none
    openvdb::BBoxd worldBox;       // of the active voxels' centers
    std::uint64_t memoryBytes = 0; // in-core size of the tree
    bool isLevelSet = false;
    std::vector<double> background; // 1 value (float, double) or 3 (vec3s, vec3d); else empty
};

/// @brief Describe a grid (fully loaded).
GridInfo describeGrid(const openvdb::GridBase& grid);

} // namespace ivdb::io
