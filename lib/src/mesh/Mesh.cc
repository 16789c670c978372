// SPDX-License-Identifier: Apache-2.0
#include <ivdb/mesh/Mesh.h>

#include <ivdb/io/AtomicFile.h>
#include <ivdb/render/Colormap.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <ostream>

namespace ivdb::mesh {

namespace {

// Twice the signed volume of the tetrahedron (origin, a, b, c), times 3: a . (b x c).
double tripleProduct(const openvdb::Vec3s& a, const openvdb::Vec3s& b, const openvdb::Vec3s& c)
{
    return openvdb::Vec3d(a).dot(openvdb::Vec3d(b).cross(openvdb::Vec3d(c)));
}

void checkData(const Mesh& mesh, const VertexData* data, const std::string& path)
{
    if (!data) return;
    if ((!data->colors.empty() && data->colors.size() != mesh.points.size()) ||
        (!data->scalars.empty() && data->scalars.size() != mesh.points.size())) {
        OPENVDB_THROW(openvdb::IoError, path + ": per-vertex data does not match the vertices");
    }
}

std::uint8_t toByte(float c)
{
    return std::uint8_t(std::lround(std::clamp(c, 0.0f, 1.0f) * 255.0f));
}

} // namespace

Mesh meshLevelSet(const openvdb::FloatGrid& grid, double adaptivity)
{
    check(limits::kAdaptivity, adaptivity);
    Mesh m;
    openvdb::tools::volumeToMesh(grid, m.points, m.triangles, m.quads, 0.0, adaptivity, true);
    // volumeToMesh's winding depends on the sign convention; make the normals point outwards.
    if (enclosedVolume(m) < 0.0) {
        for (auto& t : m.triangles) std::swap(t[1], t[2]);
        for (auto& q : m.quads) std::swap(q[1], q[3]);
    }
    return m;
}

double enclosedVolume(const Mesh& mesh)
{
    const auto& p = mesh.points;
    double v = 0.0;
    for (const auto& t : mesh.triangles) v += tripleProduct(p[t[0]], p[t[1]], p[t[2]]);
    for (const auto& q : mesh.quads) {
        v += tripleProduct(p[q[0]], p[q[1]], p[q[2]]);
        v += tripleProduct(p[q[0]], p[q[2]], p[q[3]]);
    }
    return v / 6.0;
}

Mesh arrows(const std::vector<openvdb::Vec3d>& bases, const std::vector<openvdb::Vec3d>& vectors,
            double length, std::vector<openvdb::Vec3f>* colors)
{
    constexpr int kSides = 6;
    Mesh m;
    for (size_t a = 0; a < bases.size() && a < vectors.size(); ++a) {
        const openvdb::Vec3d v = vectors[a] * length;
        const double len = v.length();
        if (!(len > 0.0) || !std::isfinite(len)) continue;
        const openvdb::Vec3d dir = v / len;
        // Two unit vectors across the arrow.
        const openvdb::Vec3d other = std::abs(dir.x()) < 0.9 ? openvdb::Vec3d(1, 0, 0)
                                                              : openvdb::Vec3d(0, 1, 0);
        const openvdb::Vec3d u = dir.cross(other).unitSafe(), w = dir.cross(u);
        const openvdb::Vec3d base = bases[a], neck = base + v * 0.75, tip = base + v;
        const double rShaft = 0.04 * len, rHead = 0.10 * len;
        const unsigned first = unsigned(m.points.size());
        // Rings: shaft at the base, shaft at the neck, head at the neck; then the tip.
        for (const auto& [centre, r] : {std::pair{base, rShaft}, {neck, rShaft}, {neck, rHead}}) {
            for (int k = 0; k < kSides; ++k) {
                const double phi = 2.0 * M_PI * k / kSides;
                m.points.emplace_back(centre + (u * std::cos(phi) + w * std::sin(phi)) * r);
            }
        }
        m.points.emplace_back(tip);
        m.points.emplace_back(base); // the centre of the base cap
        const unsigned ring0 = first, ring1 = first + kSides, ring2 = first + 2 * kSides;
        const unsigned tipIdx = first + 3 * kSides, capIdx = tipIdx + 1;
        for (unsigned k = 0; k < kSides; ++k) {
            const unsigned k1 = (k + 1) % kSides;
            // Counter-clockwise seen from outside: a closed solid per arrow.
            m.triangles.emplace_back(ring0 + k, ring1 + k1, ring1 + k); // shaft
            m.triangles.emplace_back(ring0 + k, ring0 + k1, ring1 + k1);
            m.triangles.emplace_back(ring2 + k, ring2 + k1, tipIdx);    // cone
            m.triangles.emplace_back(ring1 + k, ring2 + k1, ring2 + k); // the head's underside
            m.triangles.emplace_back(ring1 + k, ring1 + k1, ring2 + k1);
            m.triangles.emplace_back(capIdx, ring0 + k1, ring0 + k);    // base cap
        }
        if (colors) colors->insert(colors->end(), 3 * kSides + 2, render::directionColor(dir));
    }
    return m;
}

VertexData sampleVertexData(const Mesh& mesh, const openvdb::GridBase& grid,
                            const render::Colormap& colormap,
                            std::optional<std::pair<double, double>> range)
{
    VertexData data;
    const size_t n = mesh.points.size();
    data.colors.resize(n);
    data.scalars.resize(n);
    if (const auto* g = dynamic_cast<const openvdb::FloatGrid*>(&grid)) {
        data.scalarName = g->getName().empty() ? "value" : g->getName();
        openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> s(*g);
        for (size_t i = 0; i < n; ++i) data.scalars[i] = s.wsSample(mesh.points[i]);
        if (!range) {
            double lo = std::numeric_limits<double>::max(), hi = -lo;
            for (float v : data.scalars) lo = std::min(lo, double(v)), hi = std::max(hi, double(v));
            if (!(lo < hi)) hi = lo + 1.0;
            range.emplace(lo, hi);
        }
        for (size_t i = 0; i < n; ++i) {
            data.colors[i] = colormap.map(data.scalars[i], range->first, range->second);
        }
    } else if (const auto* v = dynamic_cast<const openvdb::Vec3SGrid*>(&grid)) {
        // A vector grid (a gradient): colour by direction, the scalar is the magnitude.
        data.scalarName = "magnitude";
        openvdb::tools::GridSampler<openvdb::Vec3SGrid, openvdb::tools::BoxSampler> s(*v);
        for (size_t i = 0; i < n; ++i) {
            const openvdb::Vec3s d = s.wsSample(mesh.points[i]);
            data.scalars[i] = d.length();
            data.colors[i] = render::directionColor(openvdb::Vec3d(d));
        }
    } else {
        throw ParamError(param::kColorBy, "grid '" + grid.getName() + "' is a " + grid.valueType() +
                         " grid; colouring needs a float (scalar) or vec3s (vector) grid");
    }
    return data;
}

ArrowSamples sampleArrows(const openvdb::Vec3SGrid& field, const openvdb::FloatGrid* surface,
                          int stride, double near)
{
    check(limits::kStride, stride);
    check(limits::kNear, near);
    ArrowSamples out;
    std::unique_ptr<openvdb::FloatGrid::ConstAccessor> acc;
    if (surface) acc = std::make_unique<openvdb::FloatGrid::ConstAccessor>(surface->getConstAccessor());
    for (auto it = field.cbeginValueOn(); it; ++it) {
        if (!it.isVoxelValue()) continue;
        const openvdb::Coord ijk = it.getCoord();
        if (ijk.x() % stride || ijk.y() % stride || ijk.z() % stride) continue;
        const openvdb::Vec3d world = field.indexToWorld(ijk);
        if (acc) {
            const openvdb::Coord s = surface->transform().worldToIndexCellCentered(world);
            if (!(std::abs(acc->getValue(s)) < near * surface->voxelSize()[0])) continue;
        }
        out.bases.push_back(world);
        out.vectors.emplace_back(*it);
    }
    return out;
}

void writeMesh(const std::string& path, const Mesh& mesh, const VertexData* data)
{
    const std::string ext = util::extensionOf(path);
    if (ext == ".obj") writeObj(path, mesh, data);
    else if (ext == ".ply") writePly(path, mesh, data);
    else throw ParamError(param::kOutput, "must end in .obj or .ply, got '" + path + "'");
}

void writeObj(const std::string& path, const Mesh& mesh, const VertexData* data)
{
    checkData(mesh, data, path);
    const bool colors = data && !data->colors.empty();
    io::writeFileAtomically(path, [&](std::ostream& os) {
        os << "# ivdb mesh: " << mesh.points.size() << " vertices, " << mesh.faceCount()
           << " faces\n";
        char line[160];
        for (size_t i = 0; i < mesh.points.size(); ++i) {
            const auto& v = mesh.points[i];
            int n = std::snprintf(line, sizeof(line), "v %.7g %.7g %.7g", v[0], v[1], v[2]);
            if (colors) {
                const auto& c = data->colors[i];
                n += std::snprintf(line + n, sizeof(line) - size_t(n), " %.4f %.4f %.4f", c[0],
                                   c[1], c[2]);
            }
            os << line << '\n';
        }
        for (const auto& t : mesh.triangles) {
            os << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
        }
        for (const auto& q : mesh.quads) {
            os << "f " << q[0] + 1 << ' ' << q[1] + 1 << ' ' << q[2] + 1 << ' ' << q[3] + 1 << '\n';
        }
    });
}

void writePly(const std::string& path, const Mesh& mesh, const VertexData* data)
{
    checkData(mesh, data, path);
    const bool colors = data && !data->colors.empty();
    const bool scalars = data && !data->scalars.empty();
    io::writeFileAtomically(path, [&](std::ostream& os) {
        os << "ply\nformat binary_little_endian 1.0\ncomment written by ivdb\n"
           << "element vertex " << mesh.points.size() << "\n"
           << "property float x\nproperty float y\nproperty float z\n";
        if (colors) os << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
        if (scalars) os << "property float " << data->scalarName << "\n";
        os << "element face " << mesh.faceCount() << "\n"
           << "property list uchar int vertex_indices\nend_header\n";
        std::vector<char> buf;
        auto put = [&buf](const void* p, size_t n) {
            const char* c = static_cast<const char*>(p);
            buf.insert(buf.end(), c, c + n);
        };
        for (size_t i = 0; i < mesh.points.size(); ++i) {
            const float xyz[3] = {mesh.points[i][0], mesh.points[i][1], mesh.points[i][2]};
            put(xyz, sizeof(xyz)); // x86: already little endian
            if (colors) {
                const std::uint8_t rgb[3] = {toByte(data->colors[i][0]), toByte(data->colors[i][1]),
                                             toByte(data->colors[i][2])};
                put(rgb, 3);
            }
            if (scalars) put(&data->scalars[i], sizeof(float));
            if (buf.size() > (1u << 20)) os.write(buf.data(), std::streamsize(buf.size())), buf.clear();
        }
        for (const auto& t : mesh.triangles) {
            const std::uint8_t n = 3;
            const std::int32_t idx[3] = {std::int32_t(t[0]), std::int32_t(t[1]), std::int32_t(t[2])};
            put(&n, 1);
            put(idx, sizeof(idx));
        }
        for (const auto& q : mesh.quads) {
            const std::uint8_t n = 4;
            const std::int32_t idx[4] = {std::int32_t(q[0]), std::int32_t(q[1]), std::int32_t(q[2]),
                                         std::int32_t(q[3])};
            put(&n, 1);
            put(idx, sizeof(idx));
            if (buf.size() > (1u << 20)) os.write(buf.data(), std::streamsize(buf.size())), buf.clear();
        }
        os.write(buf.data(), std::streamsize(buf.size()));
    });
}

} // namespace ivdb::mesh
