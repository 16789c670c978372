// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <openvdb/Exceptions.h>

#include <limits>
#include <string>

namespace ivdb {

/// @brief A parameter of a library call, as errors name it: a stable @a id (the scene file's
/// key where there is one; the CLI maps it to its --flag) and the @a label a sentence uses.
struct Param
{
    const char* id;
    const char* label;
};

/// @brief A bad value for a parameter: which one (param()), why (reason(), e.g. "must be > 0,
/// got -1") and, when the value came from a file, that file (context()).
/// @details what() reads "[context: ]label reason" (Kind::Invalid) or "[context: ]reason"
/// (Kind::Missing, where the reason says what to give). Front ends rephrase it with their own
/// name for the parameter (describe()): the CLI its --flag, the scene reader the JSON path.
class ParamError: public openvdb::ValueError
{
public:
    enum class Kind {
        Invalid, ///< the value given is out of range or malformed
        Missing  ///< no value was given where one is required
    };

    ParamError(const Param& param, std::string reason, std::string context = "",
               Kind kind = Kind::Invalid);

    const std::string& param() const noexcept { return mParam; }
    const std::string& label() const noexcept { return mLabel; }
    const std::string& reason() const noexcept { return mReason; }
    const std::string& context() const noexcept { return mContext; }
    Kind kind() const noexcept { return mKind; }

    /// @brief The message with @a name for the parameter: "[context: ]name reason" (Invalid),
    /// "[context: ]reason (name)" (Missing).
    std::string describe(const std::string& name) const;

private:
    std::string mParam, mLabel, mReason, mContext;
    Kind mKind;
};

/// @brief A numeric parameter's allowed range, in one place for every caller that checks it.
/// @details lo and hi may be +/-infinity (then only the other end is checked); a value must be
/// finite unless the range says otherwise. @a hint, if set, explains the parameter in messages.
struct Limit
{
    Param param;
    double lo, hi;
    bool loOpen = false, hiOpen = false; ///< exclude the end itself
    const char* unit = "";               ///< "voxels", "1/world units", ... or ""
    const char* hint = "";               ///< "(larger is sharper)" or ""

