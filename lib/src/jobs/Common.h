// SPDX-License-Identifier: Apache-2.0
// What the jobs share: the fog volume that goes with a level set, and writing their grids.
#pragma once

#include <ivdb/io/VdbFile.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <string>
#include <vector>

namespace ivdb::jobs::detail {

/// @brief A `density` fog volume made from @a surface, with its ivdb stamps.
openvdb::FloatGrid::Ptr fogWithStamps(const openvdb::FloatGrid& surface);

/// @brief Write @a grids (nulls skipped) atomically to @a path (nothing if @a path is empty)
/// with the file's `creator` metadata; returns the file's size.
std::uint64_t writeGrids(const std::string& path, const std::vector<openvdb::GridBase::ConstPtr>& grids,
                         const io::WriteOptions& options);

/// @brief @a items joined by single spaces.
std::string joined(const std::vector<std::string>& items);

} // namespace ivdb::jobs::detail
