// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <ivdb/mesh/Mesh.h>
#include <ivdb/render/Render.h>

#include <optional>
#include <string>
#include <utility>

namespace ivdb::jobs {

/// @brief What mesh() does: a level set's surface as an OBJ or PLY mesh, optionally coloured.
struct MeshOptions
{
    std::string input;                ///< a .vdb file
    std::string output;               ///< .obj or .ply, written atomically
    std::string grid;                 ///< the level set; empty: the first
    double adaptivity = 0.0;          ///< limits::kAdaptivity
    std::string colorBy;              ///< FILE.vdb[:GRID] to colour the vertices by; empty: none
    std::optional<std::string> colormap; ///< for a scalar colour grid; unset: viridis
    std::optional<std::pair<double, double>> range; ///< unset: the sampled values' range
};

struct MeshResult
{
    mesh::Mesh mesh;
    double enclosedVolume = 0.0;
    double seconds = 0.0;
};

/// @throw ParamError for a bad extension, adaptivity, colormap or colour grid; what
/// readLevelSet throws; openvdb::RuntimeError for a level set with no surface. Nothing is
/// written on any error.
MeshResult mesh(const MeshOptions& options);

/// @brief What glyphs() does: arrows of a vector grid (a gradient) near the surface.
struct GlyphsOptions
{
    std::string input, output;  ///< output: .obj or .ply
    std::string grid;           ///< the vec3s grid; empty: the first vec3s grid
    int stride = 4;             ///< one arrow every this many voxels (limits::kStride)
    double length = 0.0;        ///< world length per unit of the vector; 0: twice the stride
    double near = 0.5;          ///< with a level set in the file, only where |phi| < near voxels
};

struct GlyphsResult
{
    std::size_t arrows = 0;
    std::string field;   ///< the vector grid's name
    double length = 0.0; ///< as used
};

GlyphsResult glyphs(const GlyphsOptions& options);

/// @brief A camera given in part: what is unset comes from the automatic framing.
struct CameraChoice
{
    std::optional<openvdb::Vec3d> eye, target;
    std::optional<double> fov;
};

/// @brief What render() does: a ray-traced image of a level set's surface.
struct RenderOptions
{
    std::string input, output;   ///< output: .png or .exr
    std::string grid;            ///< empty: the first level set
    int width = 640, height = 480;
    CameraChoice camera;
    std::string colorBy;         ///< FILE.vdb[:GRID]; empty: light grey
    std::optional<std::string> colormap; ///< for a scalar colour grid; unset: hsv
    std::optional<std::pair<double, double>> range; ///< unset: the grid's active value range
    bool floatExr = false;       ///< EXR colour and alpha as 32-bit float (default half)
};

struct RenderResult
{
    int width = 0, height = 0;
    std::size_t surfacePixels = 0;
    double seconds = 0.0;
};

/// @brief Render a level set to a PNG or EXR image (written atomically). A PNG coloured by a
/// scalar grid gets a labelled colour bar: the range's ends and middle and colorBarLabel().
RenderResult render(const RenderOptions& options);

/// @brief The colour bar's title for a scalar grid: its name and, when known, the units of its
/// values in the scene's length unit: "curvature (1/length)" (mean and principal curvatures
/// and the Laplacian, from ivdb's `ivdb_curvature` metadata), "curvature (1/length^2)"
/// (Gaussian), "surface (length)" (a level set's distances); the name alone otherwise
/// (`density`, `gradient_magnitude` and other unitless or unknown quantities).
std::string colorBarLabel(const openvdb::GridBase& grid);

} // namespace ivdb::jobs
