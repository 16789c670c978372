// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace ivdb::io {

class FileMapping;

/// @brief Where a grid's parts are in a .vdb file, as validateLayout() found them.
struct GridLayout
{
    std::string uniqueName; ///< the descriptor's name (the grid's name, with a suffix if repeated)
    std::string type;       ///< the tree type as stored ("Tree_float_5_4_3", "..._HalfFloat")
    std::string parent;     ///< the unique name of the grid whose tree this one shares, or empty
    std::uint64_t start = 0; ///< the grid's compression flags, which its metadata follows
    /// Each leaf's voxel data (its value mask, then its values), in the order the tree's
    /// leaves are visited; filled for the trees whose whole topology is walked (standard
    /// 5-4-3 trees of float, double, int32, int64 and vec3 values), empty for the others.
    std::vector<std::uint64_t> leaves;
    bool leavesWalked = false; ///< leaves holds every leaf (which may be none)
};

/// @brief A .vdb file's version and grids, as validateLayout() found them.
struct FileLayout
{
    std::uint32_t fileVersion = 0, libraryMajor = 0, libraryMinor = 0;
    bool hasGridOffsets = true; ///< false in io::Stream's layout: each grid after its descriptor
    std::vector<GridLayout> grids; ///< in file order
};

/// @brief Check a .vdb file's layout with bounds-checked reads before OpenVDB's reader sees it:
/// the header (file formats 222 to 224), the file metadata, every grid descriptor's offsets, and
/// every grid's metadata, transform, root records and, for the standard 5-4-3 trees of float,
/// double, int and vector values, the whole topology and the voxel data blocks against the
/// delayed-load table. OpenVDB's reader accepts some truncations and allocates whatever a
/// damaged count claims; every count here is bounded by the bytes that part of the file may use.
/// @param file  the file's bytes
/// @param releaseBehind  let the pages walked go from the process's memory as the walk goes on
///                       (for a reader that then reads only part of the file)
/// @throw openvdb::IoError naming @a path and what is wrong
FileLayout validateLayout(const std::string& path, const FileMapping& file,
                          bool releaseBehind = false);

} // namespace ivdb::io
