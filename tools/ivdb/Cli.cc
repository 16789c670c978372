// SPDX-License-Identifier: Apache-2.0
#include "Cli.h"

#include <ivdb/Version.h>
#include <ivdb/io/AtomicFile.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Combine.h>
#include <ivdb/jobs/Differentiate.h>
#include <ivdb/jobs/Rasterize.h>
#include <ivdb/util/System.h>

#include <openvdb/openvdb.h>

#include <tbb/global_control.h>

#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <exception>
#include <iostream>

#include <unistd.h>

namespace ivdb::cli {

namespace {

// Signals. SIGINT, SIGTERM and SIGHUP end a run promptly and leave no partial output:
// - while an operation polls its interrupter (Progress, between start() and end()), the first
//   signal only sets gInterrupted; the operation stops through OpenVDB's interrupter mechanism
//   and run() returns 128 + the signal;
// - at any other moment (reading, writing, operations without an interrupter), and for a second
//   signal, the handler removes the temporary output being written and ends the process at once.
std::atomic<bool> gInterrupted{false};
volatile std::sig_atomic_t gCooperative = 0;
volatile std::sig_atomic_t gSignal = 0;

// The message an interruption prints, swapped whole (the handler reads it): two buffers so a
// new note is complete before the handler can see it.
constexpr std::size_t kNoteSize = 256;
char gNotes[2][kNoteSize] = {"ivdb: error: interrupted; nothing was written\n"};
bool gSilent = false; // another process of the run prints the errors
std::atomic<const char*> gInterruptedMessage{gNotes[0]};

[[noreturn]] void exitOnSignal(int sig)
{
    io::removePendingTemporaryFile();
    const char* msg = gInterruptedMessage.load();
    [[maybe_unused]] const ssize_t n = ::write(2, msg, std::strlen(msg));
    ::_exit(128 + sig);
}

extern "C" void onSignal(int sig)
{
    gSignal = sig;
    if (gCooperative && !gInterrupted.load()) {
        gInterrupted = true;
        return;
    }
    exitOnSignal(sig);
}

void installSignalHandlers()
{
    struct sigaction sa {};
    sa.sa_handler = onSignal;
    sigemptyset(&sa.sa_mask);
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) ::sigaction(sig, &sa, nullptr);
    // A file-size limit (ulimit -f) then fails the write with EFBIG, reported like a full disk,
    // instead of killing the process mid-file.
    std::signal(SIGXFSZ, SIG_IGN);
}

// The chosen subcommand's names for library parameters (see Command).
std::shared_ptr<std::map<std::string, std::string>> gFlags;

std::string errorMessage(const std::exception& e)
{
    if (const auto* p = dynamic_cast<const ParamError*>(&e); p && gFlags) {
        const auto it = gFlags->find(p->param());
        if (it != gFlags->end()) return p->describe(it->second);
    }
    return util::errorText(e);
}

} // namespace

Command::Command(CLI::App& app, const std::string& name, const std::string& help)
    : mApp(app.add_subcommand(name, help)), mFlags(std::make_shared<std::map<std::string, std::string>>())
{
}

std::string Command::displayName(const CLI::Option& o)
{
    return o.get_name(/*positional=*/false, /*all_options=*/false);
}

void Command::onRun(Action& action, std::function<int()> work)
{
    auto flags = mFlags;
    mApp->callback([&action, flags, work = std::move(work)]() {
        gFlags = flags;
        action = work;
    });
}

Progress::Progress(std::string label, bool shown)
    : mLabel(std::move(label)), mTerminal(shown && ::isatty(2) == 1) {}

Progress::~Progress()
{
    gCooperative = 0;
}

void Progress::start(const char*)
{
    mLastPercent = -1;
    gCooperative = 1;
}

void Progress::end()
{
    if (mTerminal && mLastPercent >= 0) std::fprintf(stderr, "\r\033[K");
    mLastPercent = -1;
    gCooperative = 0;
    // A signal that came after the operation's last poll: nothing is being written yet. (When
    // the operation is ending on an exception, run() reports the interruption instead.)
    if (gInterrupted.load() && std::uncaught_exceptions() == 0) exitOnSignal(gSignal);
}

bool Progress::wasInterrupted(int percent)
{
    int last = mLastPercent.load();
    // Only the thread that moves the percentage forward prints it.
    if (mTerminal && percent > last && mLastPercent.compare_exchange_strong(last, percent)) {
        std::fprintf(stderr, "\r%s: %3d%%", mLabel.c_str(), percent);
        std::fflush(stderr);
    }
    return gInterrupted.load();
}

