// SPDX-License-Identifier: Apache-2.0
// ivdb-mpi's rasterize: one scene over the ranks of a communicator, into one .vdb file written by
// all of them at once (MPI-IO). The pieces are MPI-free (raster::RasterRuns, io::encodeLeafRun,
// io::vdbFileHead); this file moves them between ranks.
#include <ivdb/mpi/Rasterize.h>

#include "Common.h"

#include <ivdb/io/AtomicFile.h>
#include <ivdb/io/VdbPieces.h>
#include <ivdb/raster/Partition.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <openvdb/openvdb.h>

#include <algorithm>
#include <chrono>
#include <exception>
#include <memory>
#include <string>
#include <thread>

#include <sched.h>

namespace ivdb::mpi {

using namespace detail;

namespace {

/// What each rank tells the others of its run before rank 0 gathers the leaves' fates.
struct RunHeader
{
    std::uint64_t first = 0, count = 0;
    std::uint64_t local = 0, searched = 0, approximate = 0;
    std::int32_t anyInside = 0;
    double computeSeconds = 0.0;
};

/// Every rank's @a mine, joined in rank order, on every rank. Collective.
std::vector<openvdb::Coord> gatherCoords(MPI_Comm comm, const std::vector<openvdb::Coord>& mine)
{
    const int size = sizeOf(comm);
    const int count = int(3 * mine.size());
    std::vector<int> counts(std::size_t(size), 0), at(std::size_t(size), 0);
    MPI_Allgather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, comm);
    int total = 0;
    for (int r = 0; r < size; ++r) {
        at[std::size_t(r)] = total;
        total += counts[std::size_t(r)];
    }
    std::vector<std::int32_t> send(static_cast<std::size_t>(count)), all(static_cast<std::size_t>(total));
    for (std::size_t i = 0; i < mine.size(); ++i) {
        for (int a = 0; a < 3; ++a) send[3 * i + std::size_t(a)] = mine[i][a];
    }
    MPI_Allgatherv(send.data(), count, MPI_INT32_T, all.data(), counts.data(), at.data(),
                   MPI_INT32_T, comm);
    std::vector<openvdb::Coord> out(all.size() / 3);
    for (std::size_t i = 0; i < out.size(); ++i) {
        out[i] = openvdb::Coord(all[3 * i], all[3 * i + 1], all[3 * i + 2]);
    }
    return out;
}

} // namespace

ThreadShare threadShare(MPI_Comm comm)
{
    MPI_Comm local;
    MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, rankOf(comm), MPI_INFO_NULL, &local);
    ThreadShare share;
    share.ranksHere = sizeOf(local);
    MPI_Comm_free(&local);
    share.cores = int(std::max(1u, std::thread::hardware_concurrency()));
    cpu_set_t set;
    CPU_ZERO(&set);
    share.boundCores = ::sched_getaffinity(0, sizeof(set), &set) == 0 ? CPU_COUNT(&set) : share.cores;
    share.threads = std::max(1, std::min(share.cores / std::max(1, share.ranksHere), share.boundCores));
    return share;
}

