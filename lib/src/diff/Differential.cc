// SPDX-License-Identifier: Apache-2.0
#include <ivdb/diff/Differential.h>

#include <ivdb/levelset/LevelSet.h>
#include <ivdb/util/Params.h>

#include <ivdb/util/System.h>

#include <openvdb/tree/LeafManager.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstring>
#include <cmath>
#include <memory>
#include <sstream>
#include <vector>

namespace ivdb::diff {

namespace {

using FloatTree = openvdb::FloatTree;
using LeafT = FloatTree::LeafNodeType;
using openvdb::Coord;

/// The values of one leaf and of its neighbours within @a pad voxels, as a dense block
/// (8 + 2 pad)^3 in the leaf's x-major order. Neighbour leaves are copied from their buffers;
/// where there is no leaf, the tile value (the clamped background for a level set) is used.
class PaddedLeaf
{
public:
    /// @param facesOnly  gather only the leaf and its 6 face neighbours' regions: enough for
    /// stencils along the axes (the gradient); the edge and corner regions are left at zero.
    PaddedLeaf(int pad, bool facesOnly)
        : mPad(pad), mN(LeafT::DIM + 2 * pad), mFacesOnly(facesOnly), mData(size_t(mN) * mN * mN) {}

    void gather(openvdb::tree::ValueAccessor<const FloatTree>& acc, const Coord& origin)
    {
        const int dim = LeafT::DIM;
        const int reach = (mPad + dim - 1) / dim; // neighbour leaves on each side
        for (int lx = -reach; lx <= reach; ++lx)
        for (int ly = -reach; ly <= reach; ++ly)
        for (int lz = -reach; lz <= reach; ++lz) {
            if (mFacesOnly && (lx != 0) + (ly != 0) + (lz != 0) > 1) continue;
            const Coord o = origin + Coord(lx * dim, ly * dim, lz * dim);
            // Overlap of this leaf-sized region with the padded block, in block coordinates.
            int lo[3], hi[3];
            for (int a = 0; a < 3; ++a) {
                const int start = o[a] - origin[a] + mPad;
                lo[a] = std::max(0, start);
                hi[a] = std::min(mN, start + dim);
            }
            if (lo[0] >= hi[0] || lo[1] >= hi[1] || lo[2] >= hi[2]) continue;
            const LeafT* leaf = acc.probeConstLeaf(o);
            const float tile = leaf ? 0.0f : acc.getValue(o);
            const float* buf = leaf ? leaf->buffer().data() : nullptr;
            for (int i = lo[0]; i < hi[0]; ++i)
            for (int j = lo[1]; j < hi[1]; ++j) {
                float* dst = &mData[(size_t(i) * mN + j) * mN];
                const int len = hi[2] - lo[2];
                if (buf) {
                    const int li = i - mPad + origin[0] - o[0], lj = j - mPad + origin[1] - o[1];
                    const float* src = buf + (li << 6) + (lj << 3) + (lo[2] - mPad + origin[2] - o[2]);
                    // Whole rows by a copy of constant size (inlined, where a call to memmove
                    // for 32 bytes cost more than the copy: 5% of `ivdb gradient`).
                    if (len == dim) std::memcpy(dst + lo[2], src, sizeof(float) * LeafT::DIM);
                    else for (int k = 0; k < len; ++k) dst[lo[2] + k] = src[k];
                } else {
                    for (int k = lo[2]; k < hi[2]; ++k) dst[k] = tile;
                }
            }
        }
    }

