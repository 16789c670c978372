// SPDX-License-Identifier: Apache-2.0
#include <ivdb/scene/Scene.h>

#include "KeyedValues.h"
#include "../levelset/Sweeping.h"

#include <ivdb/implicit/Blend.h>
#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/GridShape.h>
#include <ivdb/implicit/Modifiers.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/implicit/Quadric.h>
#include <ivdb/jobs/Inputs.h>
#include <ivdb/mesh/MeshInput.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <openvdb/Exceptions.h>
#include <openvdb/tools/ChangeBackground.h>
#include <openvdb/tools/LevelSetRebuild.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <utility>
#include <vector>

namespace ivdb::scene {

namespace {

using nlohmann::json;
using implicit::Implicit;
using implicit::Vec3d;
using detail::brief;

/// Reads one JSON object, remembering which keys were used so unknown keys are refused.
class ObjectReader
{
public:
    ObjectReader(const json& j, std::string path, const std::string& origin)
        : mJson(j), mPath(std::move(path)), mOrigin(origin)
    {
        if (!j.is_object()) fail(mPath, "must be an object, got " + brief(j));
    }

    [[noreturn]] void fail(const std::string& path, const std::string& what) const
    {
        throw SceneError(mOrigin + ": " + (path.empty() ? std::string("(top level)") : path) +
                         ": " + what);
    }

    std::string childPath(const std::string& key) const
    {
        return mPath.empty() ? key : mPath + "." + key;
    }

    bool has(const std::string& key) const { return mJson.contains(key); }

    const json& raw(const std::string& key)
    {
        if (!mJson.contains(key)) fail(childPath(key), "is missing");
        return mJson.at(key);
    }

    double number(const std::string& key, std::optional<double> def = std::nullopt)
    {
        if (!has(key)) {
            if (def) return *def;
            fail(childPath(key), "is missing (a number)");
        }
        return toNumber(raw(key), childPath(key));
    }

    double positive(const std::string& key, std::optional<double> def = std::nullopt)
    {
        const double v = number(key, def);
        if (!(v > 0.0)) fail(childPath(key), "must be > 0, got " + util::formatNumber(v));
        return v;
    }

    Vec3d vec3(const std::string& key, std::optional<Vec3d> def = std::nullopt)
    {
        if (!has(key)) {
            if (def) return *def;
            fail(childPath(key), "is missing (an array of 3 numbers)");
        }
        return toVec3(raw(key), childPath(key));
    }

    /// A number that @a limit accepts.
    double limited(const std::string& key, const Limit& limit)
    {
        const double v = number(key);
        if (!limit.contains(v)) fail(childPath(key), limit.reason(v));
        return v;
    }

    Vec3d positiveVec3(const std::string& key, std::optional<Vec3d> def = std::nullopt)
    {
        const Vec3d v = vec3(key, def);
        for (int i = 0; i < 3; ++i) {
            if (!(v[i] > 0.0)) {
                fail(childPath(key) + "[" + std::to_string(i) + "]",
                     "must be > 0, got " + util::formatNumber(v[i]));
            }
        }
        return v;
    }

    std::string string(const std::string& key, const std::vector<std::string>& allowed,
                       std::optional<std::string> def = std::nullopt)
    {
        if (!has(key)) {
            if (def) return *def;
            fail(childPath(key), "is missing (one of " + join(allowed) + ")");
        }
        const json& v = raw(key);
        if (!v.is_string() ||
            std::find(allowed.begin(), allowed.end(), v.get<std::string>()) == allowed.end()) {
            fail(childPath(key), "must be one of " + join(allowed) + ", got " + brief(v));
        }
        return v.get<std::string>();
    }

    /// Refuse keys outside @a known (before reading any, so a misspelt key is named rather
    /// than reported as a missing one).
    void allowOnly(const std::vector<std::string>& known) const
    {
        for (auto it = mJson.begin(); it != mJson.end(); ++it) {
            if (std::find(known.begin(), known.end(), it.key()) == known.end()) {
                fail(childPath(it.key()), "unknown key; allowed here: " + join(known));
            }
        }
    }

