// SPDX-License-Identifier: Apache-2.0
// ivdb-mpi's rasterize: one scene over the ranks of a communicator, into one .vdb file written by
// all of them at once (MPI-IO). The pieces are MPI-free (raster::RasterRuns, io::encodeLeafRun,
// io::vdbFileHead); this file moves them between ranks.
#include <ivdb/mpi/Rasterize.h>

#include <ivdb/Version.h>
#include <ivdb/io/AtomicFile.h>
#include <ivdb/io/VdbPieces.h>
#include <ivdb/raster/Partition.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <openvdb/openvdb.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>
#include <thread>

#include <sched.h>
#include <unistd.h>

namespace ivdb::mpi {

namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point t)
{
    return std::chrono::duration<double>(Clock::now() - t).count();
}

int rankOf(MPI_Comm comm)
{
    int r = 0;
    MPI_Comm_rank(comm, &r);
    return r;
}

int sizeOf(MPI_Comm comm)
{
    int n = 1;
    MPI_Comm_size(comm, &n);
    return n;
}

/// Run @a step on every rank of @a comm; if it threw on any rank, throw on every rank: the
/// lowest failing rank's error (rank 0 and that rank rethrow their own, so its type and
/// parameter survive), others a RuntimeError with its message.
template<typename Fn>
void collective(MPI_Comm comm, Fn&& step)
{
    std::exception_ptr error;
    std::string message;
    try {
        step();
    } catch (const std::exception& e) {
        error = std::current_exception();
        message = util::errorText(e);
    } catch (...) {
        error = std::current_exception();
        message = "unknown failure";
    }
    const int rank = rankOf(comm), size = sizeOf(comm);
    int mine = error ? rank : size, first = size;
    MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, comm);
    if (first == size) return;
    int length = int(std::min<std::size_t>(message.size(), 1 << 16));
    MPI_Bcast(&length, 1, MPI_INT, first, comm);
    message.resize(std::size_t(length));
    MPI_Bcast(message.data(), length, MPI_CHAR, first, comm);
    if (error) std::rethrow_exception(error);
    const std::string what = first == 0 ? message : "rank " + std::to_string(first) + ": " + message;
    OPENVDB_THROW(openvdb::RuntimeError, what);
}

/// MPI counts are ints: large buffers go in pieces of 1 GiB.
constexpr std::uint64_t kPiece = std::uint64_t(1) << 30;

void sendBlob(MPI_Comm comm, int to, int tag, const void* data, std::uint64_t bytes)
{
    const char* p = static_cast<const char*>(data);
    for (std::uint64_t at = 0; at < bytes; at += kPiece) {
        MPI_Send(p + at, int(std::min(kPiece, bytes - at)), MPI_BYTE, to, tag, comm);
    }
}

void recvBlob(MPI_Comm comm, int from, int tag, void* data, std::uint64_t bytes)
{
    char* p = static_cast<char*>(data);
    for (std::uint64_t at = 0; at < bytes; at += kPiece) {
        MPI_Recv(p + at, int(std::min(kPiece, bytes - at)), MPI_BYTE, from, tag, comm,
                 MPI_STATUS_IGNORE);
    }
}

/// What each rank tells rank 0 of its run before the arrays.
struct RunHeader
{
    std::uint64_t first = 0, count = 0, leaves = 0, bytes = 0, activeVoxels = 0, peakMemory = 0;
    std::uint64_t local = 0, searched = 0, approximate = 0, swept = 0;
    std::int32_t box[6] = {0, 0, 0, -1, -1, -1};
    std::int32_t anyInside = 0, hasSizes = 0;
    double computeSeconds = 0.0;
};

std::string mpiError(int code)
{
    char text[MPI_MAX_ERROR_STRING];
    int length = 0;
    MPI_Error_string(code, text, &length);
    return std::string(text, std::size_t(length));
}

/// One positioned write of a rank.
struct Write
{
    std::uint64_t offset;
    const char* data;
    std::uint64_t size;
};