    /// Value at leaf-local (i, j, k), each in [-pad, 8 + pad).
    float operator()(int i, int j, int k) const
    {
        return mData[(size_t(i + mPad) * mN + (j + mPad)) * mN + (k + mPad)];
    }

private:
    int mPad, mN;
    bool mFacesOnly;
    std::vector<float> mData;
};

template<typename Fn>
void runMaybeSerial(bool threaded, Fn&& fn)
{
    if (threaded) {
        fn();
    } else {
        tbb::task_arena serial(1);
        serial.execute(fn);
    }
}

/// A grid of @a OutGridT with the input's active topology, filled per active voxel by
/// @a kernel(PaddedLeaf, i, j, k) -> value. Output leaves are allocated and filled by the thread
/// that computes them (a serial TopologyCopy of a 12 M voxel band costs more in page faults than
/// the whole stencil), then linked into the tree serially.
template<typename OutGridT, typename Kernel>
typename OutGridT::Ptr stencilMap(const openvdb::FloatGrid& phi, int pad, bool axesOnly,
                                  const typename OutGridT::ValueType& background, bool threaded,
                                  const LeafList* only, const Kernel& kernel)
{
    using OutTreeT = typename OutGridT::TreeType;
    using OutLeafT = typename OutTreeT::LeafNodeType;
    const FloatTree* src = &phi.tree();
    FloatTree::Ptr voxelized;
    if (only && src->hasActiveTiles()) {
        OPENVDB_THROW(openvdb::ValueError, "a level set with active tiles is computed whole, not "
                      "by runs of leaves");
    }
    if (src->hasActiveTiles()) {
        voxelized = std::make_shared<FloatTree>(*src);
        voxelized->voxelizeActiveTiles();
        src = voxelized.get();
    }
    auto out = OutGridT::create(background);
    out->setTransform(phi.transform().copy());
    runMaybeSerial(threaded, [&]() {
        std::unique_ptr<openvdb::tree::LeafManager<const FloatTree>> manager;
        if (!only) manager = std::make_unique<openvdb::tree::LeafManager<const FloatTree>>(*src);
        const std::size_t count = only ? only->size() : manager->leafCount();
        std::vector<OutLeafT*> built(count, nullptr);
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count),
                          [&](const tbb::blocked_range<std::size_t>& r) {
            // One accessor and block per task: each gather overwrites what the stencil reads.
            openvdb::tree::ValueAccessor<const FloatTree> acc(*src);
            PaddedLeaf block(pad, axesOnly);
            for (std::size_t idx = r.begin(); idx != r.end(); ++idx) {
                const LeafT& in = only ? *(*only)[idx] : manager->leaf(idx);
                if (in.isEmpty()) continue;
                block.gather(acc, in.origin());
                auto* leaf = new OutLeafT(in.origin(), background);
                leaf->setValueMask(in.getValueMask());
                auto* buf = leaf->buffer().data();
                for (auto it = in.getValueMask().beginOn(); it; ++it) {
                    const openvdb::Index n = it.pos();
                    buf[n] = kernel(block, int(n >> 6), int((n >> 3) & 7), int(n & 7));
                }
                built[idx] = leaf;
            }
        });
        openvdb::tree::ValueAccessor<OutTreeT> acc(out->tree());
        for (OutLeafT* leaf : built) {
            if (leaf) acc.addLeaf(leaf);
        }
    });
    return out;
}

/// First and second differences at (i, j, k), in index units, OpenVDB's CD_2ND / CD_SECOND.
struct Derivatives
{
    float dx, dy, dz, dxx, dyy, dzz, dxy, dxz, dyz;

    Derivatives(const PaddedLeaf& b, int i, int j, int k)
    {
        const float c = b(i, j, k);
        const float xp = b(i + 1, j, k), xm = b(i - 1, j, k);
        const float yp = b(i, j + 1, k), ym = b(i, j - 1, k);
        const float zp = b(i, j, k + 1), zm = b(i, j, k - 1);
        dx = (xp - xm) * 0.5f;
        dy = (yp - ym) * 0.5f;
        dz = (zp - zm) * 0.5f;
        dxx = xp + xm - 2.0f * c;
        dyy = yp + ym - 2.0f * c;
        dzz = zp + zm - 2.0f * c;
        dxy = 0.25f * (b(i + 1, j + 1, k) + b(i - 1, j - 1, k) - b(i + 1, j - 1, k) - b(i - 1, j + 1, k));
        dxz = 0.25f * (b(i + 1, j, k + 1) + b(i - 1, j, k - 1) - b(i + 1, j, k - 1) - b(i - 1, j, k + 1));
        dyz = 0.25f * (b(i, j + 1, k + 1) + b(i, j - 1, k - 1) - b(i, j + 1, k - 1) - b(i, j - 1, k + 1));
    }

    /// Mean curvature in index units times 2 |grad|^3, exactly as OpenVDB's ISMeanCurvature.
    bool mean(float& alpha, float& beta) const
    {
        const float dx2 = dx * dx, dy2 = dy * dy, dz2 = dz * dz;
        const float norm = dx2 + dy2 + dz2;
        if (norm <= openvdb::math::Tolerance<float>::value()) return false;
        alpha = dx2 * (dyy + dzz) + dy2 * (dxx + dzz) + dz2 * (dxx + dyy) -
                2 * (dx * (dy * dxy + dz * dxz) + dy * dz * dyz);
        beta = float(std::sqrt(double(norm)));
        return true;
    }

