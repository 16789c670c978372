// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/jobs/Rasterize.h>

#include <mpi.h>

#include <cstdint>
#include <vector>

namespace ivdb::mpi {

/// @brief What rasterize() reports, the same on every rank.
struct RasterizeResult
{
    int ranks = 1;
    std::uint64_t leaves = 0;          ///< leaves the band may cross (the unit split over ranks)
    std::uint64_t activeVoxels = 0;
    std::uint64_t fileBytes = 0;
    raster::RasterStats stats;         ///< summed over the ranks
    double computeSeconds = 0.0;       ///< reading the scene and rasterizing (the slowest rank)
    double writeSeconds = 0.0;         ///< encoding, gathering and writing the file
    double totalSeconds = 0.0;
    /// Per rank: leaves built, active voxels and peak resident memory (bytes).
    std::vector<std::uint64_t> rankLeaves, rankActiveVoxels, rankPeakMemory;
    std::vector<std::string> notes;    ///< the scene's (open meshes, rebuilt .vdb inputs)
};

/// @brief jobs::rasterize() over the ranks of @a comm, into one .vdb file that all of them write
/// at once: the file jobs::rasterize() writes, byte for byte but its random UUID.
/// @details Every rank reads the scene and runs the interval descent (no voxel evaluated) to
/// find the leaves the band may cross, in file order (raster::RasterRuns); rank r builds the
/// r-th of as many equal runs of them (raster::partition's split) on its threads and encodes
/// its leaves' buffers (io::encodeLeafRun); the voxels no local distance method answers are
/// gathered on every rank and fast-swept together (RasterRuns::sweep). Rank 0 gathers what each leaf became and the
/// leaves' table entries (10 bytes a leaf), builds the grid's nodes and tiles
/// (RasterRuns::skeleton) and the file's head (io::vdbFileHead); then every rank writes its
/// leaves' masks into the head's topology and its buffers at its offset (a prefix sum) into a
/// temporary file in the output's folder with MPI-IO, and rank 0 renames it over the output
/// once every rank has written. With a fog volume (options.fog), each rank then turns its
/// leaves into the fog's (levelset::fogLeaf, with the ramp's end from every rank's lowest value
/// and rank 0's tiles) and encodes them too; rank 0 makes the fog's nodes and tiles from the
/// level set's (levelset::fogSkeleton) and the file holds both grids.
/// Collective: call it on every rank of @a comm with the same options.
/// @throw on every rank, the error of the lowest rank that failed (rank 0 keeps its own, so a
/// ParamError keeps its parameter): the errors of jobs::rasterize() (a keyed scene's frames are
/// rasterizeSequence()'s); ParamError for dense sampling; openvdb::IoError when the file cannot
/// be written. Nothing is written on any error: the
/// temporary file is removed and an existing output is left as it was.
RasterizeResult rasterize(MPI_Comm comm, const jobs::RasterizeOptions& options);

/// @brief What rasterizeSequence() reports: `ranks`, `frames` and `totalSeconds` on every rank,
/// the rest on rank 0 (which receives the frames' reports).
struct SequenceResult
{
    int ranks = 1;
    std::size_t frames = 0;                  ///< the sequence's
    std::size_t written = 0, skipped = 0;
    double totalSeconds = 0.0;
    std::vector<std::uint64_t> rankFrames;     ///< per rank: frames it made
    std::vector<std::uint64_t> rankPeakMemory; ///< per rank: peak resident memory (bytes)
};

/// @brief jobs::rasterizeSequence() over the ranks of @a comm: the same files, each frame made
/// and written whole by one rank, as plain ivdb makes it (several frames at once on the rank's
/// threads).
/// @details Every rank checks the sequence first (jobs::sequenceFrames). Rank 0 then hands the
/// frames out in order, one at a time, to whichever rank asks for one when it can start a frame
/// (so the ranks stay busy however the frames' costs vary), with at most an equal share of the
/// frames in flight on one rank, and calls @a options.onFrame on its main thread for each frame
/// in frame order, with the rank that made it. Once a rank's failure reaches rank 0 (when that
/// rank's frames in flight have ended), or rank 0 is interrupted, no frame is handed out; the
/// frames being made finish (or stop at their rank's interrupter) and every frame written stays
/// whole.
/// Collective: call it on every rank of @a comm with the same options, from the thread that
/// initialized MPI (the frames are made on another thread, which never calls MPI).
/// @throw on every rank, the error of the lowest rank that failed (see rasterize()): the errors
/// of jobs::rasterizeSequence(); ParamError for dense sampling or no output.
SequenceResult rasterizeSequence(MPI_Comm comm, const jobs::SequenceOptions& options);

/// @brief How many threads a rank should use.
struct ThreadShare
{
    int threads = 1;     ///< its share: min(cores / ranksHere, boundCores), at least 1
    int cores = 1;       ///< the machine's
    int ranksHere = 1;   ///< ranks of the communicator on this machine
    int boundCores = 1;  ///< cores the rank may run on (mpirun binds ranks to cores by default)
};

/// @brief The cores of each rank's machine shared among the ranks of @a comm on that machine,
/// within the cores the rank is bound to. Collective.
ThreadShare threadShare(MPI_Comm comm);

} // namespace ivdb::mpi
