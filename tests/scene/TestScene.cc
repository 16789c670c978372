// SPDX-License-Identifier: Apache-2.0
// Scene files: every node type parses to the right function, defaults apply, and every bad
// input is refused with a SceneError naming the file, the JSON path and the value.
#include <ivdb/scene/Scene.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace {

using ivdb::implicit::Vec3d;
using ivdb::scene::Scene;
using ivdb::scene::SceneError;
using ivdb::scene::loadScene;
using ivdb::scene::parseScene;

namespace fs = std::filesystem;

constexpr double kTol = 1e-12;

class TestScene: public ::testing::Test
{
protected:
    void SetUp() override { openvdb::initialize(); }

    /// Parse a scene whose "shape" is @a shape (a JSON object text) and return its value at @a p.
    static double valueOf(const std::string& shape, const Vec3d& p)
    {
        const Scene s = parseScene("{\"shape\": " + shape + "}", "scene.json");
        return s.shape->value(p);
    }

    /// The SceneError message for @a text, or a test failure if it parses.
    static std::string errorOf(const std::string& text, const std::string& origin = "scene.json")
    {
        try {
            parseScene(text, origin);
        } catch (const SceneError& e) {
            return e.what();
        } catch (const std::exception& e) {
            ADD_FAILURE() << "expected SceneError, got another exception: " << e.what();
            return e.what();
        }
        ADD_FAILURE() << "expected SceneError for: " << text;
        return "";
    }

    /// Check that @a msg contains every string of @a parts.
    static void expectMentions(const std::string& msg, const std::vector<std::string>& parts)
    {
        for (const auto& part : parts) {
            EXPECT_NE(msg.find(part), std::string::npos)
                << "message does not mention '" << part << "': " << msg;
        }
    }
};

// ---------------------------------------------------------------------------------------------
// Node types: values against closed forms

TEST_F(TestScene, SphereValues)
{
    const std::string s = R"({"type": "sphere", "center": [1, 2, 3], "radius": 0.5})";
    EXPECT_NEAR(valueOf(s, Vec3d(1, 2, 3)), -0.5, kTol);
    EXPECT_NEAR(valueOf(s, Vec3d(1.5, 2, 3)), 0.0, kTol);
    EXPECT_NEAR(valueOf(s, Vec3d(1, 2, 5)), 1.5, kTol);
    EXPECT_NEAR(valueOf(s, Vec3d(2, 3, 4)), std::sqrt(3.0) - 0.5, kTol);
    // center defaults to the origin
    EXPECT_NEAR(valueOf(R"({"type": "sphere", "radius": 2})", Vec3d(0, 3, 0)), 1.0, kTol);
}

TEST_F(TestScene, BoxValues)
{
    const std::string b = R"({"type": "box", "center": [1, 0, 0], "size": [2, 4, 6]})";
    EXPECT_NEAR(valueOf(b, Vec3d(1, 0, 0)), -1.0, kTol);        // nearest face at x = 0 or 2
    EXPECT_NEAR(valueOf(b, Vec3d(2, 0, 0)), 0.0, kTol);         // on the +x face
    EXPECT_NEAR(valueOf(b, Vec3d(1, 0, 4)), 1.0, kTol);         // 1 above the +z face
    EXPECT_NEAR(valueOf(b, Vec3d(3, 3, 0)), std::sqrt(2.0), kTol); // off the +x+y edge
    EXPECT_NEAR(valueOf(b, Vec3d(1, 1.5, 0)), -0.5, kTol);      // 0.5 from the +y face
}

TEST_F(TestScene, TorusValues)
{
    const std::string t =
        R"({"type": "torus", "center": [0, 0, 1], "major_radius": 2, "minor_radius": 0.5})";
    EXPECT_NEAR(valueOf(t, Vec3d(2, 0, 1)), -0.5, kTol);  // on the core circle
    EXPECT_NEAR(valueOf(t, Vec3d(0, 2.5, 1)), 0.0, kTol); // outer equator
    EXPECT_NEAR(valueOf(t, Vec3d(0, 0, 1)), 1.5, kTol);   // the hole's center
    EXPECT_NEAR(valueOf(t, Vec3d(2, 0, 3)), 1.5, kTol);   // above the core
    const Vec3d p(1.0, 1.0, 1.7);
    const double rho = std::sqrt(2.0);
    EXPECT_NEAR(valueOf(t, p), std::hypot(rho - 2.0, 0.7) - 0.5, kTol);
}