    bool contains(double v) const;
    /// @brief "must be in [0.1, 1000] (larger is sharper), got 2000"-style text for @a v.
    std::string reason(double v) const;
};

/// @brief Throw ParamError for @a limit unless it contains @a v.
/// @param context  the file the value came from, or empty
void check(const Limit& limit, double v, const std::string& context = "");

/// @name The parameters of the library's calls, and the ranges they accept
/// @{
namespace param {
inline constexpr Param kVoxelSize{"voxel_size", "voxel size"};
inline constexpr Param kHalfWidth{"half_width", "half width"};
inline constexpr Param kSampling{"sampling", "sampling"};
inline constexpr Param kDistance{"distance", "distance mode"};
inline constexpr Param kScene{"scene", "scene file"};
inline constexpr Param kInput{"input", "input file"};
inline constexpr Param kInputs{"inputs", "input files"};
inline constexpr Param kOutput{"output", "output file"};
inline constexpr Param kGrid{"grid", "grid"};
inline constexpr Param kStep{"step", "gradient step"};
inline constexpr Param kBlendP{"p", "blend sharpness p"};
inline constexpr Param kSmoothK{"k", "smooth width k"};
inline constexpr Param kTolerance{"tolerance", "blend tolerance"};
inline constexpr Param kAdaptivity{"adaptivity", "mesh adaptivity"};
inline constexpr Param kColorBy{"color_by", "colour grid"};
inline constexpr Param kColormap{"colormap", "colormap"};
inline constexpr Param kRange{"range", "colour range"};
inline constexpr Param kStride{"stride", "arrow stride"};
inline constexpr Param kLength{"length", "arrow length"};
inline constexpr Param kNear{"near", "surface distance for arrows"};
inline constexpr Param kImageSize{"size", "image size"};
inline constexpr Param kCamera{"camera", "camera"};
inline constexpr Param kFov{"fov", "camera field of view"};
inline constexpr Param kReps{"reps", "repetitions"};
inline constexpr Param kResolutions{"resolutions", "resolution"};
inline constexpr Param kMethod{"method", "method"};
inline constexpr Param kCompression{"compression", "compression"};
inline constexpr Param kHalf{"half", "half floats"};
inline constexpr Param kFrames{"frames", "frame range"};
inline constexpr Param kColumns{"columns", "contact sheet columns"};
inline constexpr Param kParallelFrames{"parallel_frames", "frames made at once"};
inline constexpr Param kRanks{"ranks", "number of ranks"};
inline constexpr Param kSamples{"samples", "sampled voxels"};
inline constexpr Param kDirections{"directions", "search directions"};
} // namespace param

namespace limits {
inline constexpr double kInf = std::numeric_limits<double>::infinity();
/// World units per voxel.
inline constexpr Limit kVoxelSize{param::kVoxelSize, 0.0, kInf, true, false, ""};
/// Narrow-band half width, in voxels.
inline constexpr Limit kHalfWidth{param::kHalfWidth, 1.0, 1000.0, false, false, "voxels"};
/// Central-difference step, in voxels (beyond it a stencil reads only the clamped background).
inline constexpr Limit kStep{param::kStep, 1.0, 20.0, false, false, "voxels"};
/// Blend sharpness, 1/world units: the blend reaches about ln(2)/p from the crease.
inline constexpr Limit kBlendP{param::kBlendP, 0.1, 1000.0, false, false, "",
    "(larger is sharper; the blend reaches about ln(2)/p world units from the crease)"};
/// Width of the polynomial smooth minimum, world units: it changes the sharp result only where
/// two values are within k of each other.
inline constexpr Limit kSmoothK{param::kSmoothK, 0.0, kInf, true, false, "world units",
    "(the smooth CSG differs from the sharp one only where the inputs are within k)"};
/// Error allowed on a grid blend's surface from the bands' limited reach, in voxels.
inline constexpr Limit kTolerance{param::kTolerance, 0.0, kInf, true, false, "voxels"};
/// Mesh adaptivity: 0 keeps every voxel's face, 1 merges flat regions the most.
inline constexpr Limit kAdaptivity{param::kAdaptivity, 0.0, 1.0};
/// One arrow every this many voxels along each axis.
inline constexpr Limit kStride{param::kStride, 1.0, 1000.0, false, false, "voxels"};
/// World length of an arrow per unit of the vector; 0 picks twice the stride.
inline constexpr Limit kLength{param::kLength, 0.0, kInf, false, false, "",
    "(0: twice the stride in voxels)"};
/// Arrows only where |phi| is below this many voxels.
inline constexpr Limit kNear{param::kNear, 0.0, kInf, true, false, "voxels"};
/// Image width and height, pixels.
inline constexpr Limit kImageSide{param::kImageSize, 1.0, 16384.0, false, false, "pixels"};
/// Ranks (processes) a rasterization is split over.
inline constexpr Limit kRanks{param::kRanks, 1.0, 100000.0};
/// Tiles across a contact sheet, and tiles in one.
inline constexpr Limit kColumns{param::kColumns, 1.0, 64.0};
inline constexpr Limit kSheetTiles{param::kFrames, 1.0, 1024.0, false, false, "frames"};
/// Frames of a sequence made at once (0: chosen from the threads and memory).
inline constexpr Limit kParallelFrames{param::kParallelFrames, 0.0, 1024.0, false, false, "", "(0: automatic)"};
/// Vertical field of view, degrees.
inline constexpr Limit kFov{param::kFov, 0.0, 180.0, true, true, "degrees"};
/// Voxels a distance check samples.
inline constexpr Limit kSamples{param::kSamples, 1.0, 1e7};
/// Points on each sphere of a brute-force surface search.
inline constexpr Limit kDirections{param::kDirections, 1.0, 1e6};
/// Runs per benchmark measurement.
inline constexpr Limit kReps{param::kReps, 1.0, 100.0};
/// Voxels across a benchmark scene's largest side.
inline constexpr Limit kResolution{param::kResolutions, 8.0, 4096.0, false, false, "voxels across"};
} // namespace limits
/// @}

} // namespace ivdb
