// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/io/VdbFile.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace ivdb::jobs {

/// @brief The file formats convert() writes, chosen by the output's extension.
enum class FileFormat {
    Vdb,    ///< ".vdb": OpenVDB's format, with the chosen compression and half floats
    NanoVdb ///< ".nvdb": NanoVDB, uncompressed (what NanoVDB's tools and GPU loaders read)
};

/// @brief What convert() does: re-save the grids of a .vdb file as .vdb or NanoVDB.
struct ConvertOptions
{
    std::string input, output;
    std::string grid;                        ///< empty: every grid of the file
    std::optional<io::Compression> compression; ///< .vdb only; default Blosc
    bool half = false;                       ///< .vdb only: float values as 16-bit halves
};

struct ConvertResult
{
    FileFormat format = FileFormat::Vdb;
    openvdb::GridPtrVec grids; ///< as written, in io::readVdb()'s order
    std::uint64_t fileBytes = 0;
    double readSeconds = 0.0, writeSeconds = 0.0, totalSeconds = 0.0;
};

/// @brief The format @a path's extension names (".vdb", ".nvdb", any case).
/// @throw ParamError (parameter "output") for any other extension
FileFormat outputFormat(const std::string& path);

/// @brief Read every grid of options.input (or the one named options.grid), check its values
/// (io::checkGridValues) and write them to options.output: a .vdb with the chosen compression
/// and half floats, keeping each grid's metadata; or a NanoVDB file (io::writeNanoVdb).
/// @throw ParamError for an output extension other than .vdb or .nvdb, for compression or half
/// floats asked of a NanoVDB file, or for a grid that is not in the file or that NanoVDB cannot
/// hold; openvdb::IoError for unreadable input or unwritable output. Nothing is written on any
/// error.
ConvertResult convert(const ConvertOptions& options);

} // namespace ivdb::jobs