TEST_F(TestScene, QuadricMatrixValues)
{
    // f = x^2 + 2 y^2 + 2*0.5 x z + 2*(-1) y + 3 ... written as a general symmetric Q
    const std::string q = R"({"type": "quadric", "matrix":
        [[1, 0, 0.5, 0], [0, 2, 0, -1], [0.5, 0, 0, 0.25], [0, -1, 0.25, -3]]})";
    auto f = [](const Vec3d& p) {
        const double x = p[0], y = p[1], z = p[2];
        return x * x + 2 * y * y + x * z - 2 * y + 0.5 * z - 3;
    };
    for (const Vec3d& p :
         {Vec3d(0, 0, 0), Vec3d(1, 2, 3), Vec3d(-0.5, 0.25, 2), Vec3d(3, -1, -2)}) {
        EXPECT_NEAR(valueOf(q, p), f(p), 1e-12 * (1 + std::abs(f(p)))) << p;
    }
}

TEST_F(TestScene, PlaneValues)
{
    // inside where n.p < offset; stored with a unit normal: value = (n.p - offset) / |n|
    const std::string p = R"({"type": "plane", "normal": [0, 0, 2], "offset": 1})";
    EXPECT_NEAR(valueOf(p, Vec3d(0, 0, 0.5)), 0.0, kTol);
    EXPECT_NEAR(valueOf(p, Vec3d(5, -3, 0)), -0.5, kTol);
    EXPECT_NEAR(valueOf(p, Vec3d(0, 0, 2)), 1.5, kTol);
    const std::string tilted = R"({"type": "plane", "normal": [3, 4, 0], "offset": 5})";
    EXPECT_NEAR(valueOf(tilted, Vec3d(3, 4, 0)), 4.0, kTol); // (9 + 16 - 5) / 5
    EXPECT_NEAR(valueOf(tilted, Vec3d(0, 0, 7)), -1.0, kTol);
}

TEST_F(TestScene, CylinderValues)
{
    // quadric preset: f = (distance to the axis)^2 - r^2, for any axis direction
    const std::string c =
        R"({"type": "cylinder", "center": [1, 0, 0], "axis": [1, 0, 0], "radius": 0.5})";
    EXPECT_NEAR(valueOf(c, Vec3d(7, 0.5, 0)), 0.0, 1e-12);
    EXPECT_NEAR(valueOf(c, Vec3d(-3, 0, 0)), -0.25, 1e-12);
    EXPECT_NEAR(valueOf(c, Vec3d(2, 1, 1)), 2.0 - 0.25, 1e-12);
    // surface points on a tilted axis
    const std::string t =
        R"({"type": "cylinder", "center": [0, 0, 0], "axis": [1, 1, 1], "radius": 1})";
    const Vec3d a = Vec3d(1, 1, 1) / std::sqrt(3.0), u = Vec3d(1, -1, 0) / std::sqrt(2.0);
    for (double s : {-2.0, 0.0, 3.0}) {
        EXPECT_NEAR(valueOf(t, a * s + u), 0.0, 1e-12) << s;
        EXPECT_LT(valueOf(t, a * s + u * 0.5), 0.0);
        EXPECT_GT(valueOf(t, a * s + u * 1.5), 0.0);
    }
}

TEST_F(TestScene, EllipsoidValues)
{
    const std::string e =
        R"({"type": "ellipsoid", "center": [0, 1, 0], "radii": [2, 1, 0.5]})";
    auto f = [](const Vec3d& p) {
        return p[0] * p[0] / 4 + (p[1] - 1) * (p[1] - 1) + p[2] * p[2] / 0.25 - 1;
    };
    for (const Vec3d& p : {Vec3d(2, 1, 0), Vec3d(0, 2, 0), Vec3d(0, 1, 0.5), Vec3d(0, 1, 0),
                           Vec3d(1, 1.3, -0.2), Vec3d(3, -1, 2)}) {
        EXPECT_NEAR(valueOf(e, p), f(p), 1e-12 * (1 + std::abs(f(p)))) << p;
    }
}

