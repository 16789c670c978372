// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/util/Interrupt.h>

#include <openvdb/openvdb.h>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace ivdb::jobs {

/// @brief Rasterizer settings for a scene: its voxel size, half width, bounds and distance mode,
/// with @a voxelSize and @a halfWidth (when set) in place of the file's.
/// @param scenePath  the scene's file, named in messages
/// @throw ParamError (parameter "voxel_size" or "half_width") for a bad value, or a voxel size
/// neither the scene nor @a voxelSize gives
raster::RasterSettings sceneSettings(const scene::Scene& scene, const std::string& scenePath,
                                     std::optional<double> voxelSize = std::nullopt,
                                     std::optional<double> halfWidth = std::nullopt);

/// @brief What rasterize() does: a scene file into a narrow-band level set.
struct RasterizeOptions
{
    std::string scene;                     ///< the scene file (JSON)
    std::string output;                    ///< the .vdb written atomically; empty: none
    std::optional<double> voxelSize;       ///< in place of the scene's voxel_size
    std::optional<double> halfWidth;       ///< in place of the scene's half_width
    raster::Sampling sampling = raster::Sampling::Sparse;
    std::optional<raster::Distance> distance; ///< in place of the scene's distance
    bool fog = false;                      ///< also a `density` fog volume
    io::WriteOptions write;                ///< compression and half floats on disk
    util::Interrupter* interrupter = nullptr; ///< progress and cancellation (may be null)
};

struct RasterizeResult
{
    openvdb::FloatGrid::Ptr surface;  ///< the level set `surface`
    openvdb::FloatGrid::Ptr density;  ///< the fog volume, or null
    raster::RasterSettings settings;  ///< as used
    double computeSeconds = 0.0;      ///< reading the scene and rasterizing
    double totalSeconds = 0.0;        ///< everything, writing included
    std::uint64_t fileBytes = 0;      ///< the output's size (0 without output)
    std::uint64_t activeVoxels = 0;   ///< the surface's (kept when its grid is not)
    std::uint64_t gridBytes = 0;      ///< the surface's memory (kept when its grid is not)
    raster::RasterStats stats;        ///< how true distances were found (shapes not exact SDFs)
    std::vector<std::string> notes;   ///< the scene's: open meshes, rebuilt .vdb inputs
};

/// @brief Rasterize a scene file into a level set (and a fog volume), stamped with the scene as
/// rasterized (`ivdb_scene`, the overrides applied) and written atomically to the output.
/// @throw scene::SceneError for a bad scene; ParamError for a bad setting; openvdb::IoError for
/// an output that cannot be written (checked before the work); openvdb::RuntimeError when the
/// surface has no voxel at the voxel size, memory would not suffice, or on interruption.
/// Nothing is written on any error. A keyed (animated) scene is refused: its frames are
/// rasterized by rasterizeSequence().
RasterizeResult rasterize(const RasterizeOptions& options);

/// @brief The scene of @a options (at @a frame of a keyed scene; unset: not a frame of a
/// sequence), its overrides checked first since mesh and vdb nodes are built at them;
/// @a readInputs false only checks that those nodes' files exist.
/// @throw ParamError for a bad override; scene::SceneError for a bad scene
scene::Scene loadRasterScene(const RasterizeOptions& options,
                             std::optional<double> frame = std::nullopt, bool readInputs = true);

/// @brief The settings rasterize() rasterizes @a scene with: sceneSettings() with the options'
/// sampling, distance mode and interrupter.
raster::RasterSettings rasterSettings(const scene::Scene& scene, const RasterizeOptions& options);

/// @brief Run @a step (rasterizing the scene of @a options) with rasterize()'s errors: a
/// ParamError for a value the options did not give becomes the scene file's SceneError, named
/// by its key; the shape's own problems (unbounded, too large) are the scene file's.
void withSceneErrors(const RasterizeOptions& options, const std::function<void()>& step);

/// @brief rasterize()'s error for a keyed (animated) scene, whose frames rasterizeSequence()
/// makes: a ParamError (parameter "frames") asking for them.
[[noreturn]] void throwAnimated(const RasterizeOptions& options);

