// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/Visualize.h>

#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Inputs.h>
#include <ivdb/scene/Animation.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

namespace ivdb::jobs {

namespace {

void checkExtension(const std::string& path, const std::vector<std::string>& allowed)
{
    const std::string ext = util::extensionOf(path);
    std::string list;
    for (const auto& a : allowed) {
        if (ext == a) return;
        list += (list.empty() ? "" : " or ") + a;
    }
    throw ParamError(param::kOutput, "must end in " + list + ", got '" + path + "'");
}

} // namespace

MeshResult mesh(const MeshOptions& opt)
{
    Stopwatch clock;
    checkExtension(opt.output, {".obj", ".ply"});
    check(limits::kAdaptivity, opt.adaptivity);
    const render::Colormap colormap(opt.colormap.value_or("viridis")); // refuses an unknown name
    io::checkOutputPath(opt.output);

    const openvdb::FloatGrid::Ptr surface = readLevelSet(opt.input, opt.grid);
    openvdb::GridBase::Ptr colorGrid;
    if (!opt.colorBy.empty()) {
        colorGrid = readColorGrid(opt.colorBy, opt.range.has_value(), opt.colormap.has_value());
    }
    MeshResult result;
    result.mesh = mesh::meshLevelSet(*surface, opt.adaptivity);
    if (result.mesh.faceCount() == 0) {
        OPENVDB_THROW(openvdb::RuntimeError, opt.input + ": the level set has no surface to "
                      "mesh; nothing was written");
    }
    if (colorGrid) {
        const mesh::VertexData data = mesh::sampleVertexData(result.mesh, *colorGrid, colormap, opt.range);
        mesh::writeMesh(opt.output, result.mesh, &data);
    } else {
        mesh::writeMesh(opt.output, result.mesh);
    }
    result.enclosedVolume = mesh::enclosedVolume(result.mesh);
    result.seconds = clock.total();
    return result;
}

namespace {

/// The grid named @a name, or the first vec3s grid, of @a grids (from @a path).
openvdb::Vec3SGrid::Ptr vectorGrid(const openvdb::GridPtrVec& grids, const std::string& path,
                                   const std::string& name)
{
    openvdb::GridBase::Ptr chosen;
    if (!name.empty()) {
        chosen = io::selectGrid(grids, path, name);
    } else {
        for (const auto& g : grids) {
            if (g->isType<openvdb::Vec3SGrid>()) {
                chosen = g;
                break;
            }
        }
        if (!chosen) {
            throw ParamError(param::kGrid, "holds no vec3s (vector) grid; make one with the "
                             "gradient of a level set", path, ParamError::Kind::Missing);
        }
    }
    auto field = openvdb::GridBase::grid<openvdb::Vec3SGrid>(chosen);
    if (!field) {
        throw ParamError(param::kGrid, "'" + chosen->getName() + "' is a " + chosen->valueType() +
                         " grid; arrows need a vec3s grid", path);
    }
    io::checkGridValues(*field, path);
    return field;
}

} // namespace

GlyphsResult glyphs(const GlyphsOptions& opt)
{
    checkExtension(opt.output, {".obj", ".ply"});
    check(limits::kStride, opt.stride);
    check(limits::kLength, opt.length);
    check(limits::kNear, opt.near);
    io::checkOutputPath(opt.output);
    const openvdb::GridPtrVec grids = io::readVdb(opt.input);
    const openvdb::Vec3SGrid::Ptr field = vectorGrid(grids, opt.input, opt.grid);
    // Near the surface: the file's level set (a gradient written with its input), if it has one.
    openvdb::FloatGrid::Ptr surface;
    for (const auto& g : grids) {
        if (g->getGridClass() == openvdb::GRID_LEVEL_SET && g->isType<openvdb::FloatGrid>()) {
            surface = openvdb::GridBase::grid<openvdb::FloatGrid>(g);
            io::checkGridValues(*surface, opt.input);
            break;
        }
    }
    GlyphsResult result;
    result.field = field->getName();
    result.length = opt.length > 0.0 ? opt.length : 2.0 * opt.stride * field->voxelSize()[0];
    const mesh::ArrowSamples at = mesh::sampleArrows(*field, surface.get(), opt.stride, opt.near);
    mesh::VertexData data;
    const mesh::Mesh m = mesh::arrows(at.bases, at.vectors, result.length, &data.colors);
    if (m.faceCount() == 0) {
        OPENVDB_THROW(openvdb::RuntimeError, opt.input + ": no arrows (no non-zero vector at the "
                      "chosen voxels; try a smaller stride or a larger distance to the surface); "
                      "nothing was written");
    }
    mesh::writeMesh(opt.output, m, &data);
    result.arrows = at.bases.size();
    return result;
}

namespace {

render::Camera chooseCamera(const openvdb::FloatGrid& surface, const RenderOptions& opt)
{
    render::Camera cam = render::frameGrid(surface, opt.width, opt.height);
    if (opt.camera.eye) cam.eye = *opt.camera.eye;
    if (opt.camera.target) cam.target = *opt.camera.target;
    if (opt.camera.fov) {
        check(limits::kFov, *opt.camera.fov);
        cam.fov = *opt.camera.fov;
    }
    return cam;
}

} // namespace

std::string colorBarLabel(const openvdb::GridBase& grid)
{
    std::string unit;
    if (const auto kind = grid.getMetadata<openvdb::StringMetadata>("ivdb_curvature")) {
        unit = kind->value().rfind("Gaussian", 0) == 0 ? "1/length^2" : "1/length";
    } else if (grid.getGridClass() == openvdb::GRID_LEVEL_SET) {
        unit = "length";
    }
    return unit.empty() ? grid.getName() : grid.getName() + " (" + unit + ")";
}

RenderResult render(const RenderOptions& opt)
{
    Stopwatch clock;
    checkExtension(opt.output, {".png", ".exr"});
    if (scene::hasFrameField(opt.input)) {
        throw ParamError(param::kFrames, "the input '" + opt.input + "' is a sequence (it has #): "
                         "choose the frames of a contact sheet", "", ParamError::Kind::Missing);
    }
    render::checkImageSize(opt.width, opt.height);
    if (opt.camera.fov) check(limits::kFov, *opt.camera.fov);
    render::RenderSettings s;
    s.width = opt.width;
    s.height = opt.height;
    s.colormap.emplace(opt.colormap.value_or("hsv")); // refuses an unknown name
    io::checkOutputPath(opt.output);

    const openvdb::FloatGrid::Ptr surface = readLevelSet(opt.input, opt.grid);
    s.camera = chooseCamera(*surface, opt);
    bool scalar = false;
    if (!opt.colorBy.empty()) {
        const openvdb::GridBase::Ptr g =
            readColorGrid(opt.colorBy, opt.range.has_value(), opt.colormap.has_value());
        if (auto f = openvdb::GridBase::grid<openvdb::FloatGrid>(g)) {
            s.colorScalar = f;
            scalar = true;
            std::tie(s.lo, s.hi) = opt.range ? *opt.range : render::valueRange(*f);
        } else {
            s.colorVector = openvdb::GridBase::grid<openvdb::Vec3SGrid>(g);
        }
    }
    render::Image image = render::renderLevelSet(*surface, s);
    const bool png = util::extensionOf(opt.output) == ".png";
    if (scalar && png) render::drawColorBar(image, *s.colormap, s.lo, s.hi, colorBarLabel(*s.colorScalar));
    if (png) render::writePng(opt.output, image);
    else render::writeExr(opt.output, image, !opt.floatExr);
    RenderResult result;
    result.width = opt.width;
    result.height = opt.height;
    for (float a : image.alpha) result.surfacePixels += a > 0.0f;
    result.seconds = clock.total();
    return result;
}

} // namespace ivdb::jobs
