// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <openvdb/openvdb.h>

namespace ivdb::levelset {

/// @brief A mask tree with small internal nodes (8^3 children each, against OpenVDB's 16^3 and
/// 32^3): for masks of few leaves close together, such as one voxel per leaf of a grid, where
/// clearing the nodes' tables (256 KB for each top node) is much of the work: dilatedBox() by
/// one voxel of the mask of the leaves of a radius-400 sphere's band took 1.7 to 2.6 ms on a
/// MaskTree, 0.9 to 1.3 on this (`ivdb_bench --benchmark_filter=BM_DilateLeafMask`, four runs).
using SmallMaskTree = openvdb::tree::Tree4<openvdb::ValueMask, 3, 3, 3>::Type;

/// @brief @a mask grown by @a voxels in every direction, corners included: each active voxel
/// becomes the cube of side 2 * voxels + 1 around it (the Chebyshev ball). The result equals
/// openvdb::tools::dilateActiveValues(mask, voxels, NN_FACE_EDGE_VERTEX, EXPAND_TILES) followed
/// by voxelizeActiveTiles(), but the cube is separable: three passes of one axis each, on the
/// leaves' 64-bit words, so the cost does not grow with @a voxels the way voxels repeated
/// one-voxel dilations do (30 voxels: see docs/performance.md#csg-and-blends).
/// Active tiles of @a mask count as their voxels. @a voxels <= 0 returns a voxelized copy.
openvdb::MaskTree::Ptr dilatedBox(const openvdb::MaskTree& mask, int voxels);
/// @brief dilatedBox() of a SmallMaskTree.
SmallMaskTree::Ptr dilatedBox(const SmallMaskTree& mask, int voxels);

} // namespace ivdb::levelset
