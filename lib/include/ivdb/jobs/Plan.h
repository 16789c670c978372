// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/raster/Partition.h>

#include <optional>
#include <string>
#include <vector>

namespace ivdb::jobs {

/// @brief What plan() does: how a scene's rasterization splits over ranks.
struct PlanOptions
{
    std::string scene;                ///< the scene file (JSON)
    std::optional<double> voxelSize;  ///< in place of the scene's voxel_size
    std::optional<double> halfWidth;  ///< in place of the scene's half_width
    int ranks = 1;                    ///< processes to split over (limits::kRanks)
};

struct PlanResult
{
    raster::Partition partition;
    raster::RasterSettings settings;  ///< as used
    double seconds = 0.0;             ///< reading the scene and planning
    std::vector<std::string> notes;   ///< the scene's, and a keyed scene's frame
};

/// @brief Partition a scene's rasterization into contiguous runs of leaves in file order
/// (raster::partition), without rasterizing: the leaves, the balance, and each rank's estimated
/// active voxels, memory and compute. A keyed scene is planned at its first frame.
/// @throw scene::SceneError for a bad scene; ParamError for a bad setting
PlanResult plan(const PlanOptions& options);

} // namespace ivdb::jobs
