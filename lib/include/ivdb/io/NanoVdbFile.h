// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <openvdb/openvdb.h>

#include <string>

namespace ivdb::io {

/// @brief Whether a NanoVDB file can hold @a grid: NanoVDB 10.0's converter takes float,
/// double, int32, int64, uint32, vec3s, bool and mask grids (not vec3d or vec3i).
bool nanoVdbHolds(const openvdb::GridBase& grid);

/// @brief Write @a grids to @a path as one NanoVDB file (.nvdb), atomically (writeFileAtomically),
/// uncompressed, with NanoVDB's default statistics (bounding box and value range) and checksum:
/// the files nanovdb_convert writes, which NanoVDB's tools and GPU loaders read directly.
/// @details Each grid keeps its name and class; float grids saved as half floats are written as
/// full floats (NanoVDB's Fp16 is a different, block-quantized format).
/// @throw openvdb::ValueError naming a grid NanoVDB cannot hold (nanoVdbHolds()), before
/// anything is written; openvdb::IoError naming @a path if it cannot be written
void writeNanoVdb(const std::string& path, const openvdb::GridCPtrVec& grids);

} // namespace ivdb::io
