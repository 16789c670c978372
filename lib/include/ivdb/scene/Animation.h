// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <string>
#include <vector>

namespace ivdb::scene {

/// @brief Whole frames from @a start to @a end (inclusive) every @a step frames.
struct FrameRange
{
    int start = 1, end = 1, step = 1;

    /// @brief The frames in order: start, start + step, ... up to end.
    std::vector<int> frames() const;
};

/// @brief Parse `A-B[:STEP]` or `A` (whole frames, 0 <= A <= B, STEP >= 1).
/// @throw ParamError (parameter "frames") naming the text and the rule it breaks
FrameRange parseFrameRange(const std::string& text);

/// @brief True if @a pattern holds a `#`, the place of a frame number in a file name.
bool hasFrameField(const std::string& pattern);

/// @brief @a pattern with each run of `#` replaced by @a frame, zero-padded to the run's
/// length (`out_####.vdb`, 7: `out_0007.vdb`), the convention Blender and Houdini detect.
std::string frameFileName(const std::string& pattern, int frame);

/// @brief How a keyed number moves between two keys.
enum class Interpolation {
    Linear, ///< a straight line between the keys
    Smooth, ///< the cubic 3t^2 - 2t^3 from one key to the next: flat at each key
    Step    ///< the earlier key's value until the next key
};

/// @brief A keyed number or vector: values at frames, interpolated between them. Before the
/// first key and after the last the end value holds.
struct Keys
{
    std::vector<double> frames;              ///< strictly increasing
    std::vector<std::vector<double>> values; ///< one per frame, all of the same length
    Interpolation interpolation = Interpolation::Linear;

    /// @brief The value at @a frame: at a key frame exactly that key's value.
    std::vector<double> at(double frame) const;
};

} // namespace ivdb::scene
