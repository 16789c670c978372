#include <ivdb/ops/Blend.h>

#include <ivdb/diff/Differential.h>
#include <ivdb/implicit/Blend.h>
#include <ivdb/levelset/Redistance.h>
#include <ivdb/util/System.h>

#include <openvdb/tools/FastSweeping.h>
#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tree/LeafManager.h>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>
#include <cmath>
#include <sstream>

namespace ivdb::ops {

namespace {

using FloatTree = openvdb::FloatTree;
using LeafT = FloatTree::LeafNodeType;
using MaskTree = openvdb::MaskTree;
using openvdb::Coord;

constexpr int kLeafLog2 = LeafT::LOG2DIM;
constexpr int kLeafDim = LeafT::DIM;

// Leaf nodes as the voxels of a coarse mask: voxel v stands for the leaf at origin v * 8. The
// blend's regions are decided on this mask, which is 512 times smaller than the band.
template<typename TreeT>
MaskTree::Ptr leafMask(const TreeT& tree)
{
    auto mask = std::make_shared<MaskTree>();
    for (auto it = tree.cbeginLeaf(); it; ++it) mask->setValueOn(it->origin() >> kLeafLog2);
    return mask;
}

void dilateLeaves(MaskTree& mask, int steps) // steps voxels of the mask (leaves or voxels)
{
    if (steps <= 0) return;
    openvdb::tools::dilateActiveValues(mask, steps, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::EXPAND_TILES);
    mask.voxelizeActiveTiles();
}

MaskTree::Ptr dilatedCopy(const MaskTree& mask, int leaves)
{
    auto out = std::make_shared<MaskTree>(mask);
    dilateLeaves(*out, leaves);
    return out;
}

std::vector<Coord> leafOrigins(const MaskTree& mask)
{
    std::vector<Coord> out;
    out.reserve(size_t(mask.activeVoxelCount()));
    for (auto it = mask.cbeginValueOn(); it; ++it) {
        const openvdb::CoordBBox box = it.getBoundingBox(); // a voxel, or a tile of them
        // Multiplied, not shifted: shifting a negative coordinate left is undefined in C++17.
        for (auto c = box.begin(); c; ++c) {
            const Coord v = *c;
            out.emplace_back(v.x() * kLeafDim, v.y() * kLeafDim, v.z() * kLeafDim);
        }
    }
    return out;
}

int leavesFor(double voxels) { return int(std::ceil(voxels / kLeafDim)); }

void checkInterrupt(openvdb::util::NullInterrupter* interrupter)
{
    if (interrupter && interrupter->wasInterrupted()) {
        OPENVDB_THROW(openvdb::RuntimeError, "interrupted");
    }
}

// The voxels of @a grid's band within @a keep (a voxel mask), extended by @a dilation voxels
// within @a keep by closest-point propagation. Every band voxel x gets its surface point
// c = x - phi(x) n and normal n = grad(phi)(x) / |grad(phi)(x)| (central differences, one-sided
// at the band's edge). Then, one layer of voxels at a time, each new voxel y takes the neighbour
// (of 26) whose point c is nearest, and the distance to that point's tangent plane,
// (y - c) . n, passing the same point and normal on (they stay the seeds' own). The plane
// keeps the error second order in the angle between neighbours' normals (the distance to c
// itself is off by about spacing^2 / (2 distance) on the concave side). The sign comes from the
// input, which holds it beyond the band. openvdb::tools::dilateSdf (fast sweeping) took about
// 1.3 us a voxel on this job; this is several times cheaper.
openvdb::FloatGrid::Ptr extendByClosestPoints(const openvdb::FloatGrid& grid, const MaskTree& keep,
                                             int dilation)
{
    using Vec3fTree = openvdb::Vec3STree;
    using CpLeaf = Vec3fTree::LeafNodeType;
    const double dx = grid.voxelSize()[0];
    auto ext = openvdb::FloatGrid::create(grid.background());
    ext->setTransform(grid.transform().copy());
    ext->setGridClass(openvdb::GRID_LEVEL_SET);
    Vec3fTree cps(openvdb::Vec3s(0.0f)), normals(openvdb::Vec3s(0.0f));
    MaskTree known; // voxels with a value and a closest point, in index space
    {
        openvdb::tree::ValueAccessor<const FloatTree> acc(grid.tree());
        for (auto it = keep.cbeginLeaf(); it; ++it) {
            const LeafT* leaf = acc.probeConstLeaf(it->origin());
            if (!leaf) continue;
            auto* copy = new LeafT(*leaf);
            copy->setValueMask(leaf->getValueMask() & it->getValueMask());
            if (copy->isEmpty()) {
                delete copy;
                continue;
            }
            ext->tree().addLeaf(copy);
            cps.touchLeaf(it->origin());
            normals.touchLeaf(it->origin());
            known.touchLeaf(it->origin())->setValueMask(copy->getValueMask());
        }
    }
    // The seeds' closest points (each leaf by one thread; reads of the input only).
    {
        std::vector<LeafT*> leaves;
        ext->tree().getNodes(leaves);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, leaves.size()),
                          [&](const tbb::blocked_range<size_t>& r) {
            openvdb::tree::ValueAccessor<const FloatTree> acc(grid.tree());
            for (size_t k = r.begin(); k < r.end(); ++k) {
                const LeafT& leaf = *leaves[k];
                CpLeaf* cp = cps.probeLeaf(leaf.origin());
                CpLeaf* nrm = normals.probeLeaf(leaf.origin());
                for (auto it = leaf.cbeginValueOn(); it; ++it) {
                    const Coord ijk = it.getCoord();
                    float v0;
                    acc.probeValue(ijk, v0);
                    openvdb::Vec3d g;
                    for (int a = 0; a < 3; ++a) {
                        Coord dp = ijk, dm = ijk;
                        dp[a] += 1;
                        dm[a] -= 1;
                        float vp, vm;
                        const bool p = acc.probeValue(dp, vp), m = acc.probeValue(dm, vm);
                        g[a] = p && m ? 0.5 * (double(vp) - vm) : p ? double(vp) - v0
                             : m      ? double(v0) - vm           : 0.0;
                    }
                    const double len = g.length();
                    const openvdb::Vec3d x(ijk.x(), ijk.y(), ijk.z());
                    const openvdb::Vec3d nv = len > 0.0 ? g / len : openvdb::Vec3d(0.0);
                    cp->setValueOnly(it.pos(), openvdb::Vec3s(x - nv * (double(v0) / dx)));
                    nrm->setValueOnly(it.pos(), openvdb::Vec3s(nv));
                }
            }
        });
    }
    static const Coord kNeighbours[26] = {
        {-1,-1,-1},{-1,-1,0},{-1,-1,1},{-1,0,-1},{-1,0,0},{-1,0,1},{-1,1,-1},{-1,1,0},{-1,1,1},
        {0,-1,-1},{0,-1,0},{0,-1,1},{0,0,-1},{0,0,1},{0,1,-1},{0,1,0},{0,1,1},
        {1,-1,-1},{1,-1,0},{1,-1,1},{1,0,-1},{1,0,0},{1,0,1},{1,1,-1},{1,1,0},{1,1,1}};
    auto frontier = std::make_shared<MaskTree>(known);
    for (int layer = 0; layer < dilation; ++layer) {
        // The next layer: the last layer's neighbours within keep that are not known yet.
        MaskTree next(*frontier);
        openvdb::tools::dilateActiveValues(next, 1, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                           openvdb::tools::IGNORE_TILES);
        next.topologyIntersection(keep);
        next.topologyDifference(known);
        std::vector<const MaskTree::LeafNodeType*> masks;
        for (auto it = next.cbeginLeaf(); it; ++it) {
            if (!it->isEmpty()) masks.push_back(it.getLeaf());
        }
        if (masks.empty()) break;
        std::vector<LeafT*> out(masks.size());
        std::vector<CpLeaf*> outCp(masks.size()), outN(masks.size());
        openvdb::tree::ValueAccessor<const FloatTree> signAcc(grid.tree());
        for (size_t k = 0; k < masks.size(); ++k) {
            const Coord o = masks[k]->origin();
            if (!ext->tree().probeLeaf(o)) {
                // A new leaf takes the input's values beyond the band (+/- background) for signs.
                const LeafT* src = signAcc.probeConstLeaf(o);
                auto* leaf = src ? new LeafT(*src) : new LeafT(o, signAcc.getValue(o));
                leaf->setValuesOff();
                ext->tree().addLeaf(leaf);
            }
            out[k] = ext->tree().probeLeaf(o);
            outCp[k] = cps.touchLeaf(o);
            outN[k] = normals.touchLeaf(o);
        }
        tbb::parallel_for(tbb::blocked_range<size_t>(0, masks.size()),
                          [&](const tbb::blocked_range<size_t>& r) {
            openvdb::tree::ValueAccessor<const MaskTree> knownAcc(known);
            openvdb::tree::ValueAccessor<const Vec3fTree> cpAcc(cps), nAcc(normals);
            openvdb::tree::ValueAccessor<const FloatTree> in(grid.tree());
            for (size_t k = r.begin(); k < r.end(); ++k) {
                for (auto it = masks[k]->cbeginValueOn(); it; ++it) {
                    const Coord ijk = it.getCoord();
                    const openvdb::Vec3d y(ijk.x(), ijk.y(), ijk.z());
                    double best = std::numeric_limits<double>::max();
                    Coord from = ijk;
                    for (const Coord& d : kNeighbours) {
                        const Coord n = ijk + d;
                        if (!knownAcc.isValueOn(n)) continue;
                        const double dist = (y - openvdb::Vec3d(cpAcc.getValue(n))).lengthSqr();
                        if (dist < best) best = dist, from = n;
                    }
                    const openvdb::Vec3d c(cpAcc.getValue(from)), nv(nAcc.getValue(from));
                    double d = (y - c).dot(nv);
                    if (nv.lengthSqr() == 0.0) d = std::sqrt(best); // no normal: the point
                    const double sign = in.getValue(ijk) < 0.0f ? -1.0 : 1.0;
                    out[k]->setValueOn(it.pos(), float(sign * std::abs(d) * dx));
                    outCp[k]->setValueOnly(it.pos(), openvdb::Vec3s(c)); // a seed's point
                    outN[k]->setValueOnly(it.pos(), openvdb::Vec3s(nv));
                }
            }
        });
        known.topologyUnion(next);
        frontier = std::make_shared<MaskTree>(next);
    }
    return ext;
}

