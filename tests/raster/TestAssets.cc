// SPDX-License-Identifier: Apache-2.0
// Meshes and .vdb files as scene shapes ("mesh" and "vdb" nodes): against closed forms (a box's
// and a sphere's distance), OpenVDB's own meshToLevelSet, the same mesh in every format (files
// written by Assimp's exporter), the analytic scene they stand for, and bad inputs.
#include <ivdb/implicit/GridShape.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/mesh/MeshInput.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/raster/Partition.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>

#include <assimp/Exporter.hpp>
#include <assimp/Importer.hpp>
#include <assimp/scene.h>

#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/MeshToVolume.h>

#include <gtest/gtest.h>

#include "../TempDirTest.h"

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <unistd.h>
#include <vector>

using namespace ivdb;
using implicit::Vec3d;
namespace fs = std::filesystem;

namespace {

class TestAssets: public ivdb::test::TempDirTest
{
protected:
    TestAssets(): TempDirTest("assets") {}

    /// A scene file in the test folder holding @a shape (JSON), at voxel size @a dx.
    scene::Scene scene(const std::string& shape, double dx) const
    {
        std::ostringstream os;
        os << R"({"voxel_size": )" << dx << R"(, "shape": )" << shape << "}";
        std::ofstream(path("scene.json")) << os.str();
        return scene::loadScene(path("scene.json"));
    }
};

using Triangles = std::vector<std::array<Vec3d, 3>>;

/// An OBJ of @a tris, positions with 9 significant digits (floats read back exactly).
void writeObj(const std::string& file, const std::vector<openvdb::Vec3s>& points,
              const std::vector<openvdb::Vec3I>& tris)
{
    std::ofstream out(file);
    char line[128];
    for (const auto& p : points) {
        std::snprintf(line, sizeof line, "v %.9g %.9g %.9g\n", p[0], p[1], p[2]);
        out << line;
    }
    for (const auto& t : tris) out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
}

/// The 12 triangles of the box [lo, hi].
void boxMesh(const Vec3d& lo, const Vec3d& hi, std::vector<openvdb::Vec3s>& points,
             std::vector<openvdb::Vec3I>& tris, bool openTop = false)
{
    for (int i = 0; i < 8; ++i) {
        points.emplace_back(float(i & 1 ? hi[0] : lo[0]), float(i & 2 ? hi[1] : lo[1]),
                            float(i & 4 ? hi[2] : lo[2]));
    }
    const unsigned quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                  {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (int q = 0; q < 6; ++q) {
        if (openTop && q == 1) continue; // the face at z = hi
        tris.emplace_back(quads[q][0], quads[q][1], quads[q][2]);
        tris.emplace_back(quads[q][0], quads[q][2], quads[q][3]);
    }
}

/// An icosphere of radius @a r: an icosahedron subdivided @a levels times, projected.
void icosphere(double r, int levels, std::vector<openvdb::Vec3s>& points,
               std::vector<openvdb::Vec3I>& tris)
{
    const double t = (1.0 + std::sqrt(5.0)) / 2.0;
    std::vector<Vec3d> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                            {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
    std::vector<openvdb::Vec3I> f = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11},
        {1, 5, 9}, {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2},
        {3, 2, 6}, {3, 6, 8}, {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
    for (auto& p : v) p.normalize();
    for (int l = 0; l < levels; ++l) {
        std::map<std::pair<unsigned, unsigned>, unsigned> mid;
        auto middle = [&](unsigned a, unsigned b) {
            const auto key = std::make_pair(std::min(a, b), std::max(a, b));
            auto it = mid.find(key);
            if (it != mid.end()) return it->second;
            v.push_back((v[a] + v[b]).unit());
            return mid[key] = unsigned(v.size() - 1);
        };
        std::vector<openvdb::Vec3I> next;
        for (const auto& tri : f) {
            const unsigned a = middle(tri[0], tri[1]), b = middle(tri[1], tri[2]),
                           c = middle(tri[2], tri[0]);
            next.insert(next.end(), {{tri[0], a, c}, {tri[1], b, a}, {tri[2], c, b}, {a, b, c}});
        }
        f.swap(next);
    }
    for (const auto& p : v) points.emplace_back(openvdb::Vec3s(p * r));
    tris = f;
}

double boxDistance(const Vec3d& p, const Vec3d& lo, const Vec3d& hi)
{
    Vec3d q;
    bool inside = true;
    double face = 1e30;
    for (int i = 0; i < 3; ++i) {
        q[i] = std::min(hi[i], std::max(lo[i], p[i]));
        inside = inside && p[i] > lo[i] && p[i] < hi[i];
        face = std::min({face, p[i] - lo[i], hi[i] - p[i]});
    }
    return inside ? -face : (p - q).length();
}

raster::RasterSettings settings(const scene::Scene& sc)
{
    raster::RasterSettings s;
    s.voxelSize = *sc.voxelSize;
    s.halfWidth = sc.halfWidth;
    return s;
}

} // namespace

TEST_F(TestAssets, BoxMeshIsTheBoxDistance)
{
    const double dx = 0.01;
    const Vec3d lo(-0.303, -0.207, -0.152), hi(0.296, 0.198, 0.249);
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> tris;
    boxMesh(lo, hi, points, tris);
    writeObj(path("box.obj"), points, tris);
    const scene::Scene sc = scene(R"({"type": "mesh", "file": "box.obj"})", dx);
    EXPECT_TRUE(sc.notes.empty());
    auto g = raster::rasterize(sc.shape, settings(sc));
    // Every active voxel is the box's distance (the float corners' box), and the band is where
    // that distance is below the half width.
    // Voxels whose nearest box point is on a face, and those near an edge or a corner (beyond
    // two faces outside; inside, within the band of two faces), where OpenVDB's mesh-to-volume
    // is not exact.
    const Vec3d flo(points[0]), fhi(points[7]);
    std::size_t n = 0, off = 0, faces = 0;
    double worst = 0.0, worstEdges = 0.0;
    for (auto it = g->cbeginValueOn(); it; ++it, ++n) {
        const openvdb::Coord c = it.getCoord();
        const Vec3d p = Vec3d(c.x(), c.y(), c.z()) * dx;
        const double d = boxDistance(p, flo, fhi);
        int beyond = 0, near = 0;
        for (int a = 0; a < 3; ++a) {
            beyond += p[a] < flo[a] || p[a] > fhi[a];
            near += std::min(std::abs(p[a] - flo[a]), std::abs(p[a] - fhi[a])) < 3.0 * dx;
        }
        const double err = std::abs(*it - d) / dx;
        if (beyond >= 2 || (d < 0.0 && near >= 2)) {
            worstEdges = std::max(worstEdges, err);
            continue;
        }
        ++faces;
        worst = std::max(worst, err);
        if (err > 0.05) ++off;
    }
    std::printf("12-triangle box mesh: %zu active voxels, worst error %.2g voxel at the %zu by "
                "faces, %.2g near edges and corners\n", n, worst, faces, worstEdges);
    EXPECT_GT(faces, 10000u);
    EXPECT_EQ(off, 0u) << "worst " << worst << " voxel";
    EXPECT_LE(worstEdges, 0.2);
    EXPECT_EQ(sc.shape->typeName(), "mesh");
}

/// The rotation about x, then y, then z (fixed axes) by @a deg degrees, written out (the scene
/// format's rotate_deg), applied to @a p.
Vec3d rotated(const Vec3d& deg, const Vec3d& p)
{
    Vec3d q = p;
    for (int a = 0; a < 3; ++a) {
        const double c = std::cos(deg[a] * M_PI / 180.0), s = std::sin(deg[a] * M_PI / 180.0);
        const int i = (a + 1) % 3, j = (a + 2) % 3; // the plane the axis a turns
        const double qi = c * q[i] - s * q[j], qj = s * q[i] + c * q[j];
        q[i] = qi;
        q[j] = qj;
    }
    return q;
}

TEST_F(TestAssets, MovedMeshIsTheMeshOfTheMovedVertices)
{
    // A box mesh under two transforms (a non-uniform scale, then a rotation and a translation):
    // its vertices move, and the grid is built on the scene's lattice. Against OpenVDB's
    // meshToLevelSet of the vertices moved here, and against the moved box's distance in closed
    // form. Sampled through the maps instead (the grid built in the mesh's frame, interpolated,
    // its edges left to the smooth iteration under the scale), 13,024 voxels were over 0.05
    // voxel off (up to 1.13) and 1,794 band voxels were missing.
    const double dx = 0.01;
    const Vec3d half(0.5), scale(1.5, 1.0, 0.8), deg(10.0, 20.0, 30.0), t(0.1, 0.0, 0.0);
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> tris;
    boxMesh(-half, half, points, tris);
    writeObj(path("cube.obj"), points, tris);
    const scene::Scene sc = scene(R"({"type": "transform", "rotate_deg": [10, 20, 30],
        "translate": [0.1, 0, 0], "child": {"type": "transform", "scale": [1.5, 1, 0.8],
        "child": {"type": "mesh", "file": "cube.obj"}}})", dx);
    EXPECT_TRUE(sc.notes.empty());
    EXPECT_EQ(sc.shape->typeName(), "mesh");
    auto g = raster::rasterize(sc.shape, settings(sc));

    std::vector<openvdb::Vec3s> moved;
    for (const auto& p : points) {
        const Vec3d q(p[0] * scale[0], p[1] * scale[1], p[2] * scale[2]);
        moved.emplace_back(rotated(deg, q) + t);
    }
    auto ref = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(
        *openvdb::math::Transform::createLinearTransform(dx), moved, tris, 3.0f);
    EXPECT_EQ(g->activeVoxelCount(), ref->activeVoxelCount());
    auto acc = ref->getConstAccessor();
    std::size_t missing = 0, faces = 0;
    double worst = 0.0, worstBox = 0.0, worstOuter = 0.0;
    for (auto it = g->cbeginValueOn(); it; ++it) {
        float v;
        if (!acc.probeValue(it.getCoord(), v)) {
            ++missing;
            continue;
        }
        worst = std::max(worst, std::abs(double(v) - *it) / dx);
        // The moved box's distance: in its rigid frame (translation and rotation undone, z's
        // first) the box of half sides S/2. Voxels nearest a face only, as in
        // BoxMeshIsTheBoxDistance (meshToLevelSet is not exact near edges and corners).
        const openvdb::Coord c = it.getCoord();
        Vec3d p = Vec3d(c.x(), c.y(), c.z()) * dx - t;
        p = rotated(Vec3d(-deg[0], 0.0, 0.0),
                    rotated(Vec3d(0.0, -deg[1], 0.0), rotated(Vec3d(0.0, 0.0, -deg[2]), p)));
        const Vec3d h(half[0] * scale[0], half[1] * scale[1], half[2] * scale[2]);
        const double d = boxDistance(p, -h, h);
        int beyond = 0, near = 0;
        for (int a = 0; a < 3; ++a) {
            beyond += std::abs(p[a]) > h[a];
            near += h[a] - std::abs(p[a]) < 3.0 * dx;
        }
        if (beyond >= 2 || (d < 0.0 && near >= 2)) continue;
        // Two voxels from a face or more (the band's outer voxels), meshToLevelSet's values of
        // a face that is not along the lattice's axes are up to 0.14 voxel off (not so for the
        // axis-aligned box above); ours are its values, so those are checked apart.
        const double err = std::abs(*it - d) / dx;
        if (std::abs(d) >= 2.0 * dx) {
            worstOuter = std::max(worstOuter, err);
            continue;
        }
        ++faces;
        worstBox = std::max(worstBox, err);
    }
    std::printf("moved box mesh: %zu active voxels (meshToLevelSet of the moved vertices: %zu), "
                "worst difference %.2g voxel; the moved box's distance within %.2g voxel at the "
                "%zu within two voxels of a face (%.2g beyond)\n", size_t(g->activeVoxelCount()),
                size_t(ref->activeVoxelCount()), worst, worstBox, faces, worstOuter);
    EXPECT_EQ(missing, 0u);
    EXPECT_LE(worst, 1e-5); // the vertices' float rounding (7.5e-7 measured)
    EXPECT_GT(faces, 100000u);
    EXPECT_LE(worstBox, 1e-4); // 1.4e-5 measured
    EXPECT_LE(worstOuter, 0.2);
}

TEST_F(TestAssets, IcosphereIsTheSphereWithinItsChordError)
{
    const double dx = 0.005, r = 0.4;
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> tris;
    icosphere(r, 5, points, tris);
    ASSERT_EQ(tris.size(), 20480u);
    // The chord error: how far inside the sphere a triangle's plane gets.
    double chord = 0.0;
    for (const auto& t : tris) {
        const Vec3d a(points[t[0]]), b(points[t[1]]), c(points[t[2]]);
        const Vec3d n = (b - a).cross(c - a).unit();
        chord = std::max(chord, r - std::abs(n.dot(a)));
    }
    writeObj(path("ico.obj"), points, tris);
    const scene::Scene sc = scene(R"({"type": "mesh", "file": "ico.obj"})", dx);
    auto g = raster::rasterize(sc.shape, settings(sc));
    // The surface lies between the sphere and the chords: at points of the sphere the level
    // set is within [0, chord error] (plus the interpolation's error, 0.05 voxel).
    openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> sampler(*g);
    std::mt19937 rng(9);
    std::normal_distribution<double> nd(0.0, 1.0);
    double lo = 0.0, hi = 0.0;
    for (int i = 0; i < 5000; ++i) {
        const Vec3d q = Vec3d(nd(rng), nd(rng), nd(rng)).unit() * r;
        const double v = sampler.wsSample(q);
        lo = std::min(lo, v);
        hi = std::max(hi, v);
    }
    std::printf("icosphere of %zu triangles: chord error %.3g voxel; at 5000 points of the "
                "sphere the level set is in [%.3g, %.3g] voxel\n", tris.size(), chord / dx,
                lo / dx, hi / dx);
    EXPECT_GE(lo, -0.05 * dx);
    EXPECT_LE(hi, chord + 0.05 * dx);

    // The same values as OpenVDB's meshToLevelSet on the same mesh and voxel size, voxel for voxel.
    auto ref = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(
        *openvdb::math::Transform::createLinearTransform(dx), points, tris, 3.0f);
    EXPECT_EQ(g->activeVoxelCount(), ref->activeVoxelCount());
    auto acc = ref->getConstAccessor();
    std::size_t differ = 0;
    for (auto it = g->cbeginValueOn(); it; ++it) {
        float v;
        if (!acc.probeValue(it.getCoord(), v) || v != *it) ++differ;
    }
    EXPECT_EQ(differ, 0u);
}

TEST_F(TestAssets, EveryFormatGivesTheSameGrid)
{
    // A closed, non-convex mesh (a torus-like ring of boxes would do; the icosphere minus
    // nothing is enough to tell formats apart): exported by Assimp to each format.
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> tris;
    icosphere(0.3, 3, points, tris);
    writeObj(path("m.obj"), points, tris);
    Assimp::Importer importer;
    const aiScene* model = importer.ReadFile(path("m.obj"), 0);
    ASSERT_TRUE(model) << importer.GetErrorString();
    Assimp::Exporter exporter;
    const std::vector<std::pair<std::string, std::string>> formats = {
        {"plyb", "m.ply"}, {"stlb", "m.stl"}, {"gltf2", "m.gltf"}, {"glb2", "m.glb"}};
    for (const auto& [id, file] : formats) {
        ASSERT_EQ(exporter.Export(model, id, path(file)), AI_SUCCESS) << id << ": "
                                                                      << exporter.GetErrorString();
    }
    const double dx = 0.01;
    auto reference = raster::rasterize(scene(R"({"type": "mesh", "file": "m.obj"})", dx).shape,
                                       settings(scene(R"({"type": "mesh", "file": "m.obj"})", dx)));
    for (const auto& [id, file] : formats) {
        const scene::Scene sc = scene(R"({"type": "mesh", "file": ")" + file + "\"}", dx);
        auto g = raster::rasterize(sc.shape, settings(sc));
        EXPECT_EQ(g->activeVoxelCount(), reference->activeVoxelCount()) << file;
        auto acc = reference->getConstAccessor();
        std::size_t differ = 0;
        for (auto it = g->cbeginValueOn(); it; ++it) {
            float v;
            if (!acc.probeValue(it.getCoord(), v) || v != *it) ++differ;
        }
        EXPECT_EQ(differ, 0u) << file;
    }
}

