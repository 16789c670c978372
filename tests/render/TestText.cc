// SPDX-License-Identifier: Apache-2.0
// The bitmap font and text drawing: every glyph distinct, text read back from the pixels at every
// scale, and drawing clipped at the image's edges exactly as a crop of an unclipped drawing.
#include <ivdb/render/Text.h>

#include "ReadText.h"

#include <gtest/gtest.h>

#include <climits>
#include <set>
#include <string>
#include <utility>
#include <vector>

using namespace ivdb;

namespace {

class TestText: public ::testing::Test
{
protected:
    void SetUp() override { openvdb::initialize(); }

    /// A white, transparent image (the background of a render).
    static render::Image blank(int width, int height)
    {
        render::Image img;
        img.width = width;
        img.height = height;
        img.rgb.assign(size_t(width) * size_t(height), openvdb::Vec3f(1.0f));
        img.alpha.assign(size_t(width) * size_t(height), 0.0f);
        return img;
    }

    /// The columns [lo, hi) that hold ink, or {0, 0}.
    static std::pair<int, int> inkedColumns(const test::InkMap& m)
    {
        int lo = m.width, hi = 0;
        for (int y = 0; y < m.height; ++y) {
            for (int x = 0; x < m.width; ++x) {
                if (m.at(x, y)) lo = std::min(lo, x), hi = std::max(hi, x + 1);
            }
        }
        return lo < hi ? std::make_pair(lo, hi) : std::make_pair(0, 0);
    }
};

} // namespace

TEST_F(TestText, EveryPrintableCharacterHasItsOwnGlyph)
{
    std::set<std::uint64_t> seen{test::glyphKey(render::placeholderGlyph())};
    for (int c = 32; c <= 126; ++c) {
        const render::GlyphRows& g = render::glyph(char(c));
        EXPECT_TRUE(seen.insert(test::glyphKey(g)).second) << "'" << char(c) << "' looks like another glyph";
        for (std::uint8_t row : g) EXPECT_LT(row, 1u << render::kGlyphWidth) << char(c);
        const bool descends = g[7] != 0 || g[8] != 0;
        EXPECT_EQ(descends, std::string(",_gjpqy|").find(char(c)) != std::string::npos) << char(c);
        EXPECT_EQ(test::glyphKey(g) == 0, c == ' ') << char(c);
    }
    for (char c : {'\0', '\t', '\n', char(127), char(0xC3), char(0xFF)}) {
        EXPECT_EQ(&render::glyph(c), &render::placeholderGlyph()) << int(c);
    }
    EXPECT_NE(test::glyphKey(render::placeholderGlyph()), 0u); // visible
}

TEST_F(TestText, TextReadsBackFromThePixelsAtEveryScale)
{
    std::vector<std::string> texts = {"-50", "0", "50", "0.001", "0.0015", "0.002", "-1e+05", "1e+05",
                                      "3e+05", "1.2e+03", "curvature (1/length)", "gradient_magnitude",
                                      "surface (length)", "k1 k2: 12% of a, b", "Il1| O0 o"};
    for (int c = 33; c <= 126; c += 16) { // every printable character, 16 at a time
        std::string chunk;
        for (int k = c; k < c + 16 && k <= 126; ++k) chunk += char(k);
        texts.push_back(chunk);
    }
    for (int scale : {1, 2, 3}) {
        for (const std::string& text : texts) {
            render::Image img = blank(render::textWidth(text, scale) + 10, 12 * scale + 6);
            render::drawText(img, 4, 3, text, scale);
            const test::InkMap ink = test::inkOf(img);
            EXPECT_EQ(test::readLine(ink, 4, 3, scale), text) << "scale " << scale;
            // The ink stays within textWidth() of the start.
            const auto [lo, hi] = inkedColumns(ink);
            EXPECT_GE(lo, 4) << text;
            EXPECT_LE(hi, 4 + render::textWidth(text, scale)) << text;
            for (size_t p = 0; p < img.alpha.size(); ++p) {
                EXPECT_EQ(img.alpha[p], ink.ink[p] ? 1.0f : 0.0f) << text; // ink is opaque
            }
        }
    }
    EXPECT_EQ(render::textWidth("", 1), 0);
    EXPECT_EQ(render::textWidth("-50", 2), (3 * 6 - 1) * 2);
}

