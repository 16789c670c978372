// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/jobs/Combine.h>

#include <mpi.h>

#include <cstdint>
#include <string>
#include <vector>

namespace ivdb::mpi {

/// @brief What csg() reports, the same on every rank.
struct CsgResult
{
    int ranks = 1;
    std::uint64_t nodes = 0;           ///< 128^3 nodes of the inputs (the unit split over ranks)
    std::uint64_t leaves = 0;          ///< the result's
    std::uint64_t activeVoxels = 0;    ///< the result's
    std::uint64_t fileBytes = 0;
    std::vector<std::string> notes;    ///< the operation's: a narrowed band, a blend's extension
    std::vector<std::string> warnings; ///< an empty result
    double readSeconds = 0.0;          ///< topologies and the rank's leaves (the slowest rank)
    double computeSeconds = 0.0;       ///< the CSG of the rank's nodes (the slowest rank)
    double writeSeconds = 0.0;         ///< encoding, gathering and writing the file
    double totalSeconds = 0.0;
    /// Per rank: 128^3 nodes combined, the inputs' leaves read, the result's leaves and active
    /// voxels, and peak resident memory (bytes).
    std::vector<std::uint64_t> rankNodes, rankLeavesRead, rankLeaves, rankActiveVoxels,
        rankPeakMemory;
};

/// @brief jobs::combine()'s sharp CSG or blend over the ranks of @a comm, into one .vdb file that
/// all of them write at once: the file jobs::combine() writes, byte for byte but its random UUID.
/// @details CSG is a value-by-value operation, and OpenVDB's (which ops::csg runs) decides each
/// 128^3 node of the result from the inputs' same node and the tiles above it. So every rank reads
/// the inputs' topologies (io::PartialGrid), splits the 128^3 nodes that any input holds into
/// runs in file order balanced by their leaves, reads the leaves of its own nodes only, and runs
/// ops::csgInPlace on the inputs with every other 128^3 node replaced by an active tile (which
/// keeps the nodes above from being pruned on a partial view). Rank 0 gathers each node's result
/// (its tiles and which slots are leaves, or the tile it became) and the leaves' table entries,
/// builds the grid's nodes and tiles, prunes them as OpenVDB prunes a level set, and the ranks
/// write the file as rasterize() does.
/// A blend (p or k) is the sharp operation but around the crease (ops::BlendCrease): every rank
/// finds the crease from the topologies, and its 128^3 nodes join the split; rank 0 reads the
/// inputs' leaves near the crease as well as its own, computes the blend's values there as
/// ops::blend() does and sends each rank those in its nodes, which it sets into its sharp
/// result (ops::spliceBlend) before reporting its nodes. A fog volume (options.fog) is made from
/// the result's leaves on each rank and its nodes on rank 0, as rasterize() makes it.
/// Collective: call it on every rank with the same options.
/// @throw on every rank, the error of the lowest rank that failed (rank 0 keeps its own): the
/// errors of jobs::combine(); ParamError for inputs on different transforms (plain ivdb
/// resamples them); openvdb::ValueError for a level set with active tiles. Nothing is written
/// on any error.
CsgResult csg(MPI_Comm comm, const jobs::CombineOptions& options);

} // namespace ivdb::mpi