    double toNumber(const json& v, const std::string& path) const
    {
        if (!v.is_number()) fail(path, "must be a number, got " + brief(v));
        const double d = v.get<double>();
        if (!std::isfinite(d)) fail(path, "must be finite, got " + brief(v));
        return d;
    }

    Vec3d toVec3(const json& v, const std::string& path) const
    {
        if (!v.is_array() || v.size() != 3) {
            fail(path, "must be an array of 3 numbers, got " + brief(v));
        }
        return Vec3d(toNumber(v[0], path + "[0]"), toNumber(v[1], path + "[1]"),
                     toNumber(v[2], path + "[2]"));
    }

    const std::string& path() const { return mPath; }
    const std::string& origin() const { return mOrigin; }

    static std::string join(const std::vector<std::string>& words)
    {
        std::string s;
        for (const auto& w : words) s += (s.empty() ? "" : ", ") + w;
        return s;
    }

private:
    const json& mJson;
    std::string mPath;
    const std::string& mOrigin;
};

/// What the nodes of one scene are parsed with.
struct SceneContext
{
    std::filesystem::path dir;        // relative paths of mesh and vdb nodes start here
    std::optional<double> voxelSize;  // what mesh and vdb nodes are built at
    double halfWidth;                 // the raster's half width, voxels
    std::vector<std::string>* notes;  // about mesh and vdb inputs
    bool readInputs;                  // false: mesh and vdb nodes are not built
};

/// Where a node sits: its depth, and the band (world units) within which its values must be
/// right (the raster's half width, widened by the blends, offsets and shells above it).
struct Node
{
    const SceneContext& scene;
    int depth;
    double band;
    bool lattice = true; // sampled at the raster's voxels only (no transform above)
    /// The transforms directly above a mesh node (outermost first), which move its vertices
    /// instead of its sample points (buildTransform()); @a placed of the depth is theirs.
    std::vector<std::shared_ptr<const implicit::Transform>> placement = {};
    int placed = 0;

