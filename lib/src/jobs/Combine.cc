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

CombineResult combine(const CombineOptions& opt)
{
    Stopwatch clock;
    ops::BlendSettings blend;
    if (opt.p) {
        blend.p = *opt.p;
        blend.tolerance = opt.tolerance;
        blend.interrupter = opt.interrupter;
        check(limits::kBlendP, blend.p);
        check(limits::kTolerance, blend.tolerance);
    }
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
    result.surface = opt.p ? ops::blendInPlace(opt.op, grids, blend, &result.notes)
                           : ops::csgInPlace(opt.op, grids, &result.notes);
    grids.clear();
    if (result.surface->activeVoxelCount() == 0) {
        result.warnings.push_back("the result has no surface (the inputs do not overlap as this "
                                  "operation needs); the level set written is empty");
    }
    result.computeSeconds = clock.lap();
    const std::string what = opt.p ? std::string("blend ") + implicit::toString(opt.op) + " p=" +
                                         util::formatNumber(*opt.p)
                                   : std::string("csg ") + implicit::toString(opt.op);
    io::stampGrid(*result.surface, what + " " + detail::joined(opt.inputs));
    if (opt.fog) result.density = detail::fogWithStamps(*result.surface);
    detail::writeGrids(opt.output, {result.surface, result.density}, opt.write);
    result.totalSeconds = clock.total();
    return result;
}

} // namespace ivdb::jobs
