// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/Combine.h>

#include "Common.h"

#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Inputs.h>
#include <ivdb/ops/Blend.h>
#include <ivdb/ops/Csg.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

namespace ivdb::jobs {

std::optional<ops::BlendSettings> blendSettings(const CombineOptions& opt)
{
    if (opt.p && opt.k) {
        throw ParamError(param::kSmoothK, "cannot be given with p: a blend is either "
                                          "super-elliptic (p) or smooth (k)");
    }
    if (!opt.p && !opt.k) return std::nullopt;
    ops::BlendSettings blend;
    if (opt.p) check(limits::kBlendP, blend.p = *opt.p);
    if (opt.k) check(limits::kSmoothK, blend.k = *opt.k);
    blend.tolerance = opt.tolerance;
    blend.interrupter = opt.interrupter;
    check(limits::kTolerance, blend.tolerance);
    return blend;
}

CombineResult combine(const CombineOptions& opt)
{
    Stopwatch clock;
    const std::optional<ops::BlendSettings> blend = blendSettings(opt);
    const bool blended = blend.has_value();
    if (opt.inputs.size() < 2) {
        throw ParamError(param::kInputs, "must be at least two files, got " +
                                             std::to_string(opt.inputs.size()));
    }
    if (!opt.output.empty()) io::checkOutputPath(opt.output);
    std::vector<openvdb::FloatGrid::Ptr> grids;
    for (const std::string& path : opt.inputs) grids.push_back(readLevelSet(path, opt.grid));

    CombineResult result;
    result.readSeconds = clock.lap();
    // In place: the inputs are not needed afterwards.
    result.surface = blended ? ops::blendInPlace(opt.op, grids, *blend, &result.notes)
                           : ops::csgInPlace(opt.op, grids, &result.notes);
    grids.clear();
    if (result.surface->activeVoxelCount() == 0) {
        result.warnings.push_back("the result has no surface (the inputs do not overlap as this "
                                  "operation needs); the level set written is empty");
    }
    result.computeSeconds = clock.lap();
    io::stampGrid(*result.surface, combineSource(opt));
    if (opt.fog) result.density = detail::fogWithStamps(*result.surface);
    detail::writeGrids(opt.output, {result.surface, result.density}, opt.write);
    result.totalSeconds = clock.total();
    return result;
}

std::string combineSource(const CombineOptions& opt)
{
    const std::string what =
        opt.p ? std::string("blend ") + implicit::toString(opt.op) + " p=" + util::formatNumber(*opt.p)
        : opt.k ? std::string("blend ") + implicit::toString(opt.op) + " k=" + util::formatNumber(*opt.k)
                : std::string("csg ") + implicit::toString(opt.op);
    return what + " " + detail::joined(opt.inputs);
}

} // namespace ivdb::jobs
