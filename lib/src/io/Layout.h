// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <string>

namespace ivdb::io {

/// @brief Check a .vdb file's layout with bounds-checked reads before OpenVDB's reader sees it:
/// the header (file formats 222 to 224), the file metadata, every grid descriptor's offsets, and
/// every grid's metadata, transform, root records and, for the standard 5-4-3 trees of float,
/// double, int and vector values, the whole topology and the voxel data blocks against the
/// delayed-load table. OpenVDB's reader accepts some truncations and allocates whatever a
/// damaged count claims; every count here is bounded by the bytes that part of the file may use.
/// @throw openvdb::IoError naming @a path and what is wrong
void validateLayout(const std::string& path);

} // namespace ivdb::io
