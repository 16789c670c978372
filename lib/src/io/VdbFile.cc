// SPDX-License-Identifier: Apache-2.0
#include <ivdb/io/VdbFile.h>

#include <ivdb/Version.h>
#include <ivdb/util/Params.h>

#include <filesystem>
#include <string>

namespace ivdb::io {

namespace fs = std::filesystem;

openvdb::GridBase::Ptr selectGrid(const openvdb::GridPtrVec& grids, const std::string& path,
                                  const std::string& name)
{
    std::string held;
    for (const auto& g : grids) {
        if (!name.empty() && g->getName() == name) return g;
        if (name.empty() && g->getGridClass() == openvdb::GRID_LEVEL_SET) return g;
        held += (held.empty() ? "" : ", ") + std::string("'") + g->getName() + "' (" +
                openvdb::GridBase::gridClassToString(g->getGridClass()) + ", " + g->valueType() + ")";
    }
    if (name.empty()) {
        throw ParamError(param::kGrid, "holds no level set grid (it holds " + held +
                         "); name the grid to use", path, ParamError::Kind::Missing);
    }
    throw ParamError(param::kGrid, "'" + name + "' is not in the file (it holds " + held +
                     "); name one of those", path);
}

openvdb::GridBase::Ptr readGrid(const std::string& path, const std::string& name)
{
    const openvdb::GridPtrVec grids = readVdb(path);
    openvdb::GridBase::Ptr g = name.empty() ? grids.front() : selectGrid(grids, path, name);
    checkGridValues(*g, path);
    return g;
}

GridRef GridRef::parse(const std::string& text)
{
    GridRef ref{text, ""};
    const auto colon = text.rfind(':');
    std::error_code ec;
    if (!fs::exists(text, ec) && colon != std::string::npos) {
        ref.file = text.substr(0, colon);
        ref.grid = text.substr(colon + 1);
    }
    return ref;
}

void stampGrid(openvdb::GridBase& grid, const std::string& source)
{
    grid.setCreator(std::string("ivdb ") + kVersion); // Houdini shows it as vdb_creator
    grid.insertMeta("ivdb_version", openvdb::StringMetadata(kVersion));
    grid.insertMeta("ivdb_source", openvdb::StringMetadata(source));
}

openvdb::MetaMap fileStamp()
{
    openvdb::MetaMap meta;
    meta.insertMeta("creator", openvdb::StringMetadata(std::string("ivdb ") + kVersion));
    return meta;
}

void writeVdbStamped(const std::string& path, const openvdb::GridCPtrVec& grids,
                     const WriteOptions& options)
{
    writeVdb(path, grids, fileStamp(), options);
}

GridInfo describeGrid(const openvdb::GridBase& grid)
{
    GridInfo info;
    info.name = grid.getName();
    info.gridClass = openvdb::GridBase::gridClassToString(grid.getGridClass());
    info.isLevelSet = grid.getGridClass() == openvdb::GRID_LEVEL_SET;
    info.valueType = grid.valueType();
    info.voxelSize = grid.voxelSize();
    info.activeVoxels = grid.activeVoxelCount();
    info.memoryBytes = grid.memUsage();
    info.indexBox = grid.evalActiveVoxelBoundingBox();
    if (!info.indexBox.empty()) {
        info.worldBox = grid.transform().indexToWorld(info.indexBox);
    }
    info.leafNodes = grid.baseTree().leafCount();
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) {
        info.background = {double(f->background())};
    } else if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) {
        info.background = {d->background()};
    } else if (const auto* v = dynamic_cast<const openvdb::Vec3SGrid*>(&grid)) {
        const openvdb::Vec3s b = v->background();
        info.background = {double(b[0]), double(b[1]), double(b[2])};
    } else if (const auto* w = dynamic_cast<const openvdb::Vec3DGrid*>(&grid)) {
        const openvdb::Vec3d b = w->background();
        info.background = {b[0], b[1], b[2]};
    }
    return info;
}

} // namespace ivdb::io
