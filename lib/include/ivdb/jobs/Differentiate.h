// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/diff/Differential.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/util/Interrupt.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ivdb::jobs {

/// @brief What gradient() does: the central-difference gradient of a level set from a file.
struct GradientOptions
{
    std::string input, output;  ///< output empty: nothing written
    std::string grid;           ///< empty: the first level set
    int step = 1;               ///< difference step in voxels (limits::kStep)
    bool magnitude = false;     ///< also `gradient_magnitude`
    bool withInput = false;     ///< also copy the input level set into the output
    io::WriteOptions write;     ///< compression and half floats on disk
    /// False: with an output file, the output grids are computed, compressed and written a run
    /// of leaves at a time and not returned, so that they are never whole in memory (the same
    /// file; for callers that only want the file, such as the CLI). Inputs with active tiles
    /// are computed whole all the same.
    bool keepGrids = true;
};

struct GradientResult
{
    openvdb::FloatGrid::Ptr input;
    openvdb::Vec3SGrid::Ptr gradient;  ///< null if not kept (GradientOptions::keepGrids)
    openvdb::FloatGrid::Ptr magnitude; ///< null unless asked for (and kept)
    std::uint64_t activeVoxels = 0;    ///< the gradient's
    double readSeconds = 0.0, computeSeconds = 0.0, totalSeconds = 0.0;
};

/// @throw ParamError for a bad step or grid; what readLevelSet throws. Nothing is written on
/// any error.
GradientResult gradient(const GradientOptions& options);

/// @brief The skeleton io::vdbFileHead() takes for @a output, the output of a leaf-by-leaf
/// operator (gradient, curvature) on @a phi, a float or vec3s grid whose metadata alone is read:
/// a leaf of @a phi with active voxels as an active tile, and @a output's metadata.
openvdb::GridBase::Ptr operatorSkeleton(const openvdb::GridBase& output, const openvdb::FloatGrid& phi);

/// @brief Stamp @a grid, the gradient or its magnitude made from grid @a gridName of the file
/// @a input, with what gradient() writes (ivdb_source and ivdb_step_voxels for the gradient).
void stampGradient(openvdb::GridBase& grid, const GradientOptions& options,
                   const std::string& gridName);

enum class CurvatureMethod { Mean, Gaussian, Principal, Laplacian };

/// @brief "mean", "gaussian", "principal", "laplacian".
const std::vector<std::string>& curvatureMethodNames();

struct CurvatureOptions
{
    std::string input, output, grid;
    CurvatureMethod method = CurvatureMethod::Mean;
    bool withInput = false;
    io::WriteOptions write;     ///< compression and half floats on disk
    bool keepGrids = true;      ///< as GradientOptions::keepGrids
};

struct CurvatureResult
{
    openvdb::FloatGrid::Ptr input;
    /// `curvature`, or `k1` and `k2` (principal); empty if not kept (keepGrids)
    std::vector<openvdb::FloatGrid::Ptr> grids;
    std::uint64_t activeVoxels = 0; ///< each grid's
    double readSeconds = 0.0, computeSeconds = 0.0, totalSeconds = 0.0;
};

/// @brief Curvature of a level set from a file, each grid stamped with its convention
/// (`ivdb_curvature` metadata).
CurvatureResult curvature(const CurvatureOptions& options);

/// @brief diff::curvature() or diff::principalCurvatures() as @a method asks, on the leaves
/// @a only (null: all): `curvature`, or `k1` and `k2`.
std::vector<openvdb::FloatGrid::Ptr> curvatureGrids(const openvdb::FloatGrid& phi,
                                                    CurvatureMethod method,
                                                    const diff::LeafList* only = nullptr);

/// @brief Stamp @a grid, a curvature made from grid @a gridName of @a options' input, with
/// what curvature() writes (ivdb_source and the convention, ivdb_curvature).
void stampCurvature(openvdb::GridBase& grid, const CurvatureOptions& options,
                    const std::string& gridName);

/// @brief What compareGradient() does: rasterize a scene and compare the discrete gradient of
/// its band with the shape's normalized analytic gradient.
struct CompareGradientOptions
{
    std::string scene;
    std::optional<double> voxelSize, halfWidth;
    std::vector<int> steps{1};
    util::Interrupter* interrupter = nullptr;
};

struct CompareGradientResult
{
    double voxelSize = 0.0;
    std::uint64_t activeVoxels = 0;
    std::vector<std::pair<int, diff::GradientComparison>> steps; ///< per step, in order
};

CompareGradientResult compareGradient(const CompareGradientOptions& options);

} // namespace ivdb::jobs
