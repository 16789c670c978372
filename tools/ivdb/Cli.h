// SPDX-License-Identifier: Apache-2.0
// The ivdb command line: each subcommand declares its options once (so --help cannot drift),
// parses them into a library job's options, calls the job and prints its result.
#pragma once

#include <ivdb/util/Interrupt.h>
#include <ivdb/util/Params.h>

#include <CLI/CLI.hpp>

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ivdb::jobs {
struct RasterizeOptions;
struct GradientOptions;
struct CurvatureOptions;
struct CombineOptions;
struct SequenceOptions;
struct RasterizeResult;
struct FrameReport;
}

namespace ivdb::cli {

/// @brief The work a subcommand does once its options are parsed; returns the exit code.
using Action = std::function<int()>;

/// @brief A command-line program built on this file's pieces: `ivdb`, `ivdb-mpi`.
struct Program
{
    std::string name;         ///< as errors name it: "<name>: error: ..."
    std::string description;
    /// Declares the subcommands (each sets the action when it is the one given).
    std::function<void(CLI::App&, Action&)> addCommands;
    std::string commandList;  ///< the subcommands, for the unknown-command message
    /// Print errors (false: another process of the same run prints them).
    std::function<bool()> printsErrors = [] { return true; };
    /// Handle SIGINT, SIGTERM and SIGHUP (see run()); false: the default actions (a process
    /// whose launcher stops it and reports for it).
    bool handlesSignals = true;
};

/// @brief Run @a program's command line; returns the process exit code (0 on success).
/// @details Every error is caught: it prints `NAME: error: <what>` to stderr and returns 1
/// (2 for a usage error). Nothing here exits or aborts, so tests can call it.
int run(int argc, char** argv, const Program& program);

/// @brief The `ivdb` command line (tools/ivdb/main.cc).
int run(int argc, char** argv);

/// @brief A subcommand being declared. Options that set a library parameter are declared with
/// it, so that a ParamError from the library names the option the user typed.
class Command
{
public:
    Command(CLI::App& app, const std::string& name, const std::string& help);

    CLI::App& app() { return *mApp; }

    /// @brief An option (or positional) bound to @a value that sets library parameter @a param.
    template<typename T>
    CLI::Option* add(const std::string& names, T& value, const std::string& help = "",
                     const Param* param = nullptr)
    {
        CLI::Option* o = mApp->add_option(names, value, help);
        if (param) mFlags->emplace(param->id, displayName(*o));
        return o;
    }

    /// @brief A flag bound to @a value.
    CLI::Option* flag(const std::string& names, bool& value, const std::string& help)
    {
        return mApp->add_flag(names, value, help);
    }

    /// @brief Name @a param as @a name in error messages (for parameters set by several options
    /// or parsed from one, like --camera's fov).
    void name(const Param& param, const std::string& name) { (*mFlags)[param.id] = name; }

    /// @brief Run @a work (with the parsed options) when this subcommand is the one given.
    void onRun(Action& action, std::function<int()> work);

private:
    static std::string displayName(const CLI::Option& o);

