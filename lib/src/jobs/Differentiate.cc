// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/Differentiate.h>

#include "Common.h"

#include <ivdb/io/AtomicFile.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/io/VdbPieces.h>
#include <ivdb/jobs/Inputs.h>
#include <ivdb/jobs/Rasterize.h>
#include <ivdb/raster/Rasterize.h>
#include <ivdb/scene/Scene.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <chrono>
#include <functional>

namespace ivdb::jobs {

namespace {

/// A leaf-by-leaf operator's output grids on the leaves @a only of a level set, stamped.
using LeafOperator =
    std::function<std::vector<openvdb::GridBase::Ptr>(const openvdb::FloatGrid&, const diff::LeafList&)>;

/// Leaves per run of streamedWrite(): a run's vec3 outputs take about 50 MB.
constexpr std::size_t kRunLeaves = 8192;

/// writeGrids() of @a op's outputs on @a phi (and @a phi itself if @a withInput), without ever
/// holding the outputs whole: a run of kRunLeaves leaves at a time is computed, compressed
/// (io::encodeLeafRun) and let go, and the file is laid out from the runs (io::vdbFileHead),
/// as ivdb-mpi lays out the runs of its ranks: the same bytes. The output leaves are made and
/// freed run by run, so the allocator hands the next run the memory the last one had (no new
/// pages to fault in). Returns the seconds spent computing (the rest is compressing and
/// writing) and each output's active voxels in @a activeVoxels.
double streamedWrite(const std::string& path, const openvdb::FloatGrid& phi, const LeafOperator& op,
                     bool withInput, const io::WriteOptions& options, std::uint64_t& activeVoxels)
{
    using Clock = std::chrono::steady_clock;
    diff::LeafList leaves;
    for (auto it = phi.tree().cbeginLeaf(); it; ++it) leaves.push_back(it.getLeaf());
    std::vector<std::vector<io::LeafRun>> runs;   // per output grid, its runs
    std::vector<openvdb::GridBase::Ptr> metadata; // per output grid, emptied (metadata only)
    double computeSeconds = 0.0;
    for (std::size_t first = 0; first < std::max<std::size_t>(leaves.size(), 1); first += kRunLeaves) {
        const auto start = Clock::now();
        const diff::LeafList only(leaves.begin() + std::ptrdiff_t(first),
                                  leaves.begin() + std::ptrdiff_t(std::min(leaves.size(), first + kRunLeaves)));
        std::vector<openvdb::GridBase::Ptr> outputs = op(phi, only);
        computeSeconds += std::chrono::duration<double>(Clock::now() - start).count();
        runs.resize(outputs.size());
        for (std::size_t g = 0; g < outputs.size(); ++g) {
            if (outputs[g]->isType<openvdb::Vec3SGrid>()) {
                runs[g].push_back(io::encodeLeafRun(*openvdb::gridPtrCast<openvdb::Vec3SGrid>(outputs[g]), options));
            } else {
                runs[g].push_back(io::encodeLeafRun(*openvdb::gridPtrCast<openvdb::FloatGrid>(outputs[g]), options));
            }
            outputs[g]->clear(); // its metadata stays, for the skeleton
        }
        if (metadata.empty()) metadata = outputs;
    }
    if (withInput) {
        runs.emplace_back();
        runs.back().push_back(io::encodeLeafRun(phi, options));
    }
    // Each grid's nodes from the input's topology, and the file's head.
    std::vector<io::LeafRun> entries(runs.size());
    std::vector<openvdb::GridBase::ConstPtr> skeletons;
    std::vector<io::HeadGrid> heads;
    for (std::size_t g = 0; g < runs.size(); ++g) {
        std::uint64_t bytes = 0;
        for (const io::LeafRun& r : runs[g]) {
            entries[g].appendEntries(r);
            bytes += r.byteCount();
        }
        // The input, if written, with its own metadata.
        const openvdb::GridBase::Ptr skeleton = g == metadata.size() ? io::skeletonOf(phi)
                                                                     : operatorSkeleton(*metadata[g], phi);
        skeletons.push_back(skeleton);
        heads.push_back({skeleton, &entries[g], bytes});
    }
    activeVoxels = entries.empty() ? 0 : entries[0].activeVoxels;
    io::FileHead head = io::vdbFileHead(heads, io::fileStamp(), options);
    for (std::size_t g = 0; g < runs.size(); ++g) head.putMasks(g, 0, entries[g].masks);
    io::writeFileAtomically(path, [&](std::ostream& os) {
        for (std::size_t g = 0; g < runs.size(); ++g) {
            os.write(head.grids[g].bytes.data(), std::streamsize(head.grids[g].bytes.size()));
            for (const io::LeafRun& r : runs[g]) {
                for (const std::string& piece : r.pieces) {
                    os.write(piece.data(), std::streamsize(piece.size()));
                }
            }
        }
    });
    return computeSeconds;
}

/// Whether to write a run of leaves at a time: only the file is wanted, and the operators
/// can take the leaves by runs (a level set with active tiles is computed whole).
template<typename Options>
bool streams(const Options& opt, const openvdb::FloatGrid& phi)
{
    return !opt.keepGrids && !opt.output.empty() && !phi.tree().hasActiveTiles();
}

} // namespace

openvdb::GridBase::Ptr operatorSkeleton(const openvdb::GridBase& output, const openvdb::FloatGrid& phi)
{
    openvdb::GridBase::Ptr skeleton;
    if (output.isType<openvdb::Vec3SGrid>()) {
        skeleton = io::leafSkeleton<openvdb::Vec3SGrid>(phi.tree(), phi.transform(), openvdb::Vec3s(0.0f));
    } else {
        skeleton = io::leafSkeleton<openvdb::FloatGrid>(phi.tree(), phi.transform(), 0.0f);
    }
    static_cast<openvdb::MetaMap&>(*skeleton) = static_cast<const openvdb::MetaMap&>(output);
    return skeleton;
}

GradientResult gradient(const GradientOptions& opt)
{
    Stopwatch clock;
    check(limits::kStep, opt.step);
    if (!opt.output.empty()) io::checkOutputPath(opt.output);
    GradientResult result;
    result.input = readLevelSet(opt.input, opt.grid);
    result.readSeconds = clock.lap();
    if (streams(opt, *result.input)) {
        const std::string name = result.input->getName();
        result.computeSeconds = streamedWrite(opt.output, *result.input,
            [&](const openvdb::FloatGrid& phi, const diff::LeafList& only) {
                auto g = diff::gradient(phi, opt.step, true, &only);
                std::vector<openvdb::GridBase::Ptr> out{g};
                if (opt.magnitude) out.push_back(diff::magnitude(*g));
                for (auto& grid : out) stampGradient(*grid, opt, name);
                return out;
            }, opt.withInput, opt.write, result.activeVoxels);
        clock.lap();
        result.totalSeconds = clock.total();
        return result;
    }
    result.gradient = diff::gradient(*result.input, opt.step);
    result.activeVoxels = result.gradient->activeVoxelCount();
    result.computeSeconds = clock.lap();

    if (opt.magnitude) {
        result.magnitude = diff::magnitude(*result.gradient);
        stampGradient(*result.magnitude, opt, result.input->getName());
    }
    stampGradient(*result.gradient, opt, result.input->getName());
    detail::writeGrids(opt.output, {result.gradient, result.magnitude,
                                    opt.withInput ? result.input : nullptr}, opt.write);
    result.totalSeconds = clock.total();
    return result;
}

void stampGradient(openvdb::GridBase& grid, const GradientOptions& opt, const std::string& gridName)
{
    io::stampGrid(grid, opt.input + ":" + gridName);
    if (grid.isType<openvdb::Vec3SGrid>()) {
        grid.insertMeta("ivdb_step_voxels", openvdb::Int32Metadata(opt.step));
    }
}

const std::vector<std::string>& curvatureMethodNames()
{
    static const std::vector<std::string> names{"mean", "gaussian", "principal", "laplacian"};
    return names;
}

namespace {

/// What the values mean, for the grids' `ivdb_curvature` metadata.
const char* convention(CurvatureMethod method)
{
    switch (method) {
    case CurvatureMethod::Mean: return "mean curvature (k1 + k2) / 2; 1/r on a sphere";
    case CurvatureMethod::Gaussian: return "Gaussian curvature k1 k2; 1/r^2 on a sphere";
    case CurvatureMethod::Principal: return "principal curvatures k1 >= k2; both 1/r on a sphere";
    case CurvatureMethod::Laplacian: break;
    }
    return "Laplacian of phi (docs/method.md#curvature); 2/r on a sphere's distance field";
}

} // namespace

std::vector<openvdb::FloatGrid::Ptr> curvatureGrids(const openvdb::FloatGrid& phi,
                                                    CurvatureMethod method,
                                                    const diff::LeafList* only)
{
    if (method == CurvatureMethod::Principal) {
        auto [k1, k2] = diff::principalCurvatures(phi, true, only);
        return {k1, k2};
    }
    const diff::Curvature kind = method == CurvatureMethod::Gaussian ? diff::Curvature::Gaussian
                               : method == CurvatureMethod::Laplacian ? diff::Curvature::Laplacian
                                                                      : diff::Curvature::Mean;
    return {diff::curvature(phi, kind, true, only)};
}

void stampCurvature(openvdb::GridBase& grid, const CurvatureOptions& opt, const std::string& gridName)
{
    io::stampGrid(grid, opt.input + ":" + gridName);
    grid.insertMeta("ivdb_curvature", openvdb::StringMetadata(convention(opt.method)));
}

CurvatureResult curvature(const CurvatureOptions& opt)
{
    Stopwatch clock;
    if (!opt.output.empty()) io::checkOutputPath(opt.output);
    CurvatureResult result;
    result.input = readLevelSet(opt.input, opt.grid);
    result.readSeconds = clock.lap();
    if (streams(opt, *result.input)) {
        const std::string name = result.input->getName();
        result.computeSeconds = streamedWrite(opt.output, *result.input,
            [&](const openvdb::FloatGrid& phi, const diff::LeafList& only) {
                std::vector<openvdb::GridBase::Ptr> out;
                for (auto& g : curvatureGrids(phi, opt.method, &only)) {
                    stampCurvature(*g, opt, name);
                    out.push_back(g);
                }
                return out;
            }, opt.withInput, opt.write, result.activeVoxels);
        clock.lap();
        result.totalSeconds = clock.total();
        return result;
    }
    result.grids = curvatureGrids(*result.input, opt.method);
    result.activeVoxels = result.grids.empty() ? 0 : result.grids[0]->activeVoxelCount();
    result.computeSeconds = clock.lap();
    std::vector<openvdb::GridBase::ConstPtr> out;
    for (auto& g : result.grids) {
        stampCurvature(*g, opt, result.input->getName());
        out.push_back(g);
    }
    if (opt.withInput) out.push_back(result.input);
    detail::writeGrids(opt.output, out, opt.write);
    result.totalSeconds = clock.total();
    return result;
}

CompareGradientResult compareGradient(const CompareGradientOptions& opt)
{
    for (int k : opt.steps) check(limits::kStep, k);
    const scene::Scene sc = scene::loadScene(opt.scene);
    raster::RasterSettings settings = sceneSettings(sc, opt.scene, opt.voxelSize, opt.halfWidth);
    settings.interrupter = opt.interrupter;
    openvdb::FloatGrid::Ptr phi;
    try {
        phi = raster::rasterize(sc.shape, settings);
    } catch (const ParamError&) {
        throw;
    } catch (const openvdb::Exception& e) {
        OPENVDB_THROW(openvdb::RuntimeError, opt.scene + ": " + util::errorText(e));
    }
    const auto shape = raster::clipToBounds(sc.shape, settings);
    CompareGradientResult result;
    result.voxelSize = settings.voxelSize;
    result.activeVoxels = phi->activeVoxelCount();
    for (int k : opt.steps) {
        const auto grad = diff::gradient(*phi, k);
        result.steps.emplace_back(k, diff::compareGradient(*shape, *phi, *grad, k));
    }
    return result;
}

} // namespace ivdb::jobs
