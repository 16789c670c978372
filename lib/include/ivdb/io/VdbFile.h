#pragma once

#include <openvdb/openvdb.h>

#include <cstdint>
#include <functional>
#include <ostream>
#include <string>
#include <vector>

namespace ivdb::io {

/// @brief Fail early, before a long computation, if @a path cannot become an output file: its
/// folder must exist and be writable, and @a path must not be a folder.
/// @throw openvdb::IoError naming the path and the reason
void checkOutputPath(const std::string& path);

/// @brief Write a file atomically: @a write fills a stream on a temporary file in @a path's
/// folder (`.NAME.tmp-PID-N`), which is then flushed, synced and renamed over @a path. A failure
/// (a full disk, an exception from @a write) removes the temporary file and leaves @a path as it
/// was. Stream errors throw inside @a write (the stream has exceptions enabled).
/// @throw openvdb::IoError naming the path and the reason
void writeFileAtomically(const std::string& path,
                         const std::function<void(std::ostream&)>& write);

/// @brief Remove the temporary file that writeFileAtomically is writing now, if any.
/// @details Async-signal-safe (one unlink): for a signal handler that is about to end the
/// process, so that an interrupted write leaves nothing behind.
void removePendingTemporaryFile() noexcept;

/// @brief Write @a grids to @a path with OpenVDB's default compression, atomically
/// (writeFileAtomically).
/// @details The grids go to a temporary file in the same folder (`.NAME.tmp-PID-N`), which is
/// flushed, synced and renamed over @a path: a failure (a full disk, say) or a kill leaves
/// either the old file or the complete new one, never a partial or clobbered @a path. After an
/// error the temporary file is removed (the CLI's signal handler removes it too); only SIGKILL
/// during the write can leave it behind (hidden, named after the output and the process id). Every stream error is checked, unlike
/// io::File::write.
/// @throw openvdb::IoError naming the path and the reason
void writeVdb(const std::string& path, const openvdb::GridCPtrVec& grids,
              const openvdb::MetaMap& fileMetadata = openvdb::MetaMap());

/// @brief Read every grid of a .vdb file: topology and metadata now, voxel values on first
/// access (OpenVDB's delayed loading), after checking the file's layout.
/// @throw openvdb::IoError naming the path if it is missing, a folder, not a .vdb file,
/// truncated or corrupt
openvdb::GridPtrVec readVdb(const std::string& path);

/// @brief The grid named @a name in @a grids, or the first level set when @a name is empty.
/// @param path  the file the grids came from, for messages
/// @throw openvdb::LookupError naming the file, the grid and what the file holds
openvdb::GridBase::Ptr selectGrid(const openvdb::GridPtrVec& grids, const std::string& path,
                                  const std::string& name);

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