TEST_F(TestScene, ConeValues)
{
    // double cone x^2 + y^2 = tan^2(a) z^2 about +z: with 45 degrees, f = x^2 + y^2 - z^2
    const std::string c =
        R"({"type": "cone", "apex": [0, 0, 1], "axis": [0, 0, 1], "half_angle_deg": 45})";
    EXPECT_NEAR(valueOf(c, Vec3d(1, 0, 2)), 0.0, 1e-12);
    EXPECT_NEAR(valueOf(c, Vec3d(0, 2, -1)), 0.0, 1e-12);
    EXPECT_NEAR(valueOf(c, Vec3d(0, 0, 3)), -4.0, 1e-12);
    EXPECT_NEAR(valueOf(c, Vec3d(3, 0, 1)), 9.0, 1e-12);
    // 30 degrees: the surface at height h has radius h tan(30)
    const std::string c30 = R"({"type": "cone", "half_angle_deg": 30})";
    const double r = 2.0 * std::tan(M_PI / 6.0);
    EXPECT_NEAR(valueOf(c30, Vec3d(0, r, 2)), 0.0, 1e-12);
    EXPECT_LT(valueOf(c30, Vec3d(0, 0.9 * r, 2)), 0.0);
    EXPECT_GT(valueOf(c30, Vec3d(0, 1.1 * r, 2)), 0.0);
}

TEST_F(TestScene, ParaboloidValues)
{
    // elliptic: z = (x/a)^2 + (y/b)^2 from the vertex, inside above it
    const std::string e = R"({"type": "paraboloid", "vertex": [0, 0, -1], "axis": [0, 0, 1],
                              "kind": "elliptic", "a": 2, "b": 1})";
    EXPECT_NEAR(valueOf(e, Vec3d(2, 0, 0)), 0.0, 1e-12);
    EXPECT_NEAR(valueOf(e, Vec3d(0, 1, 0)), 0.0, 1e-12);
    EXPECT_NEAR(valueOf(e, Vec3d(2, 1, 1)), 0.0, 1e-12);
    EXPECT_LT(valueOf(e, Vec3d(0, 0, 0)), 0.0);
    EXPECT_GT(valueOf(e, Vec3d(0, 0, -2)), 0.0);
    // hyperbolic: z = (x/a)^2 - (y/b)^2, defaults a = b = 1
    const std::string h = R"({"type": "paraboloid", "kind": "hyperbolic"})";
    EXPECT_NEAR(valueOf(h, Vec3d(1, 0, 1)), 0.0, 1e-12);
    EXPECT_NEAR(valueOf(h, Vec3d(0, 1, -1)), 0.0, 1e-12);
    EXPECT_NEAR(valueOf(h, Vec3d(2, 1, 3)), 0.0, 1e-12);
    EXPECT_LT(valueOf(h, Vec3d(0, 0, 1)), 0.0);
    EXPECT_GT(valueOf(h, Vec3d(0, 0, -1)), 0.0);
}

TEST_F(TestScene, HyperboloidValues)
{
    // one sheet: (x/a)^2 + (y/b)^2 - (z/c)^2 = 1, inside around the axis
    const std::string one = R"({"type": "hyperboloid", "center": [0, 0, 0], "axis": [0, 0, 1],
                                "kind": "one_sheet", "radii": [1, 1, 2]})";
    EXPECT_NEAR(valueOf(one, Vec3d(1, 0, 0)), 0.0, 1e-12);
    EXPECT_NEAR(valueOf(one, Vec3d(0, std::sqrt(2.0), 2)), 0.0, 1e-12);
    EXPECT_LT(valueOf(one, Vec3d(0, 0, 0)), 0.0);
    EXPECT_GT(valueOf(one, Vec3d(2, 0, 0)), 0.0);
    // two sheets: ... = -1, inside beyond the vertices at z = +-c
    const std::string two = R"({"type": "hyperboloid", "center": [0, 0, 0], "axis": [0, 0, 1],
                                "kind": "two_sheets", "radii": [1, 1, 2]})";
    EXPECT_NEAR(valueOf(two, Vec3d(0, 0, 2)), 0.0, 1e-12);
    EXPECT_NEAR(valueOf(two, Vec3d(0, 0, -2)), 0.0, 1e-12);
    EXPECT_NEAR(valueOf(two, Vec3d(1, 0, 2 * std::sqrt(2.0))), 0.0, 1e-12);
    EXPECT_LT(valueOf(two, Vec3d(0, 0, 3)), 0.0);
    EXPECT_GT(valueOf(two, Vec3d(0, 0, 0)), 0.0);
}

