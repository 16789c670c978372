// SPDX-License-Identifier: Apache-2.0
// ivdb-mpi's csg: the inputs' 128^3 nodes split over the ranks of a communicator, each rank
// reading and combining only its own, into one .vdb file written by all of them at once.
#include <ivdb/mpi/Combine.h>

#include "Common.h"

#include <ivdb/io/AtomicFile.h>
#include <ivdb/io/VdbPieces.h>
#include <ivdb/ops/Blend.h>
#include <ivdb/ops/Csg.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Prune.h>

#include <algorithm>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

namespace ivdb::mpi {

using namespace detail;

namespace {

using openvdb::Coord;
using TreeT = openvdb::FloatTree;
using LeafT = TreeT::LeafNodeType;
using Int2T = TreeT::RootNodeType::ChildNodeType;
using Int1T = Int2T::ChildNodeType;

/// The order of 128^3 nodes in a file: by their parent's origin (the root's map order), then by
/// their own (their offset in the parent, x-major).
bool fileOrder(const Coord& a, const Coord& b)
{
    const Coord pa = a & ~(Int2T::DIM - 1), pb = b & ~(Int2T::DIM - 1);
    return pa != pb ? pa < pb : a < b;
}

/// What a rank tells rank 0 of one of its 128^3 nodes in the result: a node (its slots: which
/// are leaves, the others' tile values and states), or the tile it became.
struct NodeReport
{
    std::int32_t origin[3] = {0, 0, 0};
    std::int32_t isNode = 0, active = 0;
    float tile = 0.0f;
};

/// A 128^3 node's slots as sent: the child (leaf) and value (active) masks, and the tiles'
/// values: inside (-background) where @a inside is on, else the background, when every tile is
/// one of the two (a level set's are, after pruning); otherwise all of them, in a NodeValues.
struct NodeTable
{
    Int1T::NodeMaskType children, values, inside;
    std::int64_t full = -1; ///< the index of its NodeValues, or -1
};

struct NodeValues
{
    float tiles[Int1T::NUM_VALUES];
};

/// @a items of every rank, on rank 0 in rank order (others: emptied); returns how many each
/// rank had. Rank 0 makes room first, inside a collective, so that no rank waits on a rank 0
/// that failed. Collective.
template<typename T>
std::vector<std::uint64_t> gatherOnRoot(MPI_Comm comm, std::vector<T>& items, int tag)
{
    const int rank = rankOf(comm), size = sizeOf(comm);
    std::uint64_t mine = items.size();
    std::vector<std::uint64_t> counts(std::size_t(size), 0);
    MPI_Allgather(&mine, 1, MPI_UINT64_T, counts.data(), 1, MPI_UINT64_T, comm);
    std::uint64_t total = 0;
    for (std::uint64_t c : counts) total += c;
    collective(comm, [&] { if (rank == 0) items.resize(total); });
    if (rank == 0) {
        std::uint64_t at = counts[0];
        for (int k = 1; k < size; ++k) {
            recvBlob(comm, k, tag, items.data() + at, counts[std::size_t(k)] * sizeof(T));
            at += counts[std::size_t(k)];
        }
    } else {
        sendBlob(comm, 0, tag, items.data(), items.size() * sizeof(T));
        items = std::vector<T>();
    }
    return counts;
}

/// Read the leaves of the 128^3 nodes @a mine of @a part, and those at @a also (origins).
void loadPart(io::PartialGrid& part, const std::set<Coord>& mine, const std::set<Coord>& also,
              std::uint64_t& leavesRead)
{
    std::vector<std::uint64_t> indices;
    const auto& leaves = part.leaves();
    for (std::uint64_t i = 0; i < leaves.size(); ++i) {
        const Coord o = leaves[i]->origin();
        if (mine.count(o & ~(Int1T::DIM - 1)) || also.count(o)) indices.push_back(i);
    }
    part.load(indices);
    part.release();
    part.checkValues(indices);
    leavesRead += indices.size();
}

/// The rank's share of an input read by loadPart(): its tree with every 128^3 node not in
/// @a mine replaced by an active tile (so that no node above it is pruned on this partial view;
/// the values there are never used).
openvdb::FloatGrid::Ptr ownPart(const io::PartialGrid& part, const std::set<Coord>& mine)
{
    const openvdb::FloatGrid::Ptr grid = part.grid();
    const float bg = grid->background();
    std::vector<Int2T*> parents;
    grid->tree().getNodes(parents);
    for (Int2T* n2 : parents) {
        for (auto it = n2->beginChildOn(); it; ++it) {
            if (!mine.count(it->origin())) n2->addTile(it.pos(), bg, true);
        }
    }
    grid->tree().clearAllAccessors();
    return grid;
}

/// Rank 0: each rank's share of @a splices (by the rank that owns their 128^3 node, @a owner),
/// sent; every rank: its own share. Collective.
std::vector<ops::BlendSplice> shareSplices(MPI_Comm comm, std::vector<ops::BlendSplice>& splices,
                                           const std::map<Coord, int>& owner)
{
    const int rank = rankOf(comm), size = sizeOf(comm);
    std::vector<std::vector<ops::BlendSplice>> byRank;
    std::vector<std::uint64_t> counts(std::size_t(size), 0);
    collective(comm, [&] {
        if (rank != 0) return;
        byRank.resize(std::size_t(size));
        for (ops::BlendSplice& leaf : splices) {
            const Coord node = Coord(leaf.origin[0], leaf.origin[1], leaf.origin[2]) & ~(Int1T::DIM - 1);
            const auto it = owner.find(node);
            if (it == owner.end()) {
                std::ostringstream os;
                os << "a blended leaf at " << node << " lies in no rank's 128^3 node";
                OPENVDB_THROW(openvdb::RuntimeError, os.str());
            }
            byRank[std::size_t(it->second)].push_back(leaf);
        }
        splices = std::vector<ops::BlendSplice>();
        for (int k = 0; k < size; ++k) counts[std::size_t(k)] = byRank[std::size_t(k)].size();
    });
    std::uint64_t mine = 0;
    MPI_Scatter(counts.data(), 1, MPI_UINT64_T, &mine, 1, MPI_UINT64_T, 0, comm);
    std::vector<ops::BlendSplice> out;
    collective(comm, [&] { if (rank != 0) out.resize(mine); });
    if (rank == 0) {
        for (int k = 1; k < size; ++k) {
            const auto& part = byRank[std::size_t(k)];
            sendBlob(comm, k, 8, part.data(), part.size() * sizeof(ops::BlendSplice));
        }
        out = std::move(byRank[0]);
    } else {
        recvBlob(comm, 0, 8, out.data(), out.size() * sizeof(ops::BlendSplice));
    }
    return out;
}

} // namespace

CsgResult csg(MPI_Comm comm, const jobs::CombineOptions& opt)
{
    const auto start = Clock::now();
    const int rank = rankOf(comm), size = sizeOf(comm);
    CsgResult result;
    result.ranks = size;

    // Every rank: the inputs' topologies, no values (and a blend's crease, found from them).
    std::vector<std::unique_ptr<io::PartialGrid>> parts;
    std::optional<ops::BlendSettings> blend;
    std::unique_ptr<ops::BlendCrease> crease;
    collective(comm, [&] {
        blend = jobs::blendSettings(opt);
        if (blend && rank != 0) blend->interrupter = nullptr;
        if (opt.inputs.size() < 2) {
            throw ParamError(param::kInputs, "must be at least two files, got " +
                                                 std::to_string(opt.inputs.size()));
        }
        if (rank == 0 && !opt.output.empty()) io::checkOutputPath(opt.output);
        for (const std::string& path : opt.inputs) {
            parts.push_back(std::make_unique<io::PartialGrid>(path, opt.grid));
            checkLevelSetInput(*parts.back(), path);
        }
        std::vector<openvdb::FloatGrid::Ptr> grids;
        for (const auto& p : parts) grids.push_back(p->grid());
        const openvdb::FloatGrid& finest = ops::finestInput(grids);
        for (std::size_t i = 0; i < parts.size(); ++i) {
            const openvdb::FloatGrid& g = *parts[i]->grid();
            if (g.transform() != finest.transform()) {
                throw ParamError(param::kInputs, "grid '" + g.getName() + "' is on another "
                                 "transform (voxel size " + util::formatNumber(g.voxelSize()[0]) +
                                 ") than the finest input's (" +
                                 util::formatNumber(finest.voxelSize()[0]) + "): ivdb-mpi "
                                 "combines level sets on one lattice; plain ivdb csg resamples "
                                 "them", opt.inputs[i]);
            }
        }
        if (blend) {
            crease = std::make_unique<ops::BlendCrease>(grids, *blend);
            result.notes.push_back(crease->note());
            if (crease->empty()) crease.reset();
        }
    });

    // The 128^3 nodes any input holds, in file order, weighed by their leaves (and one each);
    // for a blend also those its crease may write leaves into, which the inputs may not hold.
    std::map<Coord, std::uint64_t> weight;
    for (const auto& p : parts) {
        for (const LeafT* leaf : p->leaves()) ++weight[leaf->origin() & ~(Int1T::DIM - 1)];
        std::vector<const Int1T*> nodes;
        p->grid()->tree().getNodes(nodes);
        for (const Int1T* n : nodes) weight[n->origin()] += 1;
    }
    std::set<Coord> held; // the nodes an input holds
    for (const auto& w : weight) held.insert(w.first);
    if (crease) {
        for (const Coord& o : crease->leavesWritten()) weight[o & ~(Int1T::DIM - 1)] += 1;
    }
    std::vector<std::pair<Coord, std::uint64_t>> units(weight.begin(), weight.end());
    weight.clear();
    std::sort(units.begin(), units.end(), [](const auto& a, const auto& b) {
        return fileOrder(a.first, b.first);
    });
    result.nodes = units.size();
    std::uint64_t total = 0;
    for (const auto& u : units) total += u.second;
    // Rank r: the nodes whose weight before them lies in [total r / N, total (r + 1) / N).
    std::vector<Coord> mineInOrder;
    std::map<Coord, int> owner; // a blend's: every node's rank
    {
        std::uint64_t before = 0;
        int r = 0;
        for (const auto& u : units) {
            while (r + 1 < size &&
                   before >= total * std::uint64_t(r + 1) / std::uint64_t(size)) {
                ++r;
            }
            if (r == rank) mineInOrder.push_back(u.first);
            if (crease) owner.emplace(u.first, r);
            before += u.second;
        }
    }
    units.clear();
    const std::set<Coord> mine(mineInOrder.begin(), mineInOrder.end());

    // Each rank: its nodes' leaves; rank 0 also those the blend's crease reads, and computes
    // the crease's values, which go to the ranks owning their nodes.
    std::uint64_t leavesRead = 0;
    double readSeconds = 0.0;
    std::vector<ops::BlendSplice> splices;
    collective(comm, [&] {
        std::vector<openvdb::FloatGrid::Ptr> grids;
        for (std::size_t i = 0; i < parts.size(); ++i) {
            std::set<Coord> also;
            if (crease && rank == 0) {
                for (const Coord& o : crease->leavesRead(i)) also.insert(o);
            }
            loadPart(*parts[i], mine, also, leavesRead);
            grids.push_back(parts[i]->grid());
        }
        readSeconds = secondsSince(start);
        if (crease && rank == 0) splices = crease->compute(opt.op, grids, blend->interrupter);
    });
    if (crease) splices = shareSplices(comm, splices, owner);
    owner.clear();

    // Each rank: the CSG of its part, and the blend's values in its nodes.
    openvdb::FloatGrid::Ptr combined;
    std::vector<std::string> notes;
    collective(comm, [&] {
        std::vector<openvdb::FloatGrid::Ptr> grids;
        for (auto& p : parts) grids.push_back(ownPart(*p, mine));
        parts.clear();
        // A blend's sharp part, as ops::blend() runs it (its notes are the blend's).
        combined = ops::csgInPlace(opt.op, grids, blend ? nullptr : &notes);
        if (crease) {
            // Pruned here as ops::blend() prunes the whole (leaves the splice made uniform
            // become tiles); rank 0 prunes what lies above the nodes.
            ops::spliceBlend(combined->tree(), splices);
            openvdb::tools::pruneLevelSet(combined->tree());
        }
        splices = std::vector<ops::BlendSplice>();
    });
    if (!blend) result.notes.insert(result.notes.end(), notes.begin(), notes.end());
    const double computeSeconds = secondsSince(start) - readSeconds;
    const auto writeStart = Clock::now();

    // What each of its nodes became; the others' (placeholders) are dropped. The leaves move
    // to a grid of their own, with the result's half-float flag (the first input's), to be
    // encoded.
    std::vector<NodeReport> reports;
    std::vector<NodeTable> tables;
    std::vector<NodeValues> values;
    io::LeafRun encoded;
    openvdb::FloatGrid::Ptr own; // kept for a fog volume
    collective(comm, [&] {
        own = openvdb::FloatGrid::create(combined->background());
        own->setGridClass(openvdb::GRID_LEVEL_SET);
        own->setSaveFloatAsHalf(combined->saveFloatAsHalf());
        TreeT& tree = combined->tree();
        for (const Coord& o : mineInOrder) {
            NodeReport r;
            for (int a = 0; a < 3; ++a) r.origin[a] = o[a];
            if (Int1T* n = tree.probeNode<Int1T>(o)) {
                r.isNode = 1;
                NodeTable t;
                t.children = n->getChildMask();
                t.values = n->getValueMask();
                NodeValues v;
                const float bg = combined->background();
                bool signs = true;
                for (openvdb::Index i = 0; i < Int1T::NUM_VALUES; ++i) {
                    v.tiles[i] = t.children.isOn(i) ? 0.0f : n->getValue(n->offsetToGlobalCoord(i));
                    if (t.children.isOn(i)) continue;
                    signs = signs && (v.tiles[i] == bg || v.tiles[i] == -bg);
                    if (v.tiles[i] == -bg) t.inside.setOn(i);
                }
                if (!signs) {
                    t.full = std::int64_t(values.size());
                    values.push_back(v);
                }
                // The leaves move; active tiles keep their places (for rank 0's skeleton).
                std::vector<Coord> leaves;
                for (auto it = n->cbeginChildOn(); it; ++it) leaves.push_back(it.getCoord());
                for (const Coord& c : leaves) own->tree().addLeaf(n->stealNode<LeafT>(c, 0.0f, true));
                tables.push_back(t);
            } else if (!held.count(o)) {
                continue; // a node only a blend could have made, and did not: as the inputs
            } else {
                r.tile = tree.getValue(o);
                r.active = tree.isValueOn(o) ? 1 : 0;
            }
            reports.push_back(r);
        }
        tree.clearAllAccessors();
        encoded = io::encodeLeafRun(*own, opt.write);
        if (!opt.fog) own.reset();
    });
    if (rank != 0) combined.reset();
    const std::vector<RunSummary> summaries = gatherSummaries(comm, encoded);
    io::LeafRun all = gatherEntries(comm, encoded, summaries);
    encoded.codes.clear();
    encoded.sizes.clear();

    // Rank 0: every rank's nodes into its own result's nodes and tiles (right everywhere but on
    // the other ranks' nodes), pruned as OpenVDB prunes a level set; the file's head from it.
    gatherOnRoot(comm, reports, 5);
    const std::vector<std::uint64_t> tableCounts = gatherOnRoot(comm, tables, 6);
    const std::vector<std::uint64_t> valueCounts = gatherOnRoot(comm, values, 7);
    if (rank == 0) {
        // Each rank's tables point into its own values: now into everyone's.
        std::uint64_t table = 0, base = 0;
        for (int k = 0; k < size; ++k) {
            for (std::uint64_t i = 0; i < tableCounts[std::size_t(k)]; ++i, ++table) {
                if (tables[table].full >= 0) tables[table].full += std::int64_t(base);
            }
            base += valueCounts[std::size_t(k)];
        }
    }
    std::uint64_t activeVoxels = 0, bufferBytes = 0, leaves = 0;
    for (const RunSummary& s : summaries) {
        activeVoxels += s.activeVoxels;
        bufferBytes += s.bytes;
        leaves += s.leaves;
    }
    openvdb::FloatGrid::Ptr skeleton;
    collective(comm, [&] {
        if (rank != 0) return;
        skeleton = io::skeletonOf(*combined);
        combined.reset();
        TreeT& tree = skeleton->tree();
        std::size_t table = 0;
        for (const NodeReport& r : reports) {
            const Coord o(r.origin[0], r.origin[1], r.origin[2]);
            if (!r.isNode) {
                tree.addTile(2, o, r.tile, r.active != 0);
                continue;
            }
            const NodeTable& t = tables[table++];
            const float bg = skeleton->background();
            const auto tile = [&](openvdb::Index i) {
                return t.full >= 0 ? values[std::size_t(t.full)].tiles[i] : t.inside.isOn(i) ? -bg : bg;
            };
            tree.addTile(1, o, tile(0), t.values.isOn(0)); // makes the node
            Int1T* n = tree.probeNode<Int1T>(o);
            for (openvdb::Index i = 0; i < Int1T::NUM_VALUES; ++i) {
                if (t.children.isOn(i)) n->addTile(i, 0.0f, true); // a leaf
                else n->addTile(i, tile(i), t.values.isOn(i));
            }
        }
        openvdb::tools::pruneLevelSet(tree);
        io::stampGrid(*skeleton, jobs::combineSource(opt));
    });
    FogRun fog;
    if (opt.fog) fog = makeFog(comm, opt.write, own->tree(), skeleton, summaries);
    own.reset();
    result.fileBytes = writeLevelSetFile(comm, opt.output, opt.write, skeleton, all, bufferBytes,
                                         encoded, summaries, opt.fog ? &fog : nullptr);
    result.leaves = leaves;
    result.activeVoxels = activeVoxels;
    if (activeVoxels == 0) {
        result.warnings.push_back("the result has no surface (the inputs do not overlap as this "
                                  "operation needs); the level set written is empty");
    }

    double times[3] = {readSeconds, computeSeconds, secondsSince(writeStart)};
    MPI_Allreduce(MPI_IN_PLACE, times, 3, MPI_DOUBLE, MPI_MAX, comm);
    result.readSeconds = times[0];
    result.computeSeconds = times[1];
    result.writeSeconds = times[2];
    const std::uint64_t mineCounts[2] = {std::uint64_t(mineInOrder.size()), leavesRead};
    std::vector<std::uint64_t> gathered(2 * std::size_t(size));
    MPI_Allgather(mineCounts, 2, MPI_UINT64_T, gathered.data(), 2, MPI_UINT64_T, comm);
    for (int r = 0; r < size; ++r) {
        result.rankNodes.push_back(gathered[2 * std::size_t(r)]);
        result.rankLeavesRead.push_back(gathered[2 * std::size_t(r) + 1]);
        result.rankLeaves.push_back(summaries[std::size_t(r)].leaves);
        result.rankActiveVoxels.push_back(summaries[std::size_t(r)].activeVoxels);
    }
    result.rankPeakMemory = gatherPeakMemory(comm);
    double seconds = secondsSince(start);
    MPI_Allreduce(MPI_IN_PLACE, &seconds, 1, MPI_DOUBLE, MPI_MAX, comm);
    result.totalSeconds = seconds;
    return result;
}

} // namespace ivdb::mpi
