// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Blend.h>
#include <ivdb/ops/Csg.h>

#include <openvdb/util/NullInterrupter.h>

#include <ivdb/util/Interrupt.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace ivdb::ops {

struct BlendSettings
{
    /// Sharpness p in [0.1, 1000] (1/world units): the blend reaches about ln(2)/p from the crease.
    double p = 10.0;
    /// Nonzero: the polynomial smooth minimum of this width (world units) instead of the
    /// super-elliptic blend (implicit::BlendKernel); it changes the sharp result only where two
    /// inputs are within k of each other, so the bands grow by exactly k (no tolerance).
    double k = 0.0;
    /// Error allowed on the blended surface from the bands' limited reach, in voxels.
    double tolerance = 0.05;
    /// Memory the band extension may use, in bytes; 0 means 80% of the available memory.
    std::uint64_t memoryLimit = 0;
    openvdb::util::NullInterrupter* interrupter = nullptr;
};

/// @brief How far (world units) each input's band must reach beyond the output band for the
/// blend to be within @a toleranceWorld of the exact one: ln(1 / (p tolerance)) / p, since a
/// term d beyond the others contributes at most exp(-p d) / p.
double blendReach(double p, double toleranceWorld);

/// @brief Super-elliptic blended or smooth CSG of level sets (docs/method.md#grid-blend) on grids.
/// @details Inputs are resampled onto the finest one (as csg()). The blend differs from the sharp
/// operation by more than the tolerance only where two inputs are within blendReach() of each
/// other near the output band: the crease. So the result is the sharp operation (OpenVDB's csg
/// tools, as csg()) everywhere except around the crease, found on a mask with one voxel per leaf
/// node: there each input's band is extended (by closest points, or fast sweeping beyond 8
/// voxels), and each voxel the blend changes gets its distance to the blend of the two inputs'
/// tangent planes there, re-linearized at the nearest point until it settles. Where that does
/// not apply (three inputs within reach, inputs facing each other across a gap), the values are
/// combined with the same log-sum-exp as the scene-level blend, estimated as distances
/// f / |grad f| and re-distanced (levelset::redistance). docs/method.md#grid-blend. The cost
/// grows with the crease, not with the band.
/// @throw ParamError for a bad p, k or tolerance, or fewer than two inputs
/// @throw openvdb::RuntimeError if the extension would not fit in memory (the message suggests
/// the scene-level blend), or on interruption
/// @brief The kernel @a settings ask for: the polynomial smooth minimum if k is nonzero, else the
/// super-elliptic blend of p.
/// @throw ParamError for a bad p or k
implicit::BlendKernel blendKernel(const BlendSettings& settings);

openvdb::FloatGrid::Ptr blend(CsgOp op, const std::vector<openvdb::FloatGrid::ConstPtr>& inputs,
                              const BlendSettings& settings,
                              std::vector<std::string>* notes = nullptr);

/// @brief blend() that consumes its inputs (the sharp part steals their nodes, as csgInPlace()):
/// for callers that do not need the inputs afterwards (the CLI).
openvdb::FloatGrid::Ptr blendInPlace(CsgOp op, const std::vector<openvdb::FloatGrid::Ptr>& inputs,
                                     const BlendSettings& settings,
                                     std::vector<std::string>* notes = nullptr);

/// @brief One leaf of what a blend changes in the sharp operation's result: the voxels it sets
/// (marked), their values and which of them are active. Plain data (ivdb::mpi sends it).
struct BlendSplice
{
    static constexpr int kWords = 8; ///< 64-bit words of a leaf's 512-voxel mask
    std::int32_t origin[3] = {0, 0, 0};
    std::int32_t unused = 0;
    std::uint64_t marked[kWords] = {}, active[kWords] = {};
    float values[512] = {};
};

/// @brief The part of a blend that differs from the sharp operation (blend()'s steps around the
/// crease), for callers that hold only parts of the inputs (ivdb::mpi): found from the inputs'
/// topologies alone, and computed from the values of the leaves near the crease alone.
/// blend() is: BlendCrease, compute(), the sharp operation, spliceBlend() into its result, and
/// pruning it as a level set (when the crease is not empty).
class BlendCrease
{
public:
    /// @brief Plan the blend of @a grids (on one transform) and find its crease, from their
    /// topologies (no voxel value is read).
    /// @throw what blend() throws before it reads values (bad settings, an extension that would
    /// not fit in memory)
    BlendCrease(const std::vector<openvdb::FloatGrid::Ptr>& grids, const BlendSettings& settings);
    ~BlendCrease();
    BlendCrease(const BlendCrease&) = delete;
    BlendCrease& operator=(const BlendCrease&) = delete;

    /// @brief True if the inputs do not come within the blend's reach: the blend is the sharp
    /// operation.
    bool empty() const;
    /// @brief The note blend() gives (the extension and the voxels re-distanced).
    std::string note() const;
    /// @brief The origins of the leaves of input @a input whose values compute() may read.
    std::vector<openvdb::Coord> leavesRead(std::size_t input) const;
    /// @brief The origins of the leaves compute()'s splice may write (a superset).
    std::vector<openvdb::Coord> leavesWritten() const;
    /// @brief The blend's values where they differ from the sharp operation's: the bands grown
    /// around the crease and the distances to the blended surface there. Reads only the leavesRead() of
    /// @a grids (the grids given to the constructor, or the same with other leaves' values
    /// missing).
    /// @throw openvdb::RuntimeError on interruption
    std::vector<BlendSplice> compute(CsgOp op, const std::vector<openvdb::FloatGrid::Ptr>& grids,
                                     util::Interrupter* interrupter = nullptr) const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

/// @brief Set the voxels of @a leaves in @a tree (creating their leaves), without pruning.
void spliceBlend(openvdb::FloatTree& tree, const std::vector<BlendSplice>& leaves);

} // namespace ivdb::ops
