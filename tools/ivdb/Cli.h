#pragma once

#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>

#include <openvdb/util/NullInterrupter.h>

#include <CLI/CLI.hpp>

#include <atomic>
#include <functional>
#include <memory>
#include <optional>
#include <string>

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
/// @}

/// @brief Rasterizer settings from a scene and the command line's --voxel-size and --half-width.
/// @throw std::runtime_error naming the option or the scene file when a value is missing or bad
raster::RasterSettings sceneSettings(const scene::Scene& scene, const std::string& scenePath,
                                     std::optional<double> voxelSize,
                                     std::optional<double> halfWidth);

/// @brief Progress on stderr when it is a terminal, and cancellation on Ctrl-C (SIGINT).
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

} // namespace ivdb::cli
