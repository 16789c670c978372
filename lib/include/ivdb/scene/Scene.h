// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Implicit.h>
#include <ivdb/scene/Animation.h>

#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace ivdb::scene {

/// @brief A scene file that cannot be used: the message names the file, the JSON path of the
/// field (`shape.children[2].radius`), the bad value and what would fix it.
class SceneError: public std::runtime_error
{
public:
    using std::runtime_error::runtime_error;
};

/// @brief Settings given outside the scene file (a command line's) that replace the file's:
/// mesh and vdb nodes are built at the voxel size and band they give.
struct SceneOverrides
{
    std::optional<double> voxelSize;
    std::optional<double> halfWidth;
    /// The frame keyed values take (default: the file's "frames" start, else 1).
    std::optional<double> frame;
    /// False: check the scene only; mesh and vdb nodes check that their files exist but do not
    /// read them (a sequence checks every frame this way before it writes any).
    bool readInputs = true;
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
    /// "distance": "bound": store the shape's own value where it never exceeds the distance
    /// (raster::Distance::Bound).
    bool distanceBound = false;
    /// The scene's JSON text, compact, for the output's metadata.
    std::string json;
    /// What a user should know about the scene's inputs: a mesh that is not closed, a .vdb
    /// rebuilt at the scene's voxel size.
    std::vector<std::string> notes;
    /// True if some value of the file is keyed (changes from frame to frame).
    bool animated = false;
    /// The file's "frames": {"start", "end"}, if given.
    std::optional<FrameRange> frames;
    /// The frame the keyed values were resolved at.
    double frame = 1.0;
};

/// @brief Parse a scene from JSON text; @a origin names it in error messages (a file path) and
/// its folder is where the relative file names of mesh and vdb nodes start.
/// @details Mesh and vdb nodes read their files and build their level sets here, at the voxel
/// size of @a overrides or else of the scene, with a band as wide as the blends, offsets and
/// shells above them need (docs/scene-format.md#mesh). Keyed values are resolved at the frame
/// of @a overrides before any node is read (docs/scene-format.md#animation).
/// @throw SceneError on any invalid content, naming the JSON path of the field
Scene parseScene(const std::string& text, const std::string& origin,
                 const SceneOverrides& overrides = {});

/// @brief Read and parse a scene file.
/// @throw SceneError if the file cannot be read or its content is invalid
Scene loadScene(const std::string& path, const SceneOverrides& overrides = {});

} // namespace ivdb::scene
