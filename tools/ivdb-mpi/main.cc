// SPDX-License-Identifier: Apache-2.0
// ivdb-mpi: ivdb's commands over MPI ranks (`mpirun -np N ivdb-mpi rasterize ...`), each rank on
// its share of its machine's cores, writing one .vdb file together. Parsing, printing and error
// handling are ivdb's (tools/ivdb/Cli.h); only rank 0 prints.
#include "../HugePages.h"
#include "../ivdb/Cli.h"

#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Rasterize.h>
#include <ivdb/mpi/Combine.h>
#include <ivdb/mpi/Differentiate.h>
#include <ivdb/mpi/Rasterize.h>
#include <ivdb/util/System.h>

#include <mpi.h>
#include <nlohmann/json.hpp>
#include <tbb/global_control.h>

#include <csignal>
#include <cstdio>
#include <memory>
#include <optional>

#include <unistd.h>

namespace ivdb::cli {

namespace {

int worldRank()
{
    int rank = 0;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    return rank;
}

/// A column of --json's per-rank list: its name and one figure per rank.
using RankColumn = std::pair<const char*, const std::vector<std::uint64_t>*>;

/// Print @a out as --json, with `per_rank`: for each of @a ranks ranks, its number and the
/// columns' figures.
void printJson(nlohmann::json out, int ranks, const std::vector<RankColumn>& columns)
{
    nlohmann::json rows = nlohmann::json::array();
    for (int k = 0; k < ranks; ++k) {
        nlohmann::json row{{"rank", k}};
        for (const auto& [name, values] : columns) row[name] = (*values)[std::size_t(k)];
        rows.push_back(row);
    }
    out["per_rank"] = rows;
    std::printf("%s\n", out.dump(2).c_str());
}

/// The largest of the ranks' peak memories.
std::uint64_t largest(const std::vector<std::uint64_t>& perRank)
{
    std::uint64_t peak = 0;
    for (std::uint64_t m : perRank) peak = std::max(peak, m);
    return peak;
}

struct RasterizeArgs
{
    jobs::RasterizeOptions job;
    std::string compression = "blosc", distance;
    SequenceArgs seq;
    bool quiet = false, perRank = false, json = false;
};

/// A keyed scene's frames over the ranks: a line per frame (naming the rank that made it) in
/// frame order as they finish, then the sequence's.
int runSequenceMpi(RasterizeArgs& a, Progress& progress)
{
    jobs::SequenceOptions seq = a.seq.options(a.job);
    nlohmann::json frames = nlohmann::json::array();
    std::size_t done = 0;
    seq.onFrame = [&](const jobs::FrameReport& f) {
        progress.clearLine();
        printFrame(a.job.scene, f, ++done, a.quiet || a.json,
                   f.skipped ? "" : " (rank " + std::to_string(f.rank) + ")");
        if (a.json) {
            frames.push_back({{"frame", f.frame}, {"output", f.output}, {"skipped", f.skipped},
                              {"rank", f.rank}, {"active_voxels", f.result.activeVoxels},
                              {"file_bytes", f.result.fileBytes},
                              {"compute_seconds", f.result.computeSeconds},
                              {"total_seconds", f.result.totalSeconds},
                              {"peak_memory_bytes", f.peakMemory}});
        }
    };
    const mpi::SequenceResult r = mpi::rasterizeSequence(MPI_COMM_WORLD, seq);
    if (worldRank() != 0) return 0;
    if (a.json) {
        nlohmann::json out{{"scene", a.job.scene}, {"output", a.job.output}, {"ranks", r.ranks},
                           {"frames", frames}, {"written", r.written}, {"skipped", r.skipped},
                           {"total_seconds", r.totalSeconds}};
        printJson(out, r.ranks, {{"frames", &r.rankFrames}, {"peak_memory_bytes", &r.rankPeakMemory}});
        return 0;
    }
    if (a.quiet) return 0;
    std::printf("%zu frames written, %zu skipped on %d ranks, peak memory per rank up to %s, "
                "total %.3f s\n", r.written, r.skipped, r.ranks,
                util::formatBytes(double(largest(r.rankPeakMemory))).c_str(), r.totalSeconds);
    if (a.perRank) {
        for (int k = 0; k < r.ranks; ++k) {
            const std::size_t i = std::size_t(k);
            std::printf("  rank %d: %llu frames, peak memory %s\n", k,
                        (unsigned long long)r.rankFrames[i],
                        util::formatBytes(double(r.rankPeakMemory[i])).c_str());
        }
    }
    std::fflush(stdout);
    return 0;
}

void printRasterizeJson(const RasterizeArgs& a, const mpi::RasterizeResult& r)
{
    nlohmann::json out{{"scene", a.job.scene}, {"output", a.job.output}, {"ranks", r.ranks},
                       {"leaves", r.leaves}, {"active_voxels", r.activeVoxels},
                       {"file_bytes", r.fileBytes}, {"compute_seconds", r.computeSeconds},
                       {"write_seconds", r.writeSeconds}, {"total_seconds", r.totalSeconds},
                       {"local_distances", r.stats.localDistances},
                       {"searched_distances", r.stats.searchedDistances},
                       {"approximate_distances", r.stats.approximateDistances},
                       {"swept_distances", r.stats.sweptDistances}};
    printJson(out, r.ranks, {{"leaves", &r.rankLeaves}, {"active_voxels", &r.rankActiveVoxels},
                             {"peak_memory_bytes", &r.rankPeakMemory}});
}

int runRasterize(RasterizeArgs& a)
{
    const bool printer = worldRank() == 0;
    a.job.write.compression = enumOf<io::Compression>(a.compression, io::compressionNames());
    applyDistance(a.job, a.distance);
    std::optional<Progress> progress;
    if (a.seq.wanted(a.job.output)) {
        // Every rank stops its frames on a signal (mpirun passes one to every rank).
        progress.emplace("rasterize " + a.job.scene, printer);
        a.job.interrupter = &*progress;
        return runSequenceMpi(a, *progress);
    }
    if (printer) {
        progress.emplace("rasterize " + a.job.scene);
        a.job.interrupter = &*progress;
    }
    const mpi::RasterizeResult r = mpi::rasterize(MPI_COMM_WORLD, a.job);
    if (!printer) return 0;
    progress->clearLine();
    printNotes(r.notes);
    if (a.json) {
        printRasterizeJson(a, r);
        return 0;
    }
    if (a.quiet) return 0;
    const std::uint64_t peak = largest(r.rankPeakMemory);
    std::printf("%s: %llu active voxels on %d ranks, file %s, peak memory per rank up to %s, "
                "compute %.3f s, write %.3f s, total %.3f s -> %s\n",
                a.job.scene.c_str(), (unsigned long long)r.activeVoxels, r.ranks,
                util::formatBytes(double(r.fileBytes)).c_str(),
                util::formatBytes(double(peak)).c_str(), r.computeSeconds, r.writeSeconds,
                r.totalSeconds, a.job.output.c_str());
    const raster::RasterStats& st = r.stats;
    if (st.searchedDistances + st.approximateDistances + st.sweptDistances > 0) {
        std::printf("  true distances: %llu voxels by foot points, %llu by the lattice search "
                    "(%llu of them approximate), %llu by fast sweeping\n",
                    (unsigned long long)st.localDistances,
                    (unsigned long long)(st.searchedDistances + st.approximateDistances),
                    (unsigned long long)st.approximateDistances,
                    (unsigned long long)st.sweptDistances);
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
        "'surface'): the file ivdb rasterize writes, every rank writing its part; a keyed "
        "scene's frames are handed out to the ranks, each frame's file written by one");
    cmd.add("scene", a->job.scene, "Scene file (JSON; see docs/scene-format.md)")->required();
    cmd.add("-o,--output", a->job.output, "Output .vdb file (written by all ranks into a "
            "temporary file that replaces it once all have written); for a sequence, each run of "
            "# becomes the zero-padded frame number (out_####.vdb)", &param::kOutput)
        ->required();
    addSequenceOptions(cmd, a->seq);
    addRasterSettings(cmd, a->job, a->distance);
    addFogFlag(cmd, a->job.fog);
    addWriteOptions(cmd, a->compression, a->job.write.half);
    addQuietFlag(cmd, a->quiet);
    cmd.flag("--per-rank", a->perRank, "Also print each rank's leaves, voxels and peak memory "
             "(for a sequence: frames made and peak memory)");
    cmd.flag("--json", a->json, "Print the summary as JSON, with every rank's figures (bytes)");
    cmd.onRun(action, [a]() { return runRasterize(*a); });
}

/// What the differential commands print: a summary line (or JSON) and, on request, each rank's.
struct DiffPrint
{
    bool quiet = false, perRank = false, json = false;
};

void addDiffFlags(Command& cmd, DiffPrint& p)
{
    addQuietFlag(cmd, p.quiet);
    cmd.flag("--per-rank", p.perRank, "Also print each rank's leaves, leaves read, voxels and "
             "peak memory");
    cmd.flag("--json", p.json, "Print the summary as JSON, with every rank's figures (bytes)");
}

void printDiff(const DiffPrint& p, const std::string& what, const std::string& input,
               const std::string& output, const mpi::DifferentiateResult& r)
{
    if (worldRank() != 0) return;
    if (p.json) {
        nlohmann::json out{{"input", input}, {"grid", r.gridName}, {"output", output},
                           {"ranks", r.ranks}, {"leaves", r.leaves},
                           {"active_voxels", r.activeVoxels}, {"file_bytes", r.fileBytes},
                           {"read_seconds", r.readSeconds}, {"compute_seconds", r.computeSeconds},
                           {"write_seconds", r.writeSeconds}, {"total_seconds", r.totalSeconds}};
        printJson(out, r.ranks, {{"leaves", &r.rankLeaves}, {"leaves_read", &r.rankLeavesRead},
                                 {"active_voxels", &r.rankActiveVoxels},
                                 {"peak_memory_bytes", &r.rankPeakMemory}});
        return;
    }
    if (p.quiet) return;
    const std::uint64_t peak = largest(r.rankPeakMemory);
    std::printf("%s: %s of '%s', %llu active voxels on %d ranks, file %s, peak memory per rank "
                "up to %s, read %.3f s, compute %.3f s, write %.3f s, total %.3f s -> %s\n",
                input.c_str(), what.c_str(), r.gridName.c_str(),
                (unsigned long long)r.activeVoxels, r.ranks,
                util::formatBytes(double(r.fileBytes)).c_str(),
                util::formatBytes(double(peak)).c_str(), r.readSeconds, r.computeSeconds,
                r.writeSeconds, r.totalSeconds, output.c_str());
    if (p.perRank) {
        for (int k = 0; k < r.ranks; ++k) {
            const std::size_t i = std::size_t(k);
            std::printf("  rank %d: %llu leaves (%llu read), %llu active voxels, peak memory %s\n",
                        k, (unsigned long long)r.rankLeaves[i],
                        (unsigned long long)r.rankLeavesRead[i],
                        (unsigned long long)r.rankActiveVoxels[i],
                        util::formatBytes(double(r.rankPeakMemory[i])).c_str());
        }
    }
    std::fflush(stdout);
}

struct GradientArgs
{
    jobs::GradientOptions job;
    std::string compression = "blosc";
    DiffPrint print;
};

void addGradientMpi(CLI::App& app, Action& action)
{
    auto a = std::make_shared<GradientArgs>();
    Command cmd(app, "gradient",
        "Central-difference gradient of a level set over the MPI ranks (each reads its run of "
        "leaves and their neighbours): the file ivdb gradient writes, every rank writing its part");
    addGradientOptions(cmd, a->job, a->compression);
    addDiffFlags(cmd, a->print);
    cmd.onRun(action, [a]() {
        a->job.write.compression = enumOf<io::Compression>(a->compression, io::compressionNames());
        const mpi::DifferentiateResult r = mpi::gradient(MPI_COMM_WORLD, a->job);
        printDiff(a->print, "gradient (step " + std::to_string(a->job.step) + ")", a->job.input,
                  a->job.output, r);
        return 0;
    });
}

struct CurvatureArgs
{
    jobs::CurvatureOptions job;
    std::string compression = "blosc", method = "mean";
    DiffPrint print;
};

void addCurvatureMpi(CLI::App& app, Action& action)
{
    auto a = std::make_shared<CurvatureArgs>();
    Command cmd(app, "curvature",
        "Curvature of a level set over the MPI ranks (each reads its run of leaves and their "
        "neighbours): the file ivdb curvature writes (same --method conventions), every rank "
        "writing its part");
    addCurvatureOptions(cmd, a->job, a->method, a->compression);
    addDiffFlags(cmd, a->print);
    cmd.onRun(action, [a]() {
        a->job.write.compression = enumOf<io::Compression>(a->compression, io::compressionNames());
        a->job.method = enumOf<jobs::CurvatureMethod>(a->method, jobs::curvatureMethodNames());
        const mpi::DifferentiateResult r = mpi::curvature(MPI_COMM_WORLD, a->job);
        printDiff(a->print, a->method + " curvature", a->job.input, a->job.output, r);
        return 0;
    });
}

struct CsgArgs
{
    jobs::CombineOptions job;
    std::string compression = "blosc", op;
    bool quiet = false, perRank = false, json = false;
};

/// What csg and blend print: the summary line (or JSON) and, on request, each rank's.
void printCsg(const CsgArgs& a, const mpi::CsgResult& r)
{
    if (worldRank() != 0) return;
    printNotes(r.notes, r.warnings);
    if (a.json) {
        nlohmann::json out{{"inputs", a.job.inputs}, {"output", a.job.output}, {"op", a.op},
                           {"ranks", r.ranks}, {"nodes", r.nodes}, {"leaves", r.leaves},
                           {"active_voxels", r.activeVoxels}, {"file_bytes", r.fileBytes},
                           {"read_seconds", r.readSeconds}, {"compute_seconds", r.computeSeconds},
                           {"write_seconds", r.writeSeconds}, {"total_seconds", r.totalSeconds}};
        printJson(out, r.ranks, {{"nodes", &r.rankNodes}, {"leaves_read", &r.rankLeavesRead},
                                 {"leaves", &r.rankLeaves}, {"active_voxels", &r.rankActiveVoxels},
                                 {"peak_memory_bytes", &r.rankPeakMemory}});
        return;
    }
    if (a.quiet) return;
    const std::uint64_t peak = largest(r.rankPeakMemory);
    const std::string what = combineLabel(a.op, a.job);
    std::printf("%s of %zu level sets: %llu active voxels on %d ranks, file %s, peak memory "
                "per rank up to %s, read %.3f s, %s %.3f s, write %.3f s, total %.3f s -> "
                "%s\n",
                what.c_str(), a.job.inputs.size(), (unsigned long long)r.activeVoxels, r.ranks,
                util::formatBytes(double(r.fileBytes)).c_str(),
                util::formatBytes(double(peak)).c_str(), r.readSeconds,
                a.job.p || a.job.k ? "blend" : "combine", r.computeSeconds, r.writeSeconds,
                r.totalSeconds, a.job.output.c_str());
    if (a.perRank) {
        for (int k = 0; k < r.ranks; ++k) {
            const std::size_t i = std::size_t(k);
            std::printf("  rank %d: %llu nodes of 128^3, %llu leaves read, %llu leaves, %llu "
                        "active voxels, peak memory %s\n",
                        k, (unsigned long long)r.rankNodes[i],
                        (unsigned long long)r.rankLeavesRead[i], (unsigned long long)r.rankLeaves[i],
                        (unsigned long long)r.rankActiveVoxels[i],
                        util::formatBytes(double(r.rankPeakMemory[i])).c_str());
        }
    }
    std::fflush(stdout);
}

/// The flags csg and blend share.
void addCsgFlags(Command& cmd, CsgArgs& a)
{
    addCombineInputs(cmd, a.job, a.op, a.compression);
    addFogFlag(cmd, a.job.fog);
    addQuietFlag(cmd, a.quiet);
    cmd.flag("--per-rank", a.perRank, "Also print each rank's nodes, leaves read, leaves, voxels "
             "and peak memory");
    cmd.flag("--json", a.json, "Print the summary as JSON, with every rank's figures (bytes)");
}

int runCsgMpi(CsgArgs& a)
{
    a.job.write.compression = enumOf<io::Compression>(a.compression, io::compressionNames());
    a.job.op = *implicit::csgOpFromString(a.op);
    printCsg(a, mpi::csg(MPI_COMM_WORLD, a.job));
    return 0;
}

void addCsgMpi(CLI::App& app, Action& action)
{
    auto a = std::make_shared<CsgArgs>();
    Command cmd(app, "csg",
        "Sharp CSG of level sets over the MPI ranks (each reads and combines its run of 128^3 "
        "nodes): the file ivdb csg writes, every rank writing its part. The inputs must share "
        "one transform (ivdb csg resamples them)");
    addCsgFlags(cmd, *a);
    cmd.onRun(action, [a]() { return runCsgMpi(*a); });
}

void addBlendMpi(CLI::App& app, Action& action)
{
    auto a = std::make_shared<CsgArgs>();
    Command cmd(app, "blend",
        "Blended CSG of level sets over the MPI ranks (-p super-elliptic or -k smooth, as ivdb "
        "blend): the file ivdb blend writes. Each rank combines its run of 128^3 nodes sharply; "
        "rank 0 computes the blend around the crease and sends each rank its part. The inputs "
        "must share one transform (ivdb blend resamples them)");
    addCsgFlags(cmd, *a);
    addBlendOptions(cmd, a->job.p, a->job.k, a->job.tolerance);
    cmd.onRun(action, [a]() { return runCsgMpi(*a); });
}

} // namespace

} // namespace ivdb::cli

