// SPDX-License-Identifier: Apache-2.0
// ivdb check-distances: a level set's values against brute-force distances to its scene's surface.
#include "Cli.h"

#include <ivdb/jobs/CheckDistances.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <optional>
#include <sstream>

namespace ivdb::cli {

namespace {

struct CheckArgs
{
    jobs::CheckDistancesOptions job;
    std::string distance;
    std::int64_t samples = 200;     // signed: a negative count is refused, not wrapped
    std::optional<double> maxError;
    std::size_t listed = 10;
    bool json = false;
};

/// Accepts a whole number >= 0 (an unsigned option would wrap a negative value); CLI11 names
/// the option in the message.
CLI::Validator wholeNumber()
{
    return CLI::Validator(
        [](std::string& v) -> std::string {
            std::uint64_t n = 0;
            return v.find('-') == std::string::npos && CLI::detail::lexical_cast(v, n)
                       ? std::string()
                       : "must be a whole number >= 0, got " + v;
        },
        "N>=0");
}

/// The error thresholds the counts are given at, in voxels.
constexpr double kThresholds[] = {0.001, 0.01, 0.05, 0.1, 0.3, 1.0};

/// JSON has no infinity: null stands for it.
nlohmann::json finiteOrNull(double v)
{
    return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

std::string thresholdKey(double t)
{
    std::ostringstream s;
    s << t;
    return s.str();
}

void printJson(const CheckArgs& a, const jobs::CheckDistancesResult& r)
{
    nlohmann::json farther = nlohmann::json::object(), nearer = nlohmann::json::object();
    for (double t : kThresholds) {
        farther[thresholdKey(t)] = r.fartherThan(t);
        nearer[thresholdKey(t)] = r.nearerThan(t);
    }
    nlohmann::json voxels = nlohmann::json::array();
    for (const auto& v : r.voxels) {
        voxels.push_back({{"ijk", {v.ijk.x(), v.ijk.y(), v.ijk.z()}},
                          {"world", {v.world[0], v.world[1], v.world[2]}},
                          {"value", v.value}, {"searched", finiteOrNull(v.searched)},
                          {"error_voxels", finiteOrNull(r.error(v))}, {"sign_agrees", v.signAgrees}});
    }
    const double worst = r.voxels.empty() ? 0.0 : r.error(r.voxels.front());
    const double least = r.voxels.empty() ? 0.0 : r.error(r.voxels.back());
    std::cout << nlohmann::json{{"scene", a.job.raster.scene},
                                {"input", a.job.input},
                                {"voxel_size", r.voxelSize},
                                {"active_voxels", r.activeVoxels},
                                {"near_kinks", a.job.nearKinks},
                                {"candidates", r.candidates},
                                {"sampled", r.voxels.size()},
                                {"directions", a.job.directions},
                                {"seed", a.job.seed},
                                {"step_voxels", r.stepVoxels},
                                {"reach_voxels", r.reachVoxels},
                                {"worst_farther_voxels", finiteOrNull(std::max(worst, 0.0))},
                                {"worst_nearer_voxels", finiteOrNull(std::max(-least, 0.0))},
                                {"farther_than", farther},
                                {"nearer_than", nearer},
                                {"sign_mismatches", r.signMismatches()},
                                {"seconds", r.seconds},
                                {"voxels", voxels}}.dump(2)
              << std::endl;
}

void printTable(const CheckArgs& a, const jobs::CheckDistancesResult& r)
{
    const std::string what = a.job.input.empty() ? a.job.raster.scene + " rasterized" : a.job.input;
    std::printf("%s: %zu of %llu band voxels%s (%llu active, voxel size %g) against a brute-force "
                "search of %d directions (radius step %g voxel, up to a voxel beyond the value)\n",
                what.c_str(), r.voxels.size(), (unsigned long long)r.candidates,
                a.job.nearKinks ? " near a kink" : "", (unsigned long long)r.activeVoxels,
                r.voxelSize, a.job.directions, r.stepVoxels);
    std::printf("%-40s", "more than (voxels)");
    for (double t : kThresholds) std::printf(" %7g", t);
    std::printf("\n%-40s", "farther than the surface found");
    for (double t : kThresholds) std::printf(" %7zu", r.fartherThan(t));
    std::printf("\n%-40s", "nearer than the surface found");
    for (double t : kThresholds) std::printf(" %7zu", r.nearerThan(t));
    std::printf("\nsign differs from the scene's: %zu\n", r.signMismatches());
    const std::size_t listed = std::min(a.listed, r.voxels.size());
    if (listed == 0) return;
    std::printf("farthest %zu (error = |value| - searched, voxels):\n", listed);
    std::printf("%26s  %30s  %10s %10s %9s\n", "voxel", "world", "value", "searched", "error");
    for (std::size_t i = 0; i < listed; ++i) {
        const auto& v = r.voxels[i];
        char ijk[64], world[96];
        std::snprintf(ijk, sizeof ijk, "[%d %d %d]", v.ijk.x(), v.ijk.y(), v.ijk.z());
        std::snprintf(world, sizeof world, "(%.5g %.5g %.5g)", v.world[0], v.world[1], v.world[2]);
        std::printf("%26s  %30s  %10.6g %10.6g %9.4f%s\n", ijk, world, v.value, v.searched,
                    r.error(v), v.signAgrees ? "" : "  sign differs");
    }
}

int runCheck(CheckArgs& a)
{
    applyDistance(a.job.raster, a.distance);
    check(limits::kSamples, double(a.samples));
    a.job.samples = std::size_t(a.samples);
    Progress progress("check-distances " + a.job.raster.scene);
    a.job.raster.interrupter = &progress;
    const jobs::CheckDistancesResult r = jobs::checkDistances(a.job);
    progress.clearLine();
    if (a.json) printJson(a, r);
    else printTable(a, r);
    if (a.maxError && r.voxels.empty()) {
        std::fprintf(stderr, "ivdb: error: no voxel was checked (%s), so --max-error cannot "
                     "pass\n", a.job.nearKinks ? "none near a kink: drop --near-kinks"
                                               : "the band has no voxel: check the scene");
        return 1;
    }
    if (a.maxError && (r.fartherThan(*a.maxError) > 0 || r.signMismatches() > 0)) {
        std::fprintf(stderr, "ivdb: error: %zu of %zu sampled voxels are more than %g "
                     "voxel farther than the surface (worst %.4g), %zu of the wrong sign\n",
                     r.fartherThan(*a.maxError), r.voxels.size(), *a.maxError,
                     r.error(r.voxels.front()), r.signMismatches());
        return 1;
    }
    return 0;
}

} // namespace

void addCheckDistances(CLI::App& app, Action& action)
{
    auto a = std::make_shared<CheckArgs>();
    Command cmd(app, "check-distances",
        "Check a level set's values against brute-force distances to its scene's surface: at "
        "sampled band voxels, the least sphere about the voxel that reaches the other sign "
        "(bisected), so a value farther than it is certainly too far. Checks the scene "
        "rasterized, or a .vdb made from it");
    cmd.add("scene", a->job.raster.scene, "Scene file (JSON)")->required();
    cmd.add("input", a->job.input,
            "Level set to check, FILE.vdb[:GRID] (default: the file's first level set; without "
            "it, the scene is rasterized)", &param::kInput);
    addRasterSettings(cmd, a->job.raster, a->distance);
    cmd.add("--samples", a->samples, "Band voxels checked, chosen at random",
            &param::kSamples)
        ->capture_default_str();
    cmd.add("--directions", a->job.directions,
            "Points on each sphere of the search (more finds thinner features)",
            &param::kDirections)
        ->capture_default_str();
    cmd.add("--seed", a->job.seed, "Which voxels are sampled (a whole number >= 0)")
        ->capture_default_str()
        ->check(wholeNumber());
    cmd.flag("--near-kinks", a->job.nearKinks,
             "Sample only voxels within whose distance the shape may kink (a box's or capped "
             "shape's edges under a blend), where nearest points are hardest to find");
    cmd.add("--max-error", a->maxError,
            "Exit with status 1 if a sampled voxel is more than this many voxels farther than "
            "the surface or has the wrong sign, or if no voxel was sampled")
        ->check(CLI::Validator(
            [](std::string& v) -> std::string {
                double e = 0.0;
                return CLI::detail::lexical_cast(v, e) && std::isfinite(e) && e >= 0.0
                           ? std::string()
                           : "must be a finite number of voxels >= 0, got " + v;
            },
            "VOXELS"));
    cmd.add("--list", a->listed, "Farthest voxels listed in the table")
        ->capture_default_str()
        ->check(wholeNumber());
    cmd.flag("--json", a->json, "Print JSON (every sampled voxel) instead of a table");
    cmd.onRun(action, [a]() { return runCheck(*a); });
}

} // namespace ivdb::cli
