// SPDX-License-Identifier: Apache-2.0
// ivdb info: what a .vdb file holds, as text or JSON.
#include "Cli.h"

#include <ivdb/jobs/Info.h>
#include <ivdb/util/System.h>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <iostream>

namespace ivdb::cli {

namespace {

struct InfoArgs
{
    std::string file;
    bool json = false;
};

nlohmann::json toJson(const io::GridInfo& i)
{
    nlohmann::json j;
    j["name"] = i.name;
    j["class"] = i.gridClass;
    j["value_type"] = i.valueType;
    j["voxel_size"] = {i.voxelSize[0], i.voxelSize[1], i.voxelSize[2]};
    j["active_voxels"] = i.activeVoxels;
    j["leaf_nodes"] = i.leafNodes;
    j["memory_bytes"] = i.memoryBytes;
    if (i.background.size() == 1) j["background"] = i.background[0];
    if (i.background.size() == 3) j["background"] = i.background;
    if (i.indexBox.empty()) {
        j["index_bbox"] = nullptr;
        j["world_bbox"] = nullptr;
    } else {
        const auto& a = i.indexBox.min();
        const auto& b = i.indexBox.max();
        j["index_bbox"] = {{"min", {a.x(), a.y(), a.z()}}, {"max", {b.x(), b.y(), b.z()}}};
        const auto& wa = i.worldBox.min();
        const auto& wb = i.worldBox.max();
        j["world_bbox"] = {{"min", {wa[0], wa[1], wa[2]}}, {"max", {wb[0], wb[1], wb[2]}}};
    }
    return j;
}

void printText(const io::GridInfo& i)
{
    std::printf("  %s: class %s, %s, voxel size %g", i.name.empty() ? "(unnamed)" : i.name.c_str(),
                i.gridClass.c_str(), i.valueType.c_str(), i.voxelSize[0]);
    if (i.voxelSize[0] != i.voxelSize[1] || i.voxelSize[0] != i.voxelSize[2]) {
        std::printf(" x %g x %g", i.voxelSize[1], i.voxelSize[2]);
    }
    std::printf(", %llu active voxels, %llu leaves, memory %s", (unsigned long long)i.activeVoxels,
                (unsigned long long)i.leafNodes, util::formatBytes(double(i.memoryBytes)).c_str());
    if (i.background.size() == 1) std::printf(", background %g", i.background[0]);
    if (i.background.size() == 3) {
        std::printf(", background (%g, %g, %g)", i.background[0], i.background[1], i.background[2]);
    }
    std::printf("\n");
    if (!i.indexBox.empty()) {
        const auto& a = i.indexBox.min();
        const auto& b = i.indexBox.max();
        const auto& wa = i.worldBox.min();
        const auto& wb = i.worldBox.max();
        std::printf("    index bbox [%d, %d, %d] .. [%d, %d, %d]\n", a.x(), a.y(), a.z(), b.x(),
                    b.y(), b.z());
        std::printf("    world bbox [%g, %g, %g] .. [%g, %g, %g]\n", wa[0], wa[1], wa[2], wb[0],
                    wb[1], wb[2]);
    }
}

int runInfo(const InfoArgs& a)
{
    const std::vector<io::GridInfo> grids = jobs::info(a.file);
    if (a.json) {
        nlohmann::json out{{"file", a.file}, {"grids", nlohmann::json::array()}};
        for (const auto& g : grids) out["grids"].push_back(toJson(g));
        std::cout << out.dump(2) << std::endl;
        return 0;
    }
    std::printf("%s: %zu grid%s\n", a.file.c_str(), grids.size(), grids.size() == 1 ? "" : "s");
    for (const auto& g : grids) printText(g);
    return 0;
}

} // namespace

void addInfo(CLI::App& app, Action& action)
{
    auto a = std::make_shared<InfoArgs>();
    Command cmd(app, "info",
        "Describe each grid of a .vdb file: name, class, value type, voxel size, active voxels, "
        "index and world bounding box, memory");
    cmd.add("file", a->file, ".vdb file to describe")->required();
    cmd.flag("--json", a->json, "Print JSON instead of text");
    cmd.onRun(action, [a]() { return runInfo(*a); });
}

} // namespace ivdb::cli
