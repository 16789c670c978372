// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/render/Colormap.h>

#include <openvdb/openvdb.h>

#include <optional>
#include <utility>

#include <string>
#include <vector>

namespace ivdb::mesh {

/// @brief An indexed polygon mesh in world space: vertices shared between faces.
struct Mesh
{
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> triangles;
    std::vector<openvdb::Vec4I> quads;

    size_t faceCount() const { return triangles.size() + quads.size(); }
};

/// @brief The zero level set of @a grid as a mesh (openvdb::tools::volumeToMesh), with faces
/// ordered counter-clockwise seen from outside (outward normals).
/// @param adaptivity  in [0, 1]: 0 keeps every voxel's face, larger merges flat regions
/// @throw ParamError for an adaptivity outside limits::kAdaptivity
Mesh meshLevelSet(const openvdb::FloatGrid& grid, double adaptivity = 0.0);

/// @brief Signed volume enclosed by @a mesh (divergence theorem over its faces, quads split
/// into two triangles): positive for a closed mesh with outward normals.
double enclosedVolume(const Mesh& mesh);

/// @brief Arrows (a six-sided shaft and cone, 24 triangles) from each point of @a bases along
/// @a vectors scaled by @a length: the tip is at base + length * vector; the shaft's radius is
/// 4% and the head's 10% of the arrow's length, the head a quarter of it. Zero vectors are
/// skipped. @a colors, if not null, receives one colour per vertex: the direction as
/// RGB = 0.5 n + 0.5.
Mesh arrows(const std::vector<openvdb::Vec3d>& bases, const std::vector<openvdb::Vec3d>& vectors,
            double length, std::vector<openvdb::Vec3f>* colors = nullptr);

/// @brief Optional per-vertex data for the writers: sRGB colours in [0, 1] and a scalar.
struct VertexData
{
    std::vector<openvdb::Vec3f> colors;  ///< empty, or one per point
    std::vector<float> scalars;          ///< empty, or one per point
    std::string scalarName = "value";    ///< the PLY property's name
};

/// @brief Per-vertex data from @a grid sampled (trilinearly) at each point of @a mesh: a float
/// grid's values, coloured through @a colormap over @a range (default: the sampled values'
/// range; lo + 1 if they are all equal), or a vec3s grid's magnitude, coloured by direction
/// (render::directionColor).
/// @throw ParamError (parameter "color_by") for a grid of another type
VertexData sampleVertexData(const Mesh& mesh, const openvdb::GridBase& grid,
                            const render::Colormap& colormap,
                            std::optional<std::pair<double, double>> range = std::nullopt);

/// @brief Where arrows() draws a vector grid: bases in world space and the vectors there.
struct ArrowSamples
{
    std::vector<openvdb::Vec3d> bases, vectors;
};

/// @brief The active voxels of @a field whose index coordinates are multiples of @a stride and,
/// with a @a surface level set, where |surface| < @a near voxels (of the surface).
/// @throw ParamError for a stride or near outside limits::kStride, limits::kNear
ArrowSamples sampleArrows(const openvdb::Vec3SGrid& field, const openvdb::FloatGrid* surface,
                          int stride, double near);

/// @brief writeObj() or writePly(), by @a path's extension (.obj or .ply, any case).
/// @throw ParamError (parameter "output") for another extension; openvdb::IoError naming the path
void writeMesh(const std::string& path, const Mesh& mesh, const VertexData* data = nullptr);

/// @brief Write Wavefront OBJ (`v x y z [r g b]`, `f` with 1-based indices), atomically.
/// @throw openvdb::IoError naming the path
void writeObj(const std::string& path, const Mesh& mesh, const VertexData* data = nullptr);

/// @brief Write binary little-endian PLY (float x y z, uchar red green blue, float scalar,
/// faces as uchar-counted int lists), atomically.
/// @throw openvdb::IoError naming the path
void writePly(const std::string& path, const Mesh& mesh, const VertexData* data = nullptr);

} // namespace ivdb::mesh
