// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <openvdb/openvdb.h>

#include <chrono>
#include <string>

namespace ivdb::jobs {

/// @brief The level set @a grid (empty: the file's first level set) of the .vdb file @a path,
/// read with the layout check, chosen, and checked to be a scalar float level set with cubic
/// voxels and finite values: what every job that takes a level set reads.
/// @throw openvdb::IoError for a file that cannot be read; ParamError (parameter "grid") for a
/// missing grid or one that is not such a level set; openvdb::ValueError for bad values
openvdb::FloatGrid::Ptr readLevelSet(const std::string& path, const std::string& grid = "");

/// @brief The grid a surface is coloured by: @a spec is FILE.vdb[:GRID] (io::GridRef; without
/// GRID the file's first grid), a float (scalar) or vec3s (vector) grid with finite values. A
/// vector grid is coloured by direction, so @a withRange or @a withColormap (a range or colormap
/// chosen explicitly) is refused for it.
/// @throw ParamError (parameter "color_by", "range" or "colormap") or openvdb::IoError naming
/// the file and the grid
openvdb::GridBase::Ptr readColorGrid(const std::string& spec, bool withRange, bool withColormap);

/// @brief Seconds since construction or the last lap(), for the timings jobs report.
class Stopwatch
{
public:
    /// @brief Seconds since the last lap() (or construction).
    double lap()
    {
        const auto now = std::chrono::steady_clock::now();
        const double s = std::chrono::duration<double>(now - mLast).count();
        mLast = now;
        return s;
    }
    /// @brief Seconds since construction.
    double total() const
    {
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - mStart).count();
    }

private:
    std::chrono::steady_clock::time_point mStart = std::chrono::steady_clock::now(), mLast = mStart;
};

} // namespace ivdb::jobs
