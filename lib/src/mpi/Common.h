// SPDX-License-Identifier: Apache-2.0
// What ivdb-mpi's commands share: errors raised on every rank at once, large messages, and one
// file written by every rank (MPI-IO) from the MPI-free pieces (io::FileHead, io::LeafRun).
#pragma once

#include <ivdb/io/VdbPieces.h>
#include <ivdb/util/System.h>

#include <openvdb/openvdb.h>

#include <mpi.h>

#include <algorithm>
#include <chrono>
#include <deque>
#include <cstdint>
#include <exception>
#include <string>
#include <utility>
#include <vector>

namespace ivdb::mpi::detail {

using Clock = std::chrono::steady_clock;

inline double secondsSince(Clock::time_point t)
{
    return std::chrono::duration<double>(Clock::now() - t).count();
}

int rankOf(MPI_Comm comm);
int sizeOf(MPI_Comm comm);

/// Raise @a error (empty: none) from this rank on every rank of @a comm: the lowest failing
/// rank's (rank 0 and that rank rethrow their own, so its type and parameter survive), others a
/// RuntimeError with its message.
void raiseTogether(MPI_Comm comm, std::exception_ptr error, const std::string& message);

/// Run @a step and return what it threw (null if nothing), with its text in @a message.
template<typename Fn>
std::exception_ptr captured(Fn&& step, std::string& message)
{
    try {
        step();
    } catch (const std::exception& e) {
        message = util::errorText(e);
        return std::current_exception();
    } catch (...) {
        message = "unknown failure";
        return std::current_exception();
    }
    return nullptr;
}

/// Run @a step on every rank of @a comm; if it threw on any rank, throw on every rank (see
/// raiseTogether).
template<typename Fn>
void collective(MPI_Comm comm, Fn&& step)
{
    std::string message;
    const std::exception_ptr error = captured(std::forward<Fn>(step), message);
    raiseTogether(comm, error, message);
}

/// Refuse the grid @a part read from @a path unless it is a level set (levelset::checkLevelSet)
/// whose band is in leaves: a level set with active tiles (which OpenVDB's and ivdb's level-set
/// tools do not make) would need them voxelized across the ranks.
void checkLevelSetInput(const io::PartialGrid& part, const std::string& path);

/// Point-to-point messages of any size (MPI counts are ints: pieces of 1 GiB).
void sendBlob(MPI_Comm comm, int to, int tag, const void* data, std::uint64_t bytes);
void recvBlob(MPI_Comm comm, int from, int tag, void* data, std::uint64_t bytes);

/// What each rank tells the others of one grid's run of leaves, before rank 0 gathers the
/// run's table entries.
struct RunSummary
{
    std::uint64_t leaves = 0, bytes = 0, activeVoxels = 0;
    std::int32_t box[6] = {0, 0, 0, -1, -1, -1};
    std::int32_t hasSizes = 0;
};

/// Every rank's summary of its run of one grid (in rank order).
std::vector<RunSummary> gatherSummaries(MPI_Comm comm, const io::LeafRun& run);

/// On rank 0, the table entries, active voxels and box of every rank's run of one grid,
/// joined in rank order (the others send theirs and get an empty run). Collective.
io::LeafRun gatherEntries(MPI_Comm comm, const io::LeafRun& mine,
                          const std::vector<RunSummary>& summaries);

/// Rank 0's head's layout (each grid's offset, head size and mask runs; not the head's bytes)
/// on every rank. Collective.
void shareLayout(MPI_Comm comm, io::FileHead& head);

/// One positioned write of a rank.
struct Write
{
    std::uint64_t offset;
    const char* data;
    std::uint64_t size;
};

/// The writes of this rank's run of grid @a grid of @a head: its leaves' masks into the
/// topology (kept in @a masks, whose elements stay in place as more are added) and its buffers
/// after the runs of the ranks before it.
void addRunWrites(MPI_Comm comm, const io::FileHead& head, std::size_t grid,
                  const io::LeafRun& run, const std::vector<RunSummary>& summaries,
                  std::deque<std::pair<std::uint64_t, std::string>>& masks,
                  std::vector<Write>& writes);

/// Every rank's writes into one temporary file in @a output's folder, renamed over @a output
/// by rank 0 once all have written; on any failure the temporary file is removed and the
/// output left as it was. Collective.
void writeTogether(MPI_Comm comm, const std::string& output, const std::vector<Write>& writes);

/// Write the file of @a head (rank 0's; every rank learns its layout) and of every rank's runs
/// of its grids, @a runs[g] with @a summaries[g] for grid g, to @a output (nothing if empty).
/// Returns the file's size (0 if not written). Collective.
std::uint64_t writeFile(MPI_Comm comm, const std::string& output, io::FileHead& head,
                        const std::vector<const io::LeafRun*>& runs,
                        const std::vector<std::vector<RunSummary>>& summaries);

/// A fog volume's run on a rank and, on rank 0, what its head needs.
struct FogRun
{
    io::LeafRun encoded, all; ///< the rank's leaves encoded; on rank 0, every rank's entries
    std::vector<RunSummary> summaries;
    openvdb::FloatGrid::Ptr skeleton; ///< rank 0's
    io::ActiveTiles tiles;            ///< rank 0's: the skeleton's
    std::uint64_t bufferBytes = 0;
};

/// levelset::fogFromLevelSet() over the ranks: each turns its run of the level set's leaves
/// @a leaves (in file order; taken out of the tree) into the fog's in place, with the ramp's end
/// from every rank's lowest value and rank 0's @a skeleton of the level set (io::skeletonOf's
/// kind, with its metadata), and encodes them with @a write; rank 0 gathers which leaves the fog
/// keeps (a byte a leaf; @a summaries: the level set's runs) and makes its skeleton.
/// Collective.
FogRun makeFog(MPI_Comm comm, const io::WriteOptions& write, openvdb::FloatTree& leaves,
               const openvdb::FloatGrid::Ptr& skeleton, const std::vector<RunSummary>& summaries);

/// Write a level set's file (and its fog volume's, if @a fog holds one): rank 0 lays out the
/// head from its @a skeleton and every rank's entries @a all (the grid's buffers are
/// @a bufferBytes) and fog's, then every rank writes its runs (@a encoded, @a summaries and the
/// fog's). Frees the skeletons and entries. Returns the file's size (0 if @a output is empty).
/// Collective.
std::uint64_t writeLevelSetFile(MPI_Comm comm, const std::string& output,
                                const io::WriteOptions& write, openvdb::FloatGrid::Ptr& skeleton,
                                io::LeafRun& all, std::uint64_t bufferBytes,
                                const io::LeafRun& encoded,
                                const std::vector<RunSummary>& summaries, FogRun* fog);

/// Every rank's peak resident memory (bytes), in rank order. Collective.
std::vector<std::uint64_t> gatherPeakMemory(MPI_Comm comm);

} // namespace ivdb::mpi::detail