    /// Gaussian curvature in index units: grad^T adj(H) grad / |grad|^4 (double precision).
    bool gaussian(double& k) const
    {
        const double gx = dx, gy = dy, gz = dz;
        const double n2 = gx * gx + gy * gy + gz * gz;
        if (n2 <= double(openvdb::math::Tolerance<float>::value())) return false;
        const double hxx = dxx, hyy = dyy, hzz = dzz, hxy = dxy, hxz = dxz, hyz = dyz;
        const double num = gx * gx * (hyy * hzz - hyz * hyz) + gy * gy * (hxx * hzz - hxz * hxz) +
                           gz * gz * (hxx * hyy - hxy * hxy) +
                           2.0 * gx * gy * (hxz * hyz - hxy * hzz) +
                           2.0 * gy * gz * (hxy * hxz - hyz * hxx) +
                           2.0 * gx * gz * (hxy * hyz - hxz * hyy);
        k = num / (n2 * n2);
        return true;
    }
};

} // namespace

openvdb::Vec3SGrid::Ptr gradient(const openvdb::FloatGrid& phi, int step, bool threaded, const LeafList* only)
{
    check(limits::kStep, step);
    const double dx = levelset::uniformVoxelSize(phi);
    const float inv = float(1.0 / (2.0 * step * dx));
    auto out = stencilMap<openvdb::Vec3SGrid>(phi, step, /*axesOnly=*/true, openvdb::Vec3s(0.0f), threaded, only,
        [step, inv](const PaddedLeaf& b, int i, int j, int k) {
            return openvdb::Vec3s((b(i + step, j, k) - b(i - step, j, k)) * inv,
                                  (b(i, j + step, k) - b(i, j - step, k)) * inv,
                                  (b(i, j, k + step) - b(i, j, k - step)) * inv);
        });
    out->setName("gradient");
    out->setVectorType(openvdb::VEC_COVARIANT);
    out->setIsInWorldSpace(true);
    return out;
}

openvdb::FloatGrid::Ptr magnitude(const openvdb::Vec3SGrid& gradient)
{
    auto out = openvdb::FloatGrid::create(
        openvdb::FloatTree::Ptr(new openvdb::FloatTree(gradient.tree(), 0.0f, openvdb::TopologyCopy())));
    out->setTransform(gradient.transform().copy());
    openvdb::tree::LeafManager<openvdb::FloatTree> leaves(out->tree());
    leaves.foreach([&](LeafT& leaf, size_t) {
        const auto* src = gradient.tree().probeConstLeaf(leaf.origin());
        if (!src) return;
        for (auto it = leaf.beginValueOn(); it; ++it) it.setValue(src->getValue(it.pos()).length());
    });
    out->setName("gradient_magnitude");
    return out;
}

openvdb::FloatGrid::Ptr curvature(const openvdb::FloatGrid& phi, Curvature kind, bool threaded,
                                  const LeafList* only)
{
    const double dx = levelset::uniformVoxelSize(phi);
    openvdb::FloatGrid::Ptr out;
    switch (kind) {
    case Curvature::Mean: {
        const float inv2dx = float(1.0 / (2.0 * dx));
        out = stencilMap<openvdb::FloatGrid>(phi, 1, /*axesOnly=*/false, 0.0f, threaded, only,
            [inv2dx](const PaddedLeaf& b, int i, int j, int k) {
                float alpha, beta;
                if (!Derivatives(b, i, j, k).mean(alpha, beta)) return 0.0f;
                return alpha * inv2dx / (beta * beta * beta);
            });
        break;
    }
    case Curvature::Gaussian: {
        const double invdx2 = 1.0 / (dx * dx);
        out = stencilMap<openvdb::FloatGrid>(phi, 1, /*axesOnly=*/false, 0.0f, threaded, only,
            [invdx2](const PaddedLeaf& b, int i, int j, int k) {
                double g;
                return Derivatives(b, i, j, k).gaussian(g) ? float(g * invdx2) : 0.0f;
            });
        break;
    }
    case Curvature::Laplacian: {
        const float invdx2 = float(1.0 / (dx * dx));
        out = stencilMap<openvdb::FloatGrid>(phi, 1, /*axesOnly=*/false, 0.0f, threaded, only,
            [invdx2](const PaddedLeaf& b, int i, int j, int k) {
                const float c = b(i, j, k);
                return (b(i + 1, j, k) + b(i - 1, j, k) + b(i, j + 1, k) + b(i, j - 1, k) +
                        b(i, j, k + 1) + b(i, j, k - 1) - 6.0f * c) * invdx2;
            });
        break;
    }
    }
    out->setName("curvature");
    return out;
}

