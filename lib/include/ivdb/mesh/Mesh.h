#pragma once

#include <openvdb/openvdb.h>

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
/// @throw openvdb::ValueError for an adaptivity outside [0, 1]
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

/// @brief Write Wavefront OBJ (`v x y z [r g b]`, `f` with 1-based indices), atomically.
/// @throw openvdb::IoError naming the path
void writeObj(const std::string& path, const Mesh& mesh, const VertexData* data = nullptr);

/// @brief Write binary little-endian PLY (float x y z, uchar red green blue, float scalar,
/// faces as uchar-counted int lists), atomically.
/// @throw openvdb::IoError naming the path
void writePly(const std::string& path, const Mesh& mesh, const VertexData* data = nullptr);

} // namespace ivdb::mesh
