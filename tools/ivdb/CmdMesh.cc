// ivdb mesh: a level set's surface as an OBJ or PLY mesh, optionally coloured by another grid.
#include "Cli.h"

#include <ivdb/io/VdbFile.h>
#include <ivdb/mesh/Mesh.h>
#include <ivdb/render/Colormap.h>
#include <ivdb/util/System.h>

#include <openvdb/tools/Interpolation.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>

namespace ivdb::cli {

namespace {

namespace fs = std::filesystem;

struct MeshOptions
{
    std::string input, output, grid, colorBy, colormap = "viridis", range;
    double adaptivity = 0.0;
    bool quiet = false, colormapGiven = false;
};

std::string extensionOf(const std::string& path)
{
    std::string e = fs::path(path).extension().string();
    std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return e;
}

int runMesh(const MeshOptions& opt)
{
    const auto t0 = std::chrono::steady_clock::now();
    const std::string ext = extensionOf(opt.output);
    if (ext != ".obj" && ext != ".ply") {
        throw std::runtime_error(opt.output + ": the output must end in .obj or .ply");
    }
    if (!(opt.adaptivity >= 0.0 && opt.adaptivity <= 1.0)) {
        throw std::runtime_error("--adaptivity must be in [0, 1], got " +
                                 util::formatNumber(opt.adaptivity));
    }
    std::optional<std::pair<double, double>> range;
    if (!opt.range.empty()) range = parseRange(opt.range);
    const render::Colormap colormap(opt.colormap); // refuses an unknown name
    io::checkOutputPath(opt.output);

    openvdb::FloatGrid::Ptr surface = readLevelSet(opt.input, opt.grid);
    openvdb::GridBase::Ptr colorGrid;
    if (!opt.colorBy.empty()) colorGrid = readColorGrid(opt.colorBy, bool(range), opt.colormapGiven);

    const mesh::Mesh m = mesh::meshLevelSet(*surface, opt.adaptivity);
    if (m.faceCount() == 0) {
        throw std::runtime_error(opt.input + ": the level set has no surface to mesh; nothing "
                                 "was written");
    }
    mesh::VertexData data;
    if (colorGrid) {
        data.colors.resize(m.points.size());
        data.scalars.resize(m.points.size());
        if (auto g = openvdb::GridBase::grid<openvdb::FloatGrid>(colorGrid)) {
            data.scalarName = g->getName().empty() ? "value" : g->getName();
            openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> s(*g);
            for (size_t i = 0; i < m.points.size(); ++i) data.scalars[i] = s.wsSample(m.points[i]);
            double lo = range ? range->first : std::numeric_limits<double>::max();
            double hi = range ? range->second : -std::numeric_limits<double>::max();
            if (!range) {
                for (float v : data.scalars) lo = std::min(lo, double(v)), hi = std::max(hi, double(v));
                if (!(lo < hi)) hi = lo + 1.0;
            }
            for (size_t i = 0; i < m.points.size(); ++i) {
                data.colors[i] = colormap.map(data.scalars[i], lo, hi);
            }
        } else {
            // A vector grid (a gradient): colour by direction, the scalar is the magnitude.
            auto v = openvdb::GridBase::grid<openvdb::Vec3SGrid>(colorGrid);
            data.scalarName = "magnitude";
            openvdb::tools::GridSampler<openvdb::Vec3SGrid, openvdb::tools::BoxSampler> s(*v);
            for (size_t i = 0; i < m.points.size(); ++i) {
                openvdb::Vec3s d = s.wsSample(m.points[i]);
                data.scalars[i] = d.length();
                if (d.length() > 0.0f) d.normalize();
                data.colors[i] = d * 0.5f + openvdb::Vec3s(0.5f);
            }
        }
    }
    if (ext == ".obj") mesh::writeObj(opt.output, m, colorGrid ? &data : nullptr);
    else mesh::writePly(opt.output, m, colorGrid ? &data : nullptr);
    if (!opt.quiet) {
        std::printf("%s: %zu vertices, %zu triangles, %zu quads, enclosed volume %.6g, %.3f s -> %s\n",
                    opt.input.c_str(), m.points.size(), m.triangles.size(), m.quads.size(),
                    mesh::enclosedVolume(m),
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
                    opt.output.c_str());
    }
    return 0;
}

} // namespace

void addMesh(CLI::App& app, Action& action)
{
    auto opt = std::make_shared<MeshOptions>();
    CLI::App* cmd = app.add_subcommand("mesh",
        "Mesh a level set's surface (openvdb::tools::volumeToMesh) into OBJ or PLY, "
        "optionally coloured by another grid");
    cmd->add_option("input", opt->input, "Input .vdb file")->required();
    cmd->add_option("-o,--output", opt->output, "Output .obj or .ply (written atomically)")
        ->required();
    cmd->add_option("--grid", opt->grid, "Level set to mesh (default: the first level set)");
    cmd->add_option("--adaptivity", opt->adaptivity,
                    "0 keeps every voxel's face; up to 1 merges flat regions")
        ->capture_default_str();
    cmd->add_option("--color-by", opt->colorBy,
                    "FILE.vdb[:GRID]: colour the vertices by a scalar grid through the colormap, "
                    "or by a vector grid's direction; PLY also stores the sampled value");
    cmd->add_option("--colormap", opt->colormap, "hsv, viridis, coolwarm or gray")
        ->capture_default_str();
    cmd->add_option("--range", opt->range,
                    "LO,HI: the values mapped to the colormap's ends (default: the sampled "
                    "values' range)");
    cmd->add_flag("-q,--quiet", opt->quiet, "Do not print the summary line");
    cmd->callback([&action, opt, cmd]() {
        opt->colormapGiven = cmd->count("--colormap") > 0;
        action = [opt]() { return runMesh(*opt); };
    });
}

} // namespace ivdb::cli
