// SPDX-License-Identifier: Apache-2.0
// Reading text back from pixels by matching glyph cells against ivdb's font: how the tests check
// that labels are drawn, legible, and where they belong.
#pragma once

#include <ivdb/render/Text.h>

#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

namespace ivdb::test {

/// The dark pixels of an image (luminance below one half): where text ink is.
struct InkMap
{
    int width = 0, height = 0;
    std::vector<std::uint8_t> ink;

    bool at(int x, int y) const { return ink[size_t(y) * size_t(width) + size_t(x)] != 0; }
};

/// @a image's ink as writePng shows it: composited over white.
inline InkMap inkOf(const render::Image& image)
{
    InkMap m{image.width, image.height, {}};
    m.ink.resize(image.rgb.size());
    for (size_t p = 0; p < image.rgb.size(); ++p) {
        const float a = image.alpha[p];
        const openvdb::Vec3f c = image.rgb[p] * a + openvdb::Vec3f(1.0f - a);
        m.ink[p] = 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2] < 0.5f;
    }
    return m;
}

/// The ink of 8-bit RGB pixels, rows top to bottom (libpng's PNG_FORMAT_RGB).
inline InkMap inkOfRgb(int width, int height, const std::vector<unsigned char>& rgb)
{
    InkMap m{width, height, {}};
    m.ink.resize(size_t(width) * size_t(height));
    for (size_t p = 0; p < m.ink.size(); ++p) {
        m.ink[p] = 0.2126 * rgb[3 * p] + 0.7152 * rgb[3 * p + 1] + 0.0722 * rgb[3 * p + 2] < 127.5;
    }
    return m;
}

/// Marks the placeholder box in decoded text.
inline constexpr char kBox = '\1';

/// A glyph's font pixels as one number: bit (row * kGlyphWidth + column).
inline std::uint64_t glyphKey(const render::GlyphRows& rows)
{
    std::uint64_t key = 0;
    for (int r = 0; r < render::kGlyphHeight; ++r) {
        for (int c = 0; c < render::kGlyphWidth; ++c) {
            if ((rows[r] >> (render::kGlyphWidth - 1 - c)) & 1) key |= std::uint64_t(1) << (r * render::kGlyphWidth + c);
        }
    }
    return key;
}

/// The character drawn with its glyph cell's top-left corner at (x, y) at @a scale, the whole
/// cell inside the image: ' ' for a blank cell, kBox for the placeholder, '\0' for no glyph.
/// A glyph matches only where every font pixel is a uniformly inked or blank square.
inline char glyphAt(const InkMap& m, int x, int y, int scale)
{
    static const std::unordered_map<std::uint64_t, char> table = [] {
        std::unordered_map<std::uint64_t, char> t{{glyphKey(render::placeholderGlyph()), kBox}};
        for (int c = 32; c <= 126; ++c) t.emplace(glyphKey(render::glyph(char(c))), char(c));
        return t;
    }();
    const int s = scale;
    if (x < 0 || y < 0 || x + render::kGlyphWidth * s > m.width || y + render::kGlyphHeight * s > m.height) return '\0';
    std::uint64_t key = 0;
    for (int r = 0; r < render::kGlyphHeight; ++r) {
        for (int c = 0; c < render::kGlyphWidth; ++c) {
            if (m.at(x + c * s + s / 2, y + r * s + s / 2)) key |= std::uint64_t(1) << (r * render::kGlyphWidth + c);
        }
    }
    const auto it = table.find(key);
    if (it == table.end()) return '\0';
    if (key == 0) return ' ';
    for (int r = 0; r < render::kGlyphHeight * s; ++r) { // every square uniform
        for (int c = 0; c < render::kGlyphWidth * s; ++c) {
            const bool inked = (key >> ((r / s) * render::kGlyphWidth + c / s)) & 1;
            if (m.at(x + c, y + r) != inked) return '\0';
        }
    }
    return it->second;
}

/// The text whose first glyph cell starts at (x, y): glyphs one advance apart, up to the first
/// cell that is no glyph or the second blank cell in a row; no trailing blanks.
inline std::string readLine(const InkMap& m, int x, int y, int scale)
{
    std::string text;
    for (int at = x;; at += render::kGlyphAdvance * scale) {
        const char c = glyphAt(m, at, y, scale);
        if (c == '\0' || (c == ' ' && !text.empty() && text.back() == ' ')) break;
        text += c;
    }
    while (!text.empty() && text.back() == ' ') text.pop_back();
    return text;
}

/// A line of text found in an image and its first glyph cell's top-left corner.
struct Word
{
    std::string text;
    int x = 0, y = 0;
};

/// Every line of text at @a scale whose first glyph cell lies at x >= @a fromX: lines start
/// with a glyph that does not follow another (nor a single blank after one).
inline std::vector<Word> readWords(const InkMap& m, int scale, int fromX = 0)
{
    const int step = render::kGlyphAdvance * scale;
    auto isGlyph = [&](int x, int y) {
        const char c = glyphAt(m, x, y, scale);
        return c != '\0' && c != ' ';
    };
    std::vector<Word> words;
    for (int y = 0; y + render::kGlyphHeight * scale <= m.height; ++y) {
        for (int x = fromX; x + render::kGlyphWidth * scale <= m.width; ++x) {
            if (!isGlyph(x, y) || isGlyph(x - step, y)) continue;
            if (glyphAt(m, x - step, y, scale) == ' ' && isGlyph(x - 2 * step, y)) continue;
            words.push_back({readLine(m, x, y, scale), x, y});
        }
    }
    return words;
}

} // namespace ivdb::test
