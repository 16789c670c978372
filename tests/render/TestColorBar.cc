// SPDX-License-Identifier: Apache-2.0
// The labelled colour bar: the tick labels' format, and bars drawn into images from 40 to 4096
// pixels wide read back from the pixels: the values at the top, middle and bottom of the
// gradient, right-aligned beside it, the title above, everything inside the image.
#include <ivdb/render/Render.h>
#include <ivdb/render/Text.h>

#include "ReadText.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

using namespace ivdb;

namespace {

using Ticks = std::array<std::string, 3>;

class TestColorBar: public ::testing::Test
{
protected:
    void SetUp() override { openvdb::initialize(); }

    static render::Image canvas(int width, int height, float grey, float alpha)
    {
        render::Image img;
        img.width = width;
        img.height = height;
        img.rgb.assign(size_t(width) * size_t(height), openvdb::Vec3f(grey));
        img.alpha.assign(size_t(width) * size_t(height), alpha);
        return img;
    }

    /// The one word of @a words that reads @a text; a failure if there is none or several.
    static test::Word only(const std::vector<test::Word>& words, const std::string& text)
    {
        std::vector<test::Word> found;
        for (const test::Word& w : words) {
            if (w.text == text) found.push_back(w);
        }
        std::string all;
        for (const test::Word& w : words) all += " '" + w.text + "'";
        EXPECT_EQ(found.size(), 1u) << "'" << text << "' among the words read:" << all;
        return found.empty() ? test::Word{"", -1, -1} : found.front();
    }

    /// The colour, composited over white, of the first coloured (not grey) pixel right of
    /// column @a x on row @a y (the gradient), and whether a black pixel (the tick) comes
    /// before it.
    static std::pair<openvdb::Vec3f, bool> gradientRightOf(const render::Image& img, int x, int y)
    {
        bool tick = false;
        for (int i = x; i < img.width; ++i) {
            const size_t p = size_t(y) * size_t(img.width) + size_t(i);
            const openvdb::Vec3f c = img.rgb[p] * img.alpha[p] + openvdb::Vec3f(1.0f - img.alpha[p]);
            const float hi = std::max({c[0], c[1], c[2]}), lo = std::min({c[0], c[1], c[2]});
            if (hi < 0.05f) tick = true;
            else if (hi - lo > 0.1f) return {c, tick};
        }
        return {openvdb::Vec3f(-1.0f), tick};
    }

    /// Draw a viridis bar over [lo, hi] titled @a label on @a img and read it back: the values
    /// @a ticks (lo, mid, hi) at the gradient's bottom, middle and top rows, right-aligned beside
    /// it with a tick mark, and @a title above them.
    static void expectLabelledBar(render::Image img, double lo, double hi, const std::string& label,
                                  const Ticks& ticks, const std::string& title)
    {
        SCOPED_TRACE(std::to_string(img.width) + "x" + std::to_string(img.height) + " '" + label + "'");
        const render::Colormap map("viridis");
        render::drawColorBar(img, map, lo, hi, label);
        const int s = render::textScale(img.width, img.height);
        const std::vector<test::Word> words = test::readWords(test::inkOf(img), s);
        const test::Word top = only(words, title);
        std::array<test::Word, 3> value;
        for (int k = 0; k < 3; ++k) value[k] = only(words, ticks[k]);
        if (top.y < 0 || value[0].y < 0 || value[1].y < 0 || value[2].y < 0) return;
        EXPECT_LT(top.y, value[2].y);
        EXPECT_LT(value[2].y, value[1].y);
        EXPECT_LT(value[1].y, value[0].y);
        const int right = value[0].x + render::textWidth(ticks[0], s);
        EXPECT_GT(top.x + render::textWidth(title, s), right); // the title reaches over the bar
        for (int k = 0; k < 3; ++k) {
            EXPECT_EQ(value[k].x + render::textWidth(ticks[k], s), right) << ticks[k];
            // The tick row: the middle of the label's capitals; the bar there has the colour of
            // the value (t = 0, 0.5, 1), with a tick mark between label and bar.
            const int row = value[k].y + (render::kGlyphCapHeight * s - 1) / 2;
            const auto [colour, tick] = gradientRightOf(img, right, row);
            EXPECT_TRUE(tick) << ticks[k];
            EXPECT_TRUE(colour.eq(map.at(0.5 * k), 1e-5f)) << ticks[k] << ": " << colour << " vs " << map.at(0.5 * k);
        }
        // The middle tick halfway between the others, to the pixel.
        EXPECT_EQ(value[1].y - value[2].y, value[0].y - value[1].y);
    }
};

} // namespace

