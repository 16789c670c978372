// SPDX-License-Identifier: Apache-2.0
#include <ivdb/levelset/Fog.h>

#include <openvdb/tools/LevelSetUtil.h>

namespace ivdb::levelset {

openvdb::FloatGrid::Ptr fogFromLevelSet(const openvdb::FloatGrid& levelSet)
{
    openvdb::FloatGrid::Ptr fog = levelSet.deepCopy();
    openvdb::tools::sdfToFogVolume(*fog, levelSet.background());
    fog->setName("density");
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    return fog;
}

} // namespace ivdb::levelset
