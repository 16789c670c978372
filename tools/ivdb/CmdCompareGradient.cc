// SPDX-License-Identifier: Apache-2.0
// ivdb compare-gradient: discrete gradient of the rasterized scene vs its analytic gradient.
#include "Cli.h"

#include <ivdb/jobs/Differentiate.h>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <iostream>

namespace ivdb::cli {

namespace {

struct CompareArgs
{
    jobs::CompareGradientOptions job;
    bool json = false;
};

nlohmann::json toJson(const diff::ErrorStats& s)
{
    return {{"count", s.count}, {"mean", s.mean}, {"median", s.median}, {"p95", s.p95}, {"max", s.max}};
}

nlohmann::json toJson(const diff::GradientErrors& e)
{
    return {{"voxels", e.angleDeg.count}, {"angle_deg", toJson(e.angleDeg)},
            {"magnitude_error", toJson(e.magnitudeError)},
            {"mean_magnitude", e.meanMagnitude}, {"skipped", e.skipped}};
}

void printJson(const CompareArgs& a, const jobs::CompareGradientResult& r)
{
    nlohmann::json rows = nlohmann::json::array();
    for (const auto& [k, c] : r.steps) {
        rows.push_back({{"step", k}, {"band", toJson(c.band)}, {"interior", toJson(c.interior)}});
    }
    std::cout << nlohmann::json{{"scene", a.job.scene}, {"voxel_size", r.voxelSize},
                                {"active_voxels", r.activeVoxels}, {"steps", rows}}.dump(2)
              << std::endl;
}

void printTable(const CompareArgs& a, const jobs::CompareGradientResult& r)
{
    std::printf("%s: discrete gradient of the rasterized band (%llu voxels, voxel size %g) vs "
                "the normalized analytic gradient\n",
                a.job.scene.c_str(), (unsigned long long)r.activeVoxels, r.voxelSize);
    std::printf("%24s  %35s  %48s\n", "", "angle error (degrees)", "magnitude error | |grad| - 1 |");
    std::printf("%4s %-8s %9s  %8s %8s %8s %8s  %8s %9s %9s %9s %9s\n", "step", "voxels", "count",
                "mean", "median", "p95", "max", "mean|g|", "mean", "median", "p95", "max");
    for (const auto& [k, c] : r.steps) {
        for (const auto& [label, e] : {std::pair<const char*, const diff::GradientErrors&>{"band", c.band},
                                       {"interior", c.interior}}) {
            std::printf("%4d %-8s %9zu  %8.4f %8.4f %8.4f %8.4f  %8.5f %9.5f %9.5f %9.5f %9.5f\n", k,
                        label, e.angleDeg.count, e.angleDeg.mean, e.angleDeg.median, e.angleDeg.p95,
                        e.angleDeg.max, e.meanMagnitude, e.magnitudeError.mean,
                        e.magnitudeError.median, e.magnitudeError.p95, e.magnitudeError.max);
        }
    }
    std::printf("band: every band voxel; interior: voxels whose stencil stays in the band (the "
                "others read the clamped background)\n");
}

int runCompare(CompareArgs& a)
{
    Progress progress("compare-gradient " + a.job.scene);
    a.job.interrupter = &progress;
    const jobs::CompareGradientResult r = jobs::compareGradient(a.job);
    if (a.json) printJson(a, r);
    else printTable(a, r);
    return 0;
}

} // namespace

void addCompareGradient(CLI::App& app, Action& action)
{
    auto a = std::make_shared<CompareArgs>();
    Command cmd(app, "compare-gradient",
        "Rasterize a scene and compare the discrete gradient of its band (central differences, "
        "step K voxels) with the normalized analytic gradient: angle and magnitude error "
        "statistics per step");
    cmd.add("scene", a->job.scene, "Scene file (JSON)")->required();
    cmd.add("--step", a->job.steps,
            "Difference step(s) K in voxels, in [1, 20] (give several: --step 1 2 4)", &param::kStep)
        ->capture_default_str();
    cmd.add("--voxel-size", a->job.voxelSize, "World units per voxel (overrides the scene)",
            &param::kVoxelSize);
    cmd.add("--half-width", a->job.halfWidth,
            "Band half width in voxels, in [1, 1000] (overrides the scene)", &param::kHalfWidth);
    cmd.flag("--json", a->json, "Print JSON instead of a table");
    cmd.onRun(action, [a]() { return runCompare(*a); });
}

} // namespace ivdb::cli