    Node child(double childBand) const { return {scene, depth + 1, childBand, lattice}; }
};

Implicit::Ptr parseNode(const json& j, const std::string& path, const std::string& origin,
                        const Node& node);

/// Deeper trees would exhaust the evaluation stack (each level keeps a batch of values on it).
constexpr int kMaxDepth = 64;

std::vector<Implicit::Ptr> parseChildren(ObjectReader& r, std::size_t minCount, const Node& child)
{
    const json& c = r.raw("children");
    const std::string cpath = r.childPath("children");
    if (!c.is_array()) r.fail(cpath, "must be an array of shapes, got " + brief(c));
    if (c.size() < minCount) {
        r.fail(cpath, "needs at least " + std::to_string(minCount) + " shapes, got " +
                          std::to_string(c.size()));
    }
    std::vector<Implicit::Ptr> out;
    for (std::size_t i = 0; i < c.size(); ++i) {
        out.push_back(parseNode(c[i], cpath + "[" + std::to_string(i) + "]", r.origin(), child));
    }
    return out;
}

implicit::Mat4 parseMatrix(ObjectReader& r)
{
    const json& m = r.raw("matrix");
    const std::string mpath = r.childPath("matrix");
    if (!m.is_array() || m.size() != 4) {
        r.fail(mpath, "must be a 4x4 array of numbers (4 rows of 4), got " + brief(m));
    }
    implicit::Mat4 q{};
    for (std::size_t i = 0; i < 4; ++i) {
        const std::string rpath = mpath + "[" + std::to_string(i) + "]";
        if (!m[i].is_array() || m[i].size() != 4) {
            r.fail(rpath, "must be a row of 4 numbers, got " + brief(m[i]));
        }
        for (std::size_t k = 0; k < 4; ++k) {
            q[i][k] = r.toNumber(m[i][k], rpath + "[" + std::to_string(k) + "]");
        }
    }
    double scale = 0.0;
    for (auto& row : q) for (double v : row) scale = std::max(scale, std::abs(v));
    if (scale == 0.0) r.fail(mpath, "is all zero, which has no surface");
    for (int i = 0; i < 4; ++i) {
        for (int k = i + 1; k < 4; ++k) {
            if (std::abs(q[i][k] - q[k][i]) > 1e-12 * scale) {
                std::ostringstream os;
                os << "must be symmetric: [" << i << "][" << k << "] is " << q[i][k] << " but ["
                   << k << "][" << i << "] is " << q[k][i];
                r.fail(mpath, os.str());
            }
        }
    }
    return q;
}

/// A direction: three numbers, not all zero.
Vec3d axis(ObjectReader& r, const std::string& key, std::optional<Vec3d> def)
{
    const Vec3d a = r.vec3(key, def);
    if (a.length() == 0.0) r.fail(r.childPath(key), "must be non-zero, got [0, 0, 0]");
    return a;
}

const Vec3d kZero(0.0), kZAxis(0.0, 0.0, 1.0);

/// A scene node type: its JSON name, its keys (besides "type") and how to build it. A new shape
/// is one entry here plus its class.
struct NodeType
{
    const char* name;
    std::vector<std::string> keys;
    Implicit::Ptr (*build)(ObjectReader& r, const std::string& type, const Node& node);
};

Implicit::Ptr buildSphere(ObjectReader& r, const std::string&, const Node&)
{
    return std::make_shared<implicit::Sphere>(r.vec3("center", kZero), r.positive("radius"));
}

Implicit::Ptr buildBox(ObjectReader& r, const std::string&, const Node&)
{
    return std::make_shared<implicit::Box>(r.vec3("center", kZero), r.positiveVec3("size"));
}

Implicit::Ptr buildTorus(ObjectReader& r, const std::string&, const Node&)
{
    const Vec3d c = r.vec3("center", kZero);
    const double major = r.positive("major_radius"), minor = r.positive("minor_radius");
    if (!(minor < major)) {
        r.fail(r.childPath("minor_radius"), "must be < major_radius (" +
               util::formatNumber(major) + ") for a ring torus, got " + util::formatNumber(minor));
    }
    return std::make_shared<implicit::Torus>(c, major, minor);
}

Implicit::Ptr buildCapsule(ObjectReader& r, const std::string&, const Node&)
{
    return std::make_shared<implicit::Capsule>(r.vec3("a"), r.vec3("b"), r.positive("radius"));
}

Implicit::Ptr buildRoundedBox(ObjectReader& r, const std::string&, const Node&)
{
    const Vec3d c = r.vec3("center", kZero), size = r.positiveVec3("size");
    const double radius = r.positive("radius");
    const double most = 0.5 * std::min({size[0], size[1], size[2]});
    if (!(radius <= most)) {
        r.fail(r.childPath("radius"), "must be <= half the smallest size (" +
               util::formatNumber(most) + "), got " + util::formatNumber(radius));
    }
    return std::make_shared<implicit::RoundedBox>(c, size, radius);
}

/// The end points of a capped cylinder or cone: two different points.
std::pair<Vec3d, Vec3d> segment(ObjectReader& r)
{
    const Vec3d a = r.vec3("a"), b = r.vec3("b");
    if (a == b) r.fail(r.childPath("b"), "must differ from a (the axis runs from a to b)");
    return {a, b};
}

Implicit::Ptr buildCappedCylinder(ObjectReader& r, const std::string& type, const Node&)
{
    const auto [a, b] = segment(r);
    const double radius = r.positive("radius");
    return std::make_shared<implicit::CappedCone>(a, b, radius, radius, type);
}

Implicit::Ptr buildCappedCone(ObjectReader& r, const std::string& type, const Node&)
{
    const auto [a, b] = segment(r);
    double radii[2];
    const char* keys[2] = {"radius_a", "radius_b"};
    for (int i = 0; i < 2; ++i) {
        radii[i] = r.number(keys[i]);
        if (!(radii[i] >= 0.0)) {
            r.fail(r.childPath(keys[i]), "must be >= 0, got " + util::formatNumber(radii[i]));
        }
    }
    if (radii[0] == 0.0 && radii[1] == 0.0) {
        r.fail(r.childPath("radius_b"), "must be > 0 when radius_a is 0 (a cone needs a base)");
    }
    return std::make_shared<implicit::CappedCone>(a, b, radii[0], radii[1], type);
}

/// The file a mesh or vdb node names, relative to the scene file's folder.
std::string inputFile(ObjectReader& r, const Node& node)
{
    const json& f = r.raw("file");
    if (!f.is_string() || f.get<std::string>().empty()) {
        r.fail(r.childPath("file"), "must be a file name (a string), got " + brief(f));
    }
    const std::filesystem::path given(f.get<std::string>());
    const std::filesystem::path path =
        (given.is_absolute() ? given : node.scene.dir / given).lexically_normal();
    std::error_code ec;
    if (std::filesystem::exists(path, ec) && !std::filesystem::is_regular_file(path, ec)) {
        r.fail(r.childPath("file"), path.string() + " is not a regular file (a folder or a "
               "device); name a mesh or .vdb file");
    }
    return path.string();
}

/// What a mesh or vdb node is built at: the scene's voxel size, and a half width (voxels) of the
/// node's band (widened by at most kMaxExtraBand voxels beyond the raster's half width for the
/// blends above) plus a margin: none for the whole scene (then a mesh's grid is exactly
/// OpenVDB's meshToLevelSet at the raster's half width), two inside a tree (the rasterizer asks
/// for distances a voxel beyond the band, and the edge value must lie beyond that), three under
/// a transform (its interpolation between voxels).
constexpr double kMaxExtraBand = 64.0;

struct GridBuild
{
    double dx, band, margin;
};

GridBuild gridBuild(ObjectReader& r, const std::string& type, const Node& node)
{
    if (!node.scene.voxelSize) {
        r.fail(r.path(), "a " + type + " node is built at the scene's voxel size: add "
               "\"voxel_size\" to the scene (or give one on the command line)");
    }
    const double dx = *node.scene.voxelSize;
    double band = std::ceil(node.band / dx - 1e-9);
    const double most = node.scene.halfWidth + kMaxExtraBand;
    if (band > most) {
        node.scene.notes->push_back(r.origin() + ": " + r.path() + ": the blends above this " +
            type + " reach " + util::formatNumber(band - node.scene.halfWidth) + " voxels beyond "
            "the band; its distances are built " + util::formatNumber(kMaxExtraBand) + " voxels "
            "wider only, and the blend sees that band's edge value beyond");
        band = most;
    }
    const bool whole = node.depth == node.placed; // the scene's shape, moved or not
    return {dx, std::max(band, 1.0), node.lattice ? (whole ? 0.0 : 2.0) : 3.0};
}

/// What a mesh or vdb node stands for when the scene is only checked: a unit sphere, once
/// the file is known to exist.
Implicit::Ptr placeholder(ObjectReader& r, const std::string& file)
{
    std::error_code ec;
    if (!std::filesystem::exists(file, ec)) r.fail(r.childPath("file"), file + " does not exist");
    return std::make_shared<implicit::Sphere>(kZero, 1.0);
}

Implicit::Ptr buildMesh(ObjectReader& r, const std::string& type, const Node& node)
{
    const std::string file = inputFile(r, node);
    const GridBuild build = gridBuild(r, type, node);
    const double dx = build.dx;
    if (!node.scene.readInputs) return placeholder(r, file);
    mesh::TriangleMesh m;
    try {
        m = mesh::readTriangleMesh(file);
    } catch (const openvdb::Exception& e) {
        r.fail(r.childPath("file"), util::errorText(e));
    }
    // Transforms right above move the vertices (innermost first), in double precision.
    for (auto t = node.placement.rbegin(); t != node.placement.rend(); ++t) {
        for (openvdb::Vec3s& v : m.points) {
            const Vec3d w = (*t)->toWorld(Vec3d(v));
            if (!(std::abs(w[0]) < 1e30 && std::abs(w[1]) < 1e30 && std::abs(w[2]) < 1e30)) {
                r.fail(r.childPath("file"), "the mesh in " + file + " moved by the transforms "
                       "above it has a vertex beyond 1e30 (" + util::formatNumber(w[0]) + ", " +
                       util::formatNumber(w[1]) + ", " + util::formatNumber(w[2]) + "); use a "
                       "smaller scale or translation");
            }
            v = openvdb::Vec3s(w);
        }
    }
    if (const std::size_t open = mesh::openEdges(m)) {
        node.scene.notes->push_back(file + ": the mesh is not closed (" + std::to_string(open) +
            " edges not shared by exactly two triangles): its inside is what OpenVDB's "
            "mesh-to-volume makes of it, which may leak through the gaps (docs/scene-format.md#mesh)");
    }
    auto grid = mesh::meshDistance(m, dx, build.band + build.margin);
    if (grid->activeVoxelCount() == 0) {
        r.fail(r.childPath("file"), "the mesh in " + file + " has no voxel at voxel size " +
               util::formatNumber(dx) + " (it is smaller than a voxel or flat)");
    }
    return std::make_shared<implicit::GridShape>(grid, type);
}

Implicit::Ptr buildVdb(ObjectReader& r, const std::string& type, const Node& node)
{
    const std::string file = inputFile(r, node);
    std::string gridName;
    if (r.has("grid")) {
        const json& g = r.raw("grid");
        if (!g.is_string()) r.fail(r.childPath("grid"), "must be a grid name (a string), got " + brief(g));
        gridName = g.get<std::string>();
    }
    const GridBuild build = gridBuild(r, type, node);
    const double dx = build.dx;
    if (!node.scene.readInputs) return placeholder(r, file);
    openvdb::FloatGrid::Ptr grid;
    try {
        grid = jobs::readLevelSet(file, gridName);
    } catch (const openvdb::Exception& e) {
        r.fail(r.childPath(r.has("grid") ? "grid" : "file"), util::errorText(e));
    }
    const openvdb::math::Transform::Ptr lattice =
        openvdb::math::Transform::createLinearTransform(dx);
    // On another lattice it is rebuilt (through a mesh of its surface, which moves it by a
    // fraction of a voxel); on the scene's, a band narrower than the node needs is extended by
    // fast sweeping and the voxels it has are kept.
    const bool moved = !(grid->transform() == *lattice);
    const double halfWidth = build.band + build.margin;
    const int missing = int(std::ceil(halfWidth - double(grid->background()) / dx - 1e-6));
    if (!moved && missing > 0) {
        grid = levelset::detail::dilateSdf(*grid, missing);
        openvdb::tools::changeLevelSetBackground(grid->tree(), float(halfWidth * dx));
    } else if (moved) {
        std::ostringstream os;
        os << file << ": grid '" << grid->getName() << "' (voxel size " << grid->voxelSize()[0]
           << ", band " << grid->background() / grid->voxelSize()[0] << " voxels) rebuilt at "
           << "the scene's voxel size " << dx << " with a band of " << halfWidth << " voxels";
        node.scene.notes->push_back(os.str());
        grid = openvdb::tools::levelSetRebuild(*grid, 0.0f, float(halfWidth), float(halfWidth),
                                               lattice.get());
    }
    return std::make_shared<implicit::GridShape>(grid, type);
}

Implicit::Ptr buildQuadric(ObjectReader& r, const std::string&, const Node&)
{
    return std::make_shared<implicit::Quadric>(parseMatrix(r));
}

Implicit::Ptr buildPlane(ObjectReader& r, const std::string&, const Node&)
{
    const Vec3d n = axis(r, "normal", std::nullopt);
    return implicit::makePlane(n, r.number("offset", 0.0));
}

Implicit::Ptr buildCylinder(ObjectReader& r, const std::string&, const Node&)
{
    const Vec3d c = r.vec3("center", kZero), a = axis(r, "axis", kZAxis);
    return implicit::makeCylinder(c, a, r.positive("radius"));
}

Implicit::Ptr buildEllipsoid(ObjectReader& r, const std::string&, const Node&)
{
    return implicit::makeEllipsoid(r.vec3("center", kZero), r.positiveVec3("radii"));
}

Implicit::Ptr buildCone(ObjectReader& r, const std::string&, const Node&)
{
    const Vec3d apex = r.vec3("apex", kZero), a = axis(r, "axis", kZAxis);
    const double angle = r.number("half_angle_deg");
    if (!(angle > 0.0 && angle < 90.0)) {
        r.fail(r.childPath("half_angle_deg"),
               "must be in (0, 90) degrees, got " + util::formatNumber(angle));
    }
    return implicit::makeCone(apex, a, angle);
}

Implicit::Ptr buildParaboloid(ObjectReader& r, const std::string&, const Node&)
{
    const Vec3d v = r.vec3("vertex", kZero), a = axis(r, "axis", kZAxis);
    const bool hyperbolic =
        r.string("kind", {"elliptic", "hyperbolic"}, std::string("elliptic")) == "hyperbolic";
    return implicit::makeParaboloid(v, a, hyperbolic, r.positive("a", 1.0), r.positive("b", 1.0));
}

Implicit::Ptr buildHyperboloid(ObjectReader& r, const std::string&, const Node&)
{
    const Vec3d c = r.vec3("center", kZero), a = axis(r, "axis", kZAxis);
    const bool two =
        r.string("kind", {"one_sheet", "two_sheets"}, std::string("one_sheet")) == "two_sheets";
    return implicit::makeHyperboloid(c, a, two, r.positiveVec3("radii", Vec3d(1.0)));
}

Implicit::Ptr buildCsg(ObjectReader& r, const std::string& type, const Node& node)
{
    return std::make_shared<implicit::Csg>(*implicit::csgOpFromString(type),
                                           parseChildren(r, 1, node.child(node.band)));
}

/// A blend's children must be right as far beyond the band as the blend reaches (for a
/// rasterizer tolerance of 0.05 voxel), and as far as its surface swells.
Implicit::Ptr blendOf(ObjectReader& r, const std::string& op, const implicit::BlendKernel& kernel,
                      const Node& node)
{
    double band = node.band;
    if (node.scene.voxelSize) {
        const std::size_t n = r.has("children") && r.raw("children").is_array()
                                  ? std::max<std::size_t>(r.raw("children").size(), 1) : 1;
        band += kernel.reach(0.05 * *node.scene.voxelSize) + kernel.swell(n);
    }
    return std::make_shared<implicit::Blend>(*implicit::csgOpFromString(op), kernel,
                                             parseChildren(r, 2, node.child(band)));
}

Implicit::Ptr buildBlend(ObjectReader& r, const std::string&, const Node& node)
{
    const std::string op = r.string("op", implicit::csgOpNames());
    const double sharp = r.limited("p", limits::kBlendP);
    return blendOf(r, op, implicit::BlendKernel::superElliptic(sharp), node);
}

Implicit::Ptr buildSmooth(ObjectReader& r, const std::string&, const Node& node)
{
    const std::string op = r.string("op", implicit::csgOpNames());
    const double k = r.limited("k", limits::kSmoothK);
    return blendOf(r, op, implicit::BlendKernel::polynomial(k), node);
}

Implicit::Ptr buildOffset(ObjectReader& r, const std::string&, const Node& node)
{
    const double d = r.number("distance");
    auto child = parseNode(r.raw("child"), r.childPath("child"), r.origin(),
                           node.child(node.band + std::abs(d)));
    return std::make_shared<implicit::Offset>(child, d);
}

Implicit::Ptr buildShell(ObjectReader& r, const std::string&, const Node& node)
{
    const double t = r.positive("thickness");
    auto child = parseNode(r.raw("child"), r.childPath("child"), r.origin(),
                           node.child(node.band + 0.5 * t));
    return std::make_shared<implicit::Shell>(child, t);
}

/// Whether @a child is a mesh node, or a transform of one (a chain of transforms ending in a mesh).
bool movesMesh(const json& child)
{
    const json* j = &child;
    for (int depth = 0; depth <= kMaxDepth && j->is_object(); ++depth) {
        const auto type = j->find("type");
        if (type == j->end() || !type->is_string()) return false;
        if (*type == "mesh") return true;
        const auto next = j->find("child");
        if (*type != "transform" || next == j->end()) return false;
        j = &*next;
    }
    return false;
}

Implicit::Ptr buildTransform(ObjectReader& r, const std::string&, const Node& node)
{
    Vec3d scale(1.0);
    if (r.has("scale")) {
        const json& s = r.raw("scale");
        scale = s.is_number() ? Vec3d(r.toNumber(s, r.childPath("scale")))
                              : r.toVec3(s, r.childPath("scale"));
        for (int i = 0; i < 3; ++i) {
            if (!(scale[i] > 0.0)) {
                r.fail(r.childPath("scale"), "must be > 0 (a number or 3 numbers), got " + brief(s));
            }
        }
    }
    const Vec3d t = r.vec3("translate", kZero), rot = r.vec3("rotate_deg", kZero);
    if (movesMesh(r.raw("child"))) {
        // A mesh moved is the moved mesh: its vertices take the map and its grid is built on
        // the scene's lattice, exactly OpenVDB's meshToLevelSet of the moved mesh where nothing
        // else moves it. Sampled through the map instead, the grid built in the mesh's own frame
        // was interpolated between its voxels and, under a non-uniform scale, its flat facets'
        // edges were left to the smooth iteration (docs/scene-format.md#meshes-and-vdb-files).
        Node under = node.child(node.band);
        under.placement = node.placement;
        under.placement.push_back(std::make_shared<implicit::Transform>(
            std::make_shared<implicit::Sphere>(kZero, 1.0), t, rot, scale));
        under.placed = node.placed + 1;
        return parseNode(r.raw("child"), r.childPath("child"), r.origin(), under);
    }
    // The child's values are scaled by the smallest scale: its band must be that much wider.
    const double least = std::min({scale[0], scale[1], scale[2]});
    Node under = node.child(node.band / least);
    under.lattice = false;
    auto child = parseNode(r.raw("child"), r.childPath("child"), r.origin(), under);
    return std::make_shared<implicit::Transform>(child, t, rot, scale);
}

const std::vector<NodeType>& nodeTypes()
{
    static const std::vector<NodeType> types = {
        {"sphere", {"center", "radius"}, buildSphere},
        {"box", {"center", "size"}, buildBox},
        {"torus", {"center", "major_radius", "minor_radius"}, buildTorus},
        {"capsule", {"a", "b", "radius"}, buildCapsule},
        {"rounded_box", {"center", "size", "radius"}, buildRoundedBox},
        {"capped_cylinder", {"a", "b", "radius"}, buildCappedCylinder},
        {"capped_cone", {"a", "b", "radius_a", "radius_b"}, buildCappedCone},
        {"quadric", {"matrix"}, buildQuadric},
        {"plane", {"normal", "offset"}, buildPlane},
        {"cylinder", {"center", "axis", "radius"}, buildCylinder},
        {"ellipsoid", {"center", "radii"}, buildEllipsoid},
        {"cone", {"apex", "axis", "half_angle_deg"}, buildCone},
        {"paraboloid", {"vertex", "axis", "kind", "a", "b"}, buildParaboloid},
        {"hyperboloid", {"center", "axis", "kind", "radii"}, buildHyperboloid},
        {"union", {"children"}, buildCsg},
        {"intersection", {"children"}, buildCsg},
        {"difference", {"children"}, buildCsg},
        {"blend", {"op", "p", "children"}, buildBlend},
        {"smooth", {"op", "k", "children"}, buildSmooth},
        {"offset", {"distance", "child"}, buildOffset},
        {"shell", {"thickness", "child"}, buildShell},
        {"transform", {"translate", "rotate_deg", "scale", "child"}, buildTransform},
        {"mesh", {"file"}, buildMesh},
        {"vdb", {"file", "grid"}, buildVdb}};
    return types;
}

Implicit::Ptr parseNode(const json& j, const std::string& path, const std::string& origin,
                        const Node& at)
{
    const int depth = at.depth;
    ObjectReader r(j, path, origin);
    if (depth > kMaxDepth) {
        r.fail(path, "the shape tree is nested more than " + std::to_string(kMaxDepth) +
                         " levels deep; flatten it (union and intersection take many children)");
    }
    std::vector<std::string> names;
    for (const NodeType& t : nodeTypes()) names.push_back(t.name);
    const std::string type = r.string("type", names);
    const NodeType& node =
        nodeTypes()[size_t(std::find(names.begin(), names.end(), type) - names.begin())];
    std::vector<std::string> keys = {"type"};
    keys.insert(keys.end(), node.keys.begin(), node.keys.end());
    r.allowOnly(keys);
    // Library constructors validate too; their messages get this node's path.
    try {
        return node.build(r, type, at);
    } catch (const SceneError&) {
        throw;
    } catch (const openvdb::Exception& e) {
        r.fail(path, util::errorText(e));
    }
}

} // namespace

Scene parseScene(const std::string& text, const std::string& origin,
                 const SceneOverrides& overrides)
{
    json j;
    try {
        j = json::parse(text);
    } catch (const json::exception& e) {
        // parse_error for bad syntax, out_of_range for numbers such as 1e999.
        throw SceneError(origin + ": not valid JSON: " + e.what() +
                         " (scene files are JSON objects of finite numbers; see docs/"
                         "scene-format.md)");
    }
    const detail::Animation animation = detail::resolveKeyedValues(j, overrides.frame, origin);
    ObjectReader r(j, "", origin);
    r.allowOnly({"voxel_size", "half_width", "bounds", "distance", "shape"});
    Scene scene;
    scene.animated = animation.animated;
    scene.frames = animation.frames;
    scene.frame = animation.frame;
    if (r.has("voxel_size")) scene.voxelSize = r.positive("voxel_size");
    scene.halfWidth = r.has("half_width") ? r.limited("half_width", limits::kHalfWidth) : 3.0;
    scene.distanceBound =
        r.string("distance", {"exact", "bound"}, std::string("exact")) == "bound";
    if (r.has("bounds")) {
        ObjectReader b(r.raw("bounds"), "bounds", origin);
        b.allowOnly({"min", "max"});
        const Vec3d lo = b.vec3("min"), hi = b.vec3("max");
        for (int i = 0; i < 3; ++i) {
            if (!(lo[i] < hi[i])) {
                std::ostringstream os;
                os << "min must be < max in every axis, got min " << lo[i] << " >= max " << hi[i]
                   << " in axis " << "xyz"[i];
                b.fail("bounds", os.str());
            }
        }
        scene.bounds = implicit::BBoxd(lo, hi);
    }
    const SceneContext context{std::filesystem::path(origin).parent_path(),
                               overrides.voxelSize ? overrides.voxelSize : scene.voxelSize,
                               overrides.halfWidth.value_or(scene.halfWidth), &scene.notes,
                               overrides.readInputs};
    const Node top{context, 0, context.voxelSize ? context.halfWidth * *context.voxelSize : 0.0};
    scene.shape = parseNode(r.raw("shape"), "shape", origin, top);
    scene.json = j.dump();
    return scene;
}

Scene loadScene(const std::string& path, const SceneOverrides& overrides)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) throw SceneError(path + ": cannot open the scene file (does it exist and is it readable?)");
    std::ostringstream ss;
    ss << in.rdbuf();
    if (in.bad()) throw SceneError(path + ": cannot read the scene file");
    return parseScene(ss.str(), path, overrides);
}

} // namespace ivdb::scene