TEST_F(TestAssets, OpenMeshGetsANote)
{
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> tris;
    boxMesh(Vec3d(-0.3), Vec3d(0.3), points, tris, /*openTop=*/true);
    writeObj(path("open.obj"), points, tris);
    const scene::Scene sc = scene(R"({"type": "mesh", "file": "open.obj"})", 0.01);
    ASSERT_EQ(sc.notes.size(), 1u);
    EXPECT_NE(sc.notes[0].find("open.obj: the mesh is not closed (4 edges"), std::string::npos)
        << sc.notes[0];
    // What OpenVDB makes of it (docs/scene-format.md#mesh): the flood fill from outside
    // reaches the inside through the gap, so the box has no inside: its centre is outside, and
    // the band follows the faces on both sides (their unsigned distance).
    auto g = raster::rasterize(sc.shape, settings(sc));
    EXPECT_GT(g->activeVoxelCount(), 1000u);
    EXPECT_FLOAT_EQ(g->tree().getValue(openvdb::Coord(0)), g->background());
    EXPECT_GT(g->tree().getValue(openvdb::Coord(0, 0, -29)), 0.0f); // 0.01 inside the bottom
}

TEST_F(TestAssets, VdbNodeUnionEqualsTheAnalyticUnion)
{
    const double dx = 0.01;
    const Vec3d c(0.05, -0.02, 0.01);
    auto sphere = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.35f, openvdb::Vec3f(c), float(dx), 3.0f);
    sphere->setName("ball");
    io::writeVdb(path("ball.vdb"), {sphere});
    const std::string box = R"({"type": "box", "center": [0.3, 0.1, 0], "size": [0.4, 0.3, 0.5]})";
    const scene::Scene withFile =
        scene(R"({"type": "union", "children": [{"type": "vdb", "file": "ball.vdb"}, )" + box + "]}", dx);
    EXPECT_TRUE(withFile.notes.empty());
    auto g = raster::rasterize(withFile.shape, settings(withFile));
    const scene::Scene analytic = scene(R"({"type": "union", "children": [{"type": "sphere", "center": [0.05, -0.02, 0.01], "radius": 0.35}, )" + box + "]}", dx);
    auto ref = raster::rasterize(analytic.shape, settings(analytic));
    // The same band up to ties at its edge (values a float rounding from the half width).
    EXPECT_NEAR(double(g->activeVoxelCount()), double(ref->activeVoxelCount()),
                1e-4 * double(ref->activeVoxelCount()));
    auto acc = ref->getConstAccessor();
    double worst = 0.0;
    std::size_t missing = 0;
    for (auto it = g->cbeginValueOn(); it; ++it) {
        float v;
        if (!acc.probeValue(it.getCoord(), v)) {
            ++missing;
            continue;
        }
        worst = std::max(worst, double(std::abs(v - *it)) / dx);
    }
    std::printf("vdb sphere union analytic box: worst difference from the analytic union %.3g voxel\n", worst);
    EXPECT_LE(missing, g->activeVoxelCount() / 1000);
    EXPECT_LE(worst, 0.05);

    // At another voxel size the grid is rebuilt at the scene's, with a note.
    const scene::Scene finer = scene(R"({"type": "vdb", "file": "ball.vdb", "grid": "ball"})", 0.006);
    ASSERT_EQ(finer.notes.size(), 1u);
    EXPECT_NE(finer.notes[0].find("rebuilt at the scene's voxel size 0.006"), std::string::npos)
        << finer.notes[0];
    auto h = raster::rasterize(finer.shape, settings(finer));
    double err = 0.0;
    for (auto it = h->cbeginValueOn(); it; ++it) {
        const openvdb::Coord k = it.getCoord();
        err = std::max(err, std::abs(*it - ((Vec3d(k.x(), k.y(), k.z()) * 0.006 - c).length() - 0.35)));
    }
    std::printf("vdb sphere rebuilt at voxel 0.006 from 0.01: worst error %.3g of the new voxel\n",
                err / 0.006);
    // Rebuilt from the coarser grid's surface: within half a voxel of that grid.
    EXPECT_LE(err, 0.5 * 0.01);
}