TEST_F(TestColorBar, TicksAreCompactAndTellTheValuesApart)
{
    EXPECT_EQ(render::colorBarTicks(-50, 50), (Ticks{"-50", "0", "50"}));
    EXPECT_EQ(render::colorBarTicks(0.001, 0.002), (Ticks{"0.001", "0.0015", "0.002"}));
    EXPECT_EQ(render::colorBarTicks(-1e5, 3e5), (Ticks{"-1e+05", "1e+05", "3e+05"}));
    EXPECT_EQ(render::colorBarTicks(0.0123, 1234), (Ticks{"0.0123", "617", "1.23e+03"}));
    EXPECT_EQ(render::colorBarTicks(0, 1), (Ticks{"0", "0.5", "1"}));
    EXPECT_EQ(render::colorBarTicks(-0.0, 1), (Ticks{"0", "0.5", "1"})); // never "-0"
    EXPECT_EQ(render::colorBarTicks(-0.3, 0.3), (Ticks{"-0.3", "0", "0.3"}));
    EXPECT_EQ(render::colorBarTicks(-0.7, 0.7000000000001), (Ticks{"-0.7", "0", "0.7"}));
    // A midpoint within 1/1000 of the range from zero has zero's colour, and reads "0".
    EXPECT_EQ(render::colorBarTicks(-0.029934, 0.029944), (Ticks{"-0.0299", "0", "0.0299"}));
    EXPECT_EQ(render::colorBarTicks(-1, 1.01), (Ticks{"-1", "0.005", "1.01"}));
    // More digits only where three would repeat a value.
    EXPECT_EQ(render::colorBarTicks(1.0001, 1.0002), (Ticks{"1.0001", "1.00015", "1.0002"}));
    EXPECT_EQ(render::colorBarTicks(100, 101), (Ticks{"100", "100.5", "101"}));
    const double big = std::numeric_limits<double>::max();
    EXPECT_EQ(render::colorBarTicks(-big, big), (Ticks{"-1.8e+308", "0", "1.8e+308"}));
    const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
    for (auto [lo, hi] : std::vector<std::pair<double, double>>{{1, 1}, {2, 1}, {nan, 1}, {0, nan}, {0, inf}, {-inf, 0}}) {
        EXPECT_THROW(render::colorBarTicks(lo, hi), openvdb::ValueError) << lo << ", " << hi;
    }
}

TEST_F(TestColorBar, LabelsReadBackBesideTheBarAtEverySize)
{
    const std::string label = "curvature (1/length)";
    const std::vector<std::pair<double, double>> ranges = {{-50, 50}, {0.001, 0.002}, {-1e5, 3e5}};
    for (auto [w, h] : std::vector<std::pair<int, int>>{{160, 120}, {320, 240}, {200, 400}}) {
        for (const auto& [lo, hi] : ranges) {
            // Over the white background, and over a dark surface (the white backing shows).
            expectLabelledBar(canvas(w, h, 1.0f, 0.0f), lo, hi, label, render::colorBarTicks(lo, hi), label);
            expectLabelledBar(canvas(w, h, 0.15f, 1.0f), lo, hi, label, render::colorBarTicks(lo, hi), label);
        }
    }
    for (auto [w, h] : std::vector<std::pair<int, int>>{{640, 480}, {1280, 720}, {1920, 1080}, {4096, 2160}}) {
        expectLabelledBar(canvas(w, h, 0.15f, 1.0f), -50, 50, label, {"-50", "0", "50"}, label);
    }
    expectLabelledBar(canvas(160, 120, 1.0f, 0.0f), -1e5, 3e5, "gradient_magnitude",
                      {"-1e+05", "1e+05", "3e+05"}, "gradient_magnitude");
}

TEST_F(TestColorBar, LongTitlesAreShortenedToFit)
{
    const Ticks ticks{"-50", "0", "50"};
    expectLabelledBar(canvas(100, 120, 1.0f, 0.0f), -50, 50, "curvature (1/length)", ticks, "curvature");
    expectLabelledBar(canvas(40, 60, 1.0f, 0.0f), -50, 50, "curvature (1/length)", ticks, "curv..");
    expectLabelledBar(canvas(100, 120, 1.0f, 0.0f), -50, 50, "a_very_long_grid_name", ticks, "a_very_long_gr..");
}

TEST_F(TestColorBar, SmallImagesGetTheWholeBarOrNone)
{
    const render::Colormap map("hsv");
    for (auto [w, h] : std::vector<std::pair<int, int>>{{0, 0}, {1, 1}, {16, 16}, {30, 200}, {200, 30},
                                                          {40, 40}, {60, 45}, {60, 50}, {80, 60}, {1, 500}, {500, 1}}) {
        SCOPED_TRACE(std::to_string(w) + "x" + std::to_string(h));
        render::Image img = canvas(w, h, 1.0f, 0.0f);
        render::drawColorBar(img, map, -0.0015, 0.0015, "k1 (1/length)");
        EXPECT_EQ(img.rgb.size(), size_t(w) * size_t(h));
        size_t drawn = 0;
        for (float a : img.alpha) drawn += a > 0.0f;
        const std::vector<test::Word> words = test::readWords(test::inkOf(img), 1);
        size_t values = 0;
        for (const test::Word& word : words) {
            values += word.text == "-0.0015" || word.text == "0" || word.text == "0.0015";
        }
        EXPECT_EQ(values, drawn == 0 ? 0u : 3u) << drawn << " pixels drawn";
        if (w >= 60 && h >= 50) EXPECT_EQ(values, 3u);
    }
}

TEST_F(TestColorBar, RefusesBadRangesAndBuffers)
{
    const render::Colormap map("gray");
    render::Image img = canvas(160, 120, 1.0f, 0.0f);
    EXPECT_THROW(render::drawColorBar(img, map, 1, 1, "x"), openvdb::ValueError);
    EXPECT_THROW(render::drawColorBar(img, map, 0, std::numeric_limits<double>::quiet_NaN(), "x"),
                 openvdb::ValueError);
    for (float a : img.alpha) ASSERT_EQ(a, 0.0f);
    img.rgb.pop_back();
    EXPECT_THROW(render::drawColorBar(img, map, 0, 1, "x"), openvdb::ValueError);
}
