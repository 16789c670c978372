// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <openvdb/openvdb.h>

namespace ivdb::levelset {

/// @brief A fog volume named "density" from a narrow-band level set, for renderers that draw
/// volumes (Blender): 0 outside, rising smoothly across the inside half of the band from 0 at the
/// surface to 1 at the band's inner edge, 1 deeper inside (active tiles), as
/// openvdb::tools::sdfToFogVolume makes it. @a levelSet is not changed.
openvdb::FloatGrid::Ptr fogFromLevelSet(const openvdb::FloatGrid& levelSet);

} // namespace ivdb::levelset