TEST_F(TestScene, CsgValues)
{
    const std::string a = R"({"type": "sphere", "center": [-0.5, 0, 0], "radius": 1})";
    const std::string b = R"({"type": "sphere", "center": [0.5, 0, 0], "radius": 1})";
    const std::string c = R"({"type": "box", "center": [0, 0, 0], "size": [0.2, 0.2, 0.2]})";
    auto da = [](const Vec3d& p) { return (p - Vec3d(-0.5, 0, 0)).length() - 1.0; };
    auto db = [](const Vec3d& p) { return (p - Vec3d(0.5, 0, 0)).length() - 1.0; };
    auto dc = [](const Vec3d& p) {
        return std::max({std::abs(p[0]), std::abs(p[1]), std::abs(p[2])}) - 0.1;
    };
    const std::string u = R"({"type": "union", "children": [)" + a + "," + b + "]}";
    const std::string i = R"({"type": "intersection", "children": [)" + a + "," + b + "]}";
    const std::string d = R"({"type": "difference", "children": [)" + a + "," + b + "," + c + "]}";
    for (const Vec3d& p : {Vec3d(0, 0, 0), Vec3d(1.2, 0.3, 0), Vec3d(-1.4, 0, 0.2),
                           Vec3d(0, 0.8, 0), Vec3d(0.05, 0.01, 0.02), Vec3d(2, 2, 2)}) {
        EXPECT_NEAR(valueOf(u, p), std::min(da(p), db(p)), kTol) << p;
        EXPECT_NEAR(valueOf(i, p), std::max(da(p), db(p)), kTol) << p;
        // difference: first, minus each of the others
        EXPECT_NEAR(valueOf(d, p), std::max({da(p), -db(p), -dc(p)}), kTol) << p;
    }
    // a single child is allowed and is the child itself
    const std::string single = R"({"type": "union", "children": [)" + a + "]}";
    EXPECT_NEAR(valueOf(single, Vec3d(1, 0, 0)), 0.5, kTol);
}

TEST_F(TestScene, TransformValues)
{
    const std::string sphere = R"({"type": "sphere", "radius": 1})";
    // translate
    const std::string t =
        R"({"type": "transform", "translate": [1, 2, 3], "child": )" + sphere + "}";
    EXPECT_NEAR(valueOf(t, Vec3d(1, 2, 3)), -1.0, kTol);
    EXPECT_NEAR(valueOf(t, Vec3d(1, 2, 5)), 1.0, kTol);
    EXPECT_NEAR(valueOf(t, Vec3d(0, 0, 0)), std::sqrt(14.0) - 1.0, kTol);
    // uniform scale (a number) keeps an exact distance: |p| - 2
    const std::string s = R"({"type": "transform", "scale": 2, "child": )" + sphere + "}";
    EXPECT_NEAR(valueOf(s, Vec3d(0, 0, 0)), -2.0, kTol);
    EXPECT_NEAR(valueOf(s, Vec3d(3, 0, 0)), 1.0, kTol);
    EXPECT_NEAR(valueOf(s, Vec3d(0, 2, 0)), 0.0, kTol);
    // non-uniform scale (3 numbers): an ellipsoid with semi-axes 2, 1, 1; value = min(s) child(q)
    const std::string ns = R"({"type": "transform", "scale": [2, 1, 1], "child": )" + sphere + "}";
    EXPECT_NEAR(valueOf(ns, Vec3d(2, 0, 0)), 0.0, kTol);
    EXPECT_NEAR(valueOf(ns, Vec3d(0, 1, 0)), 0.0, kTol);
    EXPECT_NEAR(valueOf(ns, Vec3d(4, 0, 0)), 1.0, kTol);
    // rotate: a 2 x 1 x 1 box turned 90 degrees about z lies along y
    const std::string box = R"({"type": "box", "size": [2, 1, 1]})";
    const std::string rz =
        R"({"type": "transform", "rotate_deg": [0, 0, 90], "child": )" + box + "}";
    EXPECT_NEAR(valueOf(rz, Vec3d(0, 0.9, 0)), -0.1, 1e-9);
    EXPECT_NEAR(valueOf(rz, Vec3d(0.9, 0, 0)), 0.4, 1e-9);
    EXPECT_NEAR(valueOf(rz, Vec3d(0, 1, 0)), 0.0, 1e-9);
    // rotate about x by 90: the box's z extent (0.5) moves to y; x unchanged
    const std::string box2 = R"({"type": "box", "size": [1, 1, 4]})";
    const std::string rx =
        R"({"type": "transform", "rotate_deg": [90, 0, 0], "child": )" + box2 + "}";
    EXPECT_NEAR(valueOf(rx, Vec3d(0, 2, 0)), 0.0, 1e-9);
    EXPECT_NEAR(valueOf(rx, Vec3d(0, 0, 1)), 0.5, 1e-9);
    // all three: p = R S q + t, so q = S^-1 R^T (p - t)
    const std::string all = R"({"type": "transform", "translate": [1, 0, 0],
        "rotate_deg": [0, 0, 90],
        "scale": 2, "child": {"type": "box", "size": [2, 1, 1]}})";
    // local box half sizes (1, .5, .5) scaled by 2 -> (2, 1, 1), turned onto y, moved by +1 in x
    EXPECT_NEAR(valueOf(all, Vec3d(1, 2, 0)), 0.0, 1e-9);
    EXPECT_NEAR(valueOf(all, Vec3d(2, 0, 0)), 0.0, 1e-9);
    EXPECT_NEAR(valueOf(all, Vec3d(1, 0, 0)), -1.0, 1e-9);
    EXPECT_NEAR(valueOf(all, Vec3d(4, 0, 0)), 2.0, 1e-9);
}