    CLI::App* mApp;
    std::shared_ptr<std::map<std::string, std::string>> mFlags;
};

/// @name Subcommands: each declares its options and sets @a action when it is chosen
/// @{
void addRasterize(CLI::App& app, Action& action);
void addInfo(CLI::App& app, Action& action);
void addGradient(CLI::App& app, Action& action);
void addCurvature(CLI::App& app, Action& action);
void addCompareGradient(CLI::App& app, Action& action);
void addCheckDistances(CLI::App& app, Action& action);
void addCsg(CLI::App& app, Action& action);
void addBlend(CLI::App& app, Action& action);
void addBench(CLI::App& app, Action& action);
void addMesh(CLI::App& app, Action& action);
void addGlyphs(CLI::App& app, Action& action);
void addRender(CLI::App& app, Action& action);
void addConvert(CLI::App& app, Action& action);
void addPlan(CLI::App& app, Action& action);
/// @}

/// @brief Progress on stderr when it is a terminal, and cancellation: between start() and end()
/// a SIGINT, SIGTERM or SIGHUP makes wasInterrupted() true (see run()).
class Progress final: public util::Interrupter
{
public:
    /// @brief Polls signals; shows a percentage on a terminal unless @a shown is false (a
    /// process whose lines another one prints).
    explicit Progress(std::string label, bool shown = true);
    ~Progress() override;
    void start(const char* name = nullptr) override;
    void end() override;
    bool wasInterrupted(int percent = -1) override;
    /// @brief Clear the progress line (on a terminal) so a summary line can be printed.
    void clearLine();

private:
    std::string mLabel;
    bool mTerminal;
    std::atomic<int> mLastPercent{-1}; // called from TBB workers at once
};

/// @brief What an interruption says was written (default "nothing was written"): a sequence
/// sets it after each frame. Read by the signal handler: set it outside long operations.
void setInterruptedNote(const std::string& note);

/// @brief Print `ivdb: warning: <what>` for each warning and `ivdb: note: <what>` for each note.
void printNotes(const std::vector<std::string>& notes, const std::vector<std::string>& warnings = {});

/// @brief The --fog flag of the commands that write a level set.
void addFogFlag(Command& cmd, bool& fog);

/// @brief --compression and --half of the commands that write a .vdb, bound to @a compression
/// (a word of io::compressionNames()) and @a half.
void addWriteOptions(Command& cmd, std::string& compression, bool& half);

/// @brief --voxel-size, --half-width and --distance of the commands that rasterize a scene
/// (`ivdb rasterize`, `ivdb-mpi rasterize`), bound to @a job and @a distance ("exact" or
/// "bound"; empty: the scene's).
void addRasterSettings(Command& cmd, jobs::RasterizeOptions& job, std::string& distance);

/// @brief Set @a job's distance mode from the --distance text addRasterSettings() bound
/// (empty: left unset, the scene's).
void applyDistance(jobs::RasterizeOptions& job, const std::string& distance);

/// @brief The options of a keyed scene's sequence (`ivdb rasterize`, `ivdb-mpi rasterize`).
struct SequenceArgs
{
    std::string frames;  ///< --frames: A-B[:STEP] or A
    bool resume = false;
    int parallelFrames = 0;

    /// @brief True if the command line asks for a sequence (or names frame files, @a output).
    bool wanted(const std::string& output) const;
    /// @brief The sequence of the scene and settings of @a base.
    jobs::SequenceOptions options(const jobs::RasterizeOptions& base) const;
};

/// @brief --frames, --resume and --parallel-frames, bound to @a seq.
void addSequenceOptions(Command& cmd, SequenceArgs& seq);

/// @brief rasterize's summary line for @a r (@a what: the scene, and the frame) written to
/// @a output, with @a peakMemory, and how true distances were found.
void printRasterSummary(const std::string& what, const jobs::RasterizeResult& r,
                        const std::string& output, std::uint64_t peakMemory);

/// @brief A sequence's frame: its notes and summary line (@a maker: who made it, appended to the
/// frame's name), and what an interruption then says (@a done frames are written whole).
void printFrame(const std::string& scene, const jobs::FrameReport& f, std::size_t done,
                bool quiet, const std::string& maker = "");

/// @brief -p, -k and --tolerance of `blend` (ivdb and ivdb-mpi): exactly one of -p and -k.
void addBlendOptions(Command& cmd, std::optional<double>& p, std::optional<double>& k,
                     double& tolerance);

/// @brief What a csg or blend summary line calls the operation @a op of @a job: "csg union",
/// "blend union p=20" or "smooth union k=0.1".
std::string combineLabel(const std::string& op, const jobs::CombineOptions& job);

/// @brief The input, output and options of `gradient` (ivdb and ivdb-mpi), bound to @a job and
/// @a compression.
void addGradientOptions(Command& cmd, jobs::GradientOptions& job, std::string& compression);

/// @brief The input, output and options of `curvature` (ivdb and ivdb-mpi), bound to @a job,
/// @a method and @a compression.
void addCurvatureOptions(Command& cmd, jobs::CurvatureOptions& job, std::string& method,
                         std::string& compression);

/// @brief The operation, inputs, output, grid and write options of `csg` and `blend` (ivdb and
/// ivdb-mpi), bound to @a job, @a op and @a compression.
void addCombineInputs(Command& cmd, jobs::CombineOptions& job, std::string& op,
                      std::string& compression);

/// @brief The -q flag of the commands that print a summary line.
void addQuietFlag(Command& cmd, bool& quiet);

/// @brief `LO,HI`: two finite numbers with LO < HI.
/// @throw ParamError (parameter "range") naming the text
std::pair<double, double> parseRange(const std::string& text);

/// @brief The word's value in @a names (the CLI checked it is one of them).
template<typename Enum>
Enum enumOf(const std::string& word, const std::vector<std::string>& names)
{
    for (size_t i = 0; i < names.size(); ++i) {
        if (names[i] == word) return static_cast<Enum>(i);
    }
    return static_cast<Enum>(0);
}

} // namespace ivdb::cli
