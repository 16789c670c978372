// SPDX-License-Identifier: Apache-2.0
// The labelled colour bar of scalar-coloured renders: the gradient, ticks at its ends and middle,
// their values and the quantity's name, all inside the image.
#include <ivdb/render/Render.h>
#include <ivdb/render/Text.h>

#include "Paint.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <optional>

namespace ivdb::render {

namespace {

using Vec3f = openvdb::Vec3f;

constexpr float kBackingOpacity = 0.85f;
constexpr int kTickLength = 3; ///< font pixels
const Vec3f kInk(0.0f), kPaper(1.0f);

/// printf's %g of @a v with @a digits significant digits, whatever the locale.
std::string formatG(double v, int digits)
{
    char buf[64];
    const auto r = std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::general, digits);
    return std::string(buf, r.ptr);
}

/// A line of text and the top-left corner of its first glyph cell, in pixels.
struct Placed
{
    std::string text;
    int x = 0, y = 0;
};

/// Where the parts of the bar go, in pixels.
struct BarLayout
{
    int scale = 1, pad = 1;       ///< text scale; white backing beyond the text on each side
    int x0 = 0, x1 = 0;           ///< the gradient's columns [x0, x1)
    int top = 0, bottom = 0;      ///< the rows of the top (hi) and bottom (lo) ticks, inclusive
    std::optional<Placed> title;
    std::array<Placed, 3> values; ///< lo, mid, hi
};

/// @a label if it fits in @a room pixels at @a scale; else without its " (...)" part; else as
/// many leading characters as fit followed by ".."; else "".
std::string fitTitle(const std::string& label, int room, int scale)
{
    if (textWidth(label, scale) <= room) return label;
    const size_t open = label.rfind(" (");
    const std::string name = open == std::string::npos ? label : label.substr(0, open);
    if (textWidth(name, scale) <= room) return name;
    const int fit = (room + scale) / (kGlyphAdvance * scale);
    return fit < 3 ? std::string() : name.substr(0, size_t(fit - 2)) + "..";
}

/// The layout of a bar with @a ticks (lo, mid, hi) and @a label on a @a w x @a h image; none if
/// the three value labels do not fit.
std::optional<BarLayout> layoutColorBar(int w, int h, const std::array<std::string, 3>& ticks,
                                        const std::string& label)
{
    BarLayout b;
    const int s = b.scale = b.pad = textScale(w, h);
    const int margin = std::max({2, 2 * s, w / 80});
    b.x1 = w - margin;
    b.x0 = b.x1 - std::max(4, w / 40);
    const int right = b.x0 - (kTickLength + 1) * s; // the value labels' right edge
    int widest = 0;
    for (const std::string& t : ticks) widest = std::max(widest, textWidth(t, s));
    if (right - widest - b.pad < 0) return std::nullopt;

    int titleBottom = margin - s; // below the title's backing, or where it would start
    const std::string title = fitTitle(label, b.x1 - b.pad, s);
    if (!title.empty()) {
        b.title = Placed{title, b.x1 - textWidth(title, s), margin};
        titleBottom = margin + kGlyphHeight * s + b.pad;
    }
    // A value label's capitals are centred on its tick: its glyph cells (and backing) take
    // rows [tick - above, tick - above + line) and pad more on each side.
    const int line = kGlyphHeight * s, above = (kGlyphCapHeight * s - 1) / 2;
    b.top = std::max(h / 10, titleBottom + s + b.pad + above);
    b.bottom = std::min(h - h / 10 - 1, h - margin - b.pad - line + above);
    if ((b.bottom - b.top) % 2 != 0) --b.bottom; // the middle tick on the middle row
    if ((b.bottom - b.top) / 2 < line + 2 * b.pad + s) return std::nullopt;
    const int rows[3] = {b.bottom, (b.top + b.bottom) / 2, b.top};
    for (int k = 0; k < 3; ++k) b.values[k] = Placed{ticks[k], right - textWidth(ticks[k], s), rows[k] - above};
    return b;
}

/// @a p's text, dark on a white backing over its glyph cells, @a pad beyond them above, below
/// and to the left, and reaching to column @a right.
void drawLabel(Image& image, const Placed& p, int scale, int pad, int right)
{
    const int rows = kGlyphHeight * scale;
    detail::fillRect(image, p.x - pad, p.y - pad, right, p.y + rows + pad, kPaper, kBackingOpacity);
    drawText(image, p.x, p.y, p.text, scale, kInk);
}

/// The gradient, hi on the top tick's row and lo on the bottom one's, in a dark frame.
void drawGradient(Image& image, const Colormap& map, const BarLayout& b)
{
    const int frame = std::max(1, b.scale / 2);
    detail::fillRect(image, b.x0, b.top - frame, b.x1, b.bottom + 1 + frame, kInk);
    for (int j = b.top; j <= b.bottom; ++j) {
        const double t = double(b.bottom - j) / double(b.bottom - b.top);
        detail::fillRect(image, b.x0 + frame, j, b.x1 - frame, j + 1, map.at(t));
    }
}

} // namespace

std::array<std::string, 3> colorBarTicks(double lo, double hi)
{
    if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi)) {
        OPENVDB_THROW(openvdb::ValueError, "a colour bar needs a finite range with lo < hi, got [" +
                      formatG(lo, 6) + ", " + formatG(hi, 6) + "]");
    }
    // Halves first: no overflow near the largest doubles. A midpoint within 1/1000 of the range
    // from zero has zero's colour (a colormap has 256), and "0" reads better than "5.2e-06".
    double mid = 0.5 * lo + 0.5 * hi;
    if (std::abs(mid) <= 2e-3 * (0.5 * hi - 0.5 * lo)) mid = 0.0;
    const double values[3] = {lo == 0.0 ? 0.0 : lo, mid, hi == 0.0 ? 0.0 : hi}; // never "-0"
    std::array<std::string, 3> out;
    for (int digits = 3; digits <= 17; ++digits) {
        for (int k = 0; k < 3; ++k) out[k] = formatG(values[k], digits);
        if (out[0] != out[1] && out[1] != out[2] && out[0] != out[2]) break;
    }
    return out;
}

void drawColorBar(Image& image, const Colormap& map, double lo, double hi, const std::string& label)
{
    const std::array<std::string, 3> ticks = colorBarTicks(lo, hi);
    detail::checkCanvas(image);
    const std::optional<BarLayout> layout = layoutColorBar(image.width, image.height, ticks, label);
    if (!layout) return;
    const BarLayout& b = *layout;
    if (b.title) drawLabel(image, *b.title, b.scale, b.pad, b.x1 + b.pad);
    for (const Placed& v : b.values) drawLabel(image, v, b.scale, b.pad, b.x0);
    drawGradient(image, map, b);
    for (const int row : {b.top, (b.top + b.bottom) / 2, b.bottom}) {
        const int y = row - (b.scale - 1) / 2;
        detail::fillRect(image, b.x0 - kTickLength * b.scale, y, b.x0, y + b.scale, kInk);
    }
}

} // namespace ivdb::render