TEST_F(TestScene, NestedTreeAndDataFiles)
{
    // every scene in data/ loads, has a shape, and bounded/unbounded is as declared
    int count = 0;
    for (const auto& entry : fs::directory_iterator(IVDB_DATA_DIR)) {
        if (entry.path().extension() != ".json") continue;
        ++count;
        Scene s;
        ASSERT_NO_THROW(s = loadScene(entry.path().string())) << entry.path();
        ASSERT_TRUE(s.shape) << entry.path();
        EXPECT_FALSE(s.json.empty());
        if (!s.shape->isBounded()) EXPECT_TRUE(s.bounds.has_value()) << entry.path();
    }
    EXPECT_GE(count, 9);
    const Scene s = loadScene(std::string(IVDB_DATA_DIR) + "/sphere.json");
    ASSERT_TRUE(s.voxelSize.has_value());
    EXPECT_DOUBLE_EQ(*s.voxelSize, 0.01);
    EXPECT_NEAR(s.shape->value(Vec3d(0, 0, 0)), -1.0, kTol);
}

// ---------------------------------------------------------------------------------------------
// Defaults and top-level fields

TEST_F(TestScene, Defaults)
{
    const Scene s = parseScene(R"({"shape": {"type": "sphere", "radius": 1}})", "scene.json");
    EXPECT_DOUBLE_EQ(s.halfWidth, 3.0);
    EXPECT_FALSE(s.voxelSize.has_value());
    EXPECT_FALSE(s.bounds.has_value());
    EXPECT_EQ(s.shape->typeName(), "sphere");
    // the stored JSON is the scene, compact, and parses back to the same scene
    const Scene again = parseScene(s.json, "again");
    EXPECT_NEAR(again.shape->value(Vec3d(2, 0, 0)), 1.0, kTol);
    EXPECT_EQ(s.json.find('\n'), std::string::npos);
}

TEST_F(TestScene, TopLevelFields)
{
    const Scene s = parseScene(R"({"voxel_size": 0.025, "half_width": 4.5,
        "bounds": {"min": [-1, -2, -3], "max": [1, 2, 3.5]},
        "shape": {"type": "plane", "normal": [0, 0, 1]}})", "scene.json");
    ASSERT_TRUE(s.voxelSize.has_value());
    EXPECT_DOUBLE_EQ(*s.voxelSize, 0.025);
    EXPECT_DOUBLE_EQ(s.halfWidth, 4.5);
    ASSERT_TRUE(s.bounds.has_value());
    EXPECT_EQ(s.bounds->min(), Vec3d(-1, -2, -3));
    EXPECT_EQ(s.bounds->max(), Vec3d(1, 2, 3.5));
    EXPECT_FALSE(s.shape->isBounded());
    // offset defaults to 0
    EXPECT_NEAR(s.shape->value(Vec3d(0, 0, 0.25)), 0.25, kTol);
    EXPECT_NEAR(parseScene(R"({"half_width": 1, "shape": {"type": "sphere", "radius": 1}})", "s")
                    .halfWidth, 1.0, 0.0);
    // "distance": "exact" (the default) or "bound"
    EXPECT_FALSE(s.distanceBound);
    EXPECT_TRUE(parseScene(R"({"distance": "bound", "shape": {"type": "sphere", "radius": 1}})", "s")
                    .distanceBound);
    EXPECT_FALSE(parseScene(R"({"distance": "exact", "shape": {"type": "sphere", "radius": 1}})", "s")
                     .distanceBound);
    expectMentions(errorOf(R"({"distance": "approx", "shape": {"type": "sphere", "radius": 1}})"),
                   {"distance", "\"approx\"", "bound"});
}

