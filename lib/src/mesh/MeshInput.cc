// SPDX-License-Identifier: Apache-2.0
#include <ivdb/mesh/MeshInput.h>

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <openvdb/Exceptions.h>
#include <openvdb/tools/MeshToVolume.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <map>
#include <unordered_map>
#include <utility>

namespace ivdb::mesh {

namespace {

/// Vertices merged by their exact position.
struct PositionKey
{
    float x, y, z;
    bool operator==(const PositionKey& o) const { return x == o.x && y == o.y && z == o.z; }
};

struct PositionHash
{
    std::size_t operator()(const PositionKey& k) const
    {
        std::uint32_t b[3];
        static_assert(sizeof(b) == sizeof(float) * 3);
        std::memcpy(b, &k.x, 4);
        std::memcpy(b + 1, &k.y, 4);
        std::memcpy(b + 2, &k.z, 4);
        return (std::size_t(b[0]) * 73856093u) ^ (std::size_t(b[1]) * 19349663u) ^
               (std::size_t(b[2]) * 83492791u);
    }
};

} // namespace

TriangleMesh readTriangleMesh(const std::string& path)
{
    if (!std::ifstream(path, std::ios::binary)) {
        OPENVDB_THROW(openvdb::IoError, path + ": cannot open the mesh file (does it exist and is "
                      "it readable?)");
    }
    Assimp::Importer importer;
    const aiScene* scene =
        importer.ReadFile(path, aiProcess_Triangulate | aiProcess_PreTransformVertices);
    if (!scene) {
        OPENVDB_THROW(openvdb::IoError, path + ": not a mesh file Assimp can read (" +
                      std::string(importer.GetErrorString()) + "); use OBJ, PLY, STL, glTF or GLB");
    }
    TriangleMesh mesh;
    std::unordered_map<PositionKey, unsigned, PositionHash> index;
    for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
        const aiMesh* am = scene->mMeshes[m];
        std::vector<unsigned> map(am->mNumVertices);
        for (unsigned v = 0; v < am->mNumVertices; ++v) {
            const aiVector3D& p = am->mVertices[v];
            if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
                OPENVDB_THROW(openvdb::IoError, path + ": a vertex has a coordinate that is not "
                              "finite (mesh " + std::to_string(m) + ", vertex " +
                              std::to_string(v) + ")");
            }
            const PositionKey key{p.x, p.y, p.z};
            auto [it, added] = index.emplace(key, unsigned(mesh.points.size()));
            if (added) mesh.points.emplace_back(p.x, p.y, p.z);
            map[v] = it->second;
        }
        for (unsigned f = 0; f < am->mNumFaces; ++f) {
            const aiFace& face = am->mFaces[f];
            if (face.mNumIndices != 3) continue; // points and lines are not surfaces
            const openvdb::Vec3I t(map[face.mIndices[0]], map[face.mIndices[1]], map[face.mIndices[2]]);
            if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue; // collapsed by the merge
            mesh.triangles.push_back(t);
        }
    }
    if (mesh.triangles.empty()) {
        OPENVDB_THROW(openvdb::IoError, path + ": the file holds no triangles (a mesh of faces is "
                      "needed, not only points or lines)");
    }
    return mesh;
}

std::size_t openEdges(const TriangleMesh& mesh)
{
    std::map<std::pair<unsigned, unsigned>, unsigned> uses;
    for (const openvdb::Vec3I& t : mesh.triangles) {
        for (int e = 0; e < 3; ++e) {
            const unsigned a = t[e], b = t[(e + 1) % 3];
            ++uses[{std::min(a, b), std::max(a, b)}];
        }
    }
    return std::size_t(std::count_if(uses.begin(), uses.end(),
                                     [](const auto& u) { return u.second != 2; }));
}

openvdb::FloatGrid::Ptr meshDistance(const TriangleMesh& mesh, double voxelSize, double halfWidth)
{
    if (!(voxelSize > 0.0) || !(halfWidth > 0.0)) {
        OPENVDB_THROW(openvdb::ValueError, "mesh distance needs a positive voxel size and half width");
    }
    const openvdb::math::Transform::Ptr xform =
        openvdb::math::Transform::createLinearTransform(voxelSize);
    auto grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xform, mesh.points,
                                                                  mesh.triangles, float(halfWidth));
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    return grid;
}

} // namespace ivdb::mesh
