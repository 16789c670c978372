// SPDX-License-Identifier: Apache-2.0
#include <ivdb/render/Render.h>

#include <ivdb/io/AtomicFile.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <openvdb/math/Ray.h>
#include <openvdb/tools/Count.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/RayIntersector.h>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStdIO.h>

#include <png.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace ivdb::render {

namespace {

using Vec3d = openvdb::Vec3d;

float srgbToLinear(float c)
{
    return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

} // namespace

Image blankImage(int width, int height)
{
    Image img;
    img.width = width;
    img.height = height;
    const size_t n = size_t(width) * size_t(height);
    img.rgb.assign(n, openvdb::Vec3f(1.0f));
    img.normal.assign(n, openvdb::Vec3f(0.0f));
    img.alpha.assign(n, 0.0f);
    img.depth.assign(n, std::numeric_limits<float>::infinity());
    return img;
}

Camera frameBox(const openvdb::BBoxd& box, int width, int height, double fov)
{
    Camera cam;
    cam.fov = fov;
    const Vec3d lo = box.min(), hi = box.max();
    cam.target = 0.5 * (lo + hi);
    const double radius = 0.5 * (hi - lo).length();
    // The bounding sphere fits the narrower of the two fields of view, with a 10% margin.
    const double half = 0.5 * fov * M_PI / 180.0;
    const double halfH = std::atan(std::tan(half) * double(width) / double(height));
    const double distance = 1.1 * radius / std::sin(std::min(half, halfH));
    cam.eye = cam.target + Vec3d(1.0, 0.8, 1.3).unitSafe() * distance;
    return cam;
}

Camera frameGrid(const openvdb::FloatGrid& grid, int width, int height, double fov)
{
    const openvdb::CoordBBox box = grid.evalActiveVoxelBoundingBox();
    if (box.empty()) {
        Camera cam;
        cam.fov = fov;
        return cam;
    }
    return frameBox(openvdb::BBoxd(grid.indexToWorld(box.min()), grid.indexToWorld(box.max())),
                    width, height, fov);
}

void checkImageSize(int width, int height)
{
    const std::string size = std::to_string(width) + "x" + std::to_string(height);
    if (!limits::kImageSide.contains(width) || !limits::kImageSide.contains(height)) {
        throw ParamError(param::kImageSize, "must be WxH with each in [1, 16384] pixels, got " + size);
    }
    // The image's buffers (colour, alpha, depth, normal) and the encoder's copy.
    const double need = double(width) * double(height) * 48.0;
    const double limit = util::memoryBudget();
    if (need > limit) {
        throw ParamError(param::kImageSize, size + " needs about " + util::formatBytes(need) +
                         " but only " + util::formatBytes(limit) + " may be used: use a smaller "
                         "size");
    }
}

std::pair<double, double> valueRange(const openvdb::FloatGrid& grid)
{
    const auto mm = openvdb::tools::minMax(grid.tree());
    const double lo = mm.min();
    return {lo, mm.max() > mm.min() ? double(mm.max()) : lo + 1.0};
}

Image renderLevelSet(const openvdb::FloatGrid& grid, const RenderSettings& s)
{
    checkImageSize(s.width, s.height);
    const Vec3d forward = s.camera.target - s.camera.eye;
    if (!(forward.length() > 0.0) || !(s.camera.fov > 0.0 && s.camera.fov < 180.0)) {
        OPENVDB_THROW(openvdb::ValueError,
                      "the camera needs eye != target and a field of view in (0, 180) degrees");
    }
    const Vec3d f = forward.unitSafe();
    const Vec3d worldUp = std::abs(f.y()) > 0.99 ? Vec3d(0, 0, 1) : Vec3d(0, 1, 0);
    const Vec3d right = f.cross(worldUp).unitSafe(), up = right.cross(f);
    const double tanHalf = std::tan(0.5 * s.camera.fov * M_PI / 180.0);
    const double aspect = double(s.width) / double(s.height);
    const Vec3d light = (up * 0.6 + right * 0.3 - f).unitSafe(); // above, right, behind the eye

    Image img = blankImage(s.width, s.height);
    if (grid.activeVoxelCount() == 0) return img;

    using Intersector = openvdb::tools::LevelSetRayIntersector<openvdb::FloatGrid>;
    const Intersector prototype(grid);
    tbb::parallel_for(tbb::blocked_range<int>(0, s.height), [&](const tbb::blocked_range<int>& rows) {
        Intersector intersector(prototype);
        std::optional<openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler>> scalar;
        std::optional<openvdb::tools::GridSampler<openvdb::Vec3SGrid, openvdb::tools::BoxSampler>> vector;
        if (s.colorScalar) scalar.emplace(*s.colorScalar);
        if (s.colorVector) vector.emplace(*s.colorVector);
        for (int j = rows.begin(); j < rows.end(); ++j) {
            for (int i = 0; i < s.width; ++i) {
                const double x = (2.0 * (i + 0.5) / s.width - 1.0) * tanHalf * aspect;
                const double y = (1.0 - 2.0 * (j + 0.5) / s.height) * tanHalf;
                const Vec3d dir = (f + right * x + up * y).unitSafe();
                Intersector::RayType ray(s.camera.eye, dir);
                Vec3d hit, nml;
                if (!intersector.intersectsWS(ray, hit, nml)) continue;
                nml = nml.unitSafe();
                openvdb::Vec3f base(0.8f);
                if (scalar) {
                    base = s.colormap->map(scalar->wsSample(hit), s.lo, s.hi);
                } else if (vector) {
                    base = directionColor(openvdb::Vec3d(vector->wsSample(hit)));
                }
                const double lambert = std::max(0.0, nml.dot(light));
                const double viewFacing = std::abs(nml.dot(dir)); // a little headlight
                const float shade = float(0.15 + 0.7 * lambert + 0.15 * viewFacing);
                const size_t p = size_t(j) * size_t(s.width) + size_t(i);
                img.rgb[p] = base * shade;
                img.normal[p] = openvdb::Vec3f(nml);
                img.alpha[p] = 1.0f;
                img.depth[p] = float((hit - s.camera.eye).length());
            }
        }
    });
    return img;
}

void writePng(const std::string& path, const Image& image)
{
    std::vector<png_byte> pixels(size_t(image.width) * size_t(image.height) * 4);
    for (size_t p = 0; p < image.rgb.size(); ++p) {
        // A white background under the surface, opaque: what viewers and the README show.
        const float a = image.alpha[p];
        for (int c = 0; c < 3; ++c) {
            const float v = a * image.rgb[p][c] + (1.0f - a);
            pixels[4 * p + c] = png_byte(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f));
        }
        pixels[4 * p + 3] = 255;
    }
    png_image png{};
    png.version = PNG_IMAGE_VERSION;
    png.width = png_uint_32(image.width);
    png.height = png_uint_32(image.height);
    png.format = PNG_FORMAT_RGBA;
    png_alloc_size_t size = 0;
    if (!png_image_write_to_memory(&png, nullptr, &size, 0, pixels.data(), 0, nullptr)) {
        OPENVDB_THROW(openvdb::IoError, path + ": cannot encode the PNG: " + png.message);
    }
    std::vector<png_byte> encoded(size);
    if (!png_image_write_to_memory(&png, encoded.data(), &size, 0, pixels.data(), 0, nullptr)) {
        OPENVDB_THROW(openvdb::IoError, path + ": cannot encode the PNG: " + png.message);
    }
    io::writeFileAtomically(path, [&](std::ostream& os) {
        os.write(reinterpret_cast<const char*>(encoded.data()), std::streamsize(size));
    });
}