// ---------------------------------------------------------------------------------------------
// Bad input: SceneError naming the origin, the JSON path and the value

TEST_F(TestScene, ExactMessageForNegativeRadius)
{
    const std::string text = R"({"voxel_size": 0.01, "shape": {"type": "union", "children": [
        {"type": "sphere", "radius": 1},
        {"type": "box", "size": [1, 1, 1]},
        {"type": "sphere", "center": [1, 0, 0], "radius": -1}]}})";
    EXPECT_EQ(errorOf(text), "scene.json: shape.children[2].radius: must be > 0, got -1");
}

TEST_F(TestScene, UnknownType)
{
    const std::string msg = errorOf(R"({"shape": {"type": "spher", "radius": 1}})", "a/b.json");
    expectMentions(msg, {"a/b.json", "shape.type", "\"spher\"", "sphere"});
}

TEST_F(TestScene, UnknownKey)
{
    // an extra, misspelled key next to a valid one
    std::string msg = errorOf(R"({"shape": {"type": "union", "children": [
        {"type": "sphere", "radius": 1},
        {"type": "sphere", "radius": 1, "radus": 2}]}})");
    expectMentions(msg, {"scene.json", "shape.children[1].radus", "unknown key"});
    // a misspelled key instead of the right one: the typo must be named, not only "radius"
    msg = errorOf(R"({"shape": {"type": "union", "children": [
        {"type": "sphere", "radius": 1},
        {"type": "sphere", "radus": 2}]}})");
    expectMentions(msg, {"scene.json", "shape.children[1]", "radus"});
    // at the top level and inside bounds
    msg = errorOf(R"({"voxelsize": 0.1, "shape": {"type": "sphere", "radius": 1}})");
    expectMentions(msg, {"scene.json", "voxelsize", "unknown key"});
    msg = errorOf(R"({"bounds": {"min": [0, 0, 0], "max": [1, 1, 1], "mid": 2},
                      "shape": {"type": "sphere", "radius": 1}})");
    expectMentions(msg, {"scene.json", "bounds.mid", "unknown key"});
}

TEST_F(TestScene, WrongType)
{
    std::string msg = errorOf(R"({"shape": {"type": "sphere", "radius": "1"}})");
    expectMentions(msg, {"scene.json", "shape.radius", "number", "\"1\""});
    msg = errorOf(R"({"shape": {"type": "sphere", "radius": 1, "center": [0, "a", 0]}})");
    expectMentions(msg, {"scene.json", "shape.center[1]", "\"a\""});
    msg = errorOf(R"({"shape": [1, 2]})");
    expectMentions(msg, {"scene.json", "shape", "object", "[1,2]"});
    msg = errorOf(R"({"shape": {"type": "union", "children": {"type": "sphere"}}})");
    expectMentions(msg, {"scene.json", "shape.children", "array"});
    msg = errorOf(R"({"shape": {"type": 3}})");
    expectMentions(msg, {"scene.json", "shape.type", "3"});
}

TEST_F(TestScene, WrongLength)
{
    std::string msg = errorOf(R"({"shape": {"type": "sphere", "center": [0, 0], "radius": 1}})");
    expectMentions(msg, {"scene.json", "shape.center", "3 numbers", "[0,0]"});
    msg = errorOf(R"({"shape": {"type": "quadric", "matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0]]}})");
    expectMentions(msg, {"scene.json", "shape.matrix", "4x4"});
    msg = errorOf(R"({"shape": {"type": "quadric",
                      "matrix": [[1,0,0,0],[0,1,0],[0,0,1,0],[0,0,0,-1]]}})");
    expectMentions(msg, {"scene.json", "shape.matrix[1]", "[0,1,0]"});
}

TEST_F(TestScene, NonSymmetricMatrix)
{
    const std::string msg = errorOf(R"({"shape": {"type": "quadric",
        "matrix": [[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, -1]]}})");
    expectMentions(msg, {"scene.json", "shape.matrix", "symmetric", "0.5"});
}

TEST_F(TestScene, AllZeroMatrix)
{
    const std::string msg = errorOf(R"({"shape": {"type": "quadric",
        "matrix": [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]]}})");
    expectMentions(msg, {"scene.json", "shape.matrix", "zero"});
}

