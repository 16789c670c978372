// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/io/VdbFile.h>

#include <string>
#include <vector>

namespace ivdb::jobs {

/// @brief What a .vdb file holds: every grid described (io::describeGrid) after its values are
/// checked (io::checkGridValues), so a damaged grid fails here too and pipelines can vet files.
/// @throw openvdb::IoError or openvdb::ValueError naming the file
std::vector<io::GridInfo> info(const std::string& path);

} // namespace ivdb::jobs
