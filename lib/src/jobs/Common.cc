// SPDX-License-Identifier: Apache-2.0
#include "Common.h"

#include <ivdb/io/VdbFile.h>
#include <ivdb/levelset/Fog.h>

#include <filesystem>

namespace ivdb::jobs::detail {

openvdb::FloatGrid::Ptr fogWithStamps(const openvdb::FloatGrid& surface)
{
    openvdb::FloatGrid::Ptr density = levelset::fogFromLevelSet(surface);
    for (const char* key : {"creator", "ivdb_version", "ivdb_source"}) {
        if (auto meta = surface[key]) density->insertMeta(key, *meta);
    }
    return density;
}

std::uint64_t writeGrids(const std::string& path, const std::vector<openvdb::GridBase::ConstPtr>& grids,
                         const io::WriteOptions& options)
{
    if (path.empty()) return 0;
    openvdb::GridCPtrVec out;
    for (const auto& g : grids) {
        if (g) out.push_back(g);
    }
    io::writeVdbStamped(path, out, options);
    std::error_code ec;
    const auto size = std::filesystem::file_size(path, ec);
    return ec ? 0 : std::uint64_t(size);
}

std::string joined(const std::vector<std::string>& items)
{
    std::string s;
    for (const auto& i : items) s += (s.empty() ? "" : " ") + i;
    return s;
}

} // namespace ivdb::jobs::detail
