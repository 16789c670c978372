// SPDX-License-Identifier: Apache-2.0
#include "Common.h"

#include <ivdb/levelset/Fog.h>
#include <ivdb/levelset/LevelSet.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>

#include <unistd.h>

namespace ivdb::mpi::detail {

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

void raiseTogether(MPI_Comm comm, std::exception_ptr error, const std::string& text)
{
    const int rank = rankOf(comm), size = sizeOf(comm);
    int mine = error ? rank : size, first = size;
    MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, comm);
    if (first == size) return;
    std::string message = text;
    int length = int(std::min<std::size_t>(message.size(), 1 << 16));
    MPI_Bcast(&length, 1, MPI_INT, first, comm);
    message.resize(std::size_t(length));
    MPI_Bcast(message.data(), length, MPI_CHAR, first, comm);
    if (error) std::rethrow_exception(error);
    const std::string what = first == 0 ? message : "rank " + std::to_string(first) + ": " + message;
    OPENVDB_THROW(openvdb::RuntimeError, what);
}

void checkLevelSetInput(const io::PartialGrid& part, const std::string& path)
{
    const openvdb::FloatGrid& g = *part.grid();
    const std::string what = path + ": grid '" + g.getName() + "'";
    levelset::checkLevelSet(g, what);
    if (g.tree().hasActiveTiles()) {
        OPENVDB_THROW(openvdb::ValueError, what + " has active tiles: ivdb-mpi reads level sets "
                      "whose band is in leaves, as the level-set tools of OpenVDB and ivdb make "
                      "them; plain ivdb takes this one");
    }
}

namespace {

/// MPI counts are ints: large buffers go in pieces of 1 GiB.
constexpr std::uint64_t kPiece = std::uint64_t(1) << 30;

std::string mpiError(int code)
{
    char text[MPI_MAX_ERROR_STRING];
    int length = 0;
    MPI_Error_string(code, text, &length);
    return std::string(text, std::size_t(length));
}

} // namespace

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

std::vector<RunSummary> gatherSummaries(MPI_Comm comm, const io::LeafRun& run)
{
    RunSummary mine;
    mine.leaves = run.masks.size();
    mine.bytes = run.byteCount();
    mine.activeVoxels = run.activeVoxels;
    if (!run.activeBox.empty()) {
        for (int i = 0; i < 3; ++i) {
            mine.box[i] = run.activeBox.min()[i];
            mine.box[3 + i] = run.activeBox.max()[i];
        }
    }
    mine.hasSizes = run.sizes.empty() ? 0 : 1;
    std::vector<RunSummary> all(std::size_t(sizeOf(comm)));
    MPI_Allgather(&mine, int(sizeof(RunSummary)), MPI_BYTE, all.data(), int(sizeof(RunSummary)),
                  MPI_BYTE, comm);
    return all;
}

io::LeafRun gatherEntries(MPI_Comm comm, const io::LeafRun& mine,
                          const std::vector<RunSummary>& summaries)
{
    // Rank 0 makes room for every entry first, so that no rank waits on a rank 0 that failed.
    io::LeafRun all;
    bool sized = false; // with a codec: the same on every rank that holds leaves
    for (const RunSummary& h : summaries) sized = sized || h.hasSizes;
    collective(comm, [&] {
        if (rankOf(comm) != 0) return;
        std::uint64_t leaves = 0;
        for (const RunSummary& h : summaries) leaves += h.leaves;
        all.codes.resize(leaves);
        if (sized) all.sizes.resize(leaves);
    });
    if (rankOf(comm) != 0) {
        sendBlob(comm, 0, 2, mine.codes.data(), mine.codes.size());
        if (sized) sendBlob(comm, 0, 4, mine.sizes.data(), mine.sizes.size() * sizeof(std::int64_t));
        return all;
    }
    std::uint64_t at = 0;
    for (std::size_t r = 0; r < summaries.size(); ++r) {
        const RunSummary& h = summaries[r];
        if (r == 0) {
            std::copy(mine.codes.begin(), mine.codes.end(), all.codes.begin());
            if (sized) std::copy(mine.sizes.begin(), mine.sizes.end(), all.sizes.begin());
        } else {
            recvBlob(comm, int(r), 2, all.codes.data() + at, h.leaves);
            if (sized) recvBlob(comm, int(r), 4, all.sizes.data() + at, h.leaves * sizeof(std::int64_t));
        }
        at += h.leaves;
        all.activeVoxels += h.activeVoxels;
        if (h.box[3] >= h.box[0]) {
            all.activeBox.expand(openvdb::CoordBBox(openvdb::Coord(h.box[0], h.box[1], h.box[2]),
                                                    openvdb::Coord(h.box[3], h.box[4], h.box[5])));
        }
    }
    return all;
}

