#pragma once

#include <ivdb/ops/Csg.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>

#include <openvdb/util/NullInterrupter.h>

#include <CLI/CLI.hpp>

#include <atomic>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace ivdb::cli {

/// @brief Run the `ivdb` command line; returns the process exit code (0 on success).
/// @details Every error is caught: it prints `ivdb: error: <what>` to stderr and returns 1
/// (2 for a usage error). Nothing here exits or aborts, so tests can call it.
int run(int argc, char** argv);

/// @brief The work a subcommand does once its options are parsed; returns the exit code.
using Action = std::function<int()>;

/// @name Subcommands: each declares its options once (so --help cannot drift) and sets @a action
/// @{
void addRasterize(CLI::App& app, Action& action);
void addInfo(CLI::App& app, Action& action);
void addGradient(CLI::App& app, Action& action);
void addCurvature(CLI::App& app, Action& action);
void addCompareGradient(CLI::App& app, Action& action);
void addCsg(CLI::App& app, Action& action);
void addBlend(CLI::App& app, Action& action);
void addBench(CLI::App& app, Action& action);
void addMesh(CLI::App& app, Action& action);
void addGlyphs(CLI::App& app, Action& action);
void addRender(CLI::App& app, Action& action);
/// @}

/// @brief Rasterizer settings from a scene and the command line's --voxel-size and --half-width.
/// @throw std::runtime_error naming the option or the scene file when a value is missing or bad
raster::RasterSettings sceneSettings(const scene::Scene& scene, const std::string& scenePath,
                                     std::optional<double> voxelSize,
                                     std::optional<double> halfWidth);

/// @brief Progress on stderr when it is a terminal, and cancellation: between start() and end()
/// a SIGINT, SIGTERM or SIGHUP makes wasInterrupted() true (see run()).
class Progress final: public openvdb::util::NullInterrupter
{
public:
    explicit Progress(std::string label);
    ~Progress() override;
    void start(const char* name = nullptr) override;
    void end() override;
    bool wasInterrupted(int percent = -1) override;

private:
    std::string mLabel;
    bool mTerminal;
    std::atomic<int> mLastPercent{-1}; // called from TBB workers at once
};

/// @brief Print a warning line `ivdb: warning: <what>` on stderr.
void warn(const std::string& what);

/// @brief The level set @a grid (or the first level set) of the .vdb file @a path, checked to be
/// a scalar float level set with cubic voxels.
/// @throw openvdb::Exception naming the file, the grid and what to pick instead
openvdb::FloatGrid::Ptr readLevelSet(const std::string& path, const std::string& grid);

/// @brief Stamp @a grid with `ivdb_version` and `ivdb_source` (what made it).
void stampGrid(openvdb::GridBase& grid, const std::string& source);

/// @brief {@a surface}, plus a `density` fog volume made from it when @a fog (--fog), stamped
/// like @a surface.
openvdb::GridCPtrVec withFog(const openvdb::FloatGrid::Ptr& surface, bool fog);

/// @brief The --fog flag of the commands that write a level set.
void addFogFlag(CLI::App& cmd, bool& fog);

/// @brief Write @a grids atomically to @a path with the file's `creator` metadata.
void writeOutput(const std::string& path, const openvdb::GridCPtrVec& grids);

/// @brief "union" | "intersection" | "difference" (the CLI checked the word) as an operation.
ops::CsgOp csgOp(const std::string& word);

/// @brief `--range LO,HI`: two finite numbers with LO < HI.
/// @throw std::runtime_error naming --range and the text
std::pair<double, double> parseRange(const std::string& text);

/// @brief The grid of `--color-by FILE.vdb[:GRID]` (a path that exists is taken whole; without
/// GRID the file's first grid), checked to be float (scalar) or vec3s (vector). A vector grid is
/// coloured by direction, so @a withRange or @a withColormap (given explicitly) is refused.
/// @throw std::runtime_error or openvdb::Exception naming the file and grid
openvdb::GridBase::Ptr readColorGrid(const std::string& spec, bool withRange, bool withColormap);

/// @brief Print each note as `ivdb: note: ...` on stderr.
void printNotes(const std::vector<std::string>& notes);

} // namespace ivdb::cli
