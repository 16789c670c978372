// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/util/Interrupt.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace ivdb::jobs {

/// @brief Rasterizer settings for a scene: its voxel size, half width, bounds and distance mode,
/// with @a voxelSize and @a halfWidth (when set) in place of the file's.
/// @param scenePath  the scene's file, named in messages
/// @throw ParamError (parameter "voxel_size" or "half_width") for a bad value, or a voxel size
/// neither the scene nor @a voxelSize gives
raster::RasterSettings sceneSettings(const scene::Scene& scene, const std::string& scenePath,
                                     std::optional<double> voxelSize = std::nullopt,
                                     std::optional<double> halfWidth = std::nullopt);

/// @brief What rasterize() does: a scene file into a narrow-band level set.
struct RasterizeOptions
{
    std::string scene;                     ///< the scene file (JSON)
    std::string output;                    ///< the .vdb written atomically; empty: none
    std::optional<double> voxelSize;       ///< in place of the scene's voxel_size
    std::optional<double> halfWidth;       ///< in place of the scene's half_width
    raster::Sampling sampling = raster::Sampling::Sparse;
    std::optional<raster::Distance> distance; ///< in place of the scene's distance
    bool fog = false;                      ///< also a `density` fog volume
    io::WriteOptions write;                ///< compression and half floats on disk
    util::Interrupter* interrupter = nullptr; ///< progress and cancellation (may be null)
};

struct RasterizeResult
{
    openvdb::FloatGrid::Ptr surface;  ///< the level set `surface`
    openvdb::FloatGrid::Ptr density;  ///< the fog volume, or null
    raster::RasterSettings settings;  ///< as used
    double computeSeconds = 0.0;      ///< reading the scene and rasterizing
    double totalSeconds = 0.0;        ///< everything, writing included
    std::uint64_t fileBytes = 0;      ///< the output's size (0 without output)
    raster::RasterStats stats;        ///< how true distances were found (shapes not exact SDFs)
    std::vector<std::string> notes;   ///< the scene's: open meshes, rebuilt .vdb inputs
};

/// @brief Rasterize a scene file into a level set (and a fog volume), stamped with the scene as
/// rasterized (`ivdb_scene`, the overrides applied) and written atomically to the output.
/// @throw scene::SceneError for a bad scene; ParamError for a bad setting; openvdb::IoError for
/// an output that cannot be written (checked before the work); openvdb::RuntimeError when the
/// surface has no voxel at the voxel size, memory would not suffice, or on interruption.
/// Nothing is written on any error.
RasterizeResult rasterize(const RasterizeOptions& options);

} // namespace ivdb::jobs
