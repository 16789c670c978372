// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/CsgOp.h>

#include <openvdb/openvdb.h>

#include <string>
#include <vector>

namespace ivdb::ops {

/// @brief The operations, shared with scene trees (implicit::CsgOp).
using CsgOp = implicit::CsgOp;

/// @brief Sharp CSG of narrow-band level sets (docs/method.md#csg): union = min, intersection = max,
/// difference = max(A, -B) of the first input with each following one subtracted.
/// @details Inputs whose transform differs from the finest input's (smallest voxel) are first
/// resampled onto it (openvdb::tools::resampleToMatch, which rebuilds level sets); each
/// resampling is described in @a notes. Every input then gets the finest input's background
/// (a wider band is trimmed to it; a narrower one keeps its active voxels), so the result has
/// one background. The combination is OpenVDB's csgUnion /
/// csgIntersection / csgDifference (on copies of the inputs), which works in parallel over the union of the inputs'
/// topologies, steals whole nodes where only one input has any, and handles inactive regions and
/// tiles by their sign. The result is a level set named "surface" on the finest transform.
/// @throw openvdb::ValueError for fewer than two inputs
openvdb::FloatGrid::Ptr csg(CsgOp op, const std::vector<openvdb::FloatGrid::ConstPtr>& inputs,
                            std::vector<std::string>* notes = nullptr);

/// @brief csg() that consumes its inputs: OpenVDB's in-place csgUnion / csgIntersection /
/// csgDifference steal their nodes (no copies), so the inputs are left empty or changed.
/// For callers that do not need the inputs afterwards (the CLI).
openvdb::FloatGrid::Ptr csgInPlace(CsgOp op, const std::vector<openvdb::FloatGrid::Ptr>& inputs,
                                   std::vector<std::string>* notes = nullptr);

/// @brief The input with the smallest voxels (the first on ties): the one the others are
/// resampled onto. @a inputs must not be empty.
template<typename GridPtrT>
const openvdb::FloatGrid& finestInput(const std::vector<GridPtrT>& inputs)
{
    size_t finest = 0;
    for (size_t i = 1; i < inputs.size(); ++i) {
        if (inputs[i]->voxelSize()[0] < inputs[finest]->voxelSize()[0]) finest = i;
    }
    return *inputs[finest];
}

/// @brief @a grid on @a target's transform: a copy if the transforms match, else a resampled
/// level set (a note is appended to @a notes).
openvdb::FloatGrid::Ptr matchTransform(const openvdb::FloatGrid& grid,
                                       const openvdb::math::Transform& target,
                                       std::vector<std::string>* notes = nullptr);

} // namespace ivdb::ops
