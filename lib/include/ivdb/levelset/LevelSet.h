// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <openvdb/openvdb.h>

#include <string>

namespace ivdb::levelset {

/// @brief Check that @a grid is something the level-set operators accept: a scalar float level
/// set with a uniform voxel size. @a what names it in messages ("in.vdb: grid 'surface'").
/// @throw ParamError (parameter "grid") saying what the grid is and what to choose instead
void checkLevelSet(const openvdb::GridBase& grid, const std::string& what);

/// @brief The voxel size of a grid with cubic voxels on a linear transform.
/// @throw openvdb::ValueError if the voxels are not cubes or the transform is not linear
double uniformVoxelSize(const openvdb::GridBase& grid);

} // namespace ivdb::levelset
