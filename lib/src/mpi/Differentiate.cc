// SPDX-License-Identifier: Apache-2.0
// ivdb-mpi's gradient and curvature: a level set's leaves split over the ranks of a
// communicator, each rank reading only its run of leaves and their neighbours within the
// stencil's reach (io::PartialGrid), into one .vdb file written by all of them at once.
#include <ivdb/mpi/Differentiate.h>

#include "Common.h"

#include <ivdb/io/AtomicFile.h>
#include <ivdb/io/VdbPieces.h>
#include <ivdb/util/Params.h>

#include <openvdb/openvdb.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <functional>
#include <limits>
#include <memory>

namespace ivdb::mpi {

using namespace detail;

namespace {

using LeafT = openvdb::FloatTree::LeafNodeType;
using OutputGrids = openvdb::TypeList<openvdb::FloatGrid, openvdb::Vec3SGrid>;

/// What one differential command asks of run().
struct Job
{
    std::string input, grid, output;
    io::WriteOptions write;
    bool withInput = false;
    /// The stencil's reach in leaves, and whether it reads along the axes only (the gradient)
    /// or the whole cube around a leaf (the curvatures).
    int reach = 1;
    bool axesOnly = false;
    std::function<void()> checkOptions;
    /// The output grids of the leaves @a only of the level set, stamped as plain ivdb stamps them.
    std::function<std::vector<openvdb::GridBase::Ptr>(const openvdb::FloatGrid&,
                                                      const diff::LeafList& only)> compute;
};

/// Indices (file order) of the leaves a run [first, first + count) reads: its own and those
/// within the stencil's reach of them, sorted.
std::vector<std::uint64_t> leavesRead(const io::PartialGrid& part, std::uint64_t first,
                                      std::uint64_t count, int reach, bool axesOnly)
{
    const auto& leaves = part.leaves();
    const std::uint64_t n = leaves.size();
    if (n > std::numeric_limits<openvdb::Index32>::max()) {
        OPENVDB_THROW(openvdb::ValueError, "a grid of more than 2^32 leaves");
    }
    // Each leaf knows its index (transient data), so a neighbour found by its origin does too.
    tbb::parallel_for(tbb::blocked_range<std::uint64_t>(0, n), [&](const auto& r) {
        for (std::uint64_t i = r.begin(); i != r.end(); ++i) {
            leaves[i]->setTransientData(openvdb::Index32(i));
        }
    });
    std::vector<openvdb::Coord> offsets;
    const int dim = int(LeafT::DIM);
    for (int x = -reach; x <= reach; ++x)
    for (int y = -reach; y <= reach; ++y)
    for (int z = -reach; z <= reach; ++z) {
        const int axes = (x != 0) + (y != 0) + (z != 0);
        if (axes == 0 || (axesOnly && axes > 1)) continue;
        offsets.emplace_back(x * dim, y * dim, z * dim);
    }
    std::unique_ptr<std::atomic<std::uint8_t>[]> wanted(new std::atomic<std::uint8_t>[n]);
    for (std::uint64_t i = 0; i < n; ++i) {
        wanted[i].store(i >= first && i < first + count, std::memory_order_relaxed);
    }
    const openvdb::FloatTree& tree = part.grid()->tree();
    tbb::parallel_for(tbb::blocked_range<std::uint64_t>(first, first + count, 256),
                      [&](const auto& r) {
        openvdb::tree::ValueAccessor<const openvdb::FloatTree> acc(tree);
        for (std::uint64_t i = r.begin(); i != r.end(); ++i) {
            const openvdb::Coord origin = leaves[i]->origin();
            for (const openvdb::Coord& d : offsets) {
                if (const LeafT* leaf = acc.probeConstLeaf(origin + d)) {
                    wanted[leaf->transientData()].store(1, std::memory_order_relaxed);
                }
            }
        }
    });
    std::vector<std::uint64_t> out;
    for (std::uint64_t i = 0; i < n; ++i) {
        if (wanted[i].load(std::memory_order_relaxed)) out.push_back(i);
    }
    return out;
}

DifferentiateResult run(MPI_Comm comm, const Job& job)
{
    const auto start = Clock::now();
    const int rank = rankOf(comm), size = sizeOf(comm);
    DifferentiateResult result;
    result.ranks = size;

    // Every rank: the grid's topology, no values.
    std::unique_ptr<io::PartialGrid> part;
    collective(comm, [&] {
        job.checkOptions();
        if (rank == 0 && !job.output.empty()) io::checkOutputPath(job.output);
        part = std::make_unique<io::PartialGrid>(job.input, job.grid);
        checkLevelSetInput(*part, job.input);
    });
    const openvdb::FloatGrid::Ptr grid = part->grid();
    result.gridName = grid->getName();
    const std::uint64_t n = part->leaves().size();
    result.leaves = n;

    // Each rank its run of leaves, and the values of those and of their neighbours.
    const std::uint64_t first = n * std::uint64_t(rank) / std::uint64_t(size);
    const std::uint64_t count = n * std::uint64_t(rank + 1) / std::uint64_t(size) - first;
    std::vector<std::uint64_t> runIndices(count);
    for (std::uint64_t i = 0; i < count; ++i) runIndices[i] = first + i;
    std::vector<std::uint64_t> leavesReadIndices;
    collective(comm, [&] {
        leavesReadIndices = leavesRead(*part, first, count, job.reach, job.axesOnly);
        part->load(leavesReadIndices);
        part->release();
        part->checkValues(runIndices);
    });
    const std::uint64_t read = leavesReadIndices.size();
    const double readSeconds = secondsSince(start);

    // The run's output grids (and the input's run), encoded.
    diff::LeafList only;
    only.reserve(count);
    for (std::uint64_t i = first; i < first + count; ++i) only.push_back(part->leaves()[i]);
    std::vector<openvdb::GridBase::Ptr> outputs;
    collective(comm, [&] { outputs = job.compute(*grid, only); });
    const double computeSeconds = secondsSince(start) - readSeconds;
    collective(comm, [&] {
        if (!job.withInput) return;
        auto in = openvdb::FloatGrid::create(grid->background());
        in->setGridClass(grid->getGridClass());
        in->setSaveFloatAsHalf(grid->saveFloatAsHalf());
        for (const LeafT* leaf : only) in->tree().addLeaf(new LeafT(*leaf));
        outputs.push_back(in);
    });
    // The input's values are no longer needed (the input's run, if written, is a copy).
    for (std::uint64_t i : leavesReadIndices) {
        LeafT::Buffer values(openvdb::PartialCreate(), 0.0f); // holds nothing
        part->leaves()[i]->swap(values);                       // frees the leaf's values
    }
    const auto writeStart = Clock::now();
    std::vector<io::LeafRun> runs(outputs.size());
    collective(comm, [&] {
        for (std::size_t g = 0; g < outputs.size(); ++g) {
            outputs[g]->apply<OutputGrids>([&](const auto& out) {
                runs[g] = io::encodeLeafRun(out, job.write);
            });
            outputs[g]->clear(); // its metadata stays, for the skeleton
        }
    });
    std::vector<std::vector<RunSummary>> summaries;
    std::vector<io::LeafRun> entries;
    for (const io::LeafRun& r : runs) {
        summaries.push_back(gatherSummaries(comm, r));
        entries.push_back(gatherEntries(comm, r, summaries.back()));
    }

    // Rank 0: each grid's nodes from the input's topology, and the file's head.
    io::FileHead head;
    collective(comm, [&] {
        if (rank != 0) return;
        std::vector<openvdb::GridBase::ConstPtr> skeletons;
        for (std::size_t g = 0; g < outputs.size(); ++g) {
            if (job.withInput && g + 1 == outputs.size()) { // the input, with its own metadata
                skeletons.push_back(io::skeletonOf(*grid));
                continue;
            }
            skeletons.push_back(jobs::operatorSkeleton(*outputs[g], *grid));
        }
        std::vector<io::HeadGrid> heads;
        for (std::size_t g = 0; g < outputs.size(); ++g) {
            std::uint64_t bytes = 0;
            for (const RunSummary& s : summaries[g]) bytes += s.bytes;
            heads.push_back({skeletons[g], &entries[g], bytes});
        }
        head = io::vdbFileHead(heads, io::fileStamp(), job.write);
    });
    entries.clear();

    std::vector<const io::LeafRun*> runPointers;
    for (const io::LeafRun& r : runs) runPointers.push_back(&r);
    result.fileBytes = writeFile(comm, job.output, head, runPointers, summaries);

    double times[3] = {readSeconds, computeSeconds, secondsSince(writeStart)};
    MPI_Allreduce(MPI_IN_PLACE, times, 3, MPI_DOUBLE, MPI_MAX, comm);
    result.readSeconds = times[0];
    result.computeSeconds = times[1];
    result.writeSeconds = times[2];
    for (const RunSummary& s : summaries[0]) {
        result.activeVoxels += s.activeVoxels;
        result.rankActiveVoxels.push_back(s.activeVoxels);
    }
    // Per rank: the input's leaves it computed (its run, empty leaves included) and read.
    const std::uint64_t mine[2] = {count, read};
    std::vector<std::uint64_t> counts(2 * std::size_t(size));
    MPI_Allgather(mine, 2, MPI_UINT64_T, counts.data(), 2, MPI_UINT64_T, comm);
    for (int r = 0; r < size; ++r) {
        result.rankLeaves.push_back(counts[2 * std::size_t(r)]);
        result.rankLeavesRead.push_back(counts[2 * std::size_t(r) + 1]);
    }
    result.rankPeakMemory = gatherPeakMemory(comm);
    double total = secondsSince(start);
    MPI_Allreduce(MPI_IN_PLACE, &total, 1, MPI_DOUBLE, MPI_MAX, comm);
    result.totalSeconds = total;
    return result;
}

/// The input, output and what is written, from a command's options.
template<typename Options>
Job jobFor(const Options& opt)
{
    Job job;
    job.input = opt.input;
    job.grid = opt.grid;
    job.output = opt.output;
    job.write = opt.write;
    job.withInput = opt.withInput;
    return job;
}

} // namespace

DifferentiateResult gradient(MPI_Comm comm, const jobs::GradientOptions& opt)
{
    Job job = jobFor(opt);
    job.axesOnly = true;
    const int step = std::min(std::max(1, opt.step), diff::kMaxStep); // checked in run()
    job.reach = (step + int(LeafT::DIM) - 1) / int(LeafT::DIM);
    job.checkOptions = [&opt] { check(limits::kStep, opt.step); };
    job.compute = [&opt](const openvdb::FloatGrid& phi, const diff::LeafList& only) {
        auto g = diff::gradient(phi, opt.step, true, &only);
        std::vector<openvdb::GridBase::Ptr> out{g};
        if (opt.magnitude) out.push_back(diff::magnitude(*g));
        for (auto& grid : out) jobs::stampGradient(*grid, opt, phi.getName());
        return out;
    };
    return run(comm, job);
}

DifferentiateResult curvature(MPI_Comm comm, const jobs::CurvatureOptions& opt)
{
    Job job = jobFor(opt);
    job.reach = 1;
    job.axesOnly = false;
    job.checkOptions = [] {};
    job.compute = [&opt](const openvdb::FloatGrid& phi, const diff::LeafList& only) {
        std::vector<openvdb::GridBase::Ptr> out;
        for (auto& g : jobs::curvatureGrids(phi, opt.method, &only)) {
            jobs::stampCurvature(*g, opt, phi.getName());
            out.push_back(g);
        }
        return out;
    };
    return run(comm, job);
}

} // namespace ivdb::mpi
