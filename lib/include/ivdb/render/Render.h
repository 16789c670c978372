// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/render/Colormap.h>

#include <openvdb/openvdb.h>

#include <array>
#include <optional>
#include <utility>
#include <string>
#include <vector>

namespace ivdb::render {

/// @brief A pinhole camera in world space; @a fov is the vertical field of view in degrees.
struct Camera
{
    openvdb::Vec3d eye{0.0, 0.0, 5.0}, target{0.0};
    double fov = 40.0;
};

/// @brief A camera that frames @a grid's active voxels: looking at their centre from the
/// direction (1, 0.8, 1.3) (above and to the side), far enough that the bounding sphere fits.
Camera frameGrid(const openvdb::FloatGrid& grid, int width, int height, double fov = 40.0);

/// @brief The camera of frameGrid() for a world box (the union of several grids' boxes).
Camera frameBox(const openvdb::BBoxd& box, int width, int height, double fov = 40.0);

struct RenderSettings
{
    int width = 640, height = 480;
    Camera camera;
    /// Colour the surface by a scalar grid through @a colormap over [lo, hi], or by a vector
    /// grid's direction; neither: light grey.
    openvdb::FloatGrid::ConstPtr colorScalar;
    openvdb::Vec3SGrid::ConstPtr colorVector;
    std::optional<Colormap> colormap;
    double lo = 0.0, hi = 1.0;
};

/// @brief Check an image size before anything is computed: each side in limits::kImageSide, and
/// the image's buffers within util::memoryBudget().
/// @throw ParamError (parameter "size") saying which and why
void checkImageSize(int width, int height);

/// @brief The range of a grid's active values (and tiles), [lo, hi] with hi > lo (lo + 1 when
/// every value is the same): the default colour range.
std::pair<double, double> valueRange(const openvdb::FloatGrid& grid);

/// @brief A rendered image: rows top to bottom. Colours are sRGB-encoded in [0, 1] (as a PNG
/// stores them); alpha is 1 on the surface, 0 on the background; depth is the world distance
/// from the eye (infinity on the background); normals are world-space unit vectors.
struct Image
{
    int width = 0, height = 0;
    std::vector<openvdb::Vec3f> rgb, normal;
    std::vector<float> alpha, depth;
};

/// @brief An empty image of @a width x @a height: white, alpha 0, depth infinity, normals 0.
Image blankImage(int width, int height);

/// @brief Ray-trace the zero surface of a level set (openvdb::tools::LevelSetRayIntersector),
/// one ray a pixel, in parallel over rows; Lambert shading from a light above the eye.
/// @throw ParamError for a size outside [1, 16384] or too large for memory
/// @throw openvdb::ValueError for a degenerate camera
Image renderLevelSet(const openvdb::FloatGrid& grid, const RenderSettings& settings);

/// @brief The colour bar's labels of @a lo, (lo + hi) / 2 and @a hi, in that order: printf's
/// %g in the C locale with the fewest significant digits, at least 3, that tell the three
/// apart ("-50", "0", "50"; "0.001", "0.0015", "0.002"; "-1e+05", "1e+05", "3e+05"). A
/// midpoint within 1/1000 of hi - lo from zero is "0" (the same colour); no label is "-0".
/// @throw openvdb::ValueError unless lo < hi, both finite
std::array<std::string, 3> colorBarTicks(double lo, double hi);

/// @brief Draw a labelled vertical colour bar of @a map over [lo, hi] at the right of @a image:
/// the gradient (hi at the top, lo at the bottom) in a dark frame, tick marks at its top,
/// middle and bottom rows labelled with colorBarTicks() (right-aligned against the bar), and
/// @a label (the quantity's name and units, e.g. "curvature (1/length)") above it,
/// right-aligned with the bar. Text is dark on a white backing (85% opaque) and sets alpha, so
/// a PNG shows it over the background; its scale is textScale() of the image. A label too wide
/// for the image loses its " (...)" part, then its end ("..").
/// An image too small for the bar and its three values (under about 50 pixels tall at scale 1,
/// or too narrow for the values) is left unchanged.
/// @throw openvdb::ValueError unless lo < hi, both finite, or if the image's buffers do not
/// hold width x height pixels
void drawColorBar(Image& image, const Colormap& map, double lo, double hi, const std::string& label);

/// @brief 8-bit sRGB RGBA PNG through libpng, written atomically.
/// @throw openvdb::IoError naming the path
void writePng(const std::string& path, const Image& image);

/// @brief OpenEXR with linear R, G, B, A (half or float), Z (depth) and N.X, N.Y, N.Z (normal),
/// written atomically.
/// @throw openvdb::IoError naming the path
void writeExr(const std::string& path, const Image& image, bool halfFloat = true);

} // namespace ivdb::render
