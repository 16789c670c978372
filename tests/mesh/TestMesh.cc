// SPDX-License-Identifier: Apache-2.0
// Meshes (mesh::meshLevelSet, the OBJ and PLY writers), colormaps against matplotlib, and the
// fog volume.
#include <ivdb/levelset/Fog.h>
#include <ivdb/mesh/Mesh.h>
#include <ivdb/render/Colormap.h>

#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>

#include <unistd.h>

using namespace ivdb;

namespace {

namespace fs = std::filesystem;

class TestMesh: public ::testing::Test
{
protected:
    void SetUp() override
    {
        openvdb::initialize();
        mDir = fs::temp_directory_path() / ("ivdb-test-mesh-" + std::to_string(::getpid()));
        fs::create_directories(mDir);
    }
    void TearDown() override
    {
        std::error_code ec;
        fs::remove_all(mDir, ec);
    }
    fs::path mDir;
};

// A sphere of radius 50 voxels (radius 1, voxel size 0.02), off the lattice's centre.
openvdb::FloatGrid::Ptr sphere50()
{
    return openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        1.0f, openvdb::Vec3f(0.013f, -0.021f, 0.007f), 0.02f, 3.0f);
}

} // namespace

TEST_F(TestMesh, SphereIsClosedOutwardAndEnclosesItsVolume)
{
    const auto grid = sphere50();
    const mesh::Mesh m = mesh::meshLevelSet(*grid);
    ASSERT_GT(m.faceCount(), 10000u);
    const double exact = 4.0 / 3.0 * M_PI;
    const double v = mesh::enclosedVolume(m);
    std::printf("meshed sphere: %zu vertices, %zu faces, volume %.6f vs %.6f (%.3f%%)\n",
                m.points.size(), m.faceCount(), v, exact, 100.0 * (v - exact) / exact);
    EXPECT_NEAR(v, exact, 0.005 * exact);

    // Every edge is shared by exactly two faces, once in each direction (watertight, oriented).
    std::map<std::pair<unsigned, unsigned>, int> edges;
    auto addFace = [&](const std::vector<unsigned>& f) {
        for (size_t i = 0; i < f.size(); ++i) ++edges[{f[i], f[(i + 1) % f.size()]}];
    };
    for (const auto& t : m.triangles) addFace({t[0], t[1], t[2]});
    for (const auto& q : m.quads) addFace({q[0], q[1], q[2], q[3]});
    size_t bad = 0;
    for (const auto& [e, n] : edges) {
        const auto back = edges.find({e.second, e.first});
        if (n != 1 || back == edges.end() || back->second != 1) ++bad;
    }
    EXPECT_EQ(bad, 0u);
    // Shared vertices: far fewer than one per face corner.
    EXPECT_LT(m.points.size(), 2 * m.faceCount());
    // Outward: every face's normal points away from the centre.
    const openvdb::Vec3d c(0.013, -0.021, 0.007);
    size_t inward = 0;
    for (const auto& q : m.quads) {
        const openvdb::Vec3d a(m.points[q[0]]), b(m.points[q[1]]), d(m.points[q[2]]);
        if ((b - a).cross(d - a).dot(a - c) <= 0.0) ++inward;
    }
    EXPECT_EQ(inward, 0u);
    EXPECT_THROW(mesh::meshLevelSet(*grid, 1.5), openvdb::ValueError);
}

