// SPDX-License-Identifier: Apache-2.0
#include <ivdb/levelset/Fog.h>

#include <openvdb/tools/LevelSetUtil.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <limits>
#include <string>

namespace ivdb::levelset {

namespace {

using TreeT = openvdb::FloatTree;
using LeafT = TreeT::LeafNodeType;
using Int2T = TreeT::RootNodeType::ChildNodeType;
using Int1T = Int2T::ChildNodeType;

} // namespace

openvdb::FloatGrid::Ptr fogFromLevelSet(const openvdb::FloatGrid& levelSet)
{
    openvdb::FloatGrid::Ptr fog = levelSet.deepCopy();
    openvdb::tools::sdfToFogVolume(*fog, levelSet.background());
    fog->setName("density");
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    return fog;
}

float fogCutoff(const openvdb::FloatGrid& skeleton, float lowest)
{
    // sdfToFogVolume takes the leaves out of the tree first (their places become background
    // tiles), then looks for the lowest tile of the 128^3 nodes, and only if none is below zero
    // for the lowest voxel.
    const float bg = skeleton.background();
    float lowestTile = std::numeric_limits<float>::max();
    std::vector<const Int1T*> nodes;
    skeleton.tree().getNodes(nodes);
    for (const Int1T* n : nodes) {
        for (auto it = n->cbeginValueAll(); it; ++it) {
            lowestTile = std::min(lowestTile, it.isValueOn() ? bg : *it);
        }
    }
    float lowestSdf = lowestTile;
    if (lowestSdf > 0.0f) lowestSdf = std::min(lowestSdf, lowest);
    const float cutoff = -std::abs(bg);
    return lowestSdf > cutoff ? lowestSdf : cutoff;
}

float lowestValue(const openvdb::FloatTree& tree)
{
    std::vector<const LeafT*> leaves;
    tree.getNodes(leaves);
    return tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, leaves.size()), std::numeric_limits<float>::max(),
        [&](const tbb::blocked_range<std::size_t>& r, float low) {
            for (std::size_t k = r.begin(); k < r.end(); ++k) {
                const float* v = leaves[k]->buffer().data();
                for (openvdb::Index i = 0; i < LeafT::SIZE; ++i) low = std::min(low, v[i]);
            }
            return low;
        },
        [](float a, float b) { return std::min(a, b); });
}

bool fogLeaf(LeafT& leaf, float cutoff)
{
    // sdfToFogVolume's arithmetic, in floats: v * (1 / cutoff).
    const float weight = 1.0f / cutoff;
    leaf.setValuesOff();
    float* v = leaf.buffer().data();
    for (openvdb::Index i = 0; i < LeafT::SIZE; ++i) {
        v[i] = v[i] > 0.0f ? 0.0f : v[i] * weight;
        if (v[i] > 0.0f) leaf.setValueOn(i);
    }
    return !leaf.isEmpty();
}

openvdb::FloatGrid::Ptr fogSkeleton(const openvdb::FloatGrid& skeleton,
                                    const std::vector<std::uint8_t>& kept,
                                    io::ActiveTiles& activeTiles)
{
    std::vector<const Int1T*> nodes;
    skeleton.tree().getNodes(nodes);
    std::uint64_t leaves = 0;
    for (const Int1T* n : nodes) leaves += n->getValueMask().countOn();
    if (leaves != kept.size()) {
        OPENVDB_THROW(openvdb::ValueError, "the fog's skeleton: " + std::to_string(kept.size()) +
                      " leaves kept or not, for a level set of " + std::to_string(leaves));
    }
    auto fog = openvdb::FloatGrid::create(0.0f);
    static_cast<openvdb::MetaMap&>(*fog) = static_cast<const openvdb::MetaMap&>(skeleton);
    fog->setTransform(skeleton.transform().copy());
    fog->setName("density");
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    activeTiles.clear();
    TreeT& tree = fog->tree();
    // The 128^3 nodes with a kept leaf: a placeholder for each kept leaf, and the level set's
    // inside tiles active with value 1 (the leaves not kept leave the background, 0).
    std::uint64_t first = 0;
    for (const Int1T* n : nodes) {
        const std::uint64_t count = n->getValueMask().countOn();
        const bool any = std::any_of(kept.begin() + std::ptrdiff_t(first),
                                     kept.begin() + std::ptrdiff_t(first + count),
                                     [](std::uint8_t k) { return k != 0; });
        if (!any) {
            first += count;
            continue;
        }
        tree.addTile(1, n->origin(), 0.0f, false); // makes the node
        Int1T* out = tree.probeNode<Int1T>(n->origin());
        Int1T::NodeMaskType inside;
        for (auto it = n->cbeginValueAll(); it; ++it) {
            if (it.isValueOn()) {
                if (kept[first++]) out->addTile(it.pos(), 0.0f, true);
            } else if (*it < 0.0f) {
                out->addTile(it.pos(), 1.0f, false);
                inside.setOn(it.pos());
            }
        }
        if (!inside.isOff()) activeTiles[n->origin()] = inside;
    }
    // The tiles of the fog's 4096^3 nodes: active with value 1 where the level set (its leaves
    // taken out, so their places count as background) is inside at the tile's first voxel.
    openvdb::tree::ValueAccessor<const TreeT> in(skeleton.tree());
    const auto insideAt = [&](const openvdb::Coord& c) {
        if (const Int1T* n = in.probeConstNode<Int1T>(c)) {
            const openvdb::Index i = n->coordToOffset(c);
            return !n->isValueMaskOn(i) && n->getValue(c) < 0.0f;
        }
        return in.getValue(c) < 0.0f;
    };
    std::vector<Int2T*> uppers;
    tree.getNodes(uppers);
    for (Int2T* n : uppers) {
        for (auto it = n->beginValueAll(); it; ++it) {
            if (insideAt(it.getCoord())) it.setValueOn(true), it.setValue(1.0f);
        }
    }
    // The root's tiles inside the level set.
    for (auto it = skeleton.tree().root().cbeginValueAll(); it; ++it) {
        if (*it < 0.0f) tree.addTile(TreeT::RootNodeType::LEVEL, it.getCoord(), 1.0f, true);
    }
    return fog;
}

} // namespace ivdb::levelset
