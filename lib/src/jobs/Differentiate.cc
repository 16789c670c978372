// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/Differentiate.h>

#include "Common.h"

#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Inputs.h>
#include <ivdb/jobs/Rasterize.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

namespace ivdb::jobs {

GradientResult gradient(const GradientOptions& opt)
{
    Stopwatch clock;
    check(limits::kStep, opt.step);
    if (!opt.output.empty()) io::checkOutputPath(opt.output);
    GradientResult result;
    result.input = readLevelSet(opt.input, opt.grid);
    result.readSeconds = clock.lap();
    result.gradient = diff::gradient(*result.input, opt.step);
    result.computeSeconds = clock.lap();

    if (opt.magnitude) {
        result.magnitude = diff::magnitude(*result.gradient);
        stampGradient(*result.magnitude, opt, result.input->getName());
    }
    stampGradient(*result.gradient, opt, result.input->getName());
    detail::writeGrids(opt.output, {result.gradient, result.magnitude,
                                    opt.withInput ? result.input : nullptr}, opt.write);
    result.totalSeconds = clock.total();
    return result;
}

void stampGradient(openvdb::GridBase& grid, const GradientOptions& opt, const std::string& gridName)
{
    io::stampGrid(grid, opt.input + ":" + gridName);
    if (grid.isType<openvdb::Vec3SGrid>()) {
        grid.insertMeta("ivdb_step_voxels", openvdb::Int32Metadata(opt.step));
    }
}

const std::vector<std::string>& curvatureMethodNames()
{
    static const std::vector<std::string> names{"mean", "gaussian", "principal", "laplacian"};
    return names;
}

namespace {

/// What the values mean, for the grids' `ivdb_curvature` metadata.
const char* convention(CurvatureMethod method)
{
    switch (method) {
    case CurvatureMethod::Mean: return "mean curvature (k1 + k2) / 2; 1/r on a sphere";
    case CurvatureMethod::Gaussian: return "Gaussian curvature k1 k2; 1/r^2 on a sphere";
    case CurvatureMethod::Principal: return "principal curvatures k1 >= k2; both 1/r on a sphere";
    case CurvatureMethod::Laplacian: break;
    }
    return "Laplacian of phi (docs/method.md#curvature); 2/r on a sphere's distance field";
}

} // namespace

std::vector<openvdb::FloatGrid::Ptr> curvatureGrids(const openvdb::FloatGrid& phi,
                                                    CurvatureMethod method,
                                                    const diff::LeafList* only)
{
    if (method == CurvatureMethod::Principal) {
        auto [k1, k2] = diff::principalCurvatures(phi, true, only);
        return {k1, k2};
    }
    const diff::Curvature kind = method == CurvatureMethod::Gaussian ? diff::Curvature::Gaussian
                               : method == CurvatureMethod::Laplacian ? diff::Curvature::Laplacian
                                                                      : diff::Curvature::Mean;
    return {diff::curvature(phi, kind, true, only)};
}

void stampCurvature(openvdb::GridBase& grid, const CurvatureOptions& opt, const std::string& gridName)
{
    io::stampGrid(grid, opt.input + ":" + gridName);
    grid.insertMeta("ivdb_curvature", openvdb::StringMetadata(convention(opt.method)));
}

CurvatureResult curvature(const CurvatureOptions& opt)
{
    Stopwatch clock;
    if (!opt.output.empty()) io::checkOutputPath(opt.output);
    CurvatureResult result;
    result.input = readLevelSet(opt.input, opt.grid);
    result.readSeconds = clock.lap();
    result.grids = curvatureGrids(*result.input, opt.method);
    result.computeSeconds = clock.lap();
    std::vector<openvdb::GridBase::ConstPtr> out;
    for (auto& g : result.grids) {
        stampCurvature(*g, opt, result.input->getName());
        out.push_back(g);
    }
    if (opt.withInput) out.push_back(result.input);
    detail::writeGrids(opt.output, out, opt.write);
    result.totalSeconds = clock.total();
    return result;
}

CompareGradientResult compareGradient(const CompareGradientOptions& opt)
{
    for (int k : opt.steps) check(limits::kStep, k);
    const scene::Scene sc = scene::loadScene(opt.scene);
    raster::RasterSettings settings = sceneSettings(sc, opt.scene, opt.voxelSize, opt.halfWidth);
    settings.interrupter = opt.interrupter;
    openvdb::FloatGrid::Ptr phi;
    try {
        phi = raster::rasterize(sc.shape, settings);
    } catch (const ParamError&) {
        throw;
    } catch (const openvdb::Exception& e) {
        OPENVDB_THROW(openvdb::RuntimeError, opt.scene + ": " + util::errorText(e));
    }
    const auto shape = raster::clipToBounds(sc.shape, settings);
    CompareGradientResult result;
    result.voxelSize = settings.voxelSize;
    result.activeVoxels = phi->activeVoxelCount();
    for (int k : opt.steps) {
        const auto grad = diff::gradient(*phi, k);
        result.steps.emplace_back(k, diff::compareGradient(*shape, *phi, *grad, k));
    }
    return result;
}

} // namespace ivdb::jobs
