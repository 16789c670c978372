// SPDX-License-Identifier: Apache-2.0
// OpenVDB's fast sweeping, behind two functions in a file of their own: AddressSanitizer builds
// compile that file as libopenvdb itself is shipped, optimized and uninstrumented (see
// lib/CMakeLists.txt). Instrumented at -O1, OpenVDB's sweeping templates ran 20x slower than in
// the Release build and were half of the sanitized suite's time; they are not our code, and our
// own loops around them stay instrumented. Not an installed header.
#pragma once

#include <openvdb/openvdb.h>

#include <functional>

namespace ivdb::levelset::detail {

/// openvdb::tools::FastSweeping from the signed estimates @a samples (initSdf, iso value 0),
/// with @a seeded called on the initialized grid before the sweep (to set the boundary
/// condition: the voxels next to the interface hold finite values, the others +/- float max).
/// Null when there is nothing to sweep from.
openvdb::FloatGrid::Ptr sweepSdf(const openvdb::FloatGrid& samples,
                                 const std::function<void(openvdb::FloatGrid&)>& seeded);

/// openvdb::tools::dilateSdf(@a sdf, @a voxels, NN_FACE_EDGE_VERTEX): the band grown by
/// @a voxels, the new voxels solved by fast sweeping.
openvdb::FloatGrid::Ptr dilateSdf(const openvdb::FloatGrid& sdf, int voxels);

} // namespace ivdb::levelset::detail