RasterizeResult rasterize(MPI_Comm comm, const jobs::RasterizeOptions& opt)
{
    const auto start = Clock::now();
    const int rank = rankOf(comm), size = sizeOf(comm);
    RasterizeResult result;
    result.ranks = size;

    // Every rank: the scene, its settings and the leaves the band may cross.
    scene::Scene sc;
    raster::RasterSettings settings;
    std::unique_ptr<raster::RasterRuns> runs;
    bool ownRaster = false;
    collective(comm, [&] {
        if (opt.sampling == raster::Sampling::Dense) {
            throw ParamError(param::kSampling, "dense is the one-process reference (plain ivdb); "
                             "ranks rasterize sparsely");
        }
        if (rank == 0 && !opt.output.empty()) io::checkOutputPath(opt.output);
        sc = jobs::loadRasterScene(opt);
        if (sc.animated) jobs::throwAnimated(opt);
        settings = jobs::rasterSettings(sc, opt);
        if (rank != 0) settings.interrupter = nullptr;
        ownRaster = raster::isOwnRaster(sc.shape, settings);
        if (!ownRaster) {
            jobs::withSceneErrors(opt, [&] { runs = std::make_unique<raster::RasterRuns>(sc.shape, settings); });
        }
    });
    result.notes = sc.notes;

    if (ownRaster) {
        // A mesh or .vdb level set on the output's lattice is its own raster: a copy, which
        // rank 0 writes as plain ivdb does.
        jobs::RasterizeResult one;
        collective(comm, [&] {
            if (rank == 0) {
                one = jobs::rasterize(opt);
            }
        });
        std::uint64_t v[2] = {one.activeVoxels, one.fileBytes};
        MPI_Bcast(v, 2, MPI_UINT64_T, 0, comm);
        result.activeVoxels = v[0];
        result.fileBytes = v[1];
        result.computeSeconds = result.totalSeconds = secondsSince(start);
        result.rankLeaves.assign(std::size_t(size), 0);
        result.rankActiveVoxels.assign(std::size_t(size), 0);
        result.rankActiveVoxels[0] = result.activeVoxels;
        result.rankPeakMemory = gatherPeakMemory(comm);
        return result;
    }

    // Each rank its run: the same split as raster::partition.
    const std::uint64_t n = runs->leaves();
    result.leaves = n;
    const std::uint64_t first = n * std::uint64_t(rank) / std::uint64_t(size);
    const std::uint64_t count = n * std::uint64_t(rank + 1) / std::uint64_t(size) - first;
    raster::RunResult built;
    collective(comm, [&] { jobs::withSceneErrors(opt, [&] { built = runs->build(first, count); }); });

    // Voxels no local method answered: fast-swept as plain ivdb sweeps them, over all of them
    // (every rank gets every run's; they are few) and set by the rank that holds them.
    std::vector<openvdb::Coord> unknown = gatherCoords(comm, built.unknown);
    std::sort(unknown.begin(), unknown.end());
    result.stats.sweptDistances = unknown.size();
    if (!unknown.empty()) collective(comm, [&] { runs->sweep(built, unknown); });
    built.unknown = std::vector<openvdb::Coord>();
    const double computeSeconds = secondsSince(start);
    const auto writeStart = Clock::now();

    // Each rank encodes its leaves as the file stores them (a fog volume is made from them next).
    io::LeafRun encoded;
    collective(comm, [&] {
        auto part = openvdb::FloatGrid::create(built.leaves);
        part->setGridClass(openvdb::GRID_LEVEL_SET);
        encoded = io::encodeLeafRun(*part, opt.write);
    });
    if (!opt.fog) built.leaves.reset();

    RunHeader mine;
    mine.first = first;
    mine.count = count;
    mine.local = built.stats.localDistances;
    mine.searched = built.stats.searchedDistances;
    mine.approximate = built.stats.approximateDistances;
    mine.anyInside = built.anyInside ? 1 : 0;
    mine.computeSeconds = computeSeconds;
    std::vector<RunHeader> headers(static_cast<std::size_t>(size));
    MPI_Allgather(&mine, int(sizeof(RunHeader)), MPI_BYTE, headers.data(), int(sizeof(RunHeader)),
                  MPI_BYTE, comm);
    const std::vector<RunSummary> summaries = gatherSummaries(comm, encoded);

    // Rank 0 gathers every leaf's fate and table entry (each rank keeps its leaves' masks).
    std::vector<raster::LeafFate> fates;
    if (rank == 0) {
        fates.resize(n);
        std::copy(built.fates.begin(), built.fates.end(), fates.begin());
        for (int r = 1; r < size; ++r) {
            const RunHeader& h = headers[std::size_t(r)];
            recvBlob(comm, r, 1, fates.data() + h.first, h.count);
        }
    } else {
        sendBlob(comm, 0, 1, built.fates.data(), built.fates.size());
    }
    built.fates.clear();
    io::LeafRun all = gatherEntries(comm, encoded, summaries);
    encoded.codes.clear();
    encoded.sizes.clear();

    std::uint64_t activeVoxels = 0, bufferBytes = 0;
    int anyInside = 0;
    for (std::size_t r = 0; r < headers.size(); ++r) {
        const RunHeader& h = headers[r];
        activeVoxels += summaries[r].activeVoxels;
        bufferBytes += summaries[r].bytes;
        anyInside = anyInside || h.anyInside;
        result.stats.localDistances += h.local;
        result.stats.searchedDistances += h.searched;
        result.stats.approximateDistances += h.approximate;
        result.computeSeconds = std::max(result.computeSeconds, h.computeSeconds);
        result.rankLeaves.push_back(summaries[r].leaves);
        result.rankActiveVoxels.push_back(summaries[r].activeVoxels);
    }

    // Rank 0: the grid's nodes and tiles.
    openvdb::FloatGrid::Ptr skeleton;
    collective(comm, [&] {
        if (rank != 0) return;
        skeleton = runs->skeleton(fates, anyInside != 0);
        fates = std::vector<raster::LeafFate>();
        if (activeVoxels == 0 || skeleton->tree().activeTileCount() == 0) {
            jobs::throwNoVoxels(opt, settings);
        }
        jobs::stampRaster(*skeleton, opt, sc, settings);
    });
    FogRun fog;
    if (opt.fog) fog = makeFog(comm, opt.write, *built.leaves, skeleton, summaries);
    built.leaves.reset();

    result.activeVoxels = activeVoxels;
    result.fileBytes = writeLevelSetFile(comm, opt.output, opt.write, skeleton, all, bufferBytes,
                                         encoded, summaries, opt.fog ? &fog : nullptr);
    result.writeSeconds = secondsSince(writeStart);

    result.rankPeakMemory = gatherPeakMemory(comm);
    double total = secondsSince(start);
    MPI_Allreduce(MPI_IN_PLACE, &total, 1, MPI_DOUBLE, MPI_MAX, comm);
    result.totalSeconds = total;
    return result;
}

} // namespace ivdb::mpi