TEST_F(TestText, OtherBytesDrawAVisibleBox)
{
    render::Image img = blank(60, 12);
    render::drawText(img, 1, 1, "a\tb\xC3\xA9", 1);
    EXPECT_EQ(test::readLine(test::inkOf(img), 1, 1, 1), std::string("a") + test::kBox + "b" + test::kBox + test::kBox);
}

TEST_F(TestText, ClippedTextIsTheCropOfUnclippedText)
{
    // Drawn at every offset around a small image, the pixels inside are exactly those of the same
    // text drawn into a larger image and cropped: no wrapping into other rows, nothing lost.
    const int w = 23, h = 11, margin = 60;
    const std::string text = "Ag_|0%";
    for (int scale : {1, 2}) {
        for (int y = -20; y <= h + 2; y += 3) {
            for (int x = -40; x <= w + 2; x += 3) {
                render::Image small = blank(w, h), big = blank(w + 2 * margin, h + 2 * margin);
                render::drawText(small, x, y, text, scale);
                render::drawText(big, x + margin, y + margin, text, scale);
                for (int j = 0; j < h; ++j) {
                    for (int i = 0; i < w; ++i) {
                        const size_t p = size_t(j) * w + i, q = size_t(j + margin) * big.width + i + margin;
                        ASSERT_EQ(small.alpha[p], big.alpha[q]) << x << "," << y << " pixel " << i << "," << j;
                        ASSERT_EQ(small.rgb[p], big.rgb[q]) << x << "," << y;
                    }
                }
            }
        }
    }
    // Far-off positions, tiny and empty images: nothing drawn, nothing out of bounds.
    const std::vector<std::pair<int, int>> far = {{INT_MIN, 0}, {INT_MAX, 0}, {0, INT_MIN}, {0, INT_MAX},
                                                  {INT_MIN, INT_MIN}, {INT_MAX - 3, INT_MAX - 3}};
    for (const auto& [x, y] : far) {
        render::Image img = blank(8, 8);
        render::drawText(img, x, y, text, render::kMaxTextScale);
        for (float a : img.alpha) ASSERT_EQ(a, 0.0f);
    }
    render::Image one = blank(1, 1), none = blank(0, 0);
    render::drawText(one, 0, 0, "#", 1); // the top-left font pixel of # is blank
    EXPECT_EQ(one.alpha[0], 0.0f);
    render::drawText(one, -1, 0, "#", 1); // column 1 of # is inked on row 0
    EXPECT_EQ(one.alpha[0], 1.0f);
    render::drawText(none, 0, 0, text, 3);
    EXPECT_TRUE(none.alpha.empty());
}

TEST_F(TestText, RefusesBadScalesAndBuffers)
{
    render::Image img = blank(10, 10);
    EXPECT_THROW(render::drawText(img, 0, 0, "a", 0), openvdb::ValueError);
    EXPECT_THROW(render::drawText(img, 0, 0, "a", render::kMaxTextScale + 1), openvdb::ValueError);
    EXPECT_THROW(render::textWidth("a", -1), openvdb::ValueError);
    img.alpha.pop_back();
    EXPECT_THROW(render::drawText(img, 0, 0, "a", 1), openvdb::ValueError);
}

TEST_F(TestText, ScaleGrowsWithTheImage)
{
    EXPECT_EQ(render::textScale(1, 1), 1);
    EXPECT_EQ(render::textScale(160, 120), 1);
    EXPECT_EQ(render::textScale(640, 480), 1);
    EXPECT_EQ(render::textScale(1920, 1080), 2);
    EXPECT_EQ(render::textScale(4096, 2160), 5);
    EXPECT_EQ(render::textScale(16384, 16384), 36);
    int last = 1;
    for (int side = 1; side <= 16384; side += 97) {
        const int s = render::textScale(side, side);
        EXPECT_GE(s, last);
        last = s;
    }
}
