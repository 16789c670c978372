// SPDX-License-Identifier: Apache-2.0
#include <ivdb/ops/Csg.h>

#include <openvdb/tools/ChangeBackground.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/GridTransformer.h>
#include <openvdb/tree/LeafManager.h>

#include <cmath>

#include <sstream>

namespace ivdb::ops {

openvdb::FloatGrid::Ptr matchTransform(const openvdb::FloatGrid& grid,
                                       const openvdb::math::Transform& target,
                                       std::vector<std::string>* notes)
{
    if (grid.transform() == target) return grid.deepCopy();
    auto out = openvdb::FloatGrid::create(grid.background());
    out->setTransform(target.copy());
    out->setGridClass(grid.getGridClass());
    openvdb::tools::resampleToMatch<openvdb::tools::BoxSampler>(grid, *out);
    if (notes) {
        std::ostringstream os;
        os << "grid '" << grid.getName() << "' resampled from voxel size " << grid.voxelSize()[0]
           << " onto the finest input's transform (voxel size " << target.voxelSize()[0] << ")";
        notes->push_back(os.str());
    }
    return out;
}

namespace {

/// Give a level set the narrow band of half width @a bg (world units): active voxels with
/// |d| >= bg become inactive, and every inactive value becomes +/- bg by its sign. Inputs with
/// different bands (a coarser grid resampled, or another half width) would otherwise mix their
/// backgrounds in the result, and which one a region gets would depend on the order of the
/// inputs and on thread timing.
void normalizeBand(openvdb::FloatGrid& grid, float bg)
{
    if (grid.background() == bg) return;
    openvdb::tree::LeafManager<openvdb::FloatTree> leaves(grid.tree());
    leaves.foreach([bg](openvdb::FloatTree::LeafNodeType& leaf, size_t) {
        float* buf = leaf.buffer().data();
        for (openvdb::Index n = 0; n < leaf.SIZE; ++n) {
            if (leaf.isValueOn(n) && std::abs(buf[n]) < bg) continue;
            leaf.setValueOff(n, buf[n] > 0.0f ? bg : -bg);
        }
    });
    openvdb::tools::changeLevelSetBackground(grid.tree(), bg);
    openvdb::tools::pruneLevelSet(grid.tree());
}

} // namespace

openvdb::FloatGrid::Ptr csgInPlace(CsgOp op, const std::vector<openvdb::FloatGrid::Ptr>& inputs,
                                   std::vector<std::string>* notes)
{
    if (inputs.size() < 2) {
        OPENVDB_THROW(openvdb::ValueError, "CSG needs at least two level sets, got " +
                                               std::to_string(inputs.size()));
    }
    const openvdb::FloatGrid& finest = finestInput(inputs);
    const openvdb::math::Transform::Ptr target = finest.transform().copy();
    const float bg = finest.background();
    // Inputs already on the target with its band are used as they are.
    auto prepare = [&](const openvdb::FloatGrid::Ptr& in) -> openvdb::FloatGrid::Ptr {
        if (in->transform() == *target && in->background() == bg) return in;
        openvdb::FloatGrid::Ptr g = matchTransform(*in, *target, notes);
        normalizeBand(*g, bg);
        return g;
    };
    openvdb::FloatGrid::Ptr result = prepare(inputs[0]);
    for (size_t i = 1; i < inputs.size(); ++i) {
        const openvdb::FloatGrid::Ptr next = prepare(inputs[i]);
        switch (op) {
        case CsgOp::Union: openvdb::tools::csgUnion(*result, *next); break;
        case CsgOp::Intersection: openvdb::tools::csgIntersection(*result, *next); break;
        case CsgOp::Difference: openvdb::tools::csgDifference(*result, *next); break;
        }
    }
    result->setTransform(target);
    result->setGridClass(openvdb::GRID_LEVEL_SET);
    result->setName("surface");
    return result;
}

openvdb::FloatGrid::Ptr csg(CsgOp op, const std::vector<openvdb::FloatGrid::ConstPtr>& inputs,
                            std::vector<std::string>* notes)
{
    std::vector<openvdb::FloatGrid::Ptr> copies;
    for (const auto& in : inputs) copies.push_back(in->deepCopy());
    return csgInPlace(op, copies, notes);
}

} // namespace ivdb::ops
