// SPDX-License-Identifier: Apache-2.0
// ivdb render: a ray-traced, shaded image of a level set's surface (PNG or EXR).
#include "Cli.h"

#include <ivdb/jobs/ContactSheet.h>
#include <ivdb/jobs/Visualize.h>

#include <cmath>
#include <cstdio>
#include <sstream>

namespace ivdb::cli {

namespace {

struct RenderArgs
{
    jobs::RenderOptions job;
    std::string size = "640x480", camera, colormap = "hsv", range, frames;
    int columns = 4;
    bool colormapGiven = false, quiet = false;
};

std::vector<double> numbers(const std::string& text, const std::string& what)
{
    std::vector<double> out;
    std::stringstream ss(text);
    std::string part;
    while (std::getline(ss, part, ',')) {
        size_t used = 0;
        double v = std::nan("");
        try {
            v = std::stod(part, &used);
        } catch (const std::exception&) {
        }
        if (used != part.size() || !std::isfinite(v)) {
            throw ParamError(param::kCamera, what + ": '" + part + "' is not a finite number");
        }
        out.push_back(v);
    }
    return out;
}

// "eye=x,y,z,target=x,y,z,fov=deg" (any subset; the rest from the automatic framing).
jobs::CameraChoice parseCamera(const std::string& text)
{
    jobs::CameraChoice cam;
    size_t pos = 0;
    while (pos < text.size()) {
        const size_t eq = text.find('=', pos);
        if (eq == std::string::npos) break;
        const std::string key = text.substr(pos, eq - pos);
        const size_t next = text.find('=', eq + 1);
        const size_t end = next == std::string::npos ? text.size() : text.rfind(',', next);
        const std::string value = text.substr(eq + 1, end - eq - 1);
        if (key == "eye" || key == "target") {
            const auto v = numbers(value, key);
            if (v.size() != 3) throw ParamError(param::kCamera, key + " needs x,y,z, got '" + value + "'");
            (key == "eye" ? cam.eye : cam.target) = openvdb::Vec3d(v[0], v[1], v[2]);
        } else if (key == "fov") {
            const auto v = numbers(value, "fov");
            if (v.size() != 1) throw ParamError(param::kCamera, "fov needs one number, got '" + value + "'");
            cam.fov = v[0];
        } else {
            throw ParamError(param::kCamera, "has an unknown key '" + key +
                             "' (use eye=x,y,z,target=x,y,z,fov=deg)");
        }
        pos = end + 1;
    }
    if (pos < text.size() || text.empty()) {
        throw ParamError(param::kCamera, "must be eye=x,y,z,target=x,y,z,fov=deg (any of them), "
                                         "got '" + text + "'");
    }
    return cam;
}

// "WxH"; the library checks the range.
void parseSize(const std::string& text, int& w, int& h)
{
    char x = 0;
    std::istringstream ss(text);
    if (!(ss >> w >> x >> h) || x != 'x' || !ss.eof()) {
        throw ParamError(param::kImageSize, "must be WxH with each in [1, 16384], got '" + text + "'");
    }
}

int runRender(RenderArgs& a)
{
    parseSize(a.size, a.job.width, a.job.height);
    if (!a.range.empty()) a.job.range = parseRange(a.range);
    if (!a.camera.empty()) a.job.camera = parseCamera(a.camera);
    if (a.colormapGiven) a.job.colormap = a.colormap;
    jobs::ContactSheetOptions sheet;
    if (!a.frames.empty()) {
        sheet.base = a.job;
        sheet.frames = scene::parseFrameRange(a.frames);
        sheet.columns = a.columns;
    }
    const jobs::RenderResult r = a.frames.empty() ? jobs::render(a.job) : jobs::contactSheet(sheet);
    if (!a.quiet) {
        std::printf("%s: %dx%d, %zu pixels on the surface, %.3f s -> %s\n", a.job.input.c_str(),
                    r.width, r.height, r.surfacePixels, r.seconds, a.job.output.c_str());
    }
    return 0;
}

} // namespace

void addRender(CLI::App& app, Action& action)
{
    auto a = std::make_shared<RenderArgs>();
    Command cmd(app, "render",
        "Ray-trace a level set's surface into a shaded PNG (8-bit sRGB) or EXR (linear RGBA, "
        "depth Z, normal N.X/N.Y/N.Z)");
    cmd.add("input", a->job.input, "Input .vdb file")->required();
    cmd.add("-o,--output", a->job.output, "Output .png or .exr (written atomically)", &param::kOutput)
        ->required();
    cmd.add("--grid", a->job.grid, "Level set to render (default: the first level set)", &param::kGrid);
    cmd.add("--size", a->size, "Image size WxH", &param::kImageSize)->capture_default_str();
    cmd.add("--camera", a->camera,
            "eye=x,y,z,target=x,y,z,fov=deg (any subset; default: framed automatically, fov 40)",
            &param::kCamera);
    cmd.name(param::kFov, "--camera fov");
    cmd.add("--color-by", a->job.colorBy,
            "FILE.vdb[:GRID]: colour the surface by a scalar grid through the colormap (on PNG "
            "with a colour bar labelled with the range and the grid's name), or by a vector "
            "grid's direction", &param::kColorBy);
    CLI::Option* colormap = cmd.add("--colormap", a->colormap, "hsv, viridis, coolwarm or gray",
                                    &param::kColormap)
        ->capture_default_str();
    cmd.flag("--float", a->job.floatExr, "EXR colour and alpha as 32-bit float (default half)");
    cmd.add("--range", a->range,
            "LO,HI mapped to the colormap's ends (default: the grid's active value range)",
            &param::kRange);
    cmd.add("--frames", a->frames,
            "A-B[:STEP]: a contact sheet of these frames of a sequence (input and --color-by "
            "with # for the frame number), one tile of --size per frame", &param::kFrames);
    cmd.add("--columns", a->columns, "Tiles across a contact sheet, in [1, 64]", &param::kColumns)
        ->capture_default_str();
    addQuietFlag(cmd, a->quiet);
    cmd.onRun(action, [a, colormap]() {
        a->colormapGiven = colormap->count() > 0;
        return runRender(*a);
    });
}

} // namespace ivdb::cli
