// SPDX-License-Identifier: Apache-2.0
// ivdb plan: how a scene's rasterization splits over N ranks, without rasterizing.
#include "Cli.h"

#include <ivdb/jobs/Plan.h>
#include <ivdb/util/System.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <iostream>

namespace ivdb::cli {

namespace {

struct PlanArgs
{
    jobs::PlanOptions job;
    bool json = false;
};

nlohmann::json origin(const openvdb::Coord& c) { return {c.x(), c.y(), c.z()}; }

nlohmann::json toJson(const PlanArgs& a, const jobs::PlanResult& r)
{
    const raster::Partition& p = r.partition;
    nlohmann::json j{{"scene", a.job.scene}, {"ranks", p.ranks.size()},
                     {"voxel_size", r.settings.voxelSize}, {"half_width", r.settings.halfWidth},
                     {"leaves", p.leaves}, {"grid_leaves", p.gridLeaves},
                     {"active_voxels", p.activeVoxels},
                     {"memory_bytes", p.memoryBytes}, {"cpu_seconds", p.cpuSeconds},
                     {"balance", p.balance}, {"sampled_leaves", p.sampledLeaves},
                     {"seconds", r.seconds}, {"per_rank", nlohmann::json::array()}};
    for (size_t k = 0; k < p.ranks.size(); ++k) {
        const raster::RankShare& s = p.ranks[k];
        nlohmann::json rank{{"rank", k}, {"first_leaf", s.firstLeaf}, {"leaves", s.leaves},
                            {"active_voxels", s.activeVoxels}, {"memory_bytes", s.memoryBytes},
                            {"cpu_seconds", s.cpuSeconds}};
        rank["first_origin"] = s.leaves ? origin(s.first) : nlohmann::json(nullptr);
        rank["last_origin"] = s.leaves ? origin(s.last) : nlohmann::json(nullptr);
        j["per_rank"].push_back(rank);
    }
    return j;
}

void printText(const PlanArgs& a, const jobs::PlanResult& r)
{
    const raster::Partition& p = r.partition;
    std::printf("%s: voxel size %g, half width %g: %llu leaves the band may cross (about %.0f "
                "in the grid), about %.0f active voxels, %s, %.3g CPU-seconds (from %llu leaves "
                "built)\n", a.job.scene.c_str(), r.settings.voxelSize, r.settings.halfWidth,
                (unsigned long long)p.leaves, p.gridLeaves, p.activeVoxels,
                util::formatBytes(p.memoryBytes).c_str(), p.cpuSeconds,
                (unsigned long long)p.sampledLeaves);
    std::printf("%zu ranks, balance %.3f (max / mean leaves); planned in %.2f s\n", p.ranks.size(),
                p.balance, r.seconds);
    std::printf("%8s %12s %12s %14s %10s %10s  %s\n", "rank", "first leaf", "leaves",
                "active voxels", "memory", "CPU s", "leaf origins, first .. last");
    for (size_t k = 0; k < p.ranks.size(); ++k) {
        const raster::RankShare& s = p.ranks[k];
        std::printf("%8zu %12llu %12llu %14.0f %10s %10.3g", k, (unsigned long long)s.firstLeaf,
                    (unsigned long long)s.leaves, s.activeVoxels,
                    util::formatBytes(s.memoryBytes).c_str(), s.cpuSeconds);
        if (s.leaves) {
            std::printf("  [%d, %d, %d] .. [%d, %d, %d]", s.first.x(), s.first.y(), s.first.z(),
                        s.last.x(), s.last.y(), s.last.z());
        }
        std::printf("\n");
    }
}

int runPlan(const PlanArgs& a)
{
    const jobs::PlanResult r = jobs::plan(a.job);
    printNotes(r.notes);
    if (a.json) {
        std::cout << toJson(a, r).dump(2) << std::endl;
    } else {
        printText(a, r);
    }
    return 0;
}

} // namespace

void addPlan(CLI::App& app, Action& action)
{
    auto a = std::make_shared<PlanArgs>();
    Command cmd(app, "plan",
        "Split a scene's rasterization over N ranks without rasterizing: contiguous runs of "
        "leaves in .vdb file order, balanced by leaf count, with each rank's estimated active "
        "voxels, memory and compute");
    cmd.add("scene", a->job.scene, "Scene file (JSON; see docs/scene-format.md)", &param::kScene)
        ->required();
    cmd.add("--ranks", a->job.ranks, "Ranks (processes) to split over, in [1, 100000]",
            &param::kRanks)->required();
    cmd.add("--voxel-size", a->job.voxelSize,
            "World units per voxel (overrides the scene's voxel_size); > 0", &param::kVoxelSize);
    cmd.add("--half-width", a->job.halfWidth,
            "Narrow-band half width in voxels (overrides the scene's half_width, default 3); "
            "in [1, 1000]", &param::kHalfWidth);
    cmd.flag("--json", a->json, "Print JSON instead of text");
    cmd.onRun(action, [a]() { return runPlan(*a); });
}

} // namespace ivdb::cli
