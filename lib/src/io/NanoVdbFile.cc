// SPDX-License-Identifier: Apache-2.0
#include <ivdb/io/NanoVdbFile.h>

#include <ivdb/io/AtomicFile.h>

#include <nanovdb/util/IO.h>
#include <nanovdb/util/OpenToNanoVDB.h>

#include <vector>

namespace ivdb::io {

namespace {

using NanoVdbGrids = openvdb::TypeList<openvdb::FloatGrid, openvdb::DoubleGrid, openvdb::Int32Grid,
                                       openvdb::Int64Grid, openvdb::Grid<openvdb::UInt32Tree>,
                                       openvdb::Vec3SGrid, openvdb::BoolGrid, openvdb::MaskGrid>;

} // namespace

bool nanoVdbHolds(const openvdb::GridBase& grid)
{
    return grid.apply<NanoVdbGrids>([](const auto&) {});
}

void writeNanoVdb(const std::string& path, const openvdb::GridCPtrVec& grids)
{
    for (const auto& g : grids) {
        if (!nanoVdbHolds(*g)) {
            OPENVDB_THROW(openvdb::ValueError, "grid '" + g->getName() + "' holds " +
                          g->valueType() + " values, which a NanoVDB file cannot hold (it holds "
                          "float, double, int32, int64, uint32, vec3s, bool and mask grids)");
        }
    }
    checkOutputPath(path);
    std::vector<nanovdb::GridHandle<nanovdb::HostBuffer>> handles;
    handles.reserve(grids.size());
    for (const auto& g : grids) {
        handles.push_back(nanovdb::openToNanoVDB<nanovdb::HostBuffer>(
            openvdb::ConstPtrCast<openvdb::GridBase>(g), nanovdb::StatsMode::Default,
            nanovdb::ChecksumMode::Default, /*verbose=*/0));
    }
    writeFileAtomically(path, [&handles](std::ostream& os) {
        nanovdb::io::writeGrids<nanovdb::HostBuffer, std::vector>(os, handles, nanovdb::io::Codec::NONE);
    });
}

} // namespace ivdb::io
