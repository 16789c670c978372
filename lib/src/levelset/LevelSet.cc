// SPDX-License-Identifier: Apache-2.0
#include <ivdb/levelset/LevelSet.h>

#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <cmath>

namespace ivdb::levelset {

double uniformVoxelSize(const openvdb::GridBase& grid)
{
    const openvdb::Vec3d v = grid.voxelSize();
    if (!grid.transform().isLinear() || std::abs(v[0] - v[1]) > 1e-9 * v[0] ||
        std::abs(v[0] - v[2]) > 1e-9 * v[0]) {
        OPENVDB_THROW(openvdb::ValueError,
            "the grid's voxels are not cubes (voxel size " + util::formatNumber(v[0]) + " x " +
            util::formatNumber(v[1]) + " x " + util::formatNumber(v[2]) +
            "); resample it to a uniform linear transform first");
    }
    return v[0];
}

void checkLevelSet(const openvdb::GridBase& grid, const std::string& what)
{
    if (!grid.isType<openvdb::FloatGrid>()) {
        throw ParamError(param::kGrid, "holds " + grid.valueType() + " values; this needs a "
            "scalar float level set (such as 'surface', which ivdb writes): choose one", what,
            ParamError::Kind::Missing);
    }
    if (grid.getGridClass() == openvdb::GRID_FOG_VOLUME) {
        throw ParamError(param::kGrid, "is a fog volume (density), not a level set; choose the "
            "level set (ivdb writes it as 'surface')", what, ParamError::Kind::Missing);
    }
    if (grid.getGridClass() != openvdb::GRID_LEVEL_SET) {
        throw ParamError(param::kGrid, "has grid class '" +
            openvdb::GridBase::gridClassToString(grid.getGridClass()) +
            "', not a level set; choose a level set", what, ParamError::Kind::Missing);
    }
    try {
        uniformVoxelSize(grid);
    } catch (const openvdb::ValueError& e) {
        OPENVDB_THROW(openvdb::ValueError, what + ": " + util::errorText(e));
    }
}

} // namespace ivdb::levelset