TEST_F(TestScene, NonPositiveSizes)
{
    std::string msg = errorOf(R"({"shape": {"type": "sphere", "radius": 0}})");
    expectMentions(msg, {"scene.json", "shape.radius", "> 0", "0"});
    msg = errorOf(R"({"shape": {"type": "box", "size": [1, -2, 1]}})");
    expectMentions(msg, {"scene.json", "shape.size[1]", "> 0", "-2"});
    msg = errorOf(R"({"shape": {"type": "box", "size": [1, 1, 0]}})");
    expectMentions(msg, {"scene.json", "shape.size[2]", "> 0"});
    msg = errorOf(R"({"shape": {"type": "ellipsoid", "radii": [1, 1, -0.5]}})");
    expectMentions(msg, {"scene.json", "shape.radii[2]", "-0.5"});
    msg = errorOf(R"({"shape": {"type": "transform", "scale": [1, 0, 1],
                      "child": {"type": "sphere", "radius": 1}}})");
    expectMentions(msg, {"scene.json", "shape.scale", "> 0"});
    msg = errorOf(R"({"shape": {"type": "cylinder", "axis": [0, 0, 0], "radius": 1}})");
    expectMentions(msg, {"scene.json", "shape.axis", "non-zero"});
}

TEST_F(TestScene, BadVoxelSizeAndHalfWidth)
{
    const std::string shape = R"("shape": {"type": "sphere", "radius": 1})";
    std::string msg = errorOf("{\"voxel_size\": 0, " + shape + "}");
    expectMentions(msg, {"scene.json", "voxel_size", "> 0"});
    msg = errorOf("{\"voxel_size\": -0.5, " + shape + "}");
    expectMentions(msg, {"scene.json", "voxel_size", "-0.5"});
    msg = errorOf("{\"half_width\": 0.5, " + shape + "}");
    expectMentions(msg, {"scene.json", "half_width", "[1, 1000]", "0.5"});
    msg = errorOf("{\"half_width\": 3e9, " + shape + "}");
    expectMentions(msg, {"scene.json", "half_width", "[1, 1000]", "3e+09"});
    msg = errorOf("{\"half_width\": -2, " + shape + "}");
    expectMentions(msg, {"scene.json", "half_width", "-2"});
}

TEST_F(TestScene, BadBounds)
{
    const std::string shape = R"("shape": {"type": "sphere", "radius": 1})";
    std::string msg = errorOf(R"({"bounds": {"min": [0, 3, 0], "max": [1, 2, 1]}, )" + shape + "}");
    expectMentions(msg, {"scene.json", "bounds", "min", "max", "3", "2"});
    msg = errorOf(R"({"bounds": {"min": [0, 0, 1], "max": [1, 1, 1]}, )" + shape + "}");
    expectMentions(msg, {"scene.json", "bounds", "1"});
    msg = errorOf(R"({"bounds": {"min": [0, 0, 0]}, )" + shape + "}");
    expectMentions(msg, {"scene.json", "bounds.max", "missing"});
}

TEST_F(TestScene, HugeNumberIsRefused)
{
    // 1e999 overflows a double: whether the JSON reader refuses it or reads it as infinity, the
    // scene must be refused with a SceneError naming the file and the number (or its path)
    std::string msg = errorOf(R"({"shape": {"type": "sphere", "radius": 1e999}})");
    expectMentions(msg, {"scene.json", "1e999"});
    msg = errorOf(R"({"shape": {"type": "sphere", "center": [0, -1e999, 0], "radius": 1}})");
    expectMentions(msg, {"scene.json", "1e999"});
    msg = errorOf(R"({"voxel_size": 1e999, "shape": {"type": "sphere", "radius": 1}})");
    expectMentions(msg, {"scene.json", "1e999"});
    // a large but finite number is accepted
    const Scene s = parseScene(R"({"shape": {"type": "sphere", "radius": 1e300}})", "big.json");
    EXPECT_NEAR(s.shape->value(Vec3d(0, 0, 0)), -1e300, 1e285);
}

TEST_F(TestScene, InvalidJson)
{
    std::string msg = errorOf(R"({"shape": {"type": "sphere", "radius": 1,}})", "dir/bad.json");
    expectMentions(msg, {"dir/bad.json", "JSON"});
    msg = errorOf("", "empty.json");
    expectMentions(msg, {"empty.json", "JSON"});
    msg = errorOf("[1, 2, 3]", "array.json");
    expectMentions(msg, {"array.json", "object"});
}

