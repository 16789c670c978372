// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/Inputs.h>

#include <ivdb/io/VdbFile.h>
#include <ivdb/levelset/LevelSet.h>
#include <ivdb/util/Params.h>

namespace ivdb::jobs {

openvdb::FloatGrid::Ptr readLevelSet(const std::string& path, const std::string& grid)
{
    const openvdb::GridBase::Ptr g = io::selectGrid(io::readVdb(path), path, grid);
    levelset::checkLevelSet(*g, path + ": grid '" + g->getName() + "'");
    io::checkGridValues(*g, path);
    return openvdb::gridPtrCast<openvdb::FloatGrid>(g);
}

openvdb::GridBase::Ptr readColorGrid(const std::string& spec, bool withRange, bool withColormap)
{
    const io::GridRef ref = io::GridRef::parse(spec);
    const openvdb::GridPtrVec grids = io::readVdb(ref.file);
    openvdb::GridBase::Ptr g = ref.grid.empty() ? grids.front() : io::selectGrid(grids, ref.file, ref.grid);
    if (g->isType<openvdb::Vec3SGrid>()) {
        if (withRange || withColormap) {
            throw ParamError(withRange ? param::kRange : param::kColormap,
                             "applies to scalar grids only: grid '" + g->getName() + "' is a "
                             "vector grid, coloured by direction", ref.file);
        }
    } else if (!g->isType<openvdb::FloatGrid>()) {
        throw ParamError(param::kColorBy, "needs a float (scalar) or vec3s (vector) grid: grid '" +
                         g->getName() + "' is a " + g->valueType() + " grid", ref.file);
    }
    io::checkGridValues(*g, ref.file);
    return g;
}

} // namespace ivdb::jobs