/// @brief rasterize()'s error for a surface without voxels at the settings' voxel size.
[[noreturn]] void throwNoVoxels(const RasterizeOptions& options,
                                const raster::RasterSettings& settings,
                                std::optional<int> frame = std::nullopt);

/// @brief The metadata rasterize() gives its level set: ivdb's stamp (io::stampGrid, the scene
/// file as source), the scene as rasterized (`ivdb_scene`: the overrides applied), the sampling
/// (`ivdb_sampling`) and, for a frame of a sequence, `ivdb_frame`.
void stampRaster(openvdb::GridBase& grid, const RasterizeOptions& options, const scene::Scene& scene,
                 const raster::RasterSettings& settings, std::optional<int> frame = std::nullopt);

/// @brief One frame of a sequence, as rasterizeSequence() reports it.
struct FrameReport
{
    int frame = 0;
    std::string output;          ///< the frame's file
    bool skipped = false;        ///< resumed: the file already held a whole frame
    std::size_t index = 0;       ///< its place in the sequence, from 0
    std::size_t count = 0;       ///< the sequence's number of frames
    int rank = 0;                ///< the rank that made it, when ranks share the sequence (mpi)
    std::uint64_t peakMemory = 0; ///< its maker's peak resident memory (bytes) when it was done
    /// No grids when skipped, nor when written to a file: a sequence with an output keeps
    /// only the frames being made in memory (read a frame's grid back from its file).
    RasterizeResult result;
};

/// @brief What rasterizeSequence() does: the frames of a keyed scene, one .vdb each.
struct SequenceOptions
{
    /// The scene and settings of every frame; its output is the name pattern, where each run
    /// of `#` becomes the zero-padded frame number (scene::frameFileName).
    RasterizeOptions base;
    std::optional<scene::FrameRange> frames; ///< default: the scene's "frames"
    bool resume = false;                     ///< skip frames whose file is already a whole frame
    /// Frames made at once; 0: as many as there are threads, while that many of the first
    /// frame's peak memory fits util::memoryBudget() (docs/performance.md#sequences).
    int parallelFrames = 0;
    /// Called after each frame is written (or skipped), in frame order (in the order frames
    /// finish with nextFrame).
    std::function<void(const FrameReport&)> onFrame;
    /// When set, where the frames come from (processes sharing a sequence: ivdb::mpi's ranks):
    /// called one call at a time whenever a frame may start, it returns the index (into
    /// sequenceFrames()) of the next frame to make, or none when there are no more. Unset:
    /// every frame in order.
    std::function<std::optional<std::size_t>()> nextFrame;
    /// When set, the frames of the sequence finished so far, by every process sharing it (for
    /// the one progress percentage); unset: this process's.
    std::function<std::size_t()> framesDone;
};

struct SequenceResult
{
    std::size_t written = 0, skipped = 0;
    double totalSeconds = 0.0;
};

/// @brief The frames @a options make, in order, after checking that the scene is keyed, that
/// several frames go to distinct files, that the first frame's output can be written and that
/// every frame's scene and settings are valid (no file is read or written).
/// @throw as rasterizeSequence() does before its first frame
std::vector<int> sequenceFrames(const SequenceOptions& options);

/// @brief True if @a path already holds a whole frame: a .vdb that reads whole with a `surface`
/// level set (what `resume` skips).
bool isWholeFrame(const std::string& path);

/// @brief Rasterize the frames of a keyed scene (docs/scene-format.md#animation) into a .vdb
/// sequence: the first frame alone, then several frames at once (each on the threads it gets),
/// each file written atomically.
/// @details Every frame's scene and settings are checked before the first file is written. The
/// interrupter sees one percentage across the whole sequence; on interruption the frames
/// already written stay whole and the frame being made is not written.
/// @throw ParamError (parameter "frames") for a range the scene does not animate: a scene
/// without keyed values, no range given nor in the scene; (parameter "output") for several
/// frames and an output name without `#`; (parameter "parallel_frames") for a negative count;
/// the errors of rasterize() for any frame
SequenceResult rasterizeSequence(const SequenceOptions& options);

} // namespace ivdb::jobs