void writeExr(const std::string& path, const Image& image, bool halfFloat)
{
    const size_t n = image.rgb.size();
    std::vector<float> planes[8];
    for (auto& p : planes) p.resize(n);
    for (size_t p = 0; p < n; ++p) {
        for (int c = 0; c < 3; ++c) planes[c][p] = srgbToLinear(image.rgb[p][c]) * image.alpha[p];
        planes[3][p] = image.alpha[p];
        planes[4][p] = image.depth[p];
        for (int c = 0; c < 3; ++c) planes[5 + c][p] = image.normal[p][c];
    }
    static const char* kNames[8] = {"R", "G", "B", "A", "Z", "N.X", "N.Y", "N.Z"};
    std::ostringstream buffer;
    try {
        Imf::Header header(image.width, image.height);
        Imf::FrameBuffer fb;
        std::vector<std::vector<half>> halves(8);
        for (int c = 0; c < 8; ++c) {
            // Colours and alpha may be half; depth and normals stay float (precision).
            const bool asHalf = halfFloat && c < 4;
            header.channels().insert(kNames[c], Imf::Channel(asHalf ? Imf::HALF : Imf::FLOAT));
            if (asHalf) {
                halves[c].assign(planes[c].begin(), planes[c].end());
                fb.insert(kNames[c], Imf::Slice(Imf::HALF, reinterpret_cast<char*>(halves[c].data()),
                                                sizeof(half), sizeof(half) * size_t(image.width)));
            } else {
                fb.insert(kNames[c], Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(planes[c].data()),
                                                sizeof(float), sizeof(float) * size_t(image.width)));
            }
        }
        Imf::StdOSStream stream;
        {
            Imf::OutputFile file(stream, header);
            file.setFrameBuffer(fb);
            file.writePixels(image.height);
        }
        buffer << stream.str();
    } catch (const std::exception& e) {
        OPENVDB_THROW(openvdb::IoError, path + ": cannot encode the EXR: " + e.what());
    }
    const std::string bytes = buffer.str();
    io::writeFileAtomically(path, [&](std::ostream& os) { os.write(bytes.data(), std::streamsize(bytes.size())); });
}

} // namespace ivdb::render
