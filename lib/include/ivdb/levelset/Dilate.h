// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <openvdb/openvdb.h>

namespace ivdb::levelset {

/// @brief @a mask grown by @a voxels in every direction, corners included: each active voxel
/// becomes the cube of side 2 * voxels + 1 around it (the Chebyshev ball). The result equals
/// openvdb::tools::dilateActiveValues(mask, voxels, NN_FACE_EDGE_VERTEX, EXPAND_TILES) followed
/// by voxelizeActiveTiles(), but the cube is separable: three passes of one axis each, on the
/// leaves' 64-bit words, so the cost does not grow with @a voxels the way voxels repeated
/// one-voxel dilations do (30 voxels: see docs/performance.md#csg-and-blends).
/// Active tiles of @a mask count as their voxels. @a voxels <= 0 returns a voxelized copy.
openvdb::MaskTree::Ptr dilatedBox(const openvdb::MaskTree& mask, int voxels);

} // namespace ivdb::levelset
