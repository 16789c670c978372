// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/Rasterize.h>

#include "Common.h"

#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Inputs.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <nlohmann/json.hpp>

#include <sstream>

namespace ivdb::jobs {

raster::RasterSettings sceneSettings(const scene::Scene& sc, const std::string& scenePath,
                                     std::optional<double> voxelSize,
                                     std::optional<double> halfWidth)
{
    raster::RasterSettings settings;
    if (voxelSize) {
        check(limits::kVoxelSize, *voxelSize);
        settings.voxelSize = *voxelSize;
    } else if (sc.voxelSize) {
        settings.voxelSize = *sc.voxelSize;
    } else {
        throw ParamError(param::kVoxelSize, "voxel_size is missing: add \"voxel_size\" to the "
                         "scene or give a voxel size", scenePath, ParamError::Kind::Missing);
    }
    settings.halfWidth = sc.halfWidth;
    if (halfWidth) {
        check(limits::kHalfWidth, *halfWidth);
        settings.halfWidth = *halfWidth;
    }
    settings.bounds = sc.bounds;
    settings.distance = sc.distanceBound ? raster::Distance::Bound : raster::Distance::Exact;
    return settings;
}

namespace {

/// The scene as rasterized, for the output's metadata: the overrides replace the file's values.
std::string sceneAsRasterized(const scene::Scene& sc, const raster::RasterSettings& settings)
{
    nlohmann::json scene = nlohmann::json::parse(sc.json);
    scene["voxel_size"] = settings.voxelSize;
    scene["half_width"] = settings.halfWidth;
    scene["distance"] = settings.distance == raster::Distance::Bound ? "bound" : "exact";
    return scene.dump();
}

} // namespace

RasterizeResult rasterize(const RasterizeOptions& opt)
{
    Stopwatch clock;
    // The overrides first: mesh and vdb nodes are built at them.
    if (opt.voxelSize) check(limits::kVoxelSize, *opt.voxelSize);
    if (opt.halfWidth) check(limits::kHalfWidth, *opt.halfWidth);
    const scene::Scene sc = scene::loadScene(opt.scene, {opt.voxelSize, opt.halfWidth});
    if (!opt.output.empty()) io::checkOutputPath(opt.output);

    RasterizeResult result;
    result.notes = sc.notes;
    result.settings = sceneSettings(sc, opt.scene, opt.voxelSize, opt.halfWidth);
    raster::RasterSettings& settings = result.settings;
    settings.sampling = opt.sampling;
    if (opt.distance) settings.distance = *opt.distance;
    settings.interrupter = opt.interrupter;
    settings.stats = &result.stats;
    try {
        result.surface = raster::rasterize(sc.shape, settings);
    } catch (const ParamError& e) {
        // A value the caller gave keeps its parameter (the caller words it); one from the
        // scene file is the file's, named by its key.
        const bool given = (e.param() == param::kVoxelSize.id && opt.voxelSize) ||
                           (e.param() == param::kHalfWidth.id && opt.halfWidth);
        if (given) throw;
        throw scene::SceneError(opt.scene + ": " + e.describe(e.param() + ":"));
    } catch (const openvdb::Exception& e) {
        // The shape's own problems (unbounded, too large) are the scene file's.
        OPENVDB_THROW(openvdb::RuntimeError, opt.scene + ": " + util::errorText(e));
    }
    result.computeSeconds = clock.lap();
    if (result.surface->activeVoxelCount() == 0) {
        std::ostringstream os;
        os << opt.scene << ": the surface has no voxels at voxel size " << settings.voxelSize
           << " (no zero crossing inside the bounds, or a shape smaller than a voxel): "
           << "check the shape and bounds, or use a smaller voxel size; nothing was written";
        OPENVDB_THROW(openvdb::RuntimeError, os.str());
    }
    settings.stats = nullptr;
    io::stampGrid(*result.surface, opt.scene);
    result.surface->insertMeta("ivdb_scene", openvdb::StringMetadata(sceneAsRasterized(sc, settings)));
    result.surface->insertMeta("ivdb_sampling", openvdb::StringMetadata(
        settings.sampling == raster::Sampling::Dense ? "dense" : "sparse"));
    if (opt.fog) result.density = detail::fogWithStamps(*result.surface);
    result.fileBytes = detail::writeGrids(opt.output, {result.surface, result.density}, opt.write);
    result.totalSeconds = clock.total();
    return result;
}

} // namespace ivdb::jobs
