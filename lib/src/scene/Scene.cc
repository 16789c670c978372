// SPDX-License-Identifier: Apache-2.0
#include <ivdb/scene/Scene.h>

#include <ivdb/implicit/Blend.h>
#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/implicit/Quadric.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <openvdb/Exceptions.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <vector>

namespace ivdb::scene {

namespace {

using nlohmann::json;
using implicit::Implicit;
using implicit::Vec3d;

std::string brief(const json& v)
{
    std::string s = v.dump();
    if (s.size() > 60) s = s.substr(0, 57) + "...";
    return s;
}

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

Implicit::Ptr parseNode(const json& j, const std::string& path, const std::string& origin,
                        int depth);

/// Deeper trees would exhaust the evaluation stack (each level keeps a batch of values on it).
constexpr int kMaxDepth = 64;

std::vector<Implicit::Ptr> parseChildren(ObjectReader& r, std::size_t minCount, int depth)
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
        out.push_back(parseNode(c[i], cpath + "[" + std::to_string(i) + "]", r.origin(), depth + 1));
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
    Implicit::Ptr (*build)(ObjectReader& r, const std::string& type, int depth);
};

Implicit::Ptr buildSphere(ObjectReader& r, const std::string&, int)
{
    return std::make_shared<implicit::Sphere>(r.vec3("center", kZero), r.positive("radius"));
}

Implicit::Ptr buildBox(ObjectReader& r, const std::string&, int)
{
    return std::make_shared<implicit::Box>(r.vec3("center", kZero), r.positiveVec3("size"));
}

Implicit::Ptr buildTorus(ObjectReader& r, const std::string&, int)
{
    const Vec3d c = r.vec3("center", kZero);
    const double major = r.positive("major_radius"), minor = r.positive("minor_radius");
    if (!(minor < major)) {
        r.fail(r.childPath("minor_radius"), "must be < major_radius (" +
               util::formatNumber(major) + ") for a ring torus, got " + util::formatNumber(minor));
    }
    return std::make_shared<implicit::Torus>(c, major, minor);
}

Implicit::Ptr buildQuadric(ObjectReader& r, const std::string&, int)
{
    return std::make_shared<implicit::Quadric>(parseMatrix(r));
}

Implicit::Ptr buildPlane(ObjectReader& r, const std::string&, int)
{
    const Vec3d n = axis(r, "normal", std::nullopt);
    return implicit::makePlane(n, r.number("offset", 0.0));
}

Implicit::Ptr buildCylinder(ObjectReader& r, const std::string&, int)
{
    const Vec3d c = r.vec3("center", kZero), a = axis(r, "axis", kZAxis);
    return implicit::makeCylinder(c, a, r.positive("radius"));
}

Implicit::Ptr buildEllipsoid(ObjectReader& r, const std::string&, int)
{
    return implicit::makeEllipsoid(r.vec3("center", kZero), r.positiveVec3("radii"));
}

Implicit::Ptr buildCone(ObjectReader& r, const std::string&, int)
{
    const Vec3d apex = r.vec3("apex", kZero), a = axis(r, "axis", kZAxis);
    const double angle = r.number("half_angle_deg");
    if (!(angle > 0.0 && angle < 90.0)) {
        r.fail(r.childPath("half_angle_deg"),
               "must be in (0, 90) degrees, got " + util::formatNumber(angle));
    }
    return implicit::makeCone(apex, a, angle);
}

Implicit::Ptr buildParaboloid(ObjectReader& r, const std::string&, int)
{
    const Vec3d v = r.vec3("vertex", kZero), a = axis(r, "axis", kZAxis);
    const bool hyperbolic =
        r.string("kind", {"elliptic", "hyperbolic"}, std::string("elliptic")) == "hyperbolic";
    return implicit::makeParaboloid(v, a, hyperbolic, r.positive("a", 1.0), r.positive("b", 1.0));
}

Implicit::Ptr buildHyperboloid(ObjectReader& r, const std::string&, int)
{
    const Vec3d c = r.vec3("center", kZero), a = axis(r, "axis", kZAxis);
    const bool two =
        r.string("kind", {"one_sheet", "two_sheets"}, std::string("one_sheet")) == "two_sheets";
    return implicit::makeHyperboloid(c, a, two, r.positiveVec3("radii", Vec3d(1.0)));
}

Implicit::Ptr buildCsg(ObjectReader& r, const std::string& type, int depth)
{
    return std::make_shared<implicit::Csg>(*implicit::csgOpFromString(type),
                                           parseChildren(r, 1, depth));
}

Implicit::Ptr buildBlend(ObjectReader& r, const std::string&, int depth)
{
    const std::string op = r.string("op", implicit::csgOpNames());
    const double sharp = r.limited("p", limits::kBlendP);
    return std::make_shared<implicit::Blend>(*implicit::csgOpFromString(op), sharp,
                                             parseChildren(r, 2, depth));
}

Implicit::Ptr buildTransform(ObjectReader& r, const std::string&, int depth)
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
    auto child = parseNode(r.raw("child"), r.childPath("child"), r.origin(), depth + 1);
    return std::make_shared<implicit::Transform>(child, t, rot, scale);
}

const std::vector<NodeType>& nodeTypes()
{
    static const std::vector<NodeType> types = {
        {"sphere", {"center", "radius"}, buildSphere},
        {"box", {"center", "size"}, buildBox},
        {"torus", {"center", "major_radius", "minor_radius"}, buildTorus},
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
        {"transform", {"translate", "rotate_deg", "scale", "child"}, buildTransform}};
    return types;
}

Implicit::Ptr parseNode(const json& j, const std::string& path, const std::string& origin,
                        int depth)
{
    ObjectReader r(j, path, origin);
    if (depth > kMaxDepth) {
        r.fail(path, "the shape tree is nested more than " + std::to_string(kMaxDepth) +
                         " levels deep; flatten it (union and intersection take many children)");
    }
    std::vector<std::string> names;
    for (const NodeType& t : nodeTypes()) names.push_back(t.name);
    const std::string type = r.string("type", names);
    const NodeType& node = nodeTypes()[size_t(std::find(names.begin(), names.end(), type) - names.begin())];
    std::vector<std::string> keys = {"type"};
    keys.insert(keys.end(), node.keys.begin(), node.keys.end());
    r.allowOnly(keys);
    // Library constructors validate too; their messages get this node's path.
    try {
        return node.build(r, type, depth);
    } catch (const SceneError&) {
        throw;
    } catch (const openvdb::Exception& e) {
        r.fail(path, util::errorText(e));
    }
}

} // namespace

Scene parseScene(const std::string& text, const std::string& origin)
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
    ObjectReader r(j, "", origin);
    r.allowOnly({"voxel_size", "half_width", "bounds", "distance", "shape"});
    Scene scene;
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
    scene.shape = parseNode(r.raw("shape"), "shape", origin, 0);
    scene.json = j.dump();
    return scene;
}

Scene loadScene(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) throw SceneError(path + ": cannot open the scene file (does it exist and is it readable?)");
    std::ostringstream ss;
    ss << in.rdbuf();
    if (in.bad()) throw SceneError(path + ": cannot read the scene file");
    return parseScene(ss.str(), path);
}

} // namespace ivdb::scene