std::pair<openvdb::FloatGrid::Ptr, openvdb::FloatGrid::Ptr>
principalCurvatures(const openvdb::FloatGrid& phi, bool threaded, const LeafList* only)
{
    const double invdx = 1.0 / levelset::uniformVoxelSize(phi);
    // k = H +/- sqrt(H^2 - K), from the same differences as the mean and Gaussian curvatures.
    auto principal = [&](double sign) {
        return stencilMap<openvdb::FloatGrid>(phi, 1, /*axesOnly=*/false, 0.0f, threaded, only,
            [invdx, sign](const PaddedLeaf& b, int i, int j, int k) {
                const Derivatives d(b, i, j, k);
                float alpha, beta;
                double g;
                if (!d.mean(alpha, beta) || !d.gaussian(g)) return 0.0f;
                const double h = double(alpha) / (2.0 * double(beta) * beta * beta);
                return float((h + sign * std::sqrt(std::max(h * h - g, 0.0))) * invdx);
            });
    };
    auto k1 = principal(1.0), k2 = principal(-1.0);
    k1->setName("k1");
    k2->setName("k2");
    return {k1, k2};
}

namespace {

ErrorStats summarize(std::vector<double>& v)
{
    ErrorStats s;
    s.count = v.size();
    if (v.empty()) return s;
    std::sort(v.begin(), v.end());
    double sum = 0.0;
    for (double x : v) sum += x;
    s.mean = sum / double(v.size());
    s.median = v[v.size() / 2];
    s.p95 = v[std::min(v.size() - 1, size_t(0.95 * double(v.size())))];
    s.max = v.back();
    return s;
}

} // namespace

GradientComparison compareGradient(const implicit::Implicit& shape, const openvdb::FloatGrid& phi,
                                   const openvdb::Vec3SGrid& grad, int step)
{
    // Collect per leaf in parallel, then summarize (sorting for the percentiles).
    struct Samples { std::vector<double> angle, mag; size_t skipped = 0; };
    openvdb::tree::LeafManager<const openvdb::Vec3STree> leaves(grad.tree());
    std::vector<Samples> band(leaves.leafCount()), interior(leaves.leafCount());
    const openvdb::math::Transform& xform = grad.transform();
    leaves.foreach([&](const openvdb::Vec3STree::LeafNodeType& leaf, size_t idx) {
        openvdb::tree::ValueAccessor<const FloatTree> acc(phi.tree());
        for (auto it = leaf.cbeginValueOn(); it; ++it) {
            const Coord ijk = it.getCoord();
            bool inside = true;
            for (int a = 0; a < 3 && inside; ++a) {
                Coord d(0, 0, 0);
                d[a] = step;
                inside = acc.isValueOn(ijk + d) && acc.isValueOn(ijk - d);
            }
            const openvdb::Vec3d g(*it);
            const implicit::Vec3d a = shape.gradient(xform.indexToWorld(ijk));
            const double gl = g.length(), al = a.length();
            for (Samples* s : {&band[idx], inside ? &interior[idx] : nullptr}) {
                if (!s) continue;
                if (!(gl > 0.0) || !(al > 0.0) || !std::isfinite(al)) {
                    ++s->skipped;
                    continue;
                }
                const double c = std::max(-1.0, std::min(1.0, g.dot(a) / (gl * al)));
                s->angle.push_back(std::acos(c) * 180.0 / M_PI);
                s->mag.push_back(gl);
            }
        }
    });
    auto combine = [](std::vector<Samples>& parts) {
        std::vector<double> angle, magErr;
        GradientErrors out;
        double magSum = 0.0;
        for (Samples& p : parts) {
            angle.insert(angle.end(), p.angle.begin(), p.angle.end());
            for (double m : p.mag) {
                magSum += m;
                magErr.push_back(std::abs(m - 1.0));
            }
            out.skipped += p.skipped;
        }
        out.meanMagnitude = magErr.empty() ? 0.0 : magSum / double(magErr.size());
        out.angleDeg = summarize(angle);
        out.magnitudeError = summarize(magErr);
        return out;
    };
    return {combine(band), combine(interior)};
}

} // namespace ivdb::diff
