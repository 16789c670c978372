// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/ContactSheet.h>

#include <ivdb/io/AtomicFile.h>
#include <ivdb/jobs/Inputs.h>
#include <ivdb/render/Text.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <algorithm>
#include <limits>

namespace ivdb::jobs {

namespace {

using openvdb::Vec3d;

/// What the first pass over the frames finds: the surfaces' world box and the colour range.
struct SheetExtent
{
    openvdb::BBoxd box{Vec3d(std::numeric_limits<double>::max()), Vec3d(-std::numeric_limits<double>::max())};
    double lo = std::numeric_limits<double>::max(), hi = -std::numeric_limits<double>::max();
    bool scalar = false;
    std::string label; ///< the colour bar's title
};

SheetExtent measureFrames(const ContactSheetOptions& opt, const std::vector<int>& frames)
{
    SheetExtent extent;
    for (int f : frames) {
        const openvdb::FloatGrid::Ptr surface =
            readLevelSet(scene::frameFileName(opt.base.input, f), opt.base.grid);
        const openvdb::CoordBBox box = surface->evalActiveVoxelBoundingBox();
        if (!box.empty()) {
            extent.box.expand(surface->indexToWorld(box.min()));
            extent.box.expand(surface->indexToWorld(box.max()));
        }
        if (opt.base.colorBy.empty()) continue;
        const openvdb::GridBase::Ptr g = readColorGrid(scene::frameFileName(opt.base.colorBy, f),
            opt.base.range.has_value(), opt.base.colormap.has_value());
        if (const auto scalar = openvdb::GridBase::grid<openvdb::FloatGrid>(g)) {
            extent.scalar = true;
            extent.label = colorBarLabel(*scalar);
            const auto [lo, hi] = render::valueRange(*scalar);
            extent.lo = std::min(extent.lo, lo);
            extent.hi = std::max(extent.hi, hi);
        }
    }
    if (opt.base.range) std::tie(extent.lo, extent.hi) = *opt.base.range;
    return extent;
}

/// The settings every tile shares: size, camera, colormap and range.
render::RenderSettings tileSettings(const ContactSheetOptions& opt, const SheetExtent& extent)
{
    render::RenderSettings s;
    s.width = opt.base.width;
    s.height = opt.base.height;
    s.colormap.emplace(opt.base.colormap.value_or("hsv"));
    if (!extent.box.min().eq(Vec3d(std::numeric_limits<double>::max()))) {
        s.camera = render::frameBox(extent.box, s.width, s.height);
    }
    if (opt.base.camera.eye) s.camera.eye = *opt.base.camera.eye;
    if (opt.base.camera.target) s.camera.target = *opt.base.camera.target;
    if (opt.base.camera.fov) s.camera.fov = *opt.base.camera.fov; // checked by contactSheet()
    s.lo = extent.lo;
    s.hi = extent.hi;
    return s;
}

/// Copy @a tile into @a sheet with its top-left corner at (@a x0, @a y0).
void place(render::Image& sheet, const render::Image& tile, int x0, int y0)
{
    for (int j = 0; j < tile.height; ++j) {
        for (int i = 0; i < tile.width; ++i) {
            const size_t from = size_t(j) * size_t(tile.width) + size_t(i);
            const size_t to = size_t(y0 + j) * size_t(sheet.width) + size_t(x0 + i);
            sheet.rgb[to] = tile.rgb[from];
            sheet.alpha[to] = tile.alpha[from];
            sheet.depth[to] = tile.depth[from];
            sheet.normal[to] = tile.normal[from];
        }
    }
}

} // namespace

RenderResult contactSheet(const ContactSheetOptions& opt)
{
    Stopwatch clock;
    if (util::extensionOf(opt.base.output) != ".png") {
        throw ParamError(param::kOutput, "must end in .png for a contact sheet, got '" +
                         opt.base.output + "'");
    }
    check(limits::kColumns, opt.columns);
    const std::vector<int> frames = opt.frames.frames();
    check(limits::kSheetTiles, double(frames.size()));
    render::checkImageSize(opt.base.width, opt.base.height);
    const int columns = std::min<int>(opt.columns, int(frames.size()));
    const int rows = int((frames.size() + size_t(columns) - 1) / size_t(columns));
    // A strip at the right for the colour bar, so it covers no tile.
    const int strip = opt.base.colorBy.empty() ? 0 : std::max(opt.base.width / 3, 60);
    render::checkImageSize(columns * opt.base.width + strip, rows * opt.base.height);
    if (opt.base.camera.fov) check(limits::kFov, *opt.base.camera.fov);
    const render::Colormap colormap(opt.base.colormap.value_or("hsv")); // refuses an unknown name
    io::checkOutputPath(opt.base.output);

    const SheetExtent extent = measureFrames(opt, frames);
    const render::RenderSettings shared = tileSettings(opt, extent);
    render::Image sheet = render::blankImage(columns * opt.base.width + strip, rows * opt.base.height);
    const int scale = render::textScale(opt.base.width, opt.base.height);
    RenderResult result;
    for (size_t k = 0; k < frames.size(); ++k) {
        render::RenderSettings s = shared;
        const openvdb::FloatGrid::Ptr surface =
            readLevelSet(scene::frameFileName(opt.base.input, frames[k]), opt.base.grid);
        if (!opt.base.colorBy.empty()) {
            const openvdb::GridBase::Ptr g = readColorGrid(
                scene::frameFileName(opt.base.colorBy, frames[k]), false, false);
            s.colorScalar = openvdb::GridBase::grid<openvdb::FloatGrid>(g);
            s.colorVector = openvdb::GridBase::grid<openvdb::Vec3SGrid>(g);
        }
        render::Image tile = render::renderLevelSet(*surface, s);
        render::drawText(tile, 2 * scale, 2 * scale, "frame " + std::to_string(frames[k]), scale);
        for (float a : tile.alpha) result.surfacePixels += a > 0.0f;
        place(sheet, tile, int(k % size_t(columns)) * opt.base.width, int(k / size_t(columns)) * opt.base.height);
    }
    if (extent.scalar) render::drawColorBar(sheet, colormap, extent.lo, extent.hi, extent.label);
    render::writePng(opt.base.output, sheet);
    result.width = sheet.width;
    result.height = sheet.height;
    result.seconds = clock.total();
    return result;
}

} // namespace ivdb::jobs
