#include <ivdb/ops/Blend.h>

#include <ivdb/diff/Differential.h>
#include <ivdb/implicit/Blend.h>
#include <ivdb/levelset/Redistance.h>
#include <ivdb/util/System.h>

#include <openvdb/tools/FastSweeping.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tree/LeafManager.h>

#include <cmath>
#include <sstream>

namespace ivdb::ops {

namespace {
using FloatTree = openvdb::FloatTree;
using LeafT = FloatTree::LeafNodeType;
} // namespace

double blendReach(double p, double toleranceWorld)
{
    return std::max(0.0, std::log(1.0 / (p * toleranceWorld)) / p);
}

openvdb::FloatGrid::Ptr blend(CsgOp op, const std::vector<openvdb::FloatGrid::ConstPtr>& inputs,
                              const BlendSettings& settings, std::vector<std::string>* notes)
{
    const double p = settings.p;
    if (!(p >= 0.1 && p <= 1000.0)) {
        OPENVDB_THROW(openvdb::ValueError,
                      "blend p must be in [0.1, 1000], got " + util::formatNumber(p));
    }
    if (!(settings.tolerance > 0.0)) {
        OPENVDB_THROW(openvdb::ValueError, "blend tolerance must be > 0 voxels, got " +
                                               util::formatNumber(settings.tolerance));
    }
    if (inputs.size() < 2) {
        OPENVDB_THROW(openvdb::ValueError, "a blend needs at least two level sets, got " +
                                               std::to_string(inputs.size()));
    }
    const openvdb::math::Transform& target = finestInput(inputs).transform();
    const double dx = target.voxelSize()[0];
    const double halfWidth = double(inputs[0]->background()) / dx; // the output's, in voxels

    // How many voxels each band must reach: the output band plus the blend's reach.
    const double reachVox = blendReach(p, settings.tolerance * dx) / dx;
    if (!(halfWidth + reachVox < 1e6)) {
        OPENVDB_THROW(openvdb::RuntimeError, "blend with p = " + util::formatNumber(p) +
            " reaches " + util::formatNumber(std::ceil(reachVox)) + " voxels beyond the surfaces, "
            "far more than any band can hold. Use the scene-level blend ({\"type\": \"blend\", "
            "...} in a scene file, which needs no band extension), a larger p, or a larger "
            "--tolerance");
    }
    const int needVox = int(std::ceil(halfWidth + reachVox)) + 1;

    std::vector<openvdb::FloatGrid::Ptr> grids;
    std::vector<int> dilation;
    double estimate = 0.0;
    for (const auto& in : inputs) {
        grids.push_back(matchTransform(*in, target, notes));
        const double w = double(grids.back()->background()) / dx;
        const int d = std::max(0, needVox - int(std::floor(w)));
        dilation.push_back(d);
        // The grown band lies within the active bounding box grown by d voxels (it fills most of
        // it once d is comparable to the shape); the sweep keeps a few copies of it (values,
        // masks, slices): about 16 bytes a voxel.
        const openvdb::Coord dim = grids.back()->evalActiveVoxelDim();
        estimate += double(dim.x() + 2 * d) * double(dim.y() + 2 * d) * double(dim.z() + 2 * d) * 16.0;
    }
    const double available = double(util::availableMemory()); // 0 when unknown
    const double limit = settings.memoryLimit ? double(settings.memoryLimit)
                       : available > 0.0      ? 0.8 * available
                                              : 1e18;
    if (estimate > limit) {
        std::ostringstream os;
        os << "blend with p = " << util::formatNumber(p) << " reaches " << std::ceil(reachVox)
           << " voxels beyond the surfaces, so each band must grow to " << needVox
           << " voxels: about " << util::formatBytes(estimate) << ", more than the "
           << util::formatBytes(limit) << " available. Use the scene-level blend ({\"type\": "
           << "\"blend\", ...} in a scene file, which needs no band extension), a larger p, or a "
           << "larger --tolerance";
        OPENVDB_THROW(openvdb::RuntimeError, os.str());
    }
    if (notes) {
        std::ostringstream os;
        os << "bands extended to " << needVox << " voxels for p = " << util::formatNumber(p)
           << " (reach " << util::formatNumber(std::round(reachVox * 10) / 10) << " voxels)";
        notes->push_back(os.str());
    }
    for (size_t i = 0; i < grids.size(); ++i) {
        if (dilation[i] > 0) {
            grids[i] = openvdb::tools::dilateSdf(*grids[i], dilation[i],
                                                 openvdb::tools::NN_FACE_EDGE_VERTEX);
        }
        if (settings.interrupter && settings.interrupter->wasInterrupted()) {
            OPENVDB_THROW(openvdb::RuntimeError, "interrupted");
        }
    }

    // Combine over the union of the extended topologies. Outside an extended band an input
    // counts as +/- its extended half width, beyond the blend's reach.
    const float clamp = float(needVox * dx);
    auto combined = openvdb::FloatGrid::create(clamp);
    combined->setTransform(target.copy());
    for (const auto& g : grids) combined->tree().topologyUnion(g->tree());
    combined->tree().voxelizeActiveTiles();
    {
        const implicit::Csg::Op kind = op == CsgOp::Union ? implicit::Csg::Op::Union
                                     : op == CsgOp::Intersection ? implicit::Csg::Op::Intersection
                                                                 : implicit::Csg::Op::Difference;
        openvdb::tree::LeafManager<FloatTree> leaves(combined->tree());
        leaves.foreach([&](LeafT& leaf, size_t) {
            std::vector<openvdb::tree::ValueAccessor<const FloatTree>> acc;
            for (const auto& g : grids) acc.emplace_back(g->tree());
            std::vector<double> t(grids.size());
            for (auto it = leaf.beginValueOn(); it; ++it) {
                const openvdb::Coord ijk = it.getCoord();
                for (size_t i = 0; i < grids.size(); ++i) {
                    float v;
                    if (!acc[i].probeValue(ijk, v)) v = v > 0.0f ? clamp : -clamp;
                    v = std::max(-clamp, std::min(clamp, v));
                    t[i] = (kind == implicit::Csg::Op::Difference && i > 0) ? -double(v) : double(v);
                }
                it.setValue(float(implicit::blendTerms(kind, p, t.data(), t.size())));
            }
        });
    }
    // Tiles inside the shapes took the positive background from topologyUnion: give every
    // inactive region its sign from the band, or the inner edge of the extended band would look
    // like a surface.
    openvdb::tools::signedFloodFill(combined->tree());
    // The blend is not a distance (|grad f| < 1 near the crease): estimate f / |grad f|.
    combined->setGridClass(openvdb::GRID_LEVEL_SET);
    const auto grad = diff::gradient(*combined, 1);
    {
        openvdb::tree::LeafManager<FloatTree> leaves(combined->tree());
        leaves.foreach([&](LeafT& leaf, size_t) {
            const auto* g = grad->tree().probeConstLeaf(leaf.origin());
            if (!g) return;
            for (auto it = leaf.beginValueOn(); it; ++it) {
                const double len = g->getValue(it.pos()).length();
                const double e = *it / std::max(len, 0.1);
                it.setValue(float(std::max(-double(clamp), std::min(double(clamp), e))));
            }
        });
    }
    auto out = levelset::redistance(*combined, halfWidth, settings.interrupter);
    out->setTransform(target.copy());
    out->setGridClass(openvdb::GRID_LEVEL_SET);
    out->setName("surface");
    return out;
}

} // namespace ivdb::ops
