// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/io/VdbPieces.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <vector>

namespace ivdb::levelset {

/// @brief A fog volume named "density" from a narrow-band level set, for renderers that draw
/// volumes (Blender): 0 outside, rising smoothly across the inside half of the band from 0 at the
/// surface to 1 at the band's inner edge, 1 deeper inside (active tiles), as
/// openvdb::tools::sdfToFogVolume makes it. @a levelSet is not changed.
openvdb::FloatGrid::Ptr fogFromLevelSet(const openvdb::FloatGrid& levelSet);

/// @name fogFromLevelSet() in pieces
/// For processes that each hold a run of a level set's leaves (ivdb-mpi): the ramp's end from
/// the whole grid, each leaf on its own, and the fog's nodes and tiles from the level set's.
/// With them, each process's leaves and the skeleton make the fog fogFromLevelSet() makes.
/// @{

/// @brief The value the ramp reaches 1 at: -background, or the grid's lowest value if the
/// 128^3 nodes hold no inside tile and no voxel reaches -background (sdfToFogVolume's rule).
/// @a skeleton: the level set's nodes and tiles with an active tile for each leaf
/// (io::skeletonOf); @a lowest: the lowest value in any of its leaves, active or not
/// (lowestValue(), the least over every process's leaves).
float fogCutoff(const openvdb::FloatGrid& skeleton, float lowest);

/// @brief The lowest value in @a tree's leaves, active or not (the largest float if none).
float lowestValue(const openvdb::FloatTree& tree);

/// @brief Turn a leaf of the level set into the fog's leaf, in place, for @a cutoff
/// (fogCutoff()): 0 and inactive outside, -phi / -cutoff and active inside. Returns false if
/// no voxel is active, a leaf the fog does not keep.
bool fogLeaf(openvdb::FloatTree::LeafNodeType& leaf, float cutoff);

/// @brief The fog's skeleton (io::HeadGrid) from the level set's @a skeleton (io::skeletonOf,
/// with the grid's metadata) and @a kept, whether fogLeaf() kept each of its leaves (in file
/// order): the fog's 128^3 nodes are those with a kept leaf, their tiles inside the level set
/// active with value 1 (listed in @a activeTiles), and so are the tiles above them and the
/// root's that lie inside. Named "density", a fog volume, with the level set's other metadata.
/// @throw openvdb::ValueError if @a kept does not hold one entry per leaf of @a skeleton
openvdb::FloatGrid::Ptr fogSkeleton(const openvdb::FloatGrid& skeleton,
                                    const std::vector<std::uint8_t>& kept,
                                    io::ActiveTiles& activeTiles);
/// @}

} // namespace ivdb::levelset