TEST_F(TestAssets, BadAssetsAreRefused)
{
    std::ofstream(path("empty.obj"));
    std::ofstream(path("text.obj")) << "this is not a mesh\n";
    std::ofstream(path("lines.obj")) << "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nl 2 3\n";
    auto fog = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.3f, openvdb::Vec3f(0.0f), 0.01f);
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    fog->setName("fog");
    io::writeVdb(path("fog.vdb"), {fog});
    auto refused = [&](const std::string& shape, const std::string& message, double dx = 0.01) {
        try {
            scene(shape, dx);
            ADD_FAILURE() << "accepted: " << shape;
        } catch (const scene::SceneError& e) {
            EXPECT_NE(std::string(e.what()).find(message), std::string::npos)
                << e.what() << "\n  expected: " << message;
        }
    };
    refused(R"({"type": "mesh", "file": "missing.obj"})", "shape.file: " + path("missing.obj") + ": cannot open");
    refused(R"({"type": "mesh", "file": "empty.obj"})", "shape.file: " + path("empty.obj"));
    refused(R"({"type": "mesh", "file": "text.obj"})", "shape.file: " + path("text.obj"));
    refused(R"({"type": "mesh", "file": "lines.obj"})", "holds no triangles");
    refused(R"({"type": "mesh", "file": 3})", "shape.file: must be a file name");
    refused(R"({"type": "mesh", "file": "/dev/zero"})", "shape.file: /dev/zero is not a regular file");
    refused(R"({"type": "vdb", "file": "."})", "is not a regular file");
    refused(R"({"type": "vdb", "file": "missing.vdb"})", "shape.file: ");
    refused(R"({"type": "vdb", "file": "fog.vdb"})", "fog");
    refused(R"({"type": "vdb", "file": "fog.vdb", "grid": "nosuch"})", "shape.grid: ");
    // A mesh moved by a transform right above it: vertices beyond 1e30 are refused.
    {
        std::vector<openvdb::Vec3s> points;
        std::vector<openvdb::Vec3I> tris;
        boxMesh(Vec3d(-0.5), Vec3d(0.5), points, tris);
        writeObj(path("cube.obj"), points, tris);
    }
    refused(R"({"type": "transform", "scale": 1e300, "child": {"type": "mesh", "file": "cube.obj"}})",
            "shape.child.file: the mesh in " + path("cube.obj") +
                " moved by the transforms above it has a vertex beyond 1e30");
    // Without a voxel size there is nothing to build the level set at.
    std::ofstream(path("novoxel.json")) << R"({"shape": {"type": "mesh", "file": "empty.obj"}})";
    try {
        scene::loadScene(path("novoxel.json"));
        ADD_FAILURE() << "accepted a mesh without a voxel size";
    } catch (const scene::SceneError& e) {
        EXPECT_NE(std::string(e.what()).find("shape: a mesh node is built at the scene's voxel size"),
                  std::string::npos) << e.what();
    }
}

