// ivdb glyphs: arrows of a vector grid (a gradient) near the surface, as an OBJ or PLY mesh.
#include "Cli.h"

#include <ivdb/io/VdbFile.h>
#include <ivdb/mesh/Mesh.h>
#include <ivdb/util/System.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

namespace ivdb::cli {

namespace {

struct GlyphsOptions
{
    std::string input, output, grid;
    int stride = 4;
    double length = 0.0;
    double near = 0.5;
    bool quiet = false;
};

int runGlyphs(const GlyphsOptions& opt)
{
    std::string ext = std::filesystem::path(opt.output).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (ext != ".obj" && ext != ".ply") {
        throw std::runtime_error(opt.output + ": the output must end in .obj or .ply");
    }
    if (opt.stride < 1 || opt.stride > 1000) {
        throw std::runtime_error("--stride must be in [1, 1000] voxels, got " + std::to_string(opt.stride));
    }
    if (!(opt.length >= 0.0) || !std::isfinite(opt.length)) {
        throw std::runtime_error("--length must be >= 0 and finite (0: twice the stride in voxels), got " +
                                 util::formatNumber(opt.length));
    }
    if (!(opt.near > 0.0) || !std::isfinite(opt.near)) {
        throw std::runtime_error("--near must be > 0 voxels, got " + util::formatNumber(opt.near));
    }
    io::checkOutputPath(opt.output);
    const openvdb::GridPtrVec grids = io::readVdb(opt.input);
    openvdb::GridBase::Ptr chosen;
    if (!opt.grid.empty()) {
        chosen = io::selectGrid(grids, opt.input, opt.grid);
    } else {
        for (const auto& g : grids) {
            if (g->isType<openvdb::Vec3SGrid>()) {
                chosen = g;
                break;
            }
        }
        if (!chosen) {
            throw std::runtime_error(opt.input + ": no vec3s (vector) grid in the file; make one "
                                     "with 'ivdb gradient'");
        }
    }
    auto field = openvdb::GridBase::grid<openvdb::Vec3SGrid>(chosen);
    if (!field) {
        throw std::runtime_error(opt.input + ": grid '" + chosen->getName() + "' is a " +
                                 chosen->valueType() + " grid; glyphs need a vec3s grid");
    }
    io::checkGridValues(*field, opt.input);
    // Near the surface: the file's level set (ivdb gradient --with-input), if it has one.
    openvdb::FloatGrid::Ptr surface;
    for (const auto& g : grids) {
        if (g->getGridClass() == openvdb::GRID_LEVEL_SET && g->isType<openvdb::FloatGrid>()) {
            surface = openvdb::GridBase::grid<openvdb::FloatGrid>(g);
            io::checkGridValues(*surface, opt.input);
            break;
        }
    }
    const double dx = field->voxelSize()[0];
    const double length = opt.length > 0.0 ? opt.length : 2.0 * opt.stride * dx;
    std::vector<openvdb::Vec3d> bases, vectors;
    auto surfaceAcc = surface ? std::make_unique<openvdb::FloatGrid::ConstAccessor>(surface->getConstAccessor())
                              : nullptr;
    for (auto it = field->cbeginValueOn(); it; ++it) {
        if (!it.isVoxelValue()) continue;
        const openvdb::Coord ijk = it.getCoord();
        if (ijk.x() % opt.stride || ijk.y() % opt.stride || ijk.z() % opt.stride) continue;
        const openvdb::Vec3d world = field->indexToWorld(ijk);
        if (surfaceAcc) {
            const openvdb::Coord s = surface->transform().worldToIndexCellCentered(world);
            if (!(std::abs(surfaceAcc->getValue(s)) < opt.near * surface->voxelSize()[0])) continue;
        }
        bases.push_back(world);
        vectors.emplace_back(*it);
    }
    std::vector<openvdb::Vec3f> colors;
    const mesh::Mesh m = mesh::arrows(bases, vectors, length, &colors);
    if (m.faceCount() == 0) {
        throw std::runtime_error(opt.input + ": no arrows (no non-zero vector at the chosen voxels; "
                                 "try a smaller --stride or a larger --near); nothing was written");
    }
    mesh::VertexData data;
    data.colors = colors;
    if (ext == ".obj") mesh::writeObj(opt.output, m, &data);
    else mesh::writePly(opt.output, m, &data);
    if (!opt.quiet) {
        std::printf("%s: %zu arrows of grid '%s' (stride %d, length %g) -> %s\n", opt.input.c_str(),
                    bases.size(), field->getName().c_str(), opt.stride, length, opt.output.c_str());
    }
    return 0;
}

} // namespace

void addGlyphs(CLI::App& app, Action& action)
{
    auto opt = std::make_shared<GlyphsOptions>();
    CLI::App* cmd = app.add_subcommand("glyphs",
        "Arrows of a vector grid (a gradient) near the surface as an OBJ or PLY mesh");
    cmd->add_option("input", opt->input, "Input .vdb with a vec3s grid (ivdb gradient)")->required();
    cmd->add_option("-o,--output", opt->output, "Output .obj or .ply (written atomically)")
        ->required();
    cmd->add_option("--grid", opt->grid, "Vector grid (default: the first vec3s grid)");
    cmd->add_option("--stride", opt->stride, "One arrow every N voxels along each axis")
        ->capture_default_str();
    cmd->add_option("--length", opt->length,
                    "World length of an arrow per unit of the vector (default: twice the stride "
                    "in voxels)");
    cmd->add_option("--near", opt->near,
                    "With a level set in the file (gradient --with-input), only voxels where "
                    "|phi| < NEAR voxels")
        ->capture_default_str();
    cmd->add_flag("-q,--quiet", opt->quiet, "Do not print the summary line");
    cmd->callback([&action, opt]() { action = [opt]() { return runGlyphs(*opt); }; });
}

} // namespace ivdb::cli
