// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/Info.h>

namespace ivdb::jobs {

std::vector<io::GridInfo> info(const std::string& path)
{
    const openvdb::GridPtrVec grids = io::readVdb(path);
    std::vector<io::GridInfo> out;
    for (const auto& g : grids) {
        io::checkGridValues(*g, path);
        out.push_back(io::describeGrid(*g));
    }
    return out;
}

} // namespace ivdb::jobs
