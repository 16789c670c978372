// SPDX-License-Identifier: Apache-2.0
#include "Sweeping.h"

#include <openvdb/tools/FastSweeping.h>

namespace ivdb::levelset::detail {

openvdb::FloatGrid::Ptr sweepSdf(const openvdb::FloatGrid& samples,
                                 const std::function<void(openvdb::FloatGrid&)>& seeded)
{
    openvdb::tools::FastSweeping<openvdb::FloatGrid> sweeper;
    if (!sweeper.initSdf(samples, 0.0f, /*isInputSdf=*/true)) return nullptr;
    seeded(*sweeper.sdfGrid());
    if (sweeper.sweepingVoxelCount() > 0) sweeper.sweep(1);
    return sweeper.sdfGrid();
}

openvdb::FloatGrid::Ptr dilateSdf(const openvdb::FloatGrid& sdf, int voxels)
{
    return openvdb::tools::dilateSdf(sdf, voxels, openvdb::tools::NN_FACE_EDGE_VERTEX);
}

} // namespace ivdb::levelset::detail