/// Every rank's writes (the head's parts, its leaves' masks, its buffers) into one temporary
/// file, renamed over the output by rank 0 once all have written; on any failure the temporary
/// file is removed.
void writeTogether(MPI_Comm comm, const std::string& output, const std::vector<Write>& writes)
{
    const int rank = rankOf(comm);
    std::string tmp;
    if (rank == 0) {
        namespace fs = std::filesystem;
        const fs::path target(output);
        fs::path folder = target.parent_path();
        if (folder.empty()) folder = ".";
        tmp = (folder / ("." + target.filename().string() + ".tmp-mpi-" +
                         std::to_string(::getpid()))).string();
        std::remove(tmp.c_str());
    }
    int length = int(tmp.size());
    MPI_Bcast(&length, 1, MPI_INT, 0, comm);
    tmp.resize(std::size_t(length));
    MPI_Bcast(tmp.data(), length, MPI_CHAR, 0, comm);

    MPI_File file;
    const int opened = MPI_File_open(comm, tmp.c_str(), MPI_MODE_CREATE | MPI_MODE_WRONLY,
                                     MPI_INFO_NULL, &file);
    collective(comm, [&] {
        if (opened != MPI_SUCCESS) {
            OPENVDB_THROW(openvdb::IoError, output + ": cannot create the temporary file " + tmp +
                          ": " + mpiError(opened));
        }
    });
    try {
        int written = MPI_SUCCESS;
        for (const Write& w : writes) {
            for (std::uint64_t done = 0; done < w.size && written == MPI_SUCCESS; done += kPiece) {
                const int n = int(std::min<std::uint64_t>(kPiece, w.size - done));
                MPI_Status status;
                written = MPI_File_write_at(file, MPI_Offset(w.offset + done), w.data + done, n,
                                            MPI_BYTE, &status);
                int count = 0;
                if (written == MPI_SUCCESS) MPI_Get_count(&status, MPI_BYTE, &count);
                if (written == MPI_SUCCESS && count != n) written = MPI_ERR_IO;
            }
        }
        const int synced = MPI_File_sync(file);
        const int closed = MPI_File_close(&file);
        collective(comm, [&] {
            for (const int rc : {written, synced, closed}) {
                if (rc != MPI_SUCCESS) {
                    OPENVDB_THROW(openvdb::IoError, output + ": writing " + tmp + " failed: " +
                                  mpiError(rc) + " (a full disk or a file-size limit?)");
                }
            }
        });
        collective(comm, [&] {
            if (rank == 0 && std::rename(tmp.c_str(), output.c_str()) != 0) {
                OPENVDB_THROW(openvdb::IoError, output + ": cannot rename " + tmp + " over it: " +
                              std::strerror(errno));
            }
        });
    } catch (...) {
        if (rank == 0) std::remove(tmp.c_str());
        throw;
    }
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
        if (sc.animated) {
            OPENVDB_THROW(openvdb::RuntimeError, opt.scene + " has keyed values (an animation): "
                          "ivdb-mpi rasterizes still scenes; plain ivdb writes its frames "
                          "(ivdb rasterize --frames)");
        }
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
        result.rankPeakMemory.assign(std::size_t(size), 0);
        const std::uint64_t peak = util::peakResidentMemory();
        MPI_Allgather(&peak, 1, MPI_UINT64_T, result.rankPeakMemory.data(), 1, MPI_UINT64_T, comm);
        return result;
    }

    // Each rank its run: the same split as raster::partition.
    const std::uint64_t n = runs->leaves();
    result.leaves = n;
    const std::uint64_t first = n * std::uint64_t(rank) / std::uint64_t(size);
    const std::uint64_t count = n * std::uint64_t(rank + 1) / std::uint64_t(size) - first;
    raster::RunResult built;
    collective(comm, [&] { jobs::withSceneErrors(opt, [&] { built = runs->build(first, count); }); });
    const double computeSeconds = secondsSince(start);
    const auto writeStart = Clock::now();

    // Voxels no local method answered need fast sweeping across the runs' borders.
    std::uint64_t swept = built.stats.sweptDistances, sweptAll = 0;
    MPI_Allreduce(&swept, &sweptAll, 1, MPI_UINT64_T, MPI_SUM, comm);
    if (sweptAll > 0) {
        std::ostringstream os;
        os << opt.scene << ": " << sweptAll << " voxels of the band are farther from the surface "
           << "than the local distance search reaches (with a half width of "
           << settings.halfWidth << " voxels, near edges and corners of a shape that is not an "
              "exact distance); plain ivdb fast-sweeps them, ivdb-mpi does not yet: use a "
              "narrower band (the default 3 voxels) or plain ivdb";
        OPENVDB_THROW(openvdb::RuntimeError, os.str());
    }

    // Each rank encodes its leaves as the file stores them.
    io::LeafRun encoded;
    collective(comm, [&] {
        auto part = openvdb::FloatGrid::create(built.leaves);
        part->setGridClass(openvdb::GRID_LEVEL_SET);
        encoded = io::encodeLeafRun(*part, opt.write);
    });
    built.leaves.reset();

    RunHeader mine;
    mine.first = first;
    mine.count = count;
    mine.leaves = encoded.masks.size();
    mine.bytes = encoded.byteCount();
    mine.activeVoxels = encoded.activeVoxels;
    mine.peakMemory = util::peakResidentMemory();
    mine.local = built.stats.localDistances;
    mine.searched = built.stats.searchedDistances;
    mine.approximate = built.stats.approximateDistances;
    if (!encoded.activeBox.empty()) {
        for (int i = 0; i < 3; ++i) {
            mine.box[i] = encoded.activeBox.min()[i];
            mine.box[3 + i] = encoded.activeBox.max()[i];
        }
    }
    mine.anyInside = built.anyInside ? 1 : 0;
    mine.hasSizes = encoded.sizes.empty() ? 0 : 1;
    mine.computeSeconds = computeSeconds;
    std::vector<RunHeader> headers(static_cast<std::size_t>(size));
    MPI_Allgather(&mine, int(sizeof(RunHeader)), MPI_BYTE, headers.data(), int(sizeof(RunHeader)),
                  MPI_BYTE, comm);

    // Rank 0 gathers every leaf's fate and table entry (each rank keeps its leaves' masks).
    std::vector<raster::LeafFate> fates;
    io::LeafRun all;
    if (rank == 0) {
        fates.resize(n);
        std::copy(built.fates.begin(), built.fates.end(), fates.begin());
        all.appendEntries(encoded);
        for (int r = 1; r < size; ++r) {
            const RunHeader& h = headers[std::size_t(r)];
            recvBlob(comm, r, 1, fates.data() + h.first, h.count);
            io::LeafRun run;
            run.codes.resize(h.leaves);
            if (h.hasSizes) run.sizes.resize(h.leaves);
            recvBlob(comm, r, 2, run.codes.data(), h.leaves);
            if (h.hasSizes) recvBlob(comm, r, 4, run.sizes.data(), h.leaves * sizeof(std::int64_t));
            run.activeVoxels = h.activeVoxels;
            if (h.box[3] >= h.box[0]) {
                run.activeBox = openvdb::CoordBBox(openvdb::Coord(h.box[0], h.box[1], h.box[2]),
                                                   openvdb::Coord(h.box[3], h.box[4], h.box[5]));
            }
            all.appendEntries(run);
        }
    } else {
        sendBlob(comm, 0, 1, built.fates.data(), built.fates.size());
        sendBlob(comm, 0, 2, encoded.codes.data(), encoded.codes.size());
        if (!encoded.sizes.empty()) {
            sendBlob(comm, 0, 4, encoded.sizes.data(), encoded.sizes.size() * sizeof(std::int64_t));
        }
    }
    built.fates.clear();
    encoded.codes.clear();
    encoded.sizes.clear();

    std::uint64_t activeVoxels = 0, bufferBytes = 0;
    int anyInside = 0;
    for (const RunHeader& h : headers) {
        activeVoxels += h.activeVoxels;
        bufferBytes += h.bytes;
        anyInside = anyInside || h.anyInside;
        result.stats.localDistances += h.local;
        result.stats.searchedDistances += h.searched;
        result.stats.approximateDistances += h.approximate;
        result.computeSeconds = std::max(result.computeSeconds, h.computeSeconds);
        result.rankLeaves.push_back(h.leaves);
        result.rankActiveVoxels.push_back(h.activeVoxels);
    }

    // Rank 0: the grid's nodes and tiles, and the file's head.
    io::FileHead head;
    collective(comm, [&] {
        if (rank != 0) return;
        const openvdb::FloatGrid::Ptr skeleton = runs->skeleton(fates, anyInside != 0);
        fates = std::vector<raster::LeafFate>();
        if (activeVoxels == 0 || skeleton->tree().activeTileCount() == 0) {
            jobs::throwNoVoxels(opt, settings);
        }
        jobs::stampRaster(*skeleton, opt, sc, settings);
        openvdb::MetaMap fileMeta;
        fileMeta.insertMeta("creator", openvdb::StringMetadata(std::string("ivdb ") + kVersion));
        head = io::vdbFileHead(*skeleton, all, bufferBytes, fileMeta, opt.write);
    });
    all = io::LeafRun();
    result.activeVoxels = activeVoxels;

    // Every rank learns where the masks go in the head, and where its buffers go after it.
    std::uint64_t headBytes = head.bytes.size(), runCount = head.maskRuns.size();
    MPI_Bcast(&headBytes, 1, MPI_UINT64_T, 0, comm);
    MPI_Bcast(&runCount, 1, MPI_UINT64_T, 0, comm);
    head.maskRuns.resize(runCount);
    static_assert(sizeof(io::FileHead::MaskRun) == 3 * sizeof(std::uint64_t), "plain data");
    MPI_Bcast(head.maskRuns.data(), int(runCount * 3), MPI_UINT64_T, 0, comm);
    std::uint64_t bytesBefore = 0, leavesBefore = 0;
    for (int r = 0; r < rank; ++r) {
        bytesBefore += headers[std::size_t(r)].bytes;
        leavesBefore += headers[std::size_t(r)].leaves;
    }
    std::vector<Write> writes;
    if (rank == 0) {
        for (const auto& [at, n] : head.nonMaskParts()) writes.push_back({at, head.bytes.data() + at, n});
    }
    std::vector<std::pair<std::uint64_t, std::string>> masks;
    collective(comm, [&] { masks = head.maskWrites(leavesBefore, encoded.masks); });
    for (const auto& [at, data] : masks) writes.push_back({at, data.data(), data.size()});
    std::uint64_t at = headBytes + bytesBefore;
    for (const std::string& piece : encoded.pieces) {
        writes.push_back({at, piece.data(), piece.size()});
        at += piece.size();
    }
    if (!opt.output.empty()) writeTogether(comm, opt.output, writes);
    result.fileBytes = opt.output.empty() ? 0 : headBytes + bufferBytes;
    result.writeSeconds = secondsSince(writeStart);

    const std::uint64_t peak = util::peakResidentMemory();
    result.rankPeakMemory.assign(std::size_t(size), 0);
    MPI_Allgather(&peak, 1, MPI_UINT64_T, result.rankPeakMemory.data(), 1, MPI_UINT64_T, comm);
    double total = secondsSince(start);
    MPI_Allreduce(MPI_IN_PLACE, &total, 1, MPI_DOUBLE, MPI_MAX, comm);
    result.totalSeconds = total;
    return result;
}

} // namespace ivdb::mpi
