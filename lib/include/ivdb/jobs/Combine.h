// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/implicit/CsgOp.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/ops/Blend.h>
#include <ivdb/util/Interrupt.h>

#include <openvdb/openvdb.h>

#include <optional>
#include <string>
#include <vector>

namespace ivdb::jobs {

/// @brief What combine() does: sharp CSG, a super-elliptic blend or a smooth CSG of level sets
/// from files.
struct CombineOptions
{
    implicit::CsgOp op = implicit::CsgOp::Union;
    std::vector<std::string> inputs;  ///< two or more .vdb files
    std::string output;               ///< the .vdb written atomically; empty: none
    std::string grid;                 ///< the grid in every input; empty: each file's first level set
    std::optional<double> p;          ///< set: a blend of this sharpness
    std::optional<double> k;          ///< set: a smooth CSG of this width (world units)
    double tolerance = 0.05;          ///< a blend's allowed error from the bands' reach, voxels
    bool fog = false;                 ///< also a `density` fog volume
    io::WriteOptions write;                ///< compression and half floats on disk
    util::Interrupter* interrupter = nullptr;
};

/// @brief The blend @a options ask for (p or k set), checked; none for the sharp operation.
/// @throw ParamError for both p and k, or a bad p, k or tolerance
std::optional<ops::BlendSettings> blendSettings(const CombineOptions& options);

struct CombineResult
{
    openvdb::FloatGrid::Ptr surface, density;
    std::vector<std::string> notes;    ///< resampled inputs, the blend's extension
    std::vector<std::string> warnings; ///< an empty result
    double readSeconds = 0.0, computeSeconds = 0.0, totalSeconds = 0.0;
};

/// @brief Read the inputs' level sets (readLevelSet), resample them onto the finest, combine
/// them (ops::csgInPlace, or ops::blendInPlace when p or k is set) and write the result
/// atomically.
/// @throw ParamError for fewer than two inputs, both p and k, or a bad p, k or tolerance; what
/// readLevelSet and
/// the operations throw. Nothing is written on any error.
CombineResult combine(const CombineOptions& options);

/// @brief What combine() stamps as the result's `ivdb_source`: the operation and the inputs
/// ("csg union a.vdb b.vdb").
std::string combineSource(const CombineOptions& options);

} // namespace ivdb::jobs
