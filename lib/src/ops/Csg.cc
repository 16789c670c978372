#include <ivdb/ops/Csg.h>

#include <openvdb/tools/Composite.h>
#include <openvdb/tools/GridTransformer.h>

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

openvdb::FloatGrid::Ptr csg(CsgOp op, const std::vector<openvdb::FloatGrid::ConstPtr>& inputs,
                            std::vector<std::string>* notes)
{
    if (inputs.size() < 2) {
        OPENVDB_THROW(openvdb::ValueError, "CSG needs at least two level sets, got " +
                                               std::to_string(inputs.size()));
    }
    size_t finest = 0;
    for (size_t i = 1; i < inputs.size(); ++i) {
        if (inputs[i]->voxelSize()[0] < inputs[finest]->voxelSize()[0]) finest = i;
    }
    const openvdb::math::Transform& target = inputs[finest]->transform();
    openvdb::FloatGrid::Ptr result = matchTransform(*inputs[0], target, notes);
    for (size_t i = 1; i < inputs.size(); ++i) {
        const openvdb::FloatGrid::Ptr next = matchTransform(*inputs[i], target, notes);
        switch (op) {
        case CsgOp::Union: result = openvdb::tools::csgUnionCopy(*result, *next); break;
        case CsgOp::Intersection: result = openvdb::tools::csgIntersectionCopy(*result, *next); break;
        case CsgOp::Difference: result = openvdb::tools::csgDifferenceCopy(*result, *next); break;
        }
    }
    result->setTransform(target.copy());
    result->setGridClass(openvdb::GRID_LEVEL_SET);
    result->setName("surface");
    return result;
}

} // namespace ivdb::ops
