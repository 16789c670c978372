// SPDX-License-Identifier: Apache-2.0
#include <ivdb/levelset/Redistance.h>

#include <ivdb/util/Interrupt.h>

#include "Sweeping.h"

#include <openvdb/tools/ChangeBackground.h>
#include <openvdb/tools/Morphology.h>
#include <openvdb/tree/LeafManager.h>

#include <cmath>
#include <atomic>
#include <limits>

namespace ivdb::levelset {

namespace {

using FloatTree = openvdb::FloatTree;
using LeafT = FloatTree::LeafNodeType;
using openvdb::Coord;
using MaskTree = openvdb::MaskTree;

/// A sample of exactly 0 (a voxel centre on a face of a box, say) is inside here (v > 0 is
/// outside) but outside for FastSweeping (v < iso is inside), which then neither seeds it nor
/// keeps it: a voxel on a box edge came out 1.3 voxels off. The smallest negative float makes it
/// inside for both. Returns whether any sample is strictly inside: without one there is no
/// inside at all, only a zero set without area (the point x^2 + y^2 + z^2 = 0, the double plane
/// x^2 = 0): no surface.
bool makeZerosInside(FloatTree& tree)
{
    std::atomic<bool> anyInside{false};
    openvdb::tree::LeafManager<FloatTree> leaves(tree);
    leaves.foreach([&anyInside](LeafT& leaf, size_t) {
        float* buf = leaf.buffer().data();
        bool inside = false;
        for (auto it = leaf.beginValueOn(); it; ++it) {
            float& v = buf[it.pos()];
            if (v < 0.0f) inside = true;
            if (v == 0.0f) v = -std::numeric_limits<float>::min();
        }
        if (inside) anyInside = true;
    });
    return anyInside;
}

/// The voxels next to a sign change (a face neighbour on the other side of zero).
MaskTree interfaceVoxels(const FloatTree& tree)
{
    MaskTree interface(tree, false, openvdb::TopologyCopy());
    openvdb::tree::LeafManager<MaskTree> masks(interface);
    masks.foreach([&](MaskTree::LeafNodeType& mleaf, size_t) {
        openvdb::tree::ValueAccessor<const FloatTree> acc(tree);
        const LeafT* leaf = acc.probeConstLeaf(mleaf.origin());
        mleaf.setValuesOff();
        if (!leaf) return;
        static const Coord kFaces[6] = {Coord(1, 0, 0), Coord(-1, 0, 0), Coord(0, 1, 0),
                                        Coord(0, -1, 0), Coord(0, 0, 1), Coord(0, 0, -1)};
        for (auto it = leaf->cbeginValueOn(); it; ++it) {
            const Coord ijk = it.getCoord();
            const bool s = *it > 0.0f;
            for (const Coord& d : kFaces) {
                if ((acc.getValue(ijk + d) > 0.0f) != s) {
                    mleaf.setValueOn(it.pos());
                    break;
                }
            }
        }
    });
    return interface;
}

/// OpenVDB's sdfToSdf, with the voxels next to the interface (the boundary condition) keeping
/// their own estimates from @a samples. Null when there is nothing to sweep.
openvdb::FloatGrid::Ptr sweep(const openvdb::FloatGrid& samples)
{
    const float frozen = 0.5f * std::numeric_limits<float>::max();
    return detail::sweepSdf(samples, [&](openvdb::FloatGrid& out) {
        openvdb::tree::LeafManager<FloatTree> leaves(out.tree());
        leaves.foreach([&](LeafT& leaf, size_t) {
            const LeafT* src = samples.tree().probeConstLeaf(leaf.origin());
            if (!src) return;
            float* buf = leaf.buffer().data();
            for (auto it = leaf.beginValueOn(); it; ++it) {
                if (std::abs(*it) < frozen) buf[it.pos()] = src->getValue(it.pos());
            }
        });
    });
}

/// Trim @a out to the band: |d| < @a bg, everything else +/- bg by sign. Within @a keep of the
/// surface, the smooth estimates replace the swept values where the two agree within @a agree.
void trimToBand(openvdb::FloatGrid& out, const openvdb::FloatGrid& samples, float bg, float keep,
                float agree)
{
    auto inBand = [bg](float v) { return std::abs(v) < bg; };
    openvdb::tree::LeafManager<FloatTree> leaves(out.tree());
    leaves.foreach([&](LeafT& leaf, size_t) {
        const LeafT* est = samples.tree().probeConstLeaf(leaf.origin());
        float* buf = leaf.buffer().data();
        for (int n = 0; n < 512; ++n) {
            const float v = buf[n];
            if (leaf.isValueOn(n) && inBand(v)) {
                if (est && std::abs(v) < keep) {
                    const float e = est->getValue(n);
                    if (std::abs(e - v) <= agree && (e > 0.0f) == (v > 0.0f) && inBand(e)) buf[n] = e;
                }
                continue;
            }
            leaf.setValueOff(n, v > 0.0f ? bg : -bg);
        }
    });
    openvdb::tools::changeLevelSetBackground(out.tree(), bg);
}

} // namespace

openvdb::FloatGrid::Ptr redistance(openvdb::FloatGrid& samples, double halfWidth,
                                   openvdb::util::NullInterrupter* interrupter,
                                   double keepEstimates, double agreement)
{
    const float bg = static_cast<float>(halfWidth * samples.voxelSize()[0]);
    auto empty = [&]() { // no surface: an empty band
        auto g = openvdb::FloatGrid::create(bg);
        g->setTransform(samples.transform().copy());
        return g;
    };
    FloatTree& tree = samples.tree();
    if (!makeZerosInside(tree)) return empty();
    MaskTree interface = interfaceVoxels(tree);
    util::checkInterrupt(interrupter);
    openvdb::tools::dilateActiveValues(interface, int(std::ceil(halfWidth)),
                                       openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::IGNORE_TILES);
    tree.topologyIntersection(interface);
    if (tree.activeVoxelCount() == 0) return empty();

    openvdb::FloatGrid::Ptr out = sweep(samples);
    if (!out) return empty();
    util::checkInterrupt(interrupter);
    const double dx = samples.voxelSize()[0];
    trimToBand(*out, samples, bg, float(std::min(keepEstimates, halfWidth) * dx),
               float(agreement * dx));
    return out;
}

} // namespace ivdb::levelset