void Progress::clearLine()
{
    if (mTerminal && mLastPercent.load() >= 0) std::fprintf(stderr, "\r\033[K");
    std::fflush(stderr);
}

namespace {

/// The running program's name, for the lines it prints ("ivdb", "ivdb-mpi"); run() sets it.
std::string& programName()
{
    static std::string name = "ivdb";
    return name;
}

} // namespace

void setInterruptedNote(const std::string& note)
{
    char* next = gInterruptedMessage.load() == gNotes[0] ? gNotes[1] : gNotes[0];
    if (gSilent) next[0] = '\0';
    else std::snprintf(next, kNoteSize, "%s: error: interrupted; %s\n", programName().c_str(),
                       note.c_str());
    gInterruptedMessage = next;
}

void printNotes(const std::vector<std::string>& notes, const std::vector<std::string>& warnings)
{
    for (const auto& n : notes) std::cerr << programName() << ": note: " << n << std::endl;
    for (const auto& w : warnings) std::cerr << programName() << ": warning: " << w << std::endl;
}

void addFogFlag(Command& cmd, bool& fog)
{
    cmd.flag("--fog", fog,
             "Also write a 'density' fog volume (0 outside, a ramp across the inside of the "
             "band, 1 deeper inside) so Blender renders the file as a volume");
}

void addWriteOptions(Command& cmd, std::string& compression, bool& half)
{
    cmd.add("--compression", compression,
            "How values are compressed on disk: blosc (fast, OpenVDB's default), zip (smaller; "
            "OpenVDB never zips level sets and fog volumes) or none; always with only active "
            "values stored")
        ->check(CLI::IsMember(io::compressionNames()))
        ->capture_default_str();
    cmd.flag("--half", half,
             "Store float values as 16-bit halves (smaller files, 11 significant bits; what "
             "Houdini and vdb_tool offer)");
}

void addRasterSettings(Command& cmd, jobs::RasterizeOptions& job, std::string& distance)
{
    cmd.add("--voxel-size", job.voxelSize,
            "World units per voxel (overrides the scene's voxel_size); > 0", &param::kVoxelSize);
    cmd.add("--half-width", job.halfWidth,
            "Narrow-band half width in voxels (overrides the scene's half_width, default 3); "
            "in [1, 1000]", &param::kHalfWidth);
    cmd.add("--distance", distance,
            "exact: true signed distances (shapes that are not distances are re-distanced); "
            "bound: the shape's own value stored where it never exceeds the distance (a CSG of "
            "exact distances as min / max, as OpenVDB's csg tools give it; blends, offsets, "
            "shells, scales), without re-distancing (overrides the scene's \"distance\", "
            "default exact)",
            &param::kDistance)
        ->check(CLI::IsMember({"exact", "bound"}));
}

void applyDistance(jobs::RasterizeOptions& job, const std::string& distance)
{
    if (!distance.empty()) {
        job.distance = distance == "bound" ? raster::Distance::Bound : raster::Distance::Exact;
    }
}

void addSequenceOptions(Command& cmd, SequenceArgs& seq)
{
    cmd.add("--frames", seq.frames, "Frames of a keyed scene to write, A-B[:STEP] or A (default: "
            "the scene's \"frames\"); one .vdb per frame", &param::kFrames);
    cmd.flag("--resume", seq.resume, "Skip frames whose file already reads as a whole frame");
    cmd.add("--parallel-frames", seq.parallelFrames, "Frames made at once, in [0, 1024]; 0: as "
            "many as there are threads, while their memory fits", &param::kParallelFrames)
        ->capture_default_str();
}

bool SequenceArgs::wanted(const std::string& output) const
{
    return !frames.empty() || resume || parallelFrames != 0 || scene::hasFrameField(output);
}

jobs::SequenceOptions SequenceArgs::options(const jobs::RasterizeOptions& base) const
{
    jobs::SequenceOptions seq;
    seq.base = base;
    if (!frames.empty()) seq.frames = scene::parseFrameRange(frames);
    seq.resume = resume;
    seq.parallelFrames = parallelFrames;
    return seq;
}

