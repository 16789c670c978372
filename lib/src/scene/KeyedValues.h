// SPDX-License-Identifier: Apache-2.0
// Keyed values in scene files, resolved to plain numbers for one frame before any node is read.
#pragma once

#include <ivdb/scene/Animation.h>

#include <nlohmann/json.hpp>

#include <optional>
#include <string>

namespace ivdb::scene::detail {

/// @brief A JSON value as error messages quote it: its text, cut to 60 characters.
inline std::string brief(const nlohmann::json& v)
{
    std::string s = v.dump();
    if (s.size() > 60) s = s.substr(0, 57) + "...";
    return s;
}

/// What the keyed values of a scene file said.
struct Animation
{
    bool animated = false;            ///< some value is keyed
    std::optional<FrameRange> frames; ///< the file's "frames", if given
    double frame = 1.0;               ///< the frame resolved
};

/// @brief Replace every keyed value of @a scene (`{"keys": ..., "interpolation": ...}`) by its
/// value at @a frame (default: the file's start frame, else 1), and take out the top-level
/// "frames". Every keyed value is checked, whatever the frame.
/// @throw SceneError naming @a origin and the JSON path of the bad field
Animation resolveKeyedValues(nlohmann::json& scene, std::optional<double> frame,
                             const std::string& origin);

} // namespace ivdb::scene::detail
