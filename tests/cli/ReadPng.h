// SPDX-License-Identifier: Apache-2.0
// The ink of a PNG written by a CLI run, read back through libpng as an image viewer would.
#pragma once

#include "../render/ReadText.h"

#include <gtest/gtest.h>

#include <png.h>

#include <filesystem>
#include <vector>

namespace ivdb::test {

/// The ink (dark pixels) of the PNG @a file; a test failure (and an empty map) if it does not read.
inline InkMap readPngInk(const std::filesystem::path& file)
{
    png_image p{};
    p.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&p, file.c_str())) {
        ADD_FAILURE() << file << ": " << p.message;
        return {};
    }
    p.format = PNG_FORMAT_RGB;
    std::vector<unsigned char> rgb(PNG_IMAGE_SIZE(p));
    if (!png_image_finish_read(&p, nullptr, rgb.data(), 0, nullptr)) ADD_FAILURE() << p.message;
    return inkOfRgb(int(p.width), int(p.height), rgb);
}

} // namespace ivdb::test