// extendLocally() for long extensions: by fast sweeping (openvdb::tools::dilateSdf), which
// handles fronts that meet (past a medial axis). The leaves around are copied with their voxels
// inactive, and leaf-sized tiles carry the inside sign, so the sweep sees on which side of the
// surface each new voxel lies, as on the whole grid.
openvdb::FloatGrid::Ptr extendBySweeping(const openvdb::FloatGrid& grid, const MaskTree& keep,
                                      int dilation)
{
    auto clip = openvdb::FloatGrid::create(grid.background());
    clip->setTransform(grid.transform().copy());
    clip->setGridClass(openvdb::GRID_LEVEL_SET);
    openvdb::tree::ValueAccessor<const FloatTree> acc(grid.tree());
    openvdb::tree::ValueAccessor<const MaskTree> keepAcc(keep);
    // The leaves the grown band can reach (new voxels take their sign from there).
    const MaskTree::Ptr around = leafMask(*dilatedCopy(keep, dilation + 1));
    for (const Coord& o : leafOrigins(*around)) {
        if (const LeafT* leaf = acc.probeConstLeaf(o)) {
            auto* copy = new LeafT(*leaf);
            const MaskTree::LeafNodeType* k = keepAcc.probeConstLeaf(o);
            copy->setValueMask(k ? leaf->getValueMask() & k->getValueMask()
                                 : LeafT::NodeMaskType());
            clip->tree().addLeaf(copy);
        } else if (acc.getValue(o) < 0.0f) {
            clip->tree().addTile(1, o, -grid.background(), false);
        }
    }
    if (dilation <= 0 || clip->tree().activeVoxelCount() == 0) return clip;
    return openvdb::tools::dilateSdf(*clip, dilation, openvdb::tools::NN_FACE_EDGE_VERTEX);
}

