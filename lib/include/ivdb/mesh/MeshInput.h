// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <openvdb/openvdb.h>

#include <cstddef>
#include <string>
#include <vector>

namespace ivdb::mesh {

/// @brief A triangle mesh read from a file: vertices shared by position, triangles indexing them.
struct TriangleMesh
{
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> triangles;
};

/// @brief Read the triangles of every mesh in a model file (OBJ, PLY, STL, glTF/GLB and the other
/// formats Assimp reads), polygons triangulated and node transforms applied; vertices at the same
/// position are merged (STL and glTF repeat them per face or per normal). Lines and points are
/// skipped.
/// @throw openvdb::IoError naming @a path for a file that cannot be read or holds no triangles
TriangleMesh readTriangleMesh(const std::string& path);

/// @brief The number of edges not shared by exactly two triangles: 0 for a closed mesh.
std::size_t openEdges(const TriangleMesh& mesh);

/// @brief The signed distance to @a mesh as a narrow-band level set of @a halfWidth voxels on the
/// lattice of @a voxelSize (voxel (i, j, k) at (i, j, k) voxelSize): OpenVDB's meshToLevelSet.
/// @throw openvdb::ValueError for a voxel size or half width that is not positive
openvdb::FloatGrid::Ptr meshDistance(const TriangleMesh& mesh, double voxelSize, double halfWidth);

} // namespace ivdb::mesh