void shareLayout(MPI_Comm comm, io::FileHead& head)
{
    std::uint64_t grids = head.grids.size();
    MPI_Bcast(&grids, 1, MPI_UINT64_T, 0, comm);
    head.grids.resize(grids);
    MPI_Bcast(&head.fileBytes, 1, MPI_UINT64_T, 0, comm);
    static_assert(sizeof(io::FileHead::MaskRun) == 3 * sizeof(std::uint64_t), "plain data");
    for (io::FileHead::Grid& g : head.grids) {
        std::uint64_t v[3] = {g.at, g.size, g.maskRuns.size()};
        MPI_Bcast(v, 3, MPI_UINT64_T, 0, comm);
        g.at = v[0];
        g.size = v[1]; // the bytes stay on rank 0, which writes them
        g.maskRuns.resize(v[2]);
        MPI_Bcast(g.maskRuns.data(), int(v[2] * 3), MPI_UINT64_T, 0, comm);
    }
}

void addRunWrites(MPI_Comm comm, const io::FileHead& head, std::size_t grid,
                  const io::LeafRun& run, const std::vector<RunSummary>& summaries,
                  std::deque<std::pair<std::uint64_t, std::string>>& masks,
                  std::vector<Write>& writes)
{
    const int rank = rankOf(comm);
    std::uint64_t bytesBefore = 0, leavesBefore = 0;
    for (int r = 0; r < rank; ++r) {
        bytesBefore += summaries[std::size_t(r)].bytes;
        leavesBefore += summaries[std::size_t(r)].leaves;
    }
    const std::size_t firstMask = masks.size();
    collective(comm, [&] {
        for (auto& m : head.maskWrites(grid, leavesBefore, run.masks)) masks.push_back(std::move(m));
    });
    for (std::size_t i = firstMask; i < masks.size(); ++i) {
        writes.push_back({masks[i].first, masks[i].second.data(), masks[i].second.size()});
    }
    std::uint64_t at = head.grids[grid].buffersAt() + bytesBefore;
    for (const std::string& piece : run.pieces) {
        writes.push_back({at, piece.data(), piece.size()});
        at += piece.size();
    }
}

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

std::uint64_t writeFile(MPI_Comm comm, const std::string& output, io::FileHead& head,
                        const std::vector<const io::LeafRun*>& runs,
                        const std::vector<std::vector<RunSummary>>& summaries)
{
    // Every rank learns where the masks go in the heads, and where its buffers go after them.
    shareLayout(comm, head);
    std::vector<Write> writes;
    if (rankOf(comm) == 0) {
        for (const auto& p : head.nonMaskParts()) writes.push_back({p.offset, p.data, p.size});
    }
    std::deque<std::pair<std::uint64_t, std::string>> masks;
    for (std::size_t g = 0; g < runs.size(); ++g) {
        addRunWrites(comm, head, g, *runs[g], summaries[g], masks, writes);
    }
    if (output.empty()) return 0;
    writeTogether(comm, output, writes);
    return head.fileBytes;
}

