// ivdb rasterize: a scene file into a narrow-band level set .vdb.
#include "Cli.h"

#include <ivdb/Version.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/util/System.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>

namespace ivdb::cli {

namespace {

struct RasterizeOptions
{
    std::string scene, output;
    std::optional<double> voxelSize, halfWidth;
    std::string sampling = "sparse";
    std::string distance; // empty: the scene's
    bool quiet = false;
    bool fog = false;
};

int runRasterize(const RasterizeOptions& opt)
{
    const auto t0 = std::chrono::steady_clock::now();
    scene::Scene sc = scene::loadScene(opt.scene);
    io::checkOutputPath(opt.output);

    raster::RasterSettings settings = sceneSettings(sc, opt.scene, opt.voxelSize, opt.halfWidth);
    settings.sampling = opt.sampling == "dense" ? raster::Sampling::Dense : raster::Sampling::Sparse;
    if (!opt.distance.empty()) {
        settings.distance = opt.distance == "bound" ? raster::Distance::Bound : raster::Distance::Exact;
    }
    Progress progress("rasterize " + opt.scene);
    settings.interrupter = &progress;

    openvdb::FloatGrid::Ptr grid;
    try {
        grid = raster::rasterize(sc.shape, settings);
    } catch (const std::exception& e) {
        throw std::runtime_error(opt.scene + ": " + util::errorText(e));
    }
    const auto t1 = std::chrono::steady_clock::now();
    if (grid->activeVoxelCount() == 0) {
        std::ostringstream os;
        os << opt.scene << ": the surface has no voxels at voxel size " << settings.voxelSize
           << " (no zero crossing inside the bounds, or a shape smaller than a voxel): "
           << "check the shape and bounds, or use a smaller voxel size; nothing was written";
        throw std::runtime_error(os.str());
    }
    stampGrid(*grid, opt.scene);
    // The scene as rasterized: the command line's overrides replace the file's values.
    nlohmann::json scene = nlohmann::json::parse(sc.json);
    scene["voxel_size"] = settings.voxelSize;
    scene["half_width"] = settings.halfWidth;
    scene["distance"] = settings.distance == raster::Distance::Bound ? "bound" : "exact";
    grid->insertMeta("ivdb_scene", openvdb::StringMetadata(scene.dump()));
    grid->insertMeta("ivdb_sampling", openvdb::StringMetadata(opt.sampling));
    writeOutput(opt.output, withFog(grid, opt.fog));
    const auto t2 = std::chrono::steady_clock::now();

    if (!opt.quiet) {
        const double compute = std::chrono::duration<double>(t1 - t0).count();
        const double total = std::chrono::duration<double>(t2 - t0).count();
        std::error_code ec;
        const auto size = std::filesystem::file_size(opt.output, ec);
        std::printf("%s: %llu active voxels, grid %s, file %s, peak memory %s, compute %.3f s, "
                    "total %.3f s -> %s\n",
                    opt.scene.c_str(), (unsigned long long)grid->activeVoxelCount(),
                    util::formatBytes(double(grid->memUsage())).c_str(),
                    util::formatBytes(double(size)).c_str(),
                    util::formatBytes(double(util::peakResidentMemory())).c_str(), compute, total,
                    opt.output.c_str());
    }
    return 0;
}

} // namespace

void addRasterize(CLI::App& app, Action& action)
{
    auto opt = std::make_shared<RasterizeOptions>();
    CLI::App* cmd = app.add_subcommand("rasterize",
        "Rasterize a JSON scene into a narrow-band level set .vdb (grid 'surface')");
    cmd->add_option("scene", opt->scene, "Scene file (JSON; see the README's scene format)")
        ->required();
    cmd->add_option("-o,--output", opt->output, "Output .vdb file (written atomically)")
        ->required();
    cmd->add_option("--voxel-size", opt->voxelSize,
                    "World units per voxel (overrides the scene's voxel_size); > 0");
    cmd->add_option("--half-width", opt->halfWidth,
                    "Narrow-band half width in voxels (overrides the scene's half_width, "
                    "default 3); in [1, 1000]");
    cmd->add_option("--sampling", opt->sampling,
                    "sparse: interval-pruned, cost grows with the surface; dense: every voxel "
                    "of the bounding box (the reference; refuses if it would not fit in memory)")
        ->check(CLI::IsMember({"sparse", "dense"}))
        ->capture_default_str();
    cmd->add_option("--distance", opt->distance,
                    "exact: true signed distances (shapes that are not distances are "
                    "re-distanced); bound: a CSG of exact distances stored as min / max, as "
                    "OpenVDB's csg tools give it, without re-distancing (overrides the scene's "
                    "\"distance\", default exact)")
        ->check(CLI::IsMember({"exact", "bound"}));
    addFogFlag(*cmd, opt->fog);
    cmd->add_flag("-q,--quiet", opt->quiet, "Do not print the summary line");
    cmd->callback([&action, opt]() { action = [opt]() { return runRasterize(*opt); }; });
}

} // namespace ivdb::cli
