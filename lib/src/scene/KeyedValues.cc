// SPDX-License-Identifier: Apache-2.0
#include "KeyedValues.h"

#include <ivdb/scene/Scene.h>

#include <cmath>
#include <string>
#include <vector>

namespace ivdb::scene::detail {

namespace {

using nlohmann::json;

[[noreturn]] void fail(const std::string& origin, const std::string& path, const std::string& what)
{
    throw SceneError(origin + ": " + path + ": " + what);
}

std::string at(const std::string& path, std::size_t i)
{
    return path + "[" + std::to_string(i) + "]";
}

double finite(const json& v, const std::string& origin, const std::string& path, const char* what)
{
    if (!v.is_number()) fail(origin, path, std::string("must be ") + what + ", got " + brief(v));
    const double d = v.get<double>();
    if (!std::isfinite(d)) fail(origin, path, "must be finite, got " + brief(v));
    return d;
}

/// A key's value: a number, or an array of numbers (a vector key).
std::vector<double> keyValue(const json& v, const std::string& origin, const std::string& path)
{
    if (v.is_number()) return {finite(v, origin, path, "a number")};
    if (!v.is_array() || v.empty()) {
        fail(origin, path, "must be a number or an array of numbers (the keyed field's value), "
             "got " + brief(v));
    }
    std::vector<double> out;
    for (std::size_t c = 0; c < v.size(); ++c) out.push_back(finite(v[c], origin, at(path, c), "a number"));
    return out;
}

Interpolation interpolationOf(const json& keyed, const std::string& origin, const std::string& path)
{
    if (!keyed.contains("interpolation")) return Interpolation::Linear;
    const json& v = keyed.at("interpolation");
    const std::string where = path + ".interpolation";
    if (v == "linear") return Interpolation::Linear;
    if (v == "smooth") return Interpolation::Smooth;
    if (v == "step") return Interpolation::Step;
    fail(origin, where, "must be one of linear, smooth, step, got " + brief(v));
}

/// Read and check `{"keys": [[frame, value], ...], "interpolation": ...}` at @a path.
Keys readKeys(const json& keyed, const std::string& origin, const std::string& path)
{
    for (auto it = keyed.begin(); it != keyed.end(); ++it) {
        if (it.key() != "keys" && it.key() != "interpolation") {
            fail(origin, path + "." + it.key(), "unknown key in a keyed value; allowed here: "
                 "keys, interpolation");
        }
    }
    Keys keys;
    keys.interpolation = interpolationOf(keyed, origin, path);
    const json& list = keyed.at("keys");
    const std::string lpath = path + ".keys";
    if (!list.is_array() || list.empty()) {
        fail(origin, lpath, "must be a non-empty array of [frame, value] pairs, got " + brief(list));
    }
    for (std::size_t i = 0; i < list.size(); ++i) {
        const json& key = list[i];
        const std::string kpath = at(lpath, i);
        if (!key.is_array() || key.size() != 2) {
            fail(origin, kpath, "must be a [frame, value] pair, got " + brief(key));
        }
        const double frame = finite(key[0], origin, at(kpath, 0), "a frame number");
        if (!keys.frames.empty() && !(frame > keys.frames.back())) {
            fail(origin, at(kpath, 0), "key frames must be strictly increasing: frame " +
                 brief(key[0]) + " follows frame " + brief(list[i - 1][0]));
        }
        std::vector<double> value = keyValue(key[1], origin, at(kpath, 1));
        if (!keys.values.empty() && value.size() != keys.values.front().size()) {
            const auto kind = [](std::size_t n) {
                return n == 1 ? std::string("a number") : std::to_string(n) + " numbers";
            };
            fail(origin, at(kpath, 1), "has " + kind(value.size()) + " but the first key has " +
                 kind(keys.values.front().size()) + "; every key of a field has the same length");
        }
        keys.frames.push_back(frame);
        keys.values.push_back(std::move(value));
    }
    return keys;
}

json valueJson(const std::vector<double>& v, bool vector)
{
    if (!vector) return v.front();
    json out = json::array();
    for (double c : v) out.push_back(c);
    return out;
}

/// Replace the keyed values under @a node; true if there was any.
bool resolve(json& node, double frame, const std::string& origin, const std::string& path)
{
    bool keyed = false;
    if (node.is_object() && node.contains("keys")) {
        const Keys keys = readKeys(node, origin, path);
        const bool vector = node.at("keys")[0][1].is_array();
        node = valueJson(keys.at(frame), vector);
        return true;
    }
    if (node.is_object()) {
        for (auto it = node.begin(); it != node.end(); ++it) {
            keyed |= resolve(it.value(), frame, origin, path.empty() ? it.key() : path + "." + it.key());
        }
    } else if (node.is_array()) {
        for (std::size_t i = 0; i < node.size(); ++i) keyed |= resolve(node[i], frame, origin, at(path, i));
    }
    return keyed;
}

FrameRange readFrames(const json& v, const std::string& origin)
{
    if (!v.is_object()) fail(origin, "frames", "must be an object {\"start\": A, \"end\": B}, got " + brief(v));
    FrameRange range;
    int* fields[2] = {&range.start, &range.end};
    const char* names[2] = {"start", "end"};
    for (auto it = v.begin(); it != v.end(); ++it) {
        if (it.key() != "start" && it.key() != "end") {
            fail(origin, "frames." + it.key(), "unknown key; allowed here: start, end");
        }
    }
    for (int i = 0; i < 2; ++i) {
        const std::string path = std::string("frames.") + names[i];
        if (!v.contains(names[i])) fail(origin, path, "is missing (a whole frame number >= 0)");
        const json& f = v.at(names[i]);
        if (!f.is_number_integer() || f.get<long long>() < 0 || f.get<long long>() > 999999999) {
            fail(origin, path, "must be a whole frame number in [0, 999999999], got " + brief(f));
        }
        *fields[i] = int(f.get<long long>());
    }
    if (range.start > range.end) {
        fail(origin, "frames", "start must be <= end, got start " + std::to_string(range.start) +
             " > end " + std::to_string(range.end));
    }
    return range;
}

} // namespace

Animation resolveKeyedValues(json& scene, std::optional<double> frame, const std::string& origin)
{
    Animation anim;
    if (!scene.is_object()) return anim; // the scene reader says what is wrong
    if (scene.contains("frames")) {
        anim.frames = readFrames(scene.at("frames"), origin);
        scene.erase("frames");
    }
    if (scene.contains("voxel_size") && scene.at("voxel_size").is_object()) {
        fail(origin, "voxel_size", "cannot be keyed: every frame of a sequence shares one voxel "
             "lattice (a transform's \"scale\" can grow a shape instead)");
    }
    anim.frame = frame.value_or(anim.frames ? double(anim.frames->start) : 1.0);
    anim.animated = resolve(scene, anim.frame, origin, "");
    return anim;
}

} // namespace ivdb::scene::detail