// A grid as a shape: its interval over any box holds the interpolated values in it (corners,
// lattice points, random points), and over boxes whose samples are all one value it is that
// value, so the descent drops leaves far from the surface instead of testing them.
TEST_F(TestAssets, GridShapeIntervalHoldsItsValuesAndIsTight)
{
    raster::RasterSettings s;
    s.voxelSize = 0.02;
    s.halfWidth = 4.0;
    const auto grid = raster::rasterize(std::make_shared<implicit::Sphere>(Vec3d(0.013, -0.02, 0.0), 0.6), s);
    const implicit::GridShape shape(grid, "vdb");
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-0.9, 0.9), size(0.001, 0.9);
    int tight = 0;
    for (int b = 0; b < 400; ++b) {
        const Vec3d lo(u(rng), u(rng), u(rng));
        const double side = b % 3 == 0 ? 0.16 : size(rng); // 8 voxels, or anything up to 45
        const implicit::BBoxd box(lo, lo + Vec3d(side, side * 0.7, side * 1.1));
        const implicit::Interval iv = shape.interval(box);
        ASSERT_LE(iv.lo, iv.hi);
        std::uniform_real_distribution<double> t(0.0, 1.0);
        for (int k = 0; k < 24; ++k) {
            Vec3d p = k < 8 ? Vec3d(k & 1 ? box.max()[0] : box.min()[0], k & 2 ? box.max()[1] : box.min()[1],
                                    k & 4 ? box.max()[2] : box.min()[2])
                            : box.min() + (box.max() - box.min()) * Vec3d(t(rng), t(rng), t(rng));
            if (k >= 20) p = Vec3d(std::round(p[0] / 0.02), std::round(p[1] / 0.02), std::round(p[2] / 0.02)) * 0.02;
            if (!box.isInside(p)) continue;
            const double v = shape.value(p);
            EXPECT_TRUE(iv.lo <= v && v <= iv.hi) << v << " not in [" << iv.lo << ", " << iv.hi
                                                  << "] at " << p << ", box side " << side;
        }
        if (iv.hi - iv.lo < 1e-6 * s.voxelSize) ++tight;
    }
    EXPECT_GT(tight, 20) << "boxes far from the surface get the background itself";
    // The descent then tests at most half as many leaves again as the grid has (as for analytic
    // shapes that are not distances); the Lipschitz bound alone tested 1000 for 353 here.
    s.halfWidth = 3.0;
    const auto again = raster::rasterize(std::make_shared<implicit::GridShape>(grid, "vdb"), s);
    const raster::Partition p = raster::partition(std::make_shared<implicit::GridShape>(grid, "vdb"), s, 1);
    std::printf("grid shape: %llu leaves tested, %llu in the grid\n", (unsigned long long)p.leaves,
                (unsigned long long)again->tree().leafCount());
    EXPECT_LE(double(p.leaves), 1.5 * double(again->tree().leafCount()));
}
