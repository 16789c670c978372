// SPDX-License-Identifier: Apache-2.0
// ivdb convert: re-save a .vdb file's grids as .vdb (another compression, half floats) or as
// NanoVDB (.nvdb).
#include "Cli.h"

#include <ivdb/jobs/Convert.h>

#include <cstdio>

namespace ivdb::cli {

namespace {

struct ConvertArgs
{
    jobs::ConvertOptions job;
    std::string compression; // empty: not given
    bool quiet = false;
};

int runConvert(ConvertArgs& a)
{
    if (!a.compression.empty()) {
        a.job.compression = enumOf<io::Compression>(a.compression, io::compressionNames());
    }
    const jobs::ConvertResult r = jobs::convert(a.job);
    if (!a.quiet) {
        unsigned long long voxels = 0;
        for (const auto& g : r.grids) voxels += g->activeVoxelCount();
        std::printf("%s: %zu grid%s, %llu active voxels, read %.3f s, write %.3f s, file %.1f MB "
                    "(%s) -> %s\n",
                    a.job.input.c_str(), r.grids.size(), r.grids.size() == 1 ? "" : "s", voxels,
                    r.readSeconds, r.writeSeconds, double(r.fileBytes) / 1e6,
                    r.format == jobs::FileFormat::NanoVdb ? "NanoVDB" : "OpenVDB",
                    a.job.output.c_str());
    }
    return 0;
}

} // namespace

void addConvert(CLI::App& app, Action& action)
{
    auto a = std::make_shared<ConvertArgs>();
    Command cmd(app, "convert",
        "Re-save a .vdb file's grids: as .vdb with another compression or half floats, or as "
        "NanoVDB (.nvdb); the output's extension picks the format");
    cmd.add("input", a->job.input, "Input .vdb file", &param::kInput)->required();
    cmd.add("-o,--output", a->job.output,
            "Output file: OUT.vdb (OpenVDB) or OUT.nvdb (NanoVDB), written atomically",
            &param::kOutput)
        ->required();
    cmd.add("--grid", a->job.grid, "Convert only this grid (default: every grid)", &param::kGrid);
    cmd.add("--compression", a->compression,
            "For .vdb output: blosc (default), zip or none (OpenVDB never zips level sets and fog "
            "volumes)",
            &param::kCompression)
        ->check(CLI::IsMember(io::compressionNames()));
    cmd.flag("--half", a->job.half, "For .vdb output: store float values as 16-bit halves");
    cmd.name(param::kHalf, "--half");
    addQuietFlag(cmd, a->quiet);
    cmd.onRun(action, [a]() { return runConvert(*a); });
}

} // namespace ivdb::cli