// Closest-point propagation loses accuracy where fronts from opposite sides meet (a medial
// axis): inside a sphere of radius 15 voxels extended by 30, the blended surface was off by
// 0.8 voxel. Up to this many layers it matches fast sweeping's accuracy or beats it (the
// grid-blend tests, p = 10 and 50); beyond, fast sweeping takes over.
constexpr int kMaxClosestPointLayers = 8;

openvdb::FloatGrid::Ptr extendLocally(const openvdb::FloatGrid& grid, const MaskTree& keep,
                                      int dilation)
{
    return dilation <= kMaxClosestPointLayers ? extendByClosestPoints(grid, keep, dilation)
                                              : extendBySweeping(grid, keep, dilation);
}

implicit::Csg::Op implicitOp(CsgOp op)
{
    return op == CsgOp::Union          ? implicit::Csg::Op::Union
         : op == CsgOp::Intersection ? implicit::Csg::Op::Intersection
                                      : implicit::Csg::Op::Difference;
}

void checkSettings(size_t inputs, const BlendSettings& settings)
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
    if (inputs < 2) {
        OPENVDB_THROW(openvdb::ValueError,
                      "a blend needs at least two level sets, got " + std::to_string(inputs));
    }
}

// The blend of level sets already on one transform; consumes @a grids (the sharp operation
// steals their nodes).
openvdb::FloatGrid::Ptr blendOnTarget(CsgOp op, const std::vector<openvdb::FloatGrid::Ptr>& grids,
                                      const BlendSettings& settings, std::vector<std::string>* notes)
{
    const double p = settings.p;
    const openvdb::FloatGrid& finest = finestInput(grids);
    const double dx = finest.voxelSize()[0];
    const float bg = finest.background(); // the output's, as for the sharp operation
    const double halfWidth = double(bg) / dx;
    const size_t n = grids.size();

    // How many voxels each band must reach: the output band plus the blend's reach.
    const double reachVox = blendReach(p, settings.tolerance * dx) / dx;
    if (!(halfWidth + reachVox < 1e6)) {
        OPENVDB_THROW(openvdb::RuntimeError, "blend with p = " + util::formatNumber(p) +
            " reaches " + util::formatNumber(std::ceil(reachVox)) + " voxels beyond the surfaces, "
            "far more than any band can hold. Use the scene-level blend ({\"type\": \"blend\", "
            "...} in a scene file, which needs no band extension), a larger p, or a larger "
            "--tolerance");
    }
    // (The swell ln(n)/p of the blended surface too; see the lead rule below.)
    const int needVox = int(std::ceil(halfWidth + reachVox + std::log(double(n)) / p / dx)) + 1;
    std::vector<int> dilation(n);
    std::vector<MaskTree::Ptr> leaves(n);
    for (size_t i = 0; i < n; ++i) {
        dilation[i] = std::max(0, needVox - int(std::floor(double(grids[i]->background()) / dx)));
        leaves[i] = leafMask(grids[i]->tree());
    }

    auto refuse = [&](double estimate, double limit) {
        std::ostringstream os;
        os << "blend with p = " << util::formatNumber(p) << " reaches " << std::ceil(reachVox)
           << " voxels beyond the surfaces, so the bands must grow to " << needVox
           << " voxels where the inputs meet: about " << util::formatBytes(estimate)
           << ", more than the " << util::formatBytes(limit) << " available. Use the scene-level "
           << "blend ({\"type\": \"blend\", ...} in a scene file, which needs no band extension), "
           << "a larger p, or a larger --tolerance";
        OPENVDB_THROW(openvdb::RuntimeError, os.str());
    };
    const double available = double(util::availableMemory()); // 0 when unknown
    const double limit = settings.memoryLimit ? double(settings.memoryLimit)
                       : available > 0.0      ? 0.8 * available
                                              : 1e18;
    // The sweep keeps a few copies of the grown band (values, masks, slices): about 16 bytes a
    // voxel. A first bound, before any mask is grown: each input's whole band grown by its
    // extension, or its bounding box so grown, whichever is smaller.
    auto grownBytes = [&](const MaskTree& mask, int d) {
        openvdb::CoordBBox box;
        mask.evalActiveVoxelBoundingBox(box);
        const double k = 2.0 * leavesFor(d) + 1.0;
        const double byLeaves = double(mask.activeVoxelCount()) * k * k * k;
        const openvdb::Coord dim = box.dim();
        const double byBox = (dim.x() + k - 1.0) * (dim.y() + k - 1.0) * (dim.z() + k - 1.0);
        return std::min(byLeaves, byBox) * double(LeafT::SIZE) * 16.0;
    };
    {
        double estimate = 0.0;
        for (size_t i = 0; i < n; ++i) estimate += grownBytes(*leaves[i], dilation[i]);
        if (estimate > limit) refuse(estimate, limit);
    }

    // Where the blend differs from the sharp operation by more than the tolerance, two inputs are
    // within needVox of their surfaces: the crease. First in leaves (a leaf of one input's band
    // within reach of a leaf of another's), then in voxels within those leaves.
    auto pairwise = [n](const std::vector<MaskTree::Ptr>& masks) {
        auto out = std::make_shared<MaskTree>();
        for (size_t i = 0; i < n; ++i) {
            for (size_t j = i + 1; j < n; ++j) {
                MaskTree both(*masks[i]);
                both.topologyIntersection(*masks[j]);
                out->topologyUnion(both);
            }
        }
        return out;
    };
    MaskTree::Ptr creasePtr;
    {
        std::vector<MaskTree::Ptr> reach(n);
        for (size_t i = 0; i < n; ++i) reach[i] = dilatedCopy(*leaves[i], leavesFor(dilation[i]));
        const MaskTree::Ptr candidates = pairwise(reach);
        for (size_t i = 0; i < n; ++i) {
            // The band's voxels in the leaves that can reach a candidate, grown by the extension.
            auto band = std::make_shared<MaskTree>();
            openvdb::tree::ValueAccessor<const FloatTree> acc(grids[i]->tree());
            const MaskTree::Ptr near = dilatedCopy(*candidates, leavesFor(dilation[i]));
            for (const Coord& o : leafOrigins(*near)) {
                if (const LeafT* leaf = acc.probeConstLeaf(o)) {
                    band->touchLeaf(o)->setValueMask(leaf->getValueMask());
                }
            }
            dilateLeaves(*band, dilation[i]);
            reach[i] = band;
        }
        creasePtr = pairwise(reach);
    }
    const MaskTree& crease = *creasePtr;
    const bool hasCrease = crease.activeVoxelCount() > 0;
    checkInterrupt(settings.interrupter);

    // The rest of the blend is the sharp operation (OpenVDB's csg tools), so only the crease
    // needs grown bands and re-distancing. Its re-distancing reads the surface within a band
    // width of the crease: the region around it.
    const MaskTree::Ptr regionPtr = dilatedCopy(crease, int(std::ceil(halfWidth)) + 2);
    const MaskTree& region = *regionPtr;
    std::vector<openvdb::FloatGrid::Ptr> grown(n);
    if (hasCrease) {
        double estimate = 0.0;
        std::vector<MaskTree::Ptr> keep(n);
        for (size_t i = 0; i < n; ++i) {
            // The grown band where the crease reads it, and the band itself over the whole
            // region (whose re-distancing reads the surface there).
            keep[i] = dilatedCopy(crease, std::max(dilation[i] + 1, int(std::ceil(halfWidth)) + 2));
            estimate += grownBytes(*leafMask(*keep[i]), dilation[i]);
        }
        if (estimate > limit) refuse(estimate, limit);
        for (size_t i = 0; i < n; ++i) {
            grown[i] = extendLocally(*grids[i], *keep[i], dilation[i]);
            checkInterrupt(settings.interrupter);
        }
    }
    if (notes) {
        std::ostringstream os;
        if (!hasCrease) {
            os << "the inputs do not come within the blend's reach of each other (p = "
               << util::formatNumber(p) << "): the result is the sharp operation";
        } else {
            os << "bands extended to " << needVox << " voxels where the inputs meet, for p = "
               << util::formatNumber(p) << " (reach "
               << util::formatNumber(std::round(reachVox * 10) / 10) << " voxels; "
               << util::formatNumber(double(region.activeVoxelCount()))
               << " voxels around the crease re-distanced)";
        }
        notes->push_back(os.str());
    }

    // The blended values over the region, from the grown bands; outside a grown band an input
    // counts as +/- the extended half width (beyond the blend's reach), by its sign.
    //
    // Which voxels keep the sharp value: take a union (an intersection is the union of the
    // complements) and the deciding term s = min t_i, with the next term s + g. The blended
    // surface leaves the sharp one only where two terms are within the reach R of each other and
    // the surface has swollen by at most ln(n)/p: there every term is below R + ln(n)/p. From a
    // voxel outside (s >= 0) those points are at least s + g - R - ln(n)/p away, so the sharp
    // value s is the distance if g >= R + ln(n)/p. From inside (s < 0), the nearest sharp
    // surface point (|s| away) is in the swollen part only if g < R + ln(n)/p + 2|s|. So a voxel
    // whose lead g exceeds R + ln(n)/p + 2 max(0, -s) (plus a voxel) keeps the sharp value;
    // the others are marked as blended and get re-distanced values.
    const float clamp = float(needVox * dx);
    const double lead = blendReach(p, settings.tolerance * dx) + std::log(double(n)) / p + dx;
    MaskTree blended;
    openvdb::FloatGrid::Ptr redistanced;
    auto combined = openvdb::FloatGrid::create(clamp);
    if (hasCrease) {
        combined->setTransform(finest.transform().copy());
        std::vector<const MaskTree::LeafNodeType*> in;
        for (auto it = region.cbeginLeaf(); it; ++it) in.push_back(it.getLeaf());
        std::vector<LeafT*> out(in.size());
        std::vector<MaskTree::LeafNodeType*> marks(in.size());
        for (size_t k = 0; k < in.size(); ++k) {
            out[k] = combined->tree().touchLeaf(in[k]->origin());
            marks[k] = blended.touchLeaf(in[k]->origin());
        }
        const implicit::Csg::Op kind = implicitOp(op);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, in.size()),
                          [&](const tbb::blocked_range<size_t>& r) {
            std::vector<openvdb::tree::ValueAccessor<const FloatTree>> ext, orig;
            for (size_t i = 0; i < n; ++i) {
                ext.emplace_back(grown[i]->tree());
                orig.emplace_back(grids[i]->tree());
            }
            std::vector<double> t(n);
            std::vector<char> reached(n);
            const double sign = kind == implicit::Csg::Op::Union ? 1.0 : -1.0;
            for (size_t k = r.begin(); k < r.end(); ++k) {
                LeafT& leaf = *out[k];
                MaskTree::LeafNodeType& mark = *marks[k];
                for (openvdb::Index m = 0; m < LeafT::SIZE; ++m) {
                    const Coord ijk = leaf.offsetToGlobalCoord(m);
                    for (size_t i = 0; i < n; ++i) {
                        float v;
                        if (!ext[i].probeValue(ijk, v)) v = orig[i].getValue(ijk) > 0.0f ? clamp : -clamp;
                        reached[i] = std::abs(v) < clamp;
                        v = std::max(-clamp, std::min(clamp, v));
                        t[i] = (kind == implicit::Csg::Op::Difference && i > 0) ? -double(v) : double(v);
                    }
                    const float f = float(implicit::blendTerms(kind, p, t.data(), n));
                    if (!in[k]->isValueOn(m)) { // outside the region: its sign only
                        leaf.setValueOff(m, f > 0.0f ? clamp : -clamp);
                        continue;
                    }
                    leaf.setValueOn(m, f);
                    // The lead of the deciding term over the next; a term beyond its grown band
                    // is beyond the blend's reach, however near it looks after clamping.
                    double first = 1e30, second = 1e30;
                    for (size_t i = 0; i < n; ++i) {
                        const double v = reached[i] ? sign * t[i] : 1e30;
                        if (v < first) second = first, first = v;
                        else if (v < second) second = v;
                    }
                    if (second < 1e30 && second - first < lead + 2.0 * std::max(0.0, -first)) {
                        mark.setValueOn(m); // two terms within reach, the second close enough
                    }
                }
            }
        });
        grown.clear();
        openvdb::tools::signedFloodFill(combined->tree());
        // The blend is not a distance (|grad f| < 1 near the crease): estimate f / |grad f|.
        combined->setGridClass(openvdb::GRID_LEVEL_SET);
        const auto grad = diff::gradient(*combined, 1);
        openvdb::tree::LeafManager<FloatTree> manager(combined->tree());
        manager.foreach([&](LeafT& leaf, size_t) {
            const auto* g = grad->tree().probeConstLeaf(leaf.origin());
            if (!g) return;
            for (auto it = leaf.beginValueOn(); it; ++it) {
                const double len = g->getValue(it.pos()).length();
                const double e = *it / std::max(len, 0.1);
                it.setValue(float(std::max(-double(clamp), std::min(double(clamp), e))));
            }
        });
        checkInterrupt(settings.interrupter);
        // Re-distance only what the blended voxels read: the surface within a band width of them
        // (the other voxels keep their values, inactive, for their signs).
        auto samples = combined->deepCopy();
        {
            const MaskTree::Ptr around = dilatedCopy(blended, int(std::ceil(halfWidth)) + 2);
            openvdb::tree::LeafManager<FloatTree> sampleLeaves(samples->tree());
            sampleLeaves.foreach([&](LeafT& leaf, size_t) {
                const MaskTree::LeafNodeType* m = around->probeConstLeaf(leaf.origin());
                leaf.setValueMask(m ? leaf.getValueMask() & m->getValueMask()
                                    : LeafT::NodeMaskType());
            });
        }
        redistanced = levelset::redistance(*samples, halfWidth, settings.interrupter);
    }

    // The sharp operation everywhere, then the re-distanced blend over the crease.
    openvdb::FloatGrid::Ptr result = csgInPlace(op, grids, nullptr);
    if (hasCrease) {
        std::vector<LeafT*> out;
        for (auto it = blended.cbeginLeaf(); it; ++it) {
            if (!it->isEmpty()) out.push_back(result->tree().touchLeaf(it->origin()));
        }
        tbb::parallel_for(tbb::blocked_range<size_t>(0, out.size()),
                          [&](const tbb::blocked_range<size_t>& r) {
            for (size_t k = r.begin(); k < r.end(); ++k) {
                LeafT& leaf = *out[k];
                const LeafT* d = redistanced->tree().probeConstLeaf(leaf.origin());
                const LeafT* f = combined->tree().probeConstLeaf(leaf.origin());
                const MaskTree::LeafNodeType* mark = blended.probeConstLeaf(leaf.origin());
                for (openvdb::Index m = 0; m < LeafT::SIZE; ++m) {
                    if (!mark->isValueOn(m)) continue;
                    const float v = d ? d->getValue(m) : bg;
                    if (d && d->isValueOn(m) && std::abs(v) < bg) {
                        leaf.setValueOn(m, v);
                    } else {
                        const float s = f ? f->getValue(m) : v;
                        leaf.setValueOff(m, s > 0.0f ? bg : -bg);
                    }
                }
            }
        });
        openvdb::tools::pruneLevelSet(result->tree());
    }
    result->setGridClass(openvdb::GRID_LEVEL_SET);
    result->setName("surface");
    return result;
}

