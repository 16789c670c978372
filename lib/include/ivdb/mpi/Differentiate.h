// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/jobs/Differentiate.h>

#include <mpi.h>

#include <cstdint>
#include <string>
#include <vector>

namespace ivdb::mpi {

/// @brief What gradient() and curvature() report, the same on every rank.
struct DifferentiateResult
{
    int ranks = 1;
    std::string gridName;              ///< the input grid's
    std::uint64_t leaves = 0;          ///< the input's leaves (the unit split over ranks)
    std::uint64_t activeVoxels = 0;    ///< of each output grid
    std::uint64_t fileBytes = 0;
    double readSeconds = 0.0;          ///< topology and the rank's leaves (the slowest rank)
    double computeSeconds = 0.0;       ///< the stencils (the slowest rank)
    double writeSeconds = 0.0;         ///< encoding, gathering and writing the file
    double totalSeconds = 0.0;
    /// Per rank: the input's leaves computed (its run, empty ones included), leaves read (those
    /// and their neighbours within the stencil's reach), active voxels computed, and peak
    /// resident memory (bytes).
    std::vector<std::uint64_t> rankLeaves, rankLeavesRead, rankActiveVoxels, rankPeakMemory;
};

/// @brief jobs::gradient() over the ranks of @a comm, into one .vdb file that all of them write
/// at once: the file jobs::gradient() writes, byte for byte but its random UUID.
/// @details Every rank reads the input grid's metadata, transform and topology (io::PartialGrid,
/// about 100 bytes a leaf, no values), takes the r-th of as many equal runs of its leaves in file
/// order, and reads the values of only those leaves and of their neighbours within the
/// stencil's reach (the halo: ceil(step / 8) leaves along each axis). It computes its run's
/// leaves (diff::gradient on those leaves alone) and encodes them (io::encodeLeafRun, also the
/// input's run with `withInput`). Rank 0 gathers the leaves' table entries, makes each output
/// grid's nodes from the input's topology (io::leafSkeleton, io::skeletonOf) and the file's head
/// (io::vdbFileHead), and every rank writes its masks and buffers with MPI-IO as
/// rasterize() does. Collective: call it on every rank with the same options.
/// @throw on every rank, the error of the lowest rank that failed (rank 0 keeps its own): the
/// errors of jobs::gradient(); openvdb::ValueError for a level set with active tiles (OpenVDB and
/// ivdb keep a band in leaves; plain ivdb takes such a grid). Nothing is written on any error.
DifferentiateResult gradient(MPI_Comm comm, const jobs::GradientOptions& options);

/// @brief jobs::curvature() over the ranks of @a comm, as gradient() (a halo of one leaf in
/// every direction: the 3x3x3 stencil).
DifferentiateResult curvature(MPI_Comm comm, const jobs::CurvatureOptions& options);

} // namespace ivdb::mpi
