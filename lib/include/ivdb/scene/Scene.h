// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>

#include <optional>
#include <stdexcept>
#include <string>

namespace ivdb::scene {

/// @brief A scene file that cannot be used: the message names the file, the JSON path of the
/// field (`shape.children[2].radius`), the bad value and what would fix it.
class SceneError: public std::runtime_error
{
public:
    using std::runtime_error::runtime_error;
};

/// @brief A parsed scene: the implicit shape and how to rasterize it.
struct Scene
{
    implicit::Implicit::Ptr shape;
    /// World units per voxel; unset when the file leaves it to the command line.
    std::optional<double> voxelSize;
    /// Narrow-band half width in voxels.
    double halfWidth = 3.0;
    /// Optional clipping box in world units (required for unbounded shapes).
    std::optional<implicit::BBoxd> bounds;
    /// "distance": "bound": store CSG of exact distances as it is (raster::Distance::Bound).
    bool distanceBound = false;
    /// The scene's JSON text, compact, for the output's metadata.
    std::string json;
};

/// @brief Parse a scene from JSON text; @a origin names it in error messages (a file path).
/// @throw SceneError on any invalid content
Scene parseScene(const std::string& text, const std::string& origin);

/// @brief Read and parse a scene file.
/// @throw SceneError if the file cannot be read or its content is invalid
Scene loadScene(const std::string& path);

} // namespace ivdb::scene
