// SPDX-License-Identifier: Apache-2.0
// Painting into a render::Image (shared by the text and the colour bar): clipped rectangles
// composited over what is there.
#pragma once

#include <ivdb/render/Render.h>

#include <cstdint>

namespace ivdb::render::detail {

/// @throw openvdb::ValueError unless @a image's rgb and alpha hold width x height pixels
void checkCanvas(const Image& image);

/// @brief Composite @a colour (sRGB in [0, 1]) at @a opacity in [0, 1] over the pixels of
/// [x0, x1) x [y0, y1) (Porter-Duff over, alpha included), clipped to the image: nothing
/// outside it is touched, and any coordinates are safe.
void fillRect(Image& image, std::int64_t x0, std::int64_t y0, std::int64_t x1, std::int64_t y1,
              const openvdb::Vec3f& colour, float opacity = 1.0f);

} // namespace ivdb::render::detail
