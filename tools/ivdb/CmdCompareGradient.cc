// ivdb compare-gradient: discrete gradient of the rasterized scene vs its analytic gradient.
#include "Cli.h"

#include <ivdb/diff/Differential.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/util/System.h>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <iostream>

namespace ivdb::cli {

namespace {

struct CompareOptions
{
    std::string scene;
    std::optional<double> voxelSize, halfWidth;
    std::vector<int> steps{1};
    bool json = false;
};

nlohmann::json toJson(const diff::ErrorStats& s)
{
    return {{"count", s.count}, {"mean", s.mean}, {"median", s.median}, {"p95", s.p95}, {"max", s.max}};
}

int runCompare(const CompareOptions& opt)
{
    for (int k : opt.steps) {
        if (k < 1 || k > diff::kMaxStep) {
            throw std::runtime_error("--step must be in [1, " + std::to_string(diff::kMaxStep) +
                                     "] voxels, got " + std::to_string(k));
        }
    }
    const scene::Scene sc = scene::loadScene(opt.scene);
    raster::RasterSettings settings = sceneSettings(sc, opt.scene, opt.voxelSize, opt.halfWidth);
    Progress progress("compare-gradient " + opt.scene);
    settings.interrupter = &progress;
    openvdb::FloatGrid::Ptr phi;
    try {
        phi = raster::rasterize(sc.shape, settings);
    } catch (const std::exception& e) {
        throw std::runtime_error(opt.scene + ": " + util::errorText(e));
    }
    const auto shape = raster::clipToBounds(sc.shape, settings);
    nlohmann::json rows = nlohmann::json::array();
    if (!opt.json) {
        std::printf("%s: discrete gradient of the rasterized band (%llu voxels, voxel size %g) vs "
                    "the normalized analytic gradient\n",
                    opt.scene.c_str(), (unsigned long long)phi->activeVoxelCount(), settings.voxelSize);
        std::printf("%24s  %35s  %48s\n", "", "angle error (degrees)",
                    "magnitude error | |grad| - 1 |");
        std::printf("%4s %-8s %9s  %8s %8s %8s %8s  %8s %9s %9s %9s %9s\n", "step", "voxels", "count",
                    "mean", "median", "p95", "max", "mean|g|", "mean", "median", "p95", "max");
    }
    for (int k : opt.steps) {
        const auto grad = diff::gradient(*phi, k);
        const diff::GradientComparison c = diff::compareGradient(*shape, *phi, *grad, k);
        auto row = [](const diff::GradientErrors& e) {
            return nlohmann::json{{"voxels", e.angleDeg.count}, {"angle_deg", toJson(e.angleDeg)},
                                  {"magnitude_error", toJson(e.magnitudeError)},
                                  {"mean_magnitude", e.meanMagnitude}, {"skipped", e.skipped}};
        };
        if (opt.json) {
            rows.push_back({{"step", k}, {"band", row(c.band)}, {"interior", row(c.interior)}});
            continue;
        }
        for (const auto& [label, e] : {std::pair<const char*, const diff::GradientErrors&>{"band", c.band},
                                       {"interior", c.interior}}) {
            std::printf("%4d %-8s %9zu  %8.4f %8.4f %8.4f %8.4f  %8.5f %9.5f %9.5f %9.5f %9.5f\n", k,
                        label, e.angleDeg.count, e.angleDeg.mean, e.angleDeg.median, e.angleDeg.p95,
                        e.angleDeg.max, e.meanMagnitude, e.magnitudeError.mean,
                        e.magnitudeError.median, e.magnitudeError.p95, e.magnitudeError.max);
        }
    }
    if (!opt.json) {
        std::printf("band: every band voxel; interior: voxels whose stencil stays in the band (the "
                    "others read the clamped background)\n");
    }
    if (opt.json) {
        std::cout << nlohmann::json{{"scene", opt.scene}, {"voxel_size", settings.voxelSize},
                                    {"active_voxels", phi->activeVoxelCount()}, {"steps", rows}}.dump(2)
                  << std::endl;
    }
    return 0;
}

} // namespace

void addCompareGradient(CLI::App& app, Action& action)
{
    auto opt = std::make_shared<CompareOptions>();
    CLI::App* cmd = app.add_subcommand("compare-gradient",
        "Rasterize a scene and compare the discrete gradient of its band (central differences, "
        "step K voxels) with the normalized analytic gradient: angle and magnitude error "
        "statistics per step (the seed's section 3.3 observation)");
    cmd->add_option("scene", opt->scene, "Scene file (JSON)")->required();
    cmd->add_option("--step", opt->steps, "Difference step(s) K in voxels, in [1, 20] (give "
                                          "several: --step 1 2 4)")
        ->capture_default_str();
    cmd->add_option("--voxel-size", opt->voxelSize, "World units per voxel (overrides the scene)");
    cmd->add_option("--half-width", opt->halfWidth,
                    "Band half width in voxels, in [1, 1000] (overrides the scene)");
    cmd->add_flag("--json", opt->json, "Print JSON instead of a table");
    cmd->callback([&action, opt]() { action = [opt]() { return runCompare(*opt); }; });
}

} // namespace ivdb::cli
