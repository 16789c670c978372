// SPDX-License-Identifier: Apache-2.0
// ivdb mesh: a level set's surface as an OBJ or PLY mesh, optionally coloured by another grid.
#include "Cli.h"

#include <ivdb/jobs/Visualize.h>

#include <cstdio>

namespace ivdb::cli {

namespace {

struct MeshArgs
{
    jobs::MeshOptions job;
    std::string colormap = "viridis", range;
    bool colormapGiven = false, quiet = false;
};

int runMesh(MeshArgs& a)
{
    if (!a.range.empty()) a.job.range = parseRange(a.range);
    // Unset unless given: the job's default then applies, and a vector grid is allowed.
    if (a.colormapGiven) a.job.colormap = a.colormap;
    const jobs::MeshResult r = jobs::mesh(a.job);
    if (!a.quiet) {
        std::printf("%s: %zu vertices, %zu triangles, %zu quads, enclosed volume %.6g, %.3f s -> %s\n",
                    a.job.input.c_str(), r.mesh.points.size(), r.mesh.triangles.size(),
                    r.mesh.quads.size(), r.enclosedVolume, r.seconds, a.job.output.c_str());
    }
    return 0;
}

} // namespace

void addMesh(CLI::App& app, Action& action)
{
    auto a = std::make_shared<MeshArgs>();
    Command cmd(app, "mesh",
        "Mesh a level set's surface (openvdb::tools::volumeToMesh) into OBJ or PLY, "
        "optionally coloured by another grid");
    cmd.add("input", a->job.input, "Input .vdb file")->required();
    cmd.add("-o,--output", a->job.output, "Output .obj or .ply (written atomically)", &param::kOutput)
        ->required();
    cmd.add("--grid", a->job.grid, "Level set to mesh (default: the first level set)", &param::kGrid);
    cmd.add("--adaptivity", a->job.adaptivity,
            "0 keeps every voxel's face; up to 1 merges flat regions", &param::kAdaptivity)
        ->capture_default_str();
    cmd.add("--color-by", a->job.colorBy,
            "FILE.vdb[:GRID]: colour the vertices by a scalar grid through the colormap, or by a "
            "vector grid's direction; PLY also stores the sampled value", &param::kColorBy);
    CLI::Option* colormap = cmd.add("--colormap", a->colormap, "hsv, viridis, coolwarm or gray",
                                    &param::kColormap)
        ->capture_default_str();
    cmd.add("--range", a->range,
            "LO,HI: the values mapped to the colormap's ends (default: the sampled values' range)",
            &param::kRange);
    addQuietFlag(cmd, a->quiet);
    cmd.onRun(action, [a, colormap]() {
        a->colormapGiven = colormap->count() > 0;
        return runMesh(*a);
    });
}

} // namespace ivdb::cli
