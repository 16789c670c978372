// SPDX-License-Identifier: Apache-2.0
// Grids of every kind a .vdb file holds, for the writer's and the reader's tests.
#pragma once

#include <ivdb/diff/Differential.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/LevelSetUtil.h>

#include <cmath>
#include <string>
#include <type_traits>

namespace ivdb::test {

inline openvdb::FloatGrid::Ptr sphere(float radius, float dx, const std::string& name = "surface")
{
    auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(radius, openvdb::Vec3f(0.1f),
                                                                      dx, 3.0f);
    g->setName(name);
    return g;
}

/// Leaves with every mask-compression case: inactive values that are one other value, two
/// others, the background and another, three or more, and NaNs (never equal to themselves);
/// float values, or vec3s values built from them (a NaN in one component).
template<typename GridT>
typename GridT::Ptr assortedLeaves(const std::string& name)
{
    using ValueT = typename GridT::ValueType;
    const auto value = [](float f) {
        if constexpr (std::is_same_v<ValueT, float>) return f;
        else return ValueT(1.0f, f, -f); // NaN only in the last two components
    };
    auto assorted = GridT::create(value(0.5f));
    assorted->setName(name);
    auto acc = assorted->getAccessor();
    const float inactive[][3] = {{2.0f, 2.0f, 2.0f}, {2.0f, 3.0f, 2.0f}, {0.5f, 3.0f, 0.5f},
                                 {1.0f, 2.0f, 3.0f}, {-0.5f, 0.5f, -0.5f},
                                 {std::nanf(""), 1.0f, 1.0f}, {-0.0f, 0.0f, -0.0f}};
    for (int leaf = 0; leaf < 7; ++leaf) {
        for (int k = 0; k < 512; ++k) {
            const openvdb::Coord c(leaf * 8 + (k >> 6), (k >> 3) & 7, k & 7);
            if (k % 3 == 0) acc.setValueOn(c, value(float(k) * 0.25f));
            else acc.setValueOff(c, value(inactive[leaf][k % 3 == 1 ? 0 : (k % 2 ? 1 : 2)]));
        }
    }
    // One NaN among inactive values that are otherwise all one value: after it (k = 100) and
    // first (k = 1). OpenVDB counts a NaN as a value of its own each time.
    for (int leaf = 7; leaf < 9; ++leaf) {
        for (int k = 0; k < 512; ++k) {
            const openvdb::Coord c(leaf * 8 + (k >> 6), (k >> 3) & 7, k & 7);
            if (k % 3 == 0) acc.setValueOn(c, value(float(k)));
            else acc.setValueOff(c, value(k == (leaf == 7 ? 100 : 1) ? std::nanf("") : 1.0f));
        }
    }
    return assorted;
}

/// A level set, its gradient (vec3s), a fog volume, double, int32, int64 and vec3d grids with
/// tiles, an empty grid, a grid sharing the first one's tree, two grids of the same name and
/// assorted inactive values (float and vec3s); with @a bools also a bool grid (a type whose leaves store no
/// compressed values).
inline openvdb::GridCPtrVec everyKindOfGrid(bool bools)
{
    auto s = sphere(1.0f, 0.02f);
    auto gradient = ivdb::diff::gradient(*s, 1);
    auto empty = openvdb::FloatGrid::create(1.0f);
    auto density = s->deepCopy();
    openvdb::tools::sdfToFogVolume(*density);
    density->setName("density");
    auto doubles = openvdb::DoubleGrid::create(2.0);
    doubles->setName("doubles");
    doubles->tree().setValue(openvdb::Coord(1, 2, 3), 4.5);
    doubles->tree().setValue(openvdb::Coord(-100, 7, 3), -1.5);
    auto ints = openvdb::Int32Grid::create(0);
    ints->setName("ints");
    ints->tree().fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(20)), 7, true);
    ints->tree().setValueOff(openvdb::Coord(3, 3, 3), 9);
    auto longs = openvdb::Int64Grid::create(-1);
    longs->setName("longs");
    longs->tree().fill(openvdb::CoordBBox(openvdb::Coord(-200), openvdb::Coord(-100)), 1ll << 40,
                       true);
    auto vectors = openvdb::Vec3DGrid::create(openvdb::Vec3d(0, 0, 1));
    vectors->setName("vectors");
    vectors->tree().setValue(openvdb::Coord(9, -9, 9), openvdb::Vec3d(1.5, -2.5, 3.5));
    auto twin = s->copyGrid(); // shares the tree: an instance record
    twin->setName("twin");
    auto dup1 = sphere(0.3f, 0.05f, "dup"), dup2 = sphere(0.4f, 0.05f, "dup");
    openvdb::GridCPtrVec all{s, gradient, density, doubles, ints, longs, vectors, empty,
                             assortedLeaves<openvdb::FloatGrid>("assorted"), twin, dup1, dup2,
                             assortedLeaves<openvdb::Vec3SGrid>("assorted_vectors")};
    if (bools) {
        auto b = openvdb::BoolGrid::create(false);
        b->setName("bools");
        b->tree().setValue(openvdb::Coord(5), true);
        all.push_back(b);
    }
    return all;
}

} // namespace ivdb::test
