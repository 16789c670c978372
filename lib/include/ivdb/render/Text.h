// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/render/Render.h>

#include <array>
#include <cstdint>
#include <string>

namespace ivdb::render {

/// The built-in bitmap font's glyph cell, in font pixels: 5 columns by 9 rows, rows 0-6 from the
/// cap line down to the baseline and rows 7-8 for descenders (g, j, p, q, y, the comma, _).
inline constexpr int kGlyphWidth = 5, kGlyphHeight = 9, kGlyphCapHeight = 7;
/// Font pixels from one character's left edge to the next one's (one blank column between).
inline constexpr int kGlyphAdvance = 6;
/// The largest scale (image pixels per font pixel) text is drawn at.
inline constexpr int kMaxTextScale = 256;

/// A glyph's rows, top first; bit (kGlyphWidth - 1 - x) is set where column x is inked.
using GlyphRows = std::array<std::uint8_t, kGlyphHeight>;

/// @brief The glyph of @a c. Printable ASCII (32-126) has glyphs of its own, all different;
/// every other byte (control characters, UTF-8 bytes) gets the placeholder, a hollow box.
const GlyphRows& glyph(char c);

/// @brief The placeholder glyph (a hollow box the height of a capital letter).
const GlyphRows& placeholderGlyph();

/// @brief Width in pixels of @a text at @a scale, from the first glyph's left edge to the last
/// one's right edge (no trailing blank column); 0 for "". Saturates at INT_MAX.
/// @throw openvdb::ValueError for a scale outside [1, kMaxTextScale]
int textWidth(const std::string& text, int scale);

/// @brief The scale that keeps labels legible on a @a width x @a height image: the shorter side
/// / 450, rounded, at least 1 (glyphs 9 pixels tall, below 675 pixels) and at most
/// kMaxTextScale: 2 at 1920x1080, 5 at 4096x2160.
int textScale(int width, int height);

/// @brief Draw @a text in @a colour (sRGB in [0, 1], opaque: alpha becomes 1) with the first
/// glyph cell's top-left corner at pixel (x, y), x to the right and y down, each font pixel a
/// scale x scale square. Only inked pixels change; pixels off the image are skipped.
/// @throw openvdb::ValueError for a scale outside [1, kMaxTextScale], or an image whose
/// buffers do not hold width x height pixels
void drawText(Image& image, int x, int y, const std::string& text, int scale,
              const openvdb::Vec3f& colour = openvdb::Vec3f(0.0f));

} // namespace ivdb::render
