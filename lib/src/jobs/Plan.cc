// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/Plan.h>

#include <ivdb/jobs/Inputs.h>
#include <ivdb/jobs/Rasterize.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

namespace ivdb::jobs {

PlanResult plan(const PlanOptions& opt)
{
    Stopwatch clock;
    check(limits::kRanks, double(opt.ranks));
    if (opt.voxelSize) check(limits::kVoxelSize, *opt.voxelSize);
    if (opt.halfWidth) check(limits::kHalfWidth, *opt.halfWidth);
    const scene::Scene sc = scene::loadScene(opt.scene, {opt.voxelSize, opt.halfWidth, std::nullopt, true});
    PlanResult result;
    result.notes = sc.notes;
    if (sc.animated) {
        result.notes.push_back(opt.scene + " is keyed: planned at frame " +
                               util::formatNumber(sc.frame));
    }
    result.settings = sceneSettings(sc, opt.scene, opt.voxelSize, opt.halfWidth);
    try {
        result.partition = raster::partition(sc.shape, result.settings, opt.ranks);
    } catch (const ParamError& e) {
        // The scene file's own values are named by its keys; the caller's keep their parameter.
        const bool given = (e.param() == param::kVoxelSize.id && opt.voxelSize) ||
                           (e.param() == param::kHalfWidth.id && opt.halfWidth) ||
                           e.param() == param::kRanks.id;
        if (given) throw;
        throw scene::SceneError(opt.scene + ": " + e.describe(e.param() + ":"));
    } catch (const openvdb::Exception& e) {
        OPENVDB_THROW(openvdb::RuntimeError, opt.scene + ": " + util::errorText(e));
    }
    result.seconds = clock.total();
    return result;
}

} // namespace ivdb::jobs