TEST_F(TestScene, MissingShape)
{
    std::string msg = errorOf(R"({"voxel_size": 0.1})");
    expectMentions(msg, {"scene.json", "shape", "missing"});
    msg = errorOf(R"({"shape": {"type": "sphere"}})");
    expectMentions(msg, {"scene.json", "shape.radius", "missing"});
    msg = errorOf(R"({"shape": {"radius": 1}})");
    expectMentions(msg, {"scene.json", "shape.type", "missing"});
    msg = errorOf(R"({"shape": {"type": "transform", "translate": [1, 0, 0]}})");
    expectMentions(msg, {"scene.json", "shape.child", "missing"});
}

TEST_F(TestScene, TorusMinorNotBelowMajor)
{
    std::string msg = errorOf(
        R"({"shape": {"type": "torus", "major_radius": 1, "minor_radius": 1.5}})");
    expectMentions(msg, {"scene.json", "shape.minor_radius", "major_radius", "1.5"});
    msg = errorOf(R"({"shape": {"type": "torus", "major_radius": 1, "minor_radius": 1}})");
    expectMentions(msg, {"scene.json", "shape.minor_radius"});
}

TEST_F(TestScene, EmptyChildren)
{
    for (const char* op : {"union", "intersection", "difference"}) {
        const std::string msg =
            errorOf(std::string(R"({"shape": {"type": ")") + op + R"(", "children": []}})");
        expectMentions(msg, {"scene.json", "shape.children", "0"});
    }
    // an error deep in the tree keeps the whole path
    const std::string msg = errorOf(R"({"shape": {"type": "difference", "children": [
        {"type": "sphere", "radius": 1},
        {"type": "transform", "child": {"type": "intersection", "children": []}}]}})");
    expectMentions(msg, {"scene.json", "shape.children[1].child.children"});
}

TEST_F(TestScene, ConeAngle)
{
    for (const char* angle : {"90", "0", "120", "-10"}) {
        const std::string msg = errorOf(
            std::string(R"({"shape": {"type": "cone", "half_angle_deg": )") + angle + "}}");
        expectMentions(msg, {"scene.json", "shape.half_angle_deg", "90", angle});
    }
}

TEST_F(TestScene, BadKind)
{
    std::string msg = errorOf(R"({"shape": {"type": "paraboloid", "kind": "round"}})");
    expectMentions(msg, {"scene.json", "shape.kind", "\"round\"", "elliptic", "hyperbolic"});
    msg = errorOf(R"({"shape": {"type": "hyperboloid", "kind": "three_sheets"}})");
    expectMentions(msg, {"scene.json", "shape.kind", "\"three_sheets\"", "one_sheet"});
}

TEST_F(TestScene, LoadSceneFiles)
{
    const fs::path dir =
        fs::temp_directory_path() / ("ivdb-test-scene-" + std::to_string(::getpid()));
    fs::create_directories(dir);
    struct Cleanup
    {
        fs::path p;
        ~Cleanup() { std::error_code ec; fs::remove_all(p, ec); }
    } cleanup{dir};

    // a good file round trip
    const std::string good = (dir / "good.json").string();
    {
        std::ofstream(good) << R"({"voxel_size": 0.05, "shape": {"type": "sphere", "radius": 2}})";
    }
    const Scene s = loadScene(good);
    ASSERT_TRUE(s.voxelSize.has_value());
    EXPECT_DOUBLE_EQ(*s.voxelSize, 0.05);
    EXPECT_NEAR(s.shape->value(Vec3d(0, 0, 3)), 1.0, kTol);

    // errors in a file name the file
    const std::string bad = (dir / "bad.json").string();
    {
        std::ofstream(bad) << R"({"shape": {"type": "sphere", "radius": -3}})";
    }
    try {
        loadScene(bad);
        ADD_FAILURE() << "expected SceneError";
    } catch (const SceneError& e) {
        EXPECT_EQ(std::string(e.what()), bad + ": shape.radius: must be > 0, got -3");
    }

    // a missing file
    const std::string missing = (dir / "missing.json").string();
    try {
        loadScene(missing);
        ADD_FAILURE() << "expected SceneError for a missing file";
    } catch (const SceneError& e) {
        expectMentions(e.what(), {missing});
    } catch (...) {
        ADD_FAILURE() << "expected SceneError for a missing file, got another exception";
    }

    // a folder
    const std::string folder = (dir / "folder.json").string();
    fs::create_directories(folder);
    try {
        loadScene(folder);
        ADD_FAILURE() << "expected SceneError for a folder";
    } catch (const SceneError& e) {
        expectMentions(e.what(), {folder});
    } catch (...) {
        ADD_FAILURE() << "expected SceneError for a folder, got another exception";
    }
}

} // namespace
