// SPDX-License-Identifier: Apache-2.0
// ivdb rasterize: a scene file into a narrow-band level set .vdb.
#include "Cli.h"

#include <ivdb/jobs/Rasterize.h>
#include <ivdb/util/System.h>

#include <cstdio>

namespace ivdb::cli {

namespace {

struct RasterizeArgs
{
    jobs::RasterizeOptions job;
    std::string compression = "blosc";
    std::string sampling = "sparse", distance;
    bool quiet = false;
};

int runRasterize(RasterizeArgs& a)
{
    a.job.write.compression = enumOf<io::Compression>(a.compression, io::compressionNames());
    a.job.sampling = a.sampling == "dense" ? raster::Sampling::Dense : raster::Sampling::Sparse;
    if (!a.distance.empty()) {
        a.job.distance = a.distance == "bound" ? raster::Distance::Bound : raster::Distance::Exact;
    }
    Progress progress("rasterize " + a.job.scene);
    a.job.interrupter = &progress;
    const jobs::RasterizeResult r = jobs::rasterize(a.job);
    printNotes(r.notes);
    if (!a.quiet) {
        std::printf("%s: %llu active voxels, grid %s, file %s, peak memory %s, compute %.3f s, "
                    "total %.3f s -> %s\n",
                    a.job.scene.c_str(), (unsigned long long)r.surface->activeVoxelCount(),
                    util::formatBytes(double(r.surface->memUsage())).c_str(),
                    util::formatBytes(double(r.fileBytes)).c_str(),
                    util::formatBytes(double(util::peakResidentMemory())).c_str(),
                    r.computeSeconds, r.totalSeconds, a.job.output.c_str());
        const raster::RasterStats& st = r.stats;
        if (st.searchedDistances + st.approximateDistances + st.sweptDistances > 0) {
            std::printf("  true distances: %llu voxels by foot points, %llu by the lattice search "
                        "(%llu of them approximate), %llu by fast sweeping\n",
                        (unsigned long long)st.localDistances,
                        (unsigned long long)(st.searchedDistances + st.approximateDistances),
                        (unsigned long long)st.approximateDistances,
                        (unsigned long long)st.sweptDistances);
        }
    }
    return 0;
}

} // namespace

void addRasterize(CLI::App& app, Action& action)
{
    auto a = std::make_shared<RasterizeArgs>();
    Command cmd(app, "rasterize",
        "Rasterize a JSON scene into a narrow-band level set .vdb (grid 'surface')");
    cmd.add("scene", a->job.scene, "Scene file (JSON; see docs/scene-format.md)")->required();
    cmd.add("-o,--output", a->job.output, "Output .vdb file (written atomically)")->required();
    cmd.add("--voxel-size", a->job.voxelSize,
            "World units per voxel (overrides the scene's voxel_size); > 0", &param::kVoxelSize);
    cmd.add("--half-width", a->job.halfWidth,
            "Narrow-band half width in voxels (overrides the scene's half_width, default 3); "
            "in [1, 1000]", &param::kHalfWidth);
    cmd.add("--sampling", a->sampling,
            "sparse: interval-pruned, cost grows with the surface; dense: every voxel of the "
            "bounding box (the reference; refuses if it would not fit in memory)", &param::kSampling)
        ->check(CLI::IsMember({"sparse", "dense"}))
        ->capture_default_str();
    cmd.add("--distance", a->distance,
            "exact: true signed distances (shapes that are not distances are re-distanced); "
            "bound: a CSG of exact distances stored as min / max, as OpenVDB's csg tools give "
            "it, without re-distancing (overrides the scene's \"distance\", default exact)",
            &param::kDistance)
        ->check(CLI::IsMember({"exact", "bound"}));
    addWriteOptions(cmd, a->compression, a->job.write.half);
    addFogFlag(cmd, a->job.fog);
    addQuietFlag(cmd, a->quiet);
    cmd.onRun(action, [a]() { return runRasterize(*a); });
}

} // namespace ivdb::cli
