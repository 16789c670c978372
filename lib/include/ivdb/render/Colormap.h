// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <openvdb/Types.h>

#include <string>
#include <vector>

namespace ivdb::render {

/// @brief A colormap: a value's colour over a range [lo, hi] (values outside are clamped).
/// @details `hsv`, `viridis`, `coolwarm` and `gray` are matplotlib's maps of those names, with
/// its 256-entry tables and its lookup (the same colours as matplotlib for every value).
class Colormap
{
public:
    /// @throw ParamError (parameter "colormap") naming the choices for an unknown @a name
    explicit Colormap(const std::string& name);

    /// The names accepted, in the order the CLI lists them.
    static const std::vector<std::string>& names();

    const std::string& name() const { return mName; }

    /// The colour at @a t in [0, 1] (clamped; NaN maps to the low end): RGB in [0, 1], sRGB
    /// encoded as matplotlib gives it (write it as is to PNG; convert to linear for EXR).
    openvdb::Vec3f at(double t) const;

    /// at((v - lo) / (hi - lo)).
    openvdb::Vec3f map(double v, double lo, double hi) const
    {
        return at((v - lo) / (hi - lo));
    }

private:
    std::string mName;
    const float (*mTable)[3] = nullptr; // 256 entries; null: gray, i / 255
};

/// @brief The colour of a direction, the one convention of every vector colouring (render, mesh
/// vertices, arrows): RGB = 0.5 n + 0.5 for the unit vector n of @a v; mid grey for a zero
/// vector.
openvdb::Vec3f directionColor(const openvdb::Vec3d& v);

} // namespace ivdb::render
