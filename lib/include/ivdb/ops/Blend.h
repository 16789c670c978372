// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/Blend.h>
#include <ivdb/ops/Csg.h>

#include <openvdb/util/NullInterrupter.h>

#include <cstdint>

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
/// node: there each input's band is extended by fast sweeping (openvdb::tools::dilateSdf) on a
/// clipped copy, the values are combined with the same log-sum-exp as the scene-level blend,
/// estimated as distances f / |grad f| and re-distanced (levelset::redistance) into a narrow band
/// of the finest input's half width. The cost grows with the crease, not with the band.
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

} // namespace ivdb::ops
