// SPDX-License-Identifier: Apache-2.0
// ivdb mesh, glyphs, render (its colour bar read back from the PNG) and --fog end to end: the
// files written (read back with OpenVDB, libpng), and bad arguments (non-zero exit,
// `ivdb: error: `, no output).
#include "CliRun.h"
#include "ReadPng.h"
#include "../render/ReadText.h"

#include <ivdb/render/Render.h>
#include <ivdb/render/Text.h>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

#include <gtest/gtest.h>

#include <png.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using ivdb::test::runIvdb;
using ivdb::test::slurpFile;

class TestCliMesh: public ::testing::Test
{
protected:
    void SetUp() override
    {
        openvdb::initialize();
        static std::atomic<int> counter{0};
        mDir = fs::temp_directory_path() /
               ("ivdb-test-cli-mesh-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
        fs::remove_all(mDir);
        fs::create_directories(mDir);
        std::ofstream(mDir / "s.json") << R"({"voxel_size": 0.05, "shape": {"type": "sphere", "radius": 1}})";
    }
    void TearDown() override
    {
        std::error_code ec;
        fs::remove_all(mDir, ec);
    }
    fs::path mDir;
};

TEST_F(TestCliMesh, FogGridBesideTheSurface)
{
    for (const auto& args : std::vector<std::vector<std::string>>{
             {"rasterize", "s.json", "-o", "a.vdb", "--fog", "-q"},
             {"rasterize", "s.json", "-o", "b.vdb", "-q"},
             {"csg", "union", "a.vdb", "b.vdb", "-o", "u.vdb", "--fog", "-q"},
             {"blend", "union", "a.vdb", "b.vdb", "-p", "50", "-o", "bl.vdb", "--fog", "-q"}}) {
        const auto r = runIvdb(mDir, args);
        ASSERT_EQ(r.exitCode, 0) << args[0] << ": " << r.err;
    }
    for (const char* name : {"a.vdb", "u.vdb", "bl.vdb"}) {
        openvdb::io::File f((mDir / name).string());
        f.open();
        auto grids = f.getGrids();
        f.close();
        ASSERT_EQ(grids->size(), 2u) << name;
        openvdb::GridBase::Ptr surface, density;
        for (const auto& g : *grids) (g->getName() == "surface" ? surface : density) = g;
        ASSERT_TRUE(surface && density) << name;
        EXPECT_EQ(density->getName(), "density");
        EXPECT_EQ(surface->getGridClass(), openvdb::GRID_LEVEL_SET);
        EXPECT_EQ(density->getGridClass(), openvdb::GRID_FOG_VOLUME);
        auto fog = openvdb::gridPtrCast<openvdb::FloatGrid>(density);
        EXPECT_EQ(fog->tree().getValue(openvdb::Coord(0, 0, 0)), 1.0f) << name;  // deep inside
        EXPECT_EQ(fog->tree().getValue(openvdb::Coord(40, 0, 0)), 0.0f) << name; // outside
    }
    openvdb::io::File f((mDir / "b.vdb").string());
    f.open();
    EXPECT_EQ(f.getGrids()->size(), 1u); // no --fog: the surface only
}

TEST_F(TestCliMesh, ObjAndColouredPly)
{
    ASSERT_EQ(runIvdb(mDir, {"rasterize", "s.json", "-o", "s.vdb", "-q"}).exitCode, 0);
    auto r = runIvdb(mDir, {"mesh", "s.vdb", "-o", "s.obj"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("enclosed volume"), std::string::npos) << r.out;
    const std::string obj = slurpFile(mDir / "s.obj");
    EXPECT_NE(obj.find("\nv "), std::string::npos);
    EXPECT_NE(obj.find("\nf "), std::string::npos);
    r = runIvdb(mDir, {"mesh", "s.vdb", "-o", "s.ply", "--color-by", "s.vdb:surface", "--colormap",
                       "hsv", "--range", "-0.1,0.1", "-q"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const std::string ply = slurpFile(mDir / "s.ply");
    EXPECT_EQ(ply.rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u);
    EXPECT_NE(ply.find("property uchar red"), std::string::npos);
    EXPECT_NE(ply.find("property float surface"), std::string::npos);
}

TEST_F(TestCliMesh, BadArguments)
{
    ASSERT_EQ(runIvdb(mDir, {"rasterize", "s.json", "-o", "s.vdb", "--fog", "-q"}).exitCode, 0);
    const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
        {{"mesh", "s.vdb", "-o", "x.obj", "--colormap", "jet", "--color-by", "s.vdb"}, "colormap 'jet'"},
        {{"mesh", "s.vdb", "-o", "x.obj", "--range", "1,1", "--color-by", "s.vdb"}, "LO < HI"},
        {{"mesh", "s.vdb", "-o", "x.obj", "--range", "a,b", "--color-by", "s.vdb"}, "--range"},
        {{"mesh", "s.vdb", "-o", "x.stl"}, ".obj or .ply"},
        {{"mesh", "s.vdb", "-o", "x.obj", "--adaptivity", "2"}, "--adaptivity"},
        {{"mesh", "s.vdb", "-o", "x.obj", "--grid", "density"}, "density"},
        {{"mesh", "missing.vdb", "-o", "x.obj"}, "missing.vdb"},
        {{"mesh", "s.vdb", "-o", "x.obj", "--color-by", "s.vdb:nothing"}, "nothing"},
        {{"mesh", "s.vdb", "-o", "no/such/folder/x.obj"}, "no/such/folder"},
    };
    for (const auto& [args, mention] : cases) {
        const auto r = runIvdb(mDir, args);
        EXPECT_NE(r.exitCode, 0) << mention;
        EXPECT_EQ(r.err.rfind("ivdb: error: ", 0), 0u) << r.err;
        EXPECT_NE(r.err.find(mention), std::string::npos) << "expected '" << mention << "' in " << r.err;
        EXPECT_FALSE(fs::exists(mDir / "x.obj")) << mention;
        EXPECT_FALSE(fs::exists(mDir / "x.stl")) << mention;
    }
}

} // namespace

namespace {

TEST_F(TestCliMesh, GlyphsPointAlongTheGradient)
{
    ASSERT_EQ(runIvdb(mDir, {"rasterize", "s.json", "-o", "s.vdb", "--fog", "-q"}).exitCode, 0);
    ASSERT_EQ(runIvdb(mDir, {"gradient", "s.vdb", "-o", "g.vdb", "--with-input", "-q"}).exitCode, 0);
    auto r = runIvdb(mDir, {"glyphs", "g.vdb", "-o", "a.obj", "--stride", "2"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("arrows"), std::string::npos) << r.out;
    // Every arrow (20 vertices: 18 ring vertices, the tip, the base) points away from the centre.
    std::istringstream in(slurpFile(mDir / "a.obj"));
    std::string line;
    std::vector<openvdb::Vec3d> v;
    while (std::getline(in, line)) {
        double x, y, z;
        if (std::sscanf(line.c_str(), "v %lf %lf %lf", &x, &y, &z) == 3) v.emplace_back(x, y, z);
    }
    ASSERT_GT(v.size(), 20u * 50u);
    ASSERT_EQ(v.size() % 20, 0u);
    for (size_t a = 0; a < v.size(); a += 20) {
        const openvdb::Vec3d tip = v[a + 18], base = v[a + 19];
        // Near the surface of the unit sphere, along the outward normal.
        EXPECT_NEAR(base.length(), 1.0, 0.05);
        EXPECT_GT((tip - base).unitSafe().dot(base.unitSafe()), 0.99);
    }
    const std::vector<std::pair<std::vector<std::string>, std::string>> bad = {
        {{"glyphs", "g.vdb", "-o", "x.obj", "--stride", "0"}, "--stride"},
        {{"glyphs", "s.vdb", "-o", "x.obj"}, "no vec3s"},
        {{"glyphs", "g.vdb", "-o", "x.stl"}, ".obj or .ply"},
        {{"glyphs", "g.vdb", "-o", "x.obj", "--grid", "surface"}, "vec3s"},
    };
    for (const auto& [args, mention] : bad) {
        r = runIvdb(mDir, args);
        EXPECT_NE(r.exitCode, 0) << mention;
        EXPECT_NE(r.err.find(mention), std::string::npos) << r.err;
        EXPECT_FALSE(fs::exists(mDir / "x.obj"));
    }
}

} // namespace

namespace {

TEST_F(TestCliMesh, RenderWritesImagesAndRefusesBadArguments)
{
    ASSERT_EQ(runIvdb(mDir, {"rasterize", "s.json", "-o", "s.vdb", "-q"}).exitCode, 0);
    ASSERT_EQ(runIvdb(mDir, {"gradient", "s.vdb", "-o", "g.vdb", "-q"}).exitCode, 0);
    auto r = runIvdb(mDir, {"render", "s.vdb", "-o", "a.png", "--size", "80x60", "--color-by",
                            "s.vdb:surface", "--colormap", "coolwarm", "--range=-0.1,0.1"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(slurpFile(mDir / "a.png").substr(1, 3), "PNG");
    r = runIvdb(mDir, {"render", "s.vdb", "-o", "a.exr", "--size", "80x60", "--camera",
                       "eye=0,0,4,target=0,0,0,fov=30", "--color-by", "g.vdb", "-q"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(slurpFile(mDir / "a.exr").substr(0, 4), std::string("\x76\x2f\x31\x01", 4));
    const std::vector<std::pair<std::vector<std::string>, std::string>> bad = {
        {{"render", "s.vdb", "-o", "x.png", "--colormap", "jet"}, "colormap 'jet'"},
        {{"render", "s.vdb", "-o", "x.png", "--color-by", "s.vdb", "--range", "1,0"}, "LO < HI"},
        {{"render", "s.vdb", "-o", "x.png", "--size", "0x10"}, "--size"},
        {{"render", "s.vdb", "-o", "x.png", "--color-by", "g.vdb", "--range", "0,1"}, "scalar grids only"},
        {{"render", "s.vdb", "-o", "x.png", "--color-by", "g.vdb", "--colormap", "viridis"}, "scalar grids only"},
        {{"render", "s.vdb", "-o", "x.png", "--camera", "eye=1,2"}, "x,y,z"},
        {{"render", "s.vdb", "-o", "x.jpg"}, ".png or .exr"},
        {{"render", "s.vdb", "-o", "no/such/folder/x.png"}, "no/such/folder"},
    };
    for (const auto& [args, mention] : bad) {
        r = runIvdb(mDir, args);
        EXPECT_NE(r.exitCode, 0) << mention;
        EXPECT_NE(r.err.find(mention), std::string::npos) << "expected '" << mention << "' in " << r.err;
        EXPECT_FALSE(fs::exists(mDir / "x.png")) << mention;
    }
}

using ivdb::test::readPngInk;

/// The words of @a texts in @a ink at the text scale of its size, each found exactly once, in
/// the order given.
std::vector<ivdb::test::Word> findWords(const ivdb::test::InkMap& ink, const std::vector<std::string>& texts)
{
    const auto words = ivdb::test::readWords(ink, ivdb::render::textScale(ink.width, ink.height));
    std::string all;
    for (const auto& w : words) all += " '" + w.text + "'";
    std::vector<ivdb::test::Word> found;
    for (const std::string& text : texts) {
        const auto n = std::count_if(words.begin(), words.end(), [&](const auto& w) { return w.text == text; });
        EXPECT_EQ(n, 1) << "'" << text << "' among the words read:" << all;
        const auto it = std::find_if(words.begin(), words.end(), [&](const auto& w) { return w.text == text; });
        found.push_back(it == words.end() ? ivdb::test::Word{"", -1, -1} : *it);
    }
    return found;
}

TEST_F(TestCliMesh, RenderedColourBarShowsTheRangeAndTheQuantity)
{
    ASSERT_EQ(runIvdb(mDir, {"rasterize", "s.json", "-o", "s.vdb", "-q"}).exitCode, 0);
    ASSERT_EQ(runIvdb(mDir, {"curvature", "s.vdb", "-o", "k.vdb", "-q"}).exitCode, 0);
    ASSERT_EQ(runIvdb(mDir, {"gradient", "s.vdb", "-o", "g.vdb", "-q"}).exitCode, 0);
    auto r = runIvdb(mDir, {"render", "s.vdb", "-o", "a.png", "--size", "160x120", "--color-by",
                            "k.vdb:curvature", "--range=-50,50", "-q"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    // The title above the values, hi at the top, right-aligned in the right half of the image.
    const std::vector<std::string> texts = {"curvature (1/length)", "50", "0", "-50"};
    const auto at = findWords(readPngInk(mDir / "a.png"), texts);
    for (size_t k = 1; k < texts.size(); ++k) {
        EXPECT_LT(at[k - 1].y, at[k].y) << texts[k - 1] << " above " << texts[k];
        const int right = at[k].x + ivdb::render::textWidth(texts[k], 1);
        EXPECT_EQ(right, at[3].x + ivdb::render::textWidth("-50", 1)) << texts[k];
        EXPECT_GT(right, 80) << texts[k];
    }

    // Without --range, the level set's own value range; its distances are lengths.
    r = runIvdb(mDir, {"render", "s.vdb", "-o", "b.png", "--size", "320x240", "--color-by", "s.vdb", "-q"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    openvdb::io::File file((mDir / "s.vdb").string());
    file.open();
    const auto surface = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("surface"));
    file.close();
    // The range read independently: the smallest and largest active value.
    double lo = std::numeric_limits<double>::max(), hi = std::numeric_limits<double>::lowest();
    for (auto it = surface->cbeginValueOn(); it; ++it) {
        lo = std::min(lo, double(*it));
        hi = std::max(hi, double(*it));
    }
    ASSERT_LT(lo, hi);
    const auto ticks = ivdb::render::colorBarTicks(lo, hi);
    const auto atB = findWords(readPngInk(mDir / "b.png"), {"surface (length)", ticks[2], ticks[1], ticks[0]});
    EXPECT_LT(atB[1].y, atB[2].y);
    EXPECT_LT(atB[2].y, atB[3].y);

    // Coloured by direction, or written as EXR: no bar.
    r = runIvdb(mDir, {"render", "s.vdb", "-o", "c.png", "--size", "160x120", "--color-by", "g.vdb", "-q"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    for (const auto& w : ivdb::test::readWords(readPngInk(mDir / "c.png"), 1)) {
        EXPECT_EQ(w.text.find("gradient"), std::string::npos) << w.text;
    }
}

/// The centre of the surface's pixels (not white) in the tile at (x0, y0) of size w x h, from a
/// PNG read back through libpng.
std::pair<double, double> surfaceCentre(const fs::path& file, int x0, int y0, int w, int h)
{
    png_image p{};
    p.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&p, file.c_str())) return {-1, -1};
    p.format = PNG_FORMAT_RGB;
    std::vector<unsigned char> rgb(PNG_IMAGE_SIZE(p));
    png_image_finish_read(&p, nullptr, rgb.data(), 0, nullptr);
    double sx = 0, sy = 0, n = 0;
    for (int y = y0 + 20; y < y0 + h; ++y) { // below the frame label
        for (int x = x0; x < x0 + w; ++x) {
            const unsigned char* px = &rgb[3 * (size_t(y) * p.width + size_t(x))];
            if (px[0] < 250 || px[1] < 250 || px[2] < 250) sx += x, sy += y, ++n;
        }
    }
    return {n ? sx / n : -1, n ? sy / n : -1};
}

// A contact sheet of a sequence: one tile a frame, labelled, from one camera (the sphere moves
// across the tiles), one colour bar for the sheet; bad sheets refused with nothing written.
TEST_F(TestCliMesh, ContactSheetTilesTheFramesFromOneCamera)
{
    std::ofstream(mDir / "move.json") << R"({"voxel_size": 0.02, "frames": {"start": 1, "end": 4},
        "shape": {"type": "sphere", "radius": 0.3, "center": {"keys": [[1, [-0.6, 0, 0]], [4, [0.6, 0, 0]]]}}})";
    ASSERT_EQ(runIvdb(mDir, {"rasterize", "move.json", "-o", "m_#.vdb", "-q"}).exitCode, 0);
    for (const char* f : {"1", "2", "3", "4"}) {
        ASSERT_EQ(runIvdb(mDir, {"curvature", std::string("m_") + f + ".vdb", "-o", std::string("k_") + f + ".vdb", "-q"}).exitCode, 0);
    }
    const auto r = runIvdb(mDir, {"render", "m_#.vdb", "--frames", "1-4", "--columns", "2", "--size",
        "160x120", "--color-by", "k_#.vdb:curvature", "--range=-5,5", "-o", "sheet.png"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("380x240"), std::string::npos) << r.out; // 2 tiles + a 60-pixel strip
    const ivdb::test::InkMap ink = readPngInk(mDir / "sheet.png");
    ASSERT_EQ(ink.width, 380);
    ASSERT_EQ(ink.height, 240);
    const auto at = findWords(ink, {"frame 1", "frame 2", "frame 3", "frame 4", "curvature (1/length)", "5", "0", "-5"});
    for (int k = 0; k < 4; ++k) { // each label in its tile's top-left corner
        EXPECT_EQ(at[size_t(k)].x, (k % 2) * 160 + 2) << "frame " << k + 1;
        EXPECT_EQ(at[size_t(k)].y, (k / 2) * 120 + 2) << "frame " << k + 1;
    }
    EXPECT_GT(at[4].x, 320 - 80); // the bar's title at the right
    // One camera: the sphere's image moves from tile to tile (per-tile framing would centre it).
    const auto first = surfaceCentre(mDir / "sheet.png", 0, 0, 160, 120);
    const auto last = surfaceCentre(mDir / "sheet.png", 160, 120, 160, 120);
    ASSERT_GT(first.first, 0);
    ASSERT_GT(last.first, 0);
    EXPECT_GT(std::abs((last.first - 160) - first.first), 20.0);

    const std::vector<std::pair<std::vector<std::string>, std::string>> bad = {
        {{"render", "m_#.vdb", "-o", "x.png"}, "is a sequence (it has #): choose the frames"},
        {{"render", "m_#.vdb", "--frames", "1-4", "-o", "x.exr"}, "must end in .png for a contact sheet"},
        {{"render", "m_#.vdb", "--frames", "1-5", "-o", "x.png"}, "m_5.vdb"},
        {{"render", "m_#.vdb", "--frames", "1-4", "--columns", "0", "-o", "x.png"}, "--columns"},
        {{"render", "m_#.vdb", "--frames", "4-1", "-o", "x.png"}, "A > B"},
    };
    for (const auto& [args, mention] : bad) {
        const auto e = runIvdb(mDir, args);
        EXPECT_EQ(e.exitCode, 1) << mention;
        EXPECT_NE(e.err.find(mention), std::string::npos) << "expected '" << mention << "' in " << e.err;
        EXPECT_FALSE(fs::exists(mDir / "x.png")) << mention;
        EXPECT_FALSE(fs::exists(mDir / "x.exr")) << mention;
    }
}

} // namespace

namespace {

// The PLY's per-vertex scalar is the colouring grid at the vertex (OpenVDB's own trilinear
// sampler as the reference), and its colour is that value through the colormap.
TEST_F(TestCliMesh, PlyScalarIsTheGridAtEachVertex)
{
    ASSERT_EQ(runIvdb(mDir, {"rasterize", "s.json", "-o", "s.vdb", "-q"}).exitCode, 0);
    ASSERT_EQ(runIvdb(mDir, {"curvature", "s.vdb", "-o", "c.vdb", "-q"}).exitCode, 0);
    const auto r = runIvdb(mDir, {"mesh", "s.vdb", "-o", "c.ply", "--color-by", "c.vdb:curvature",
                                  "--colormap", "gray", "--range", "0,2", "-q"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    openvdb::io::File f((mDir / "c.vdb").string());
    f.open();
    auto curv = openvdb::gridPtrCast<openvdb::FloatGrid>(f.readGrid("curvature"));
    f.close();
    ASSERT_TRUE(curv);
    openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> sampler(*curv);

    std::ifstream in(mDir / "c.ply", std::ios::binary);
    std::string line;
    size_t vertices = 0;
    while (std::getline(in, line) && line != "end_header") {
        std::sscanf(line.c_str(), "element vertex %zu", &vertices);
    }
    ASSERT_GT(vertices, 1000u);
    double meanCurvature = 0.0;
    for (size_t i = 0; i < vertices; ++i) {
        float xyz[3], s;
        unsigned char rgb[3];
        in.read(reinterpret_cast<char*>(xyz), sizeof(xyz));
        in.read(reinterpret_cast<char*>(rgb), 3);
        in.read(reinterpret_cast<char*>(&s), sizeof(s));
        ASSERT_TRUE(in);
        ASSERT_EQ(s, float(sampler.wsSample(openvdb::Vec3d(xyz[0], xyz[1], xyz[2])))) << i;
        // gray over [0, 2]: matplotlib's 256-entry table, index min(int(t * 256), 255).
        const int index = std::min(int(std::clamp(s / 2.0, 0.0, 1.0) * 256), 255);
        ASSERT_EQ(int(rgb[0]), index) << i;
        meanCurvature += s;
    }
    // A unit sphere's mean curvature is 1.
    EXPECT_NEAR(meanCurvature / double(vertices), 1.0, 0.05);
}

} // namespace
