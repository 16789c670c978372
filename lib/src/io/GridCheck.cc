// SPDX-License-Identifier: Apache-2.0
// Checks of a grid read from a file before any command uses it: the transform and the values.
#include <ivdb/io/VdbFile.h>

#include <ivdb/util/System.h>

#include <openvdb/tools/Diagnostics.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <cmath>
#include <cstddef>
#include <limits>
#include <mutex>
#include <sstream>
#include <vector>

namespace ivdb::io {

namespace {

std::string oneLine(std::string text)
{
    std::string out;
    for (char c : text) out += c == '\n' ? std::string("; ") : std::string(1, c);
    while (!out.empty() && (out.back() == ';' || out.back() == ' ')) out.pop_back();
    return out;
}

/// Whether the @a count numbers from @a values are all finite: a loop the compiler vectorizes
/// (a NaN fails the comparison, an infinity exceeds the largest finite number).
template<typename T>
bool allFinite(const T* values, std::size_t count)
{
    bool ok = true;
    for (std::size_t i = 0; i < count; ++i) ok &= std::abs(values[i]) <= std::numeric_limits<T>::max();
    return ok;
}

/// Whether every value of @a grid (background, tiles, voxels, active or not) is finite: the
/// leaves' buffers in parallel, read as arrays of their numbers (a scalar or a vector's
/// components). This is the pass every command's input takes; OpenVDB's Diagnose, which also
/// says where a value is not finite, took about ten times as long and runs only on a failure.
template<typename GridT>
bool allFinite(const GridT& grid)
{
    using TreeT = typename GridT::TreeType;
    using LeafT = typename TreeT::LeafNodeType;
    using ValueT = typename GridT::ValueType;
    using Number = typename openvdb::VecTraits<ValueT>::ElementType;
    constexpr std::size_t kNumbers = sizeof(ValueT) / sizeof(Number);
    static_assert(kNumbers * sizeof(Number) == sizeof(ValueT), "a value is an array of numbers");
    const auto finite = [](const ValueT& v) {
        return allFinite(reinterpret_cast<const Number*>(&v), kNumbers);
    };
    if (!finite(grid.background())) return false;
    typename TreeT::ValueAllCIter tiles = grid.tree().cbeginValueAll();
    tiles.setMaxDepth(TreeT::ValueAllCIter::LEAF_DEPTH - 1); // the root's and nodes' tiles
    for (; tiles; ++tiles) {
        if (!finite(*tiles)) return false;
    }
    std::vector<const LeafT*> leaves;
    leaves.reserve(grid.tree().leafCount());
    grid.tree().getNodes(leaves);
    return tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, leaves.size()), true,
        [&](const tbb::blocked_range<std::size_t>& r, bool ok) {
            for (std::size_t k = r.begin(); ok && k < r.end(); ++k) {
                const ValueT* values = leaves[k]->buffer().data();
                ok = allFinite(reinterpret_cast<const Number*>(values), LeafT::SIZE * kNumbers);
            }
            return ok;
        },
        [](bool a, bool b) { return a && b; });
}

/// Every value (background, tiles, voxels, active or not) finite; where one is not, OpenVDB's
/// threaded diagnostics say where.
template<typename GridT>
void checkFinite(const GridT& grid, const std::string& what)
{
    if (allFinite(grid)) return;
    openvdb::tools::Diagnose<GridT> diagnose(grid);
    openvdb::tools::CheckFinite<GridT, typename GridT::ValueAllCIter> finite;
    const std::string found = diagnose.check(finite, /*updateMask=*/false, /*voxels=*/true,
                                             /*tiles=*/true, /*background=*/true);
    if (!found.empty()) {
        OPENVDB_THROW(openvdb::ValueError, what + " holds values that are not finite (NaN or "
            "infinity): " + oneLine(found) + "; the file is damaged or was written by a faulty "
            "tool, make it again");
    }
}

/// OpenVDB 10's delayed loading cannot survive a voxel buffer that fails to decompress:
/// LeafBuffer::doLoad frees the buffer's file record and allocates the values, then throws with
/// the buffer still marked out of core, so destroying the leaf frees the values array as a file
/// record (a crash). A grid whose loading failed is therefore kept alive, unreachable from the
/// caller, until the process ends (the CLI ends right after the error).
void keepDamagedGrid(const openvdb::GridBase& grid)
{
    static std::mutex mutex;
    static auto* kept = new std::vector<openvdb::GridBase::ConstPtr>; // never destroyed
    std::lock_guard<std::mutex> lock(mutex);
    kept->push_back(grid.copyGrid()); // shares, and so keeps, the tree
}

template<typename GridT>
void checkFiniteOrKeep(const GridT& grid, const std::string& what, const std::string& path)
{
    try {
        checkFinite(grid, what);
    } catch (const openvdb::ValueError&) {
        throw;
    } catch (const std::exception& e) {
        keepDamagedGrid(grid);
        OPENVDB_THROW(openvdb::IoError, path + ": not a valid .vdb file: the voxel data of grid '" +
            grid.getName() + "' cannot be read (" + util::errorText(e) + "); the file is damaged");
    }
}

} // namespace

void checkGridValues(const openvdb::GridBase& grid, const std::string& path)
{
    const std::string what = path + ": grid '" + grid.getName() + "'";
    const openvdb::Vec3d vs = grid.voxelSize();
    for (int a = 0; a < 3; ++a) {
        if (!std::isfinite(vs[a]) || !(vs[a] > 0.0)) {
            std::ostringstream os;
            os << what << " has an invalid transform (voxel size " << util::formatNumber(vs[0])
               << " x " << util::formatNumber(vs[1]) << " x " << util::formatNumber(vs[2])
               << "); the file is damaged, make it again";
            OPENVDB_THROW(openvdb::ValueError, os.str());
        }
    }
    const openvdb::Vec3d origin = grid.transform().indexToWorld(openvdb::Vec3d(0.0));
    if (!std::isfinite(origin[0]) || !std::isfinite(origin[1]) || !std::isfinite(origin[2])) {
        OPENVDB_THROW(openvdb::ValueError, what + " has an invalid transform (its origin is not "
                                                  "finite); the file is damaged, make it again");
    }
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) {
        checkFiniteOrKeep(*f, what, path);
        if (grid.getGridClass() == openvdb::GRID_LEVEL_SET && !(f->background() > 0.0f)) {
            OPENVDB_THROW(openvdb::ValueError, what + " is a level set with background " +
                util::formatNumber(f->background()) + "; a level set's background (the band's "
                "half width in world units) must be > 0, the file is damaged or not a level set");
        }
    } else if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) {
        checkFiniteOrKeep(*d, what, path);
    } else if (const auto* v = dynamic_cast<const openvdb::Vec3SGrid*>(&grid)) {
        checkFiniteOrKeep(*v, what, path);
    } else if (const auto* w = dynamic_cast<const openvdb::Vec3DGrid*>(&grid)) {
        checkFiniteOrKeep(*w, what, path);
    }
}

} // namespace ivdb::io
