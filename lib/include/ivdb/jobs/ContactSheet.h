// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/jobs/Visualize.h>
#include <ivdb/scene/Animation.h>

namespace ivdb::jobs {

/// @brief What contactSheet() does: frames of a .vdb sequence rendered side by side into one
/// PNG, each tile labelled with its frame number.
struct ContactSheetOptions
{
    /// input and colorBy are name patterns (each run of `#` becomes the zero-padded frame
    /// number, scene::frameFileName); width and height are one tile's; output must be a .png.
    RenderOptions base;
    scene::FrameRange frames;
    int columns = 4; ///< tiles across (limits::kColumns); rows follow
};

/// @brief Render the frames of a sequence into one contact sheet, all from one camera (framing
/// every frame's surface, unless the camera is given) so motion shows, and when coloured by a
/// scalar grid all over one range (the union of the frames' ranges, unless given) with one
/// labelled colour bar at the right of the sheet.
/// @details Frames are rendered one after another, each on all threads; each frame's grids are
/// read twice (once to frame the camera and range, once to render), so only one frame is in
/// memory at a time.
/// @throw ParamError for an output that is not a .png, a bad tile size, column count or frame
/// count (limits::kSheetTiles), or the errors of render() for any frame's files, naming them.
/// Nothing is written on any error.
RenderResult contactSheet(const ContactSheetOptions& options);

} // namespace ivdb::jobs
