// ivdb render: a ray-traced, shaded image of a level set's surface (PNG or EXR).
#include "Cli.h"

#include <ivdb/io/VdbFile.h>
#include <ivdb/render/Render.h>
#include <ivdb/util/System.h>

#include <openvdb/tools/Count.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <sstream>

namespace ivdb::cli {

namespace {

namespace fs = std::filesystem;

struct RenderOptions
{
    std::string input, output, grid, size = "640x480", camera, colorBy, colormap = "hsv", range;
    bool quiet = false, floatExr = false, colormapGiven = false;
};

std::vector<double> numbers(const std::string& text, char sep, const std::string& what)
{
    std::vector<double> out;
    std::stringstream ss(text);
    std::string part;
    while (std::getline(ss, part, sep)) {
        size_t used = 0;
        double v = std::nan("");
        try {
            v = std::stod(part, &used);
        } catch (const std::exception&) {
        }
        if (used != part.size() || !std::isfinite(v)) {
            throw std::runtime_error(what + ": '" + part + "' is not a finite number");
        }
        out.push_back(v);
    }
    return out;
}

// "eye=x,y,z,target=x,y,z,fov=deg" (any subset; the rest from the automatic framing).
render::Camera parseCamera(const std::string& text, render::Camera cam)
{
    std::string rest = text;
    size_t pos = 0;
    while (pos < rest.size()) {
        const size_t eq = rest.find('=', pos);
        if (eq == std::string::npos) break;
        const std::string key = rest.substr(pos, eq - pos);
        size_t next = rest.find('=', eq + 1);
        size_t end = rest.size();
        if (next != std::string::npos) end = rest.rfind(',', next);
        const std::string value = rest.substr(eq + 1, end - eq - 1);
        if (key == "eye" || key == "target") {
            const auto v = numbers(value, ',', "--camera " + key);
            if (v.size() != 3) throw std::runtime_error("--camera " + key + " needs x,y,z, got '" + value + "'");
            (key == "eye" ? cam.eye : cam.target) = openvdb::Vec3d(v[0], v[1], v[2]);
        } else if (key == "fov") {
            const auto v = numbers(value, ',', "--camera fov");
            if (v.size() != 1 || !(v[0] > 0.0 && v[0] < 180.0)) {
                throw std::runtime_error("--camera fov must be in (0, 180) degrees, got '" + value + "'");
            }
            cam.fov = v[0];
        } else {
            throw std::runtime_error("--camera: unknown key '" + key + "' (use eye=x,y,z,target=x,y,z,fov=deg)");
        }
        pos = end + 1;
    }
    if (pos < rest.size() || rest.empty()) {
        throw std::runtime_error("--camera must be eye=x,y,z,target=x,y,z,fov=deg (any of them), got '" + text + "'");
    }
    return cam;
}

int runRender(const RenderOptions& opt)
{
    const auto t0 = std::chrono::steady_clock::now();
    std::string ext = fs::path(opt.output).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (ext != ".png" && ext != ".exr") {
        throw std::runtime_error(opt.output + ": the output must end in .png or .exr");
    }
    int w = 0, h = 0;
    {
        char x = 0;
        std::istringstream ss(opt.size);
        if (!(ss >> w >> x >> h) || x != 'x' || !ss.eof() || w < 1 || h < 1 || w > 16384 || h > 16384) {
            throw std::runtime_error("--size must be WxH with each in [1, 16384], got '" + opt.size + "'");
        }
    }
    {
        // The image's buffers (colour, alpha, depth, normal) and the encoder's copy.
        const double need = double(w) * double(h) * 48.0;
        const double available = double(util::availableMemory()); // 0 when unknown
        if (available > 0.0 && need > 0.8 * available) {
            throw std::runtime_error("--size " + opt.size + ": the image needs about " +
                                     util::formatBytes(need) + " but only " +
                                     util::formatBytes(0.8 * available) +
                                     " may be used: use a smaller --size");
        }
    }
    std::optional<std::pair<double, double>> range;
    if (!opt.range.empty()) range = parseRange(opt.range);
    render::RenderSettings s;
    s.width = w;
    s.height = h;
    s.colormap.emplace(opt.colormap); // refuses an unknown name
    io::checkOutputPath(opt.output);

    openvdb::FloatGrid::Ptr surface = readLevelSet(opt.input, opt.grid);
    s.camera = render::frameGrid(*surface, w, h);
    if (!opt.camera.empty()) s.camera = parseCamera(opt.camera, s.camera);
    bool scalar = false;
    if (!opt.colorBy.empty()) {
        const openvdb::GridBase::Ptr g = readColorGrid(opt.colorBy, bool(range), opt.colormapGiven);
        if (auto f = openvdb::GridBase::grid<openvdb::FloatGrid>(g)) {
            s.colorScalar = f;
            scalar = true;
            if (range) {
                s.lo = range->first;
                s.hi = range->second;
            } else {
                const auto mm = openvdb::tools::minMax(f->tree());
                s.lo = mm.min();
                s.hi = mm.max() > mm.min() ? double(mm.max()) : s.lo + 1.0;
            }
        } else {
            s.colorVector = openvdb::GridBase::grid<openvdb::Vec3SGrid>(g);
        }
    }
    render::Image image = render::renderLevelSet(*surface, s);
    if (scalar && ext == ".png") render::drawColorBar(image, *s.colormap);
    if (ext == ".png") render::writePng(opt.output, image);
    else render::writeExr(opt.output, image, !opt.floatExr);
    if (!opt.quiet) {
        size_t hits = 0;
        for (float a : image.alpha) hits += a > 0.0f;
        std::printf("%s: %dx%d, %zu pixels on the surface, %.3f s -> %s\n", opt.input.c_str(), w, h,
                    hits, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
                    opt.output.c_str());
    }
    return 0;
}

} // namespace

void addRender(CLI::App& app, Action& action)
{
    auto opt = std::make_shared<RenderOptions>();
    CLI::App* cmd = app.add_subcommand("render",
        "Ray-trace a level set's surface into a shaded PNG (8-bit sRGB) or EXR (linear RGBA, "
        "depth Z, normal N.X/N.Y/N.Z)");
    cmd->add_option("input", opt->input, "Input .vdb file")->required();
    cmd->add_option("-o,--output", opt->output, "Output .png or .exr (written atomically)")->required();
    cmd->add_option("--grid", opt->grid, "Level set to render (default: the first level set)");
    cmd->add_option("--size", opt->size, "Image size WxH")->capture_default_str();
    cmd->add_option("--camera", opt->camera,
                    "eye=x,y,z,target=x,y,z,fov=deg (any subset; default: framed automatically, "
                    "fov 40)");
    cmd->add_option("--color-by", opt->colorBy,
                    "FILE.vdb[:GRID]: colour the surface by a scalar grid through the colormap "
                    "(with a colour bar on PNG), or by a vector grid's direction");
    cmd->add_option("--colormap", opt->colormap, "hsv, viridis, coolwarm or gray")->capture_default_str();
    cmd->add_flag("--float", opt->floatExr, "EXR colour and alpha as 32-bit float (default half)");
    cmd->add_option("--range", opt->range, "LO,HI mapped to the colormap's ends (default: the grid's "
                    "active value range)");
    cmd->add_flag("-q,--quiet", opt->quiet, "Do not print the summary line");
    cmd->callback([&action, opt, cmd]() {
        opt->colormapGiven = cmd->count("--colormap") > 0;
        action = [opt]() { return runRender(*opt); };
    });
}

} // namespace ivdb::cli
