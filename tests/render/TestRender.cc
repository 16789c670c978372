// SPDX-License-Identifier: Apache-2.0
// The ray-traced renderer: a sphere's silhouette against its analytic projection, and the PNG and
// EXR files read back through libpng and OpenEXR.
#include <ivdb/render/Render.h>

#include <openvdb/tools/LevelSetSphere.h>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>

#include <png.h>

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include <unistd.h>

using namespace ivdb;

namespace {

namespace fs = std::filesystem;

class TestRender: public ::testing::Test
{
protected:
    void SetUp() override
    {
        openvdb::initialize();
        mDir = fs::temp_directory_path() / ("ivdb-test-render-" + std::to_string(::getpid()));
        fs::create_directories(mDir);
        mSphere = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
            1.0f, openvdb::Vec3f(0.0f), 0.01f, 3.0f);
    }
    void TearDown() override
    {
        std::error_code ec;
        fs::remove_all(mDir, ec);
    }

    render::RenderSettings settings(int w, int h) const
    {
        render::RenderSettings s;
        s.width = w;
        s.height = h;
        s.camera.eye = openvdb::Vec3d(0, 0, 5);
        s.camera.target = openvdb::Vec3d(0);
        s.camera.fov = 40.0;
        return s;
    }

    fs::path mDir;
    openvdb::FloatGrid::Ptr mSphere;
};

} // namespace

TEST_F(TestRender, SphereSilhouetteMatchesTheAnalyticProjection)
{
    const int n = 201;
    const render::Image img = render::renderLevelSet(*mSphere, settings(n, n));
    // The silhouette cone: sin(a) = R / d; on the image plane tan(a) / tan(fov / 2) of the
    // half height.
    const double a = std::asin(1.0 / 5.0);
    const double expected = std::tan(a) / std::tan(20.0 * M_PI / 180.0) * (n / 2.0);
    int row = 0, column = 0;
    for (int i = 0; i < n; ++i) {
        row += img.alpha[size_t(n / 2) * n + i] > 0.0f;
        column += img.alpha[size_t(i) * n + n / 2] > 0.0f;
    }
    std::printf("silhouette radius: row %.1f, column %.1f, analytic %.2f pixels\n", row / 2.0,
                column / 2.0, expected);
    EXPECT_NEAR(row / 2.0, expected, 1.0);
    EXPECT_NEAR(column / 2.0, expected, 1.0);
    // The centre: depth 4 (eye at 5, radius 1), normal towards the eye, lit.
    const size_t c = size_t(n / 2) * n + n / 2;
    EXPECT_NEAR(img.depth[c], 4.0f, 0.01f);
    EXPECT_GT(img.normal[c].z(), 0.999f);
    EXPECT_LT(img.rgb[c].x(), 1.0f);
    EXPECT_EQ(img.alpha[0], 0.0f);

    EXPECT_THROW(render::renderLevelSet(*mSphere, settings(0, 10)), openvdb::ValueError);
    auto bad = settings(10, 10);
    bad.camera.target = bad.camera.eye;
    EXPECT_THROW(render::renderLevelSet(*mSphere, bad), openvdb::ValueError);
}

TEST_F(TestRender, FramingShowsTheWholeShape)
{
    const auto s = render::frameGrid(*mSphere, 64, 48);
    auto rs = settings(64, 48);
    rs.camera = s;
    const render::Image img = render::renderLevelSet(*mSphere, rs);
    size_t hits = 0, border = 0;
    for (int j = 0; j < 48; ++j) {
        for (int i = 0; i < 64; ++i) {
            const bool hit = img.alpha[size_t(j) * 64 + i] > 0.0f;
            hits += hit;
            if (hit && (i == 0 || j == 0 || i == 63 || j == 47)) ++border;
        }
    }
    EXPECT_GT(hits, 200u);
    EXPECT_EQ(border, 0u); // nothing cut off at the edges
}

TEST_F(TestRender, ExrAndPngReadBack)
{
    auto s = settings(64, 48);
    s.colorScalar = mSphere;
    s.colormap.emplace("viridis");
    s.lo = -0.03;
    s.hi = 0.03;
    render::Image img = render::renderLevelSet(*mSphere, s);
    const std::string exr = (mDir / "a.exr").string(), png = (mDir / "a.png").string();
    render::writeExr(exr, img);
    render::drawColorBar(img, *s.colormap, s.lo, s.hi, "surface (length)");
    render::writePng(png, img);

    Imf::InputFile in(exr.c_str());
    const Imath::Box2i dw = in.header().dataWindow();
    EXPECT_EQ(dw.max.x - dw.min.x + 1, 64);
    EXPECT_EQ(dw.max.y - dw.min.y + 1, 48);
    for (const char* ch : {"R", "G", "B", "A", "Z", "N.X", "N.Y", "N.Z"}) {
        EXPECT_NE(in.header().channels().findChannel(ch), nullptr) << ch;
    }
    std::vector<float> z(64 * 48), a(64 * 48);
    Imf::FrameBuffer fb;
    fb.insert("Z", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(z.data()), sizeof(float), 64 * sizeof(float)));
    fb.insert("A", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(a.data()), sizeof(float), 64 * sizeof(float)));
    in.setFrameBuffer(fb);
    in.readPixels(dw.min.y, dw.max.y);
    EXPECT_NEAR(z[24 * 64 + 32], 4.0f, 0.02f);
    EXPECT_EQ(a[24 * 64 + 32], 1.0f);
    EXPECT_EQ(a[0], 0.0f);

    png_image p{};
    p.version = PNG_IMAGE_VERSION;
    ASSERT_TRUE(png_image_begin_read_from_file(&p, png.c_str())) << p.message;
    EXPECT_EQ(p.width, 64u);
    EXPECT_EQ(p.height, 48u);
    p.format = PNG_FORMAT_RGB;
    std::vector<png_byte> rgb(PNG_IMAGE_SIZE(p));
    ASSERT_TRUE(png_image_finish_read(&p, nullptr, rgb.data(), 0, nullptr)) << p.message;
    EXPECT_EQ(rgb[0], 255); // the background is white
    const size_t c = (24 * 64 + 32) * 3;
    EXPECT_LT(int(rgb[c]) + rgb[c + 1] + rgb[c + 2], 3 * 250); // the surface is not
}