void printRasterSummary(const std::string& what, const jobs::RasterizeResult& r,
                        const std::string& output, std::uint64_t peakMemory)
{
    std::printf("%s: %llu active voxels, grid %s, file %s, peak memory %s, compute %.3f s, "
                "total %.3f s -> %s\n",
                what.c_str(), (unsigned long long)r.activeVoxels,
                util::formatBytes(double(r.gridBytes)).c_str(),
                util::formatBytes(double(r.fileBytes)).c_str(),
                util::formatBytes(double(peakMemory)).c_str(),
                r.computeSeconds, r.totalSeconds, output.c_str());
    const raster::RasterStats& st = r.stats;
    if (st.searchedDistances + st.approximateDistances + st.sweptDistances > 0) {
        std::printf("  true distances: %llu voxels by foot points, %llu by the lattice search "
                    "(%llu of them approximate), %llu by fast sweeping\n",
                    (unsigned long long)st.localDistances,
                    (unsigned long long)(st.searchedDistances + st.approximateDistances),
                    (unsigned long long)st.approximateDistances,
                    (unsigned long long)st.sweptDistances);
    }
    std::fflush(stdout);
}

void printFrame(const std::string& scene, const jobs::FrameReport& f, std::size_t done,
                bool quiet, const std::string& maker)
{
    printNotes(f.result.notes);
    setInterruptedNote(std::to_string(done) + " of " + std::to_string(f.count) +
                       " frames are written whole, the frames being made were not written; "
                       "--resume carries on");
    if (quiet) return;
    const std::string what = scene + " frame " + std::to_string(f.frame) + maker;
    if (f.skipped) std::printf("%s: already written, skipped -> %s\n", what.c_str(), f.output.c_str());
    else printRasterSummary(what, f.result, f.output, f.peakMemory);
}

void addGradientOptions(Command& cmd, jobs::GradientOptions& job, std::string& compression)
{
    cmd.add("input", job.input, "Input .vdb file")->required();
    cmd.add("-o,--output", job.output, "Output .vdb file (written atomically)")->required();
    cmd.add("--step", job.step,
            "Difference step K in voxels: (phi(x+K) - phi(x-K)) / (2 K dx); in [1, 20]",
            &param::kStep)
        ->capture_default_str();
    cmd.add("--grid", job.grid, "Input grid name (default: the first level set)", &param::kGrid);
    cmd.flag("--magnitude", job.magnitude, "Also write 'gradient_magnitude' (|gradient|)");
    cmd.flag("--with-input", job.withInput, "Also copy the input grid into the output file");
    addWriteOptions(cmd, compression, job.write.half);
}

void addCurvatureOptions(Command& cmd, jobs::CurvatureOptions& job, std::string& method,
                         std::string& compression)
{
    cmd.add("input", job.input, "Input .vdb file")->required();
    cmd.add("-o,--output", job.output, "Output .vdb file (written atomically)")->required();
    cmd.add("--method", method, "mean | gaussian | principal | laplacian", &param::kMethod)
        ->check(CLI::IsMember(jobs::curvatureMethodNames()))
        ->capture_default_str();
    cmd.add("--grid", job.grid, "Input grid name (default: the first level set)", &param::kGrid);
    cmd.flag("--with-input", job.withInput, "Also copy the input grid into the output file");
    addWriteOptions(cmd, compression, job.write.half);
}

void addCombineInputs(Command& cmd, jobs::CombineOptions& job, std::string& op,
                      std::string& compression)
{
    cmd.add("op", op, "union | intersection | difference")
        ->required()
        ->check(CLI::IsMember(implicit::csgOpNames()));
    cmd.add("inputs", job.inputs, "Two or more input .vdb files")->required();
    cmd.name(param::kInputs, cmd.app().get_name() + " " + "inputs");
    cmd.add("-o,--output", job.output, "Output .vdb file (written atomically)")->required();
    cmd.add("--grid", job.grid, "Grid name in every input (default: each file's first level set)",
            &param::kGrid);
    addWriteOptions(cmd, compression, job.write.half);
}

void addBlendOptions(Command& cmd, std::optional<double>& p, std::optional<double>& k,
                     double& tolerance)
{
    auto* po = cmd.add("-p", p, "Sharpness p in [0.1, 1000], 1/world units (larger is sharper)",
                       &param::kBlendP);
    auto* ko = cmd.add("-k,--smooth", k, "Smooth CSG of width k > 0, world units (instead of -p)",
                       &param::kSmoothK);
    cmd.name(param::kSmoothK, "-k");
    po->excludes(ko);
    cmd.app().parse_complete_callback([po, ko]() {
        if (po->count() + ko->count() == 0) throw CLI::RequiredError("-p (a blend) or -k (smooth CSG)");
    });
    cmd.add("--tolerance", tolerance,
            "Error allowed on the surface from the bands' limited reach, in voxels",
            &param::kTolerance)
        ->capture_default_str();
}