FogRun makeFog(MPI_Comm comm, const io::WriteOptions& write, openvdb::FloatTree& leaves,
               const openvdb::FloatGrid::Ptr& skeleton, const std::vector<RunSummary>& summaries)
{
    const int rank = rankOf(comm), size = sizeOf(comm);
    float lowest = levelset::lowestValue(leaves);
    MPI_Allreduce(MPI_IN_PLACE, &lowest, 1, MPI_FLOAT, MPI_MIN, comm);
    float cutoff = 0.0f;
    if (rank == 0) cutoff = levelset::fogCutoff(*skeleton, lowest);
    MPI_Bcast(&cutoff, 1, MPI_FLOAT, 0, comm);
    FogRun fog;
    std::vector<std::uint8_t> kept;
    collective(comm, [&] {
        using LeafT = openvdb::FloatTree::LeafNodeType;
        std::vector<LeafT*> stolen;
        leaves.stealNodes(stolen); // in file order
        std::vector<std::unique_ptr<LeafT>> run(stolen.begin(), stolen.end());
        kept.assign(run.size(), 0);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, run.size()),
                          [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t k = r.begin(); k < r.end(); ++k) {
                kept[k] = levelset::fogLeaf(*run[k], cutoff) ? 1 : 0;
            }
        });
        auto part = openvdb::FloatGrid::create(0.0f);
        part->setGridClass(openvdb::GRID_FOG_VOLUME);
        for (std::size_t k = 0; k < run.size(); ++k) {
            if (kept[k]) part->tree().addLeaf(run[k].release());
        }
        run.clear();
        fog.encoded = io::encodeLeafRun(*part, write);
    });
    fog.summaries = gatherSummaries(comm, fog.encoded);
    fog.all = gatherEntries(comm, fog.encoded, fog.summaries);
    fog.encoded.codes.clear();
    fog.encoded.sizes.clear();
    // Rank 0: which of every leaf the fog keeps, in file order, and the fog's skeleton.
    if (rank == 0) {
        std::vector<std::uint8_t> all(kept);
        for (int r = 1; r < size; ++r) {
            const std::size_t at = all.size();
            all.resize(at + summaries[std::size_t(r)].leaves);
            recvBlob(comm, r, 2, all.data() + at, summaries[std::size_t(r)].leaves);
        }
        kept = std::move(all);
    } else {
        sendBlob(comm, 0, 2, kept.data(), kept.size());
    }
    collective(comm, [&] {
        if (rank != 0) return;
        fog.skeleton = levelset::fogSkeleton(*skeleton, kept, fog.tiles);
    });
    for (const RunSummary& s : fog.summaries) fog.bufferBytes += s.bytes;
    return fog;
}

std::uint64_t writeLevelSetFile(MPI_Comm comm, const std::string& output,
                                const io::WriteOptions& write, openvdb::FloatGrid::Ptr& skeleton,
                                io::LeafRun& all, std::uint64_t bufferBytes,
                                const io::LeafRun& encoded,
                                const std::vector<RunSummary>& summaries, FogRun* fog)
{
    io::FileHead head;
    collective(comm, [&] {
        if (rankOf(comm) != 0) return;
        std::vector<io::HeadGrid> grids{{skeleton, &all, bufferBytes}};
        if (fog) grids.push_back({fog->skeleton, &fog->all, fog->bufferBytes, &fog->tiles});
        head = io::vdbFileHead(grids, io::fileStamp(), write);
    });
    skeleton.reset();
    all = io::LeafRun();
    if (!fog) return writeFile(comm, output, head, {&encoded}, {summaries});
    fog->skeleton.reset();
    fog->all = io::LeafRun();
    return writeFile(comm, output, head, {&encoded, &fog->encoded}, {summaries, fog->summaries});
}

std::vector<std::uint64_t> gatherPeakMemory(MPI_Comm comm)
{
    const std::uint64_t peak = util::peakResidentMemory();
    std::vector<std::uint64_t> all(std::size_t(sizeOf(comm)), 0);
    MPI_Allgather(&peak, 1, MPI_UINT64_T, all.data(), 1, MPI_UINT64_T, comm);
    return all;
}

} // namespace ivdb::mpi::detail