int main(int argc, char** argv)
{
    // Transparent huge pages (../HugePages.h): restart once with them, before MPI starts (the
    // launcher does this for ivdb; ranks are launched by mpirun).
    if (ivdb::tools::askForHugePages()) execv("/proc/self/exe", argv);
    int provided = 0;
    MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
    if (provided < MPI_THREAD_FUNNELED) {
        // Sequences make frames on threads of their own while the main thread calls MPI.
        if (ivdb::cli::worldRank() == 0) {
            std::fprintf(stderr, "ivdb-mpi: error: this MPI library does not support threads "
                         "(MPI_THREAD_FUNNELED); use a build of MPI that does\n");
        }
        MPI_Finalize();
        return 1;
    }
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
        program.description = "ivdb-mpi: ivdb's rasterizing, gradient, curvature, CSG and blends over MPI "
                              "ranks, into one .vdb file (run as mpirun -np N ivdb-mpi COMMAND ...)";
        program.commandList = "rasterize, gradient, curvature, csg, blend";
        program.addCommands = [](CLI::App& app, ivdb::cli::Action& action) {
            ivdb::cli::addRasterizeMpi(app, action);
            ivdb::cli::addGradientMpi(app, action);
            ivdb::cli::addCurvatureMpi(app, action);
            ivdb::cli::addCsgMpi(app, action);
            ivdb::cli::addBlendMpi(app, action);
        };
        program.printsErrors = [rank] { return rank == 0; };
        // Every rank: one being signalled outside an interruptible stretch removes the file it
        // is writing (a frame of a sequence) before it ends; only rank 0 says so.
        program.handlesSignals = true;
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
