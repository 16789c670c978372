// SPDX-License-Identifier: Apache-2.0
// ivdb-mpi: ivdb's commands over MPI ranks (`mpirun -np N ivdb-mpi rasterize ...`), each rank on
// its share of its machine's cores, writing one .vdb file together. Parsing, printing and error
// handling are ivdb's (tools/ivdb/Cli.h); only rank 0 prints.
#include "../ivdb/Cli.h"

#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Rasterize.h>
#include <ivdb/mpi/Rasterize.h>
#include <ivdb/util/System.h>

#include <mpi.h>
#include <nlohmann/json.hpp>
#include <tbb/global_control.h>

#include <csignal>
#include <cstdio>
#include <memory>
#include <optional>

namespace ivdb::cli {

namespace {

int worldRank()
{
    int rank = 0;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    return rank;
}

struct RasterizeArgs
{
    jobs::RasterizeOptions job;
    std::string compression = "blosc", distance;
    bool quiet = false, perRank = false, json = false;
};

void printJson(const RasterizeArgs& a, const mpi::RasterizeResult& r)
{
    nlohmann::json out{{"scene", a.job.scene}, {"output", a.job.output}, {"ranks", r.ranks},
                       {"leaves", r.leaves}, {"active_voxels", r.activeVoxels},
                       {"file_bytes", r.fileBytes}, {"compute_seconds", r.computeSeconds},
                       {"write_seconds", r.writeSeconds}, {"total_seconds", r.totalSeconds}};
    nlohmann::json ranks = nlohmann::json::array();
    for (int k = 0; k < r.ranks; ++k) {
        const std::size_t i = std::size_t(k);
        ranks.push_back({{"rank", k}, {"leaves", r.rankLeaves[i]},
                         {"active_voxels", r.rankActiveVoxels[i]},
                         {"peak_memory_bytes", r.rankPeakMemory[i]}});
    }
    out["per_rank"] = ranks;
    std::printf("%s\n", out.dump(2).c_str());
}

int runRasterize(RasterizeArgs& a)
{
    const bool printer = worldRank() == 0;
    a.job.write.compression = enumOf<io::Compression>(a.compression, io::compressionNames());
    if (!a.distance.empty()) {
        a.job.distance = a.distance == "bound" ? raster::Distance::Bound : raster::Distance::Exact;
    }
    std::optional<Progress> progress;
    if (printer) {
        progress.emplace("rasterize " + a.job.scene);
        a.job.interrupter = &*progress;
    }
    const mpi::RasterizeResult r = mpi::rasterize(MPI_COMM_WORLD, a.job);
    if (!printer) return 0;
    progress->clearLine();
    printNotes(r.notes);
    if (a.json) {
        printJson(a, r);
        return 0;
    }
    if (a.quiet) return 0;
    std::uint64_t peak = 0;
    for (std::uint64_t m : r.rankPeakMemory) peak = std::max(peak, m);
    std::printf("%s: %llu active voxels on %d ranks, file %s, peak memory per rank up to %s, "
                "compute %.3f s, write %.3f s, total %.3f s -> %s\n",
                a.job.scene.c_str(), (unsigned long long)r.activeVoxels, r.ranks,
                util::formatBytes(double(r.fileBytes)).c_str(),
                util::formatBytes(double(peak)).c_str(), r.computeSeconds, r.writeSeconds,
                r.totalSeconds, a.job.output.c_str());
    const raster::RasterStats& st = r.stats;
    if (st.searchedDistances + st.approximateDistances > 0) {
        std::printf("  true distances: %llu voxels by foot points, %llu by the lattice search "
                    "(%llu of them approximate)\n",
                    (unsigned long long)st.localDistances,
                    (unsigned long long)(st.searchedDistances + st.approximateDistances),
                    (unsigned long long)st.approximateDistances);
    }
    if (a.perRank) {
        for (int k = 0; k < r.ranks; ++k) {
            const std::size_t i = std::size_t(k);
            std::printf("  rank %d: %llu leaves, %llu active voxels, peak memory %s\n", k,
                        (unsigned long long)(i < r.rankLeaves.size() ? r.rankLeaves[i] : 0),
                        (unsigned long long)(i < r.rankActiveVoxels.size() ? r.rankActiveVoxels[i] : 0),
                        util::formatBytes(double(r.rankPeakMemory[i])).c_str());
        }
    }
    std::fflush(stdout);
    return 0;
}

void addRasterizeMpi(CLI::App& app, Action& action)
{
    auto a = std::make_shared<RasterizeArgs>();
    Command cmd(app, "rasterize",
        "Rasterize a JSON scene over the MPI ranks into one narrow-band level set .vdb (grid "
        "'surface'): the file ivdb rasterize writes, every rank writing its part");
    cmd.add("scene", a->job.scene, "Scene file (JSON; see docs/scene-format.md)")->required();
    cmd.add("-o,--output", a->job.output, "Output .vdb file (written by all ranks into a "
            "temporary file that replaces it once all have written)", &param::kOutput)
        ->required();
    addRasterSettings(cmd, a->job, a->distance);
    addWriteOptions(cmd, a->compression, a->job.write.half);
    addQuietFlag(cmd, a->quiet);
    cmd.flag("--per-rank", a->perRank, "Also print each rank's leaves, voxels and peak memory");
    cmd.flag("--json", a->json, "Print the summary as JSON, with every rank's figures (bytes)");
    cmd.onRun(action, [a]() { return runRasterize(*a); });
}

} // namespace

} // namespace ivdb::cli

int main(int argc, char** argv)
{
    int provided = 0;
    MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
    // Each rank on its share of its machine's cores (--threads lowers it further).
    const ivdb::mpi::ThreadShare share = ivdb::mpi::threadShare(MPI_COMM_WORLD);
    int code = 0;
    {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism,
                                  std::size_t(share.threads));
        const int rank = ivdb::cli::worldRank();
        if (rank == 0 && share.boundCores < share.cores / share.ranksHere) {
            // Open MPI binds each of up to two ranks to one core unless told otherwise.
            std::fprintf(stderr, "ivdb-mpi: note: mpirun bound each rank to %d of this machine's "
                         "%d cores (%d ranks here): add --bind-to none to give each rank its "
                         "share of them\n", share.boundCores, share.cores, share.ranksHere);
        }
        ivdb::cli::Program program;
        program.name = "ivdb-mpi";
        program.description = "ivdb-mpi: ivdb's rasterizing over MPI ranks, into one .vdb file "
                              "(run as mpirun -np N ivdb-mpi COMMAND ...)";
        program.commandList = "rasterize";
        program.addCommands = [](CLI::App& app, ivdb::cli::Action& action) {
            ivdb::cli::addRasterizeMpi(app, action);
        };
        program.printsErrors = [rank] { return rank == 0; };
        program.handlesSignals = rank == 0;
        code = ivdb::cli::run(argc, argv, program);
    }
    // Done (and any error printed): when a rank exits non-zero, mpirun stops the others, which
    // may still be finishing; they end silently.
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) std::signal(sig, SIG_DFL);
    // Every rank agrees on the exit code: the worst.
    int worst = code;
    MPI_Allreduce(&code, &worst, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    MPI_Finalize();
    return worst;
}