TEST_F(TestMesh, PlyCarriesColoursAndTheSampledScalar)
{
    const auto grid = sphere50();
    const mesh::Mesh m = mesh::meshLevelSet(*grid, 0.0);
    mesh::VertexData data;
    data.scalarName = "x";
    const render::Colormap cmap("viridis");
    for (const auto& p : m.points) {
        data.scalars.push_back(p.x());
        data.colors.push_back(cmap.map(p.x(), -1.0, 1.0));
    }
    const std::string path = (mDir / "s.ply").string();
    mesh::writePly(path, m, &data);

    // Read it back: header, then binary vertices (x y z, r g b, scalar) and faces.
    std::ifstream in(path, std::ios::binary);
    std::string line, header;
    size_t vertices = 0, faces = 0;
    while (std::getline(in, line) && line != "end_header") {
        header += line + "\n";
        std::sscanf(line.c_str(), "element vertex %zu", &vertices);
        std::sscanf(line.c_str(), "element face %zu", &faces);
    }
    EXPECT_NE(header.find("format binary_little_endian 1.0"), std::string::npos);
    EXPECT_NE(header.find("property float x\n"), std::string::npos);
    EXPECT_NE(header.find("property uchar red"), std::string::npos);
    ASSERT_EQ(vertices, m.points.size());
    ASSERT_EQ(faces, m.faceCount());
    openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> phi(*grid);
    for (size_t i = 0; i < vertices; ++i) {
        float xyz[3], s;
        unsigned char rgb[3];
        in.read(reinterpret_cast<char*>(xyz), sizeof(xyz));
        in.read(reinterpret_cast<char*>(rgb), 3);
        in.read(reinterpret_cast<char*>(&s), sizeof(s));
        ASSERT_TRUE(in);
        ASSERT_EQ(xyz[0], m.points[i].x());
        ASSERT_EQ(s, xyz[0]); // the scalar stored is the value at the vertex
        const openvdb::Vec3f c = cmap.map(s, -1.0, 1.0);
        ASSERT_NEAR(rgb[1], c[1] * 255.0f, 0.51f);
        // Vertices lie on the surface: the level set is ~0 there.
        ASSERT_LT(std::abs(phi.wsSample(openvdb::Vec3d(xyz[0], xyz[1], xyz[2]))), 0.05 * 0.02);
    }
    for (size_t f = 0; f < faces; ++f) {
        unsigned char n = 0;
        in.read(reinterpret_cast<char*>(&n), 1);
        ASSERT_TRUE(n == 3 || n == 4);
        std::int32_t idx[4];
        in.read(reinterpret_cast<char*>(idx), n * sizeof(std::int32_t));
        for (int k = 0; k < n; ++k) ASSERT_LT(size_t(idx[k]), vertices);
    }
    in.peek();
    EXPECT_TRUE(in.eof()); // nothing after the last face

    // OBJ: the same counts of `v` and `f` lines.
    const std::string obj = (mDir / "s.obj").string();
    mesh::writeObj(obj, m);
    std::ifstream o(obj);
    size_t v = 0, fl = 0;
    while (std::getline(o, line)) {
        if (line.rfind("v ", 0) == 0) ++v;
        if (line.rfind("f ", 0) == 0) ++fl;
    }
    EXPECT_EQ(v, m.points.size());
    EXPECT_EQ(fl, m.faceCount());
}

// The colormaps against matplotlib itself (python3-matplotlib, an outside reference).
TEST_F(TestMesh, ColormapsMatchMatplotlib)
{
    const std::string script = (mDir / "cm.py").string();
    std::ofstream(script) << "import matplotlib\n"
                             "for name in ['hsv', 'viridis', 'coolwarm', 'gray']:\n"
                             "    cm = matplotlib.colormaps[name]\n"
                             "    for i in range(0, 101):\n"
                             "        r, g, b, a = cm(i / 100.0)\n"
                             "        print(name, i / 100.0, r, g, b)\n";
    const std::string out = (mDir / "cm.txt").string();
    ASSERT_EQ(std::system(("/usr/bin/python3 " + script + " > " + out).c_str()), 0)
        << "needs python3-matplotlib (./scripts/deps.sh installs it)";
    std::ifstream in(out);
    std::string name;
    double t, r, g, b;
    int n = 0;
    double worst = 0.0;
    while (in >> name >> t >> r >> g >> b) {
        const openvdb::Vec3f c = render::Colormap(name).at(t);
        worst = std::max({worst, std::abs(c[0] - r), std::abs(c[1] - g), std::abs(c[2] - b)});
        ++n;
    }
    EXPECT_EQ(n, 404);
    std::printf("colormaps: worst difference from matplotlib %.5f\n", worst);
    EXPECT_LT(worst, 1e-5);
    // Known colours: HSV's ends are red, its third is green-ish; gray is linear; clamping.
    EXPECT_NEAR(render::Colormap("hsv").at(0.0)[0], 1.0f, 1e-6);
    EXPECT_NEAR(render::Colormap("gray").map(25.0, -50.0, 50.0)[1], 192.0f / 255.0f, 1e-6);
    EXPECT_EQ(render::Colormap("viridis").at(7.0), render::Colormap("viridis").at(1.0));
    EXPECT_EQ(render::Colormap("viridis").at(std::nan("")), render::Colormap("viridis").at(0.0));
    EXPECT_THROW(render::Colormap("jet"), openvdb::ValueError);
}