// blendOnTarget between the interrupter's start() and end().
openvdb::FloatGrid::Ptr blendWithInterrupter(CsgOp op,
                                             const std::vector<openvdb::FloatGrid::Ptr>& grids,
                                             const BlendSettings& settings,
                                             std::vector<std::string>* notes)
{
    if (settings.interrupter) settings.interrupter->start("Blending");
    openvdb::FloatGrid::Ptr out = blendOnTarget(op, grids, settings, notes);
    if (settings.interrupter) settings.interrupter->end();
    return out;
}

} // namespace

double blendReach(double p, double toleranceWorld)
{
    return std::max(0.0, std::log(1.0 / (p * toleranceWorld)) / p);
}

openvdb::FloatGrid::Ptr blend(CsgOp op, const std::vector<openvdb::FloatGrid::ConstPtr>& inputs,
                              const BlendSettings& settings, std::vector<std::string>* notes)
{
    checkSettings(inputs.size(), settings);
    const openvdb::math::Transform& target = finestInput(inputs).transform();
    std::vector<openvdb::FloatGrid::Ptr> grids;
    for (const auto& in : inputs) grids.push_back(matchTransform(*in, target, notes));
    return blendWithInterrupter(op, grids, settings, notes);
}

openvdb::FloatGrid::Ptr blendInPlace(CsgOp op, const std::vector<openvdb::FloatGrid::Ptr>& inputs,
                                     const BlendSettings& settings, std::vector<std::string>* notes)
{
    checkSettings(inputs.size(), settings);
    const openvdb::math::Transform target = finestInput(inputs).transform();
    std::vector<openvdb::FloatGrid::Ptr> grids;
    for (const auto& in : inputs) {
        grids.push_back(in->transform() == target ? in : matchTransform(*in, target, notes));
    }
    return blendWithInterrupter(op, grids, settings, notes);
}

} // namespace ivdb::ops
