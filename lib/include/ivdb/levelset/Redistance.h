// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <openvdb/openvdb.h>
#include <openvdb/util/NullInterrupter.h>

namespace ivdb::levelset {

/// @brief Turn a grid of signed distance *estimates* into a narrow-band level set of true
/// signed distances with half width @a halfWidth voxels.
/// @details Only the signs of @a estimates and its values next to the sign changes matter: the
/// voxels within ceil(halfWidth) voxels (26-neighbourhood steps) of a voxel next to a sign change
/// are kept; those next to the interface keep their own estimate as the boundary condition
/// (better than OpenVDB FastSweeping's axis-crossing formula, which is off by up to 0.3 voxel on
/// curved surfaces, provided the estimates are first-order distances such as f / |grad f|), the
/// others are solved by fast sweeping (openvdb::tools::FastSweeping); the result is trimmed to
/// |d| < halfWidth x voxel size, with +/- that background outside and inside.
/// Fast sweeping is first-order: its distances are good (a few hundredths of a voxel) but their
/// second differences are noisy, which ruins curvature. So within @a keepEstimates voxels of the
/// surface (default: the whole band) the smooth estimate replaces the swept value wherever the
/// two agree within @a agreement voxels; where they do not (near CSG creases, where
/// f / |grad f| is only a bound: the distance to one child rather than to the result), the
/// swept distance stays.
/// @a samples (the estimates) must hold every voxel within ceil(halfWidth) + 1 voxels of the interface as an
/// active voxel; its active topology is reduced in place. The result has its transform.
/// @throw openvdb::RuntimeError if the interrupter cancels the run
openvdb::FloatGrid::Ptr redistance(openvdb::FloatGrid& samples, double halfWidth,
                                   openvdb::util::NullInterrupter* interrupter = nullptr,
                                   double keepEstimates = 1e9, double agreement = 1.0);

} // namespace ivdb::levelset