TEST_F(TestMesh, FogIsZeroOutsideOneInsideAndMonotonic)
{
    const auto grid = sphere50();
    const auto fog = levelset::fogFromLevelSet(*grid);
    EXPECT_EQ(fog->getName(), "density");
    EXPECT_EQ(fog->getGridClass(), openvdb::GRID_FOG_VOLUME);
    EXPECT_EQ(grid->getGridClass(), openvdb::GRID_LEVEL_SET); // the input is unchanged
    auto phi = grid->getConstAccessor();
    auto rho = fog->getConstAccessor();
    // Along a ray from the centre outwards: 1 deep inside, non-increasing, 0 outside.
    const openvdb::Coord c = grid->transform().worldToIndexCellCentered(openvdb::Vec3d(0.013, -0.021, 0.007));
    float previous = 2.0f;
    for (int i = 0; i < 70; ++i) {
        const openvdb::Coord ijk = c + openvdb::Coord(i, 0, 0);
        const float d = rho.getValue(ijk), p = phi.getValue(ijk);
        EXPECT_GE(d, 0.0f);
        EXPECT_LE(d, 1.0f);
        EXPECT_LE(d, previous + 1e-6f) << i;
        if (p >= 0.0f) EXPECT_EQ(d, 0.0f) << i;
        if (p <= -grid->background()) EXPECT_EQ(d, 1.0f) << i;
        previous = d;
    }
}

TEST_F(TestMesh, ArrowsAreClosedSolidsFromBaseToTip)
{
    const std::vector<openvdb::Vec3d> bases{{0, 0, 0}, {1, 2, 3}, {-1, 0.5, 0}};
    const std::vector<openvdb::Vec3d> vectors{{1, 0, 0}, {0, 0.5, 0.5}, {0, 0, 0}};
    std::vector<openvdb::Vec3f> colors;
    const mesh::Mesh m = mesh::arrows(bases, vectors, 2.0, &colors);
    // Two arrows (the zero vector is skipped), 20 vertices and 36 triangles each.
    ASSERT_EQ(m.points.size(), 40u);
    ASSERT_EQ(m.triangles.size(), 72u);
    ASSERT_EQ(colors.size(), 40u);
    for (int a = 0; a < 2; ++a) {
        mesh::Mesh one;
        one.points.assign(m.points.begin() + 20 * a, m.points.begin() + 20 * (a + 1));
        for (size_t t = 36 * a; t < 36 * size_t(a + 1); ++t) {
            one.triangles.push_back(m.triangles[t] - openvdb::Vec3I(20 * a));
        }
        // A closed, outward solid: positive volume, close to a cylinder plus a cone.
        const double len = (vectors[a] * 2.0).length();
        const double expected = M_PI * std::pow(0.04 * len, 2) * 0.75 * len +
                                M_PI * std::pow(0.10 * len, 2) * 0.25 * len / 3.0;
        EXPECT_NEAR(mesh::enclosedVolume(one), expected, 0.25 * expected) << a;
        // The tip (vertex 18) is base + length * vector; the cap centre (19) is the base.
        EXPECT_LT((openvdb::Vec3d(one.points[18]) - (bases[a] + vectors[a] * 2.0)).length(), 1e-6);
        EXPECT_LT((openvdb::Vec3d(one.points[19]) - bases[a]).length(), 1e-6);
    }
    EXPECT_NEAR(colors[0][0], 1.0f, 1e-6); // +x: red 0.5 + 0.5
}
