// SPDX-License-Identifier: Apache-2.0
// ivdb glyphs: arrows of a vector grid (a gradient) near the surface, as an OBJ or PLY mesh.
#include "Cli.h"

#include <ivdb/jobs/Visualize.h>

#include <cstdio>

namespace ivdb::cli {

namespace {

struct GlyphsArgs
{
    jobs::GlyphsOptions job;
    bool quiet = false;
};

int runGlyphs(const GlyphsArgs& a)
{
    const jobs::GlyphsResult r = jobs::glyphs(a.job);
    if (!a.quiet) {
        std::printf("%s: %zu arrows of grid '%s' (stride %d, length %g) -> %s\n",
                    a.job.input.c_str(), r.arrows, r.field.c_str(), a.job.stride, r.length,
                    a.job.output.c_str());
    }
    return 0;
}

} // namespace

void addGlyphs(CLI::App& app, Action& action)
{
    auto a = std::make_shared<GlyphsArgs>();
    Command cmd(app, "glyphs",
        "Arrows of a vector grid (a gradient) near the surface as an OBJ or PLY mesh");
    cmd.add("input", a->job.input, "Input .vdb with a vec3s grid (ivdb gradient)")->required();
    cmd.add("-o,--output", a->job.output, "Output .obj or .ply (written atomically)", &param::kOutput)
        ->required();
    cmd.add("--grid", a->job.grid, "Vector grid (default: the first vec3s grid)", &param::kGrid);
    cmd.add("--stride", a->job.stride, "One arrow every N voxels along each axis", &param::kStride)
        ->capture_default_str();
    cmd.add("--length", a->job.length,
            "World length of an arrow per unit of the vector (default: twice the stride in voxels)",
            &param::kLength);
    cmd.add("--near", a->job.near,
            "With a level set in the file (gradient --with-input), only voxels where |phi| < NEAR "
            "voxels", &param::kNear)
        ->capture_default_str();
    addQuietFlag(cmd, a->quiet);
    cmd.onRun(action, [a]() { return runGlyphs(*a); });
}

} // namespace ivdb::cli