std::string combineLabel(const std::string& op, const jobs::CombineOptions& job)
{
    if (job.p) return "blend " + op + " p=" + util::formatNumber(*job.p);
    if (job.k) return "smooth " + op + " k=" + util::formatNumber(*job.k);
    return "csg " + op;
}

void addQuietFlag(Command& cmd, bool& quiet)
{
    cmd.flag("-q,--quiet", quiet, "Do not print the summary line");
}

std::pair<double, double> parseRange(const std::string& text)
{
    const auto comma = text.find(',');
    double lo = std::nan(""), hi = std::nan("");
    try {
        if (comma != std::string::npos) {
            size_t n1 = 0, n2 = 0;
            lo = std::stod(text.substr(0, comma), &n1);
            hi = std::stod(text.substr(comma + 1), &n2);
            if (n1 != comma || n2 != text.size() - comma - 1) lo = hi = std::nan("");
        }
    } catch (const std::exception&) {
        lo = hi = std::nan("");
    }
    if (!std::isfinite(lo) || !std::isfinite(hi)) {
        throw ParamError(param::kRange, "must be LO,HI (two finite numbers), got '" + text + "'");
    }
    if (!(lo < hi)) {
        throw ParamError(param::kRange, "needs LO < HI, got " + util::formatNumber(lo) + "," +
                                            util::formatNumber(hi));
    }
    return {lo, hi};
}

int run(int argc, char** argv, const Program& program)
{
    programName() = program.name;
    gSilent = !program.printsErrors();
    setInterruptedNote("nothing was written");
    const std::string error = program.name + ": error: ";
    try {
        if (program.handlesSignals) installSignalHandlers();
        openvdb::initialize();
        CLI::App app{program.description, program.name};
        app.require_subcommand(1);
        app.set_version_flag("--version", program.name + " " + ivdb::kVersion);
        std::optional<int> threads;
        app.add_option("--threads", threads, "Worker threads (default: all cores)")
            ->check(CLI::Validator(
                [](std::string& v) -> std::string {
                    int n = 0;
                    return CLI::detail::lexical_cast(v, n) && n >= 1
                               ? std::string()
                               : "a number of threads must be a whole number >= 1, got " + v;
                },
                "POSITIVE"));
        Action action;
        program.addCommands(app, action);
        // CLI11 reports an unknown command only as "a subcommand is required": name it.
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            if (a == "--threads") { ++i; continue; }
            if (a.rfind("-", 0) == 0) continue;
            const auto subs = app.get_subcommands([&a](const CLI::App* c) { return c->get_name() == a; });
            if (subs.empty()) {
                if (program.printsErrors()) {
                    std::cerr << error << "unknown command '" << a << "'; commands: "
                              << program.commandList << " (run '" << program.name << " --help')"
                              << std::endl;
                }
                return 2;
            }
            break;
        }
        try {
            app.parse(argc, argv);
        } catch (const CLI::CallForHelp& e) {
            return program.printsErrors() ? app.exit(e) : 0;
        } catch (const CLI::CallForAllHelp& e) {
            return program.printsErrors() ? app.exit(e) : 0;
        } catch (const CLI::CallForVersion& e) {
            return program.printsErrors() ? app.exit(e) : 0;
        } catch (const CLI::ParseError& e) {
            if (program.printsErrors()) {
                std::cerr << error << e.what() << "\nRun '" << program.name << " --help' or '"
                          << program.name << " COMMAND --help'." << std::endl;
            }
            return 2;
        }
        std::optional<tbb::global_control> limit;
        if (threads) limit.emplace(tbb::global_control::max_allowed_parallelism, size_t(*threads));
        return action ? action() : 2;
    } catch (const std::exception& e) {
        if (gInterrupted.load()) {
            std::cerr << gInterruptedMessage.load() << std::flush;
            return 128 + gSignal;
        }
        if (program.printsErrors()) std::cerr << error << errorMessage(e) << std::endl;
        return 1;
    } catch (...) {
        if (program.printsErrors()) std::cerr << error << "unknown failure" << std::endl;
        return 1;
    }
}

} // namespace ivdb::cli
