#include <ivdb/io/VdbFile.h>

#include <ivdb/util/System.h>

#include <openvdb/io/Archive.h>
#include <openvdb/io/File.h>

#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace ivdb::io {

namespace fs = std::filesystem;

namespace {

// The temporary file being written, for removePendingTemporaryFile() (a signal handler).
char gPendingPath[4096];
volatile std::sig_atomic_t gPendingSet = 0;

void setPending(const std::string& tmp)
{
    gPendingSet = 0;
    std::atomic_signal_fence(std::memory_order_seq_cst);
    if (tmp.size() >= sizeof(gPendingPath)) return;
    std::memcpy(gPendingPath, tmp.c_str(), tmp.size() + 1);
    std::atomic_signal_fence(std::memory_order_seq_cst);
    gPendingSet = 1;
}

void clearPending()
{
    gPendingSet = 0;
    std::atomic_signal_fence(std::memory_order_seq_cst);
}

[[noreturn]] void ioError(const std::string& path, const std::string& what)
{
    OPENVDB_THROW(openvdb::IoError, path + ": " + what);
}

/// io::File writes through an unchecked ofstream; this writes the same seekable layout (with
/// grid offsets for delayed loading) to a stream whose every error we check.
class CheckedArchive: public openvdb::io::Archive
{
public:
    void writeTo(std::ostream& os, const openvdb::GridCPtrVec& grids,
                 const openvdb::MetaMap& meta) const
    {
        this->write(os, grids, /*seekable=*/true, meta);
    }
};

std::string folderOf(const std::string& path)
{
    const fs::path p(path);
    return p.has_parent_path() ? p.parent_path().string() : std::string(".");
}

/// Bounds-checked reads of the file's own layout, so that a truncated or corrupt file is refused
/// before OpenVDB's reader sees it (which accepts some truncations and allocates whatever length a
/// corrupt metadata field claims).
class LayoutReader
{
public:
    LayoutReader(const std::string& path, std::uint64_t size): mPath(path), mSize(size)
    {
        mIn.open(path, std::ios::binary);
        if (!mIn) ioError(path, std::string("cannot open: ") + std::strerror(errno));
    }

    std::uint64_t pos() const { return mPos; }

    void seek(std::uint64_t pos)
    {
        if (pos > mSize) corrupt("an offset points past the end of the file");
        mPos = pos;
        mIn.clear();
        mIn.seekg(std::streamoff(pos));
    }

    void bytes(void* out, std::uint64_t n, std::uint64_t end)
    {
        if (n > end || mPos > end - n) corrupt("it ends in the middle of a field (truncated?)");
        mIn.read(static_cast<char*>(out), std::streamsize(n));
        if (!mIn) corrupt("it cannot be read to the end (truncated?)");
        mPos += n;
    }

    void skip(std::uint64_t n, std::uint64_t end)
    {
        if (n > end || mPos > end - n) corrupt("a field claims more bytes than the file holds");
        seek(mPos + n);
    }

    std::uint32_t u32(std::uint64_t end)
    {
        std::uint32_t v = 0;
        bytes(&v, sizeof(v), end);
        return v;
    }

    std::int64_t i64(std::uint64_t end)
    {
        std::int64_t v = 0;
        bytes(&v, sizeof(v), end);
        return v;
    }

    std::string str(std::uint64_t end)
    {
        const std::uint32_t n = u32(end);
        if (n > end - mPos || n > (1u << 20)) corrupt("a name claims more bytes than the file holds");
        std::string s(n, '\0');
        if (n) bytes(&s[0], n, end);
        return s;
    }

    /// A MetaMap: count, then (name, type name, byte count + value) per entry.
    void metaMap(std::uint64_t end)
    {
        const std::uint32_t count = u32(end);
        if (std::uint64_t(count) * 12 > end - mPos) corrupt("its metadata count is impossible");
        for (std::uint32_t i = 0; i < count; ++i) {
            str(end);
            str(end);
            skip(u32(end), end);
        }
    }

    [[noreturn]] void corrupt(const std::string& why) const
    {
        ioError(mPath, "not a valid .vdb file: " + why);
    }

private:
    std::string mPath;
    std::uint64_t mSize, mPos = 0;
    std::ifstream mIn;
};

/// Check the header, the file metadata, every grid descriptor's offsets and every grid's metadata.
void validateLayout(const std::string& path)
{
    std::error_code ec;
    const std::uint64_t size = fs::file_size(path, ec);
    if (ec) ioError(path, "cannot get the file size: " + ec.message());
    if (size == 0) ioError(path, "is empty, not a .vdb file");
    LayoutReader in(path, size);
    std::int64_t magic = 0;
    if (size < 8) ioError(path, "is too short to be a .vdb file");
    in.bytes(&magic, 8, size);
    if (magic != openvdb::OPENVDB_MAGIC) ioError(path, "is not a .vdb file (no OpenVDB magic number)");
    const std::uint32_t version = in.u32(size);
    // Older layouts differ; leave them to OpenVDB's reader.
    if (version < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION) return;
    in.u32(size);           // library major
    in.u32(size);           // library minor
    char hasOffsets = 0;
    in.bytes(&hasOffsets, 1, size);
    in.skip(36, size);      // UUID
    in.metaMap(size);       // file metadata
    if (!hasOffsets) return; // a stream, not a seekable file: no offsets to check
    const std::int32_t count = std::int32_t(in.u32(size));
    if (count <= 0) ioError(path, "holds no grids");
    if (std::uint64_t(count) * 36 > size - in.pos()) in.corrupt("its grid count is impossible");
    struct Desc { std::string name; std::int64_t grid, block, end; };
    std::vector<Desc> grids;
    for (std::int32_t i = 0; i < count; ++i) {
        Desc d;
        d.name = in.str(size);
        in.str(size);                                  // grid type
        if (version >= openvdb::OPENVDB_FILE_VERSION_GRID_INSTANCING) in.str(size);
        d.grid = in.i64(size);
        d.block = in.i64(size);
        d.end = in.i64(size);
        grids.push_back(d);
        const std::uint64_t header = in.pos();
        if (d.grid < std::int64_t(header) || d.block < d.grid || d.end < d.block ||
            std::uint64_t(d.end) > size) {
            std::ostringstream os;
            os << "not a valid .vdb file: grid " << i << " ('" << d.name.substr(0, 64)
               << "') claims bytes " << d.grid << " to " << d.end << " but the file has " << size
               << " bytes (truncated?)";
            ioError(path, os.str());
        }
        in.seek(std::uint64_t(d.end));
    }
    for (const Desc& d : grids) {
        in.seek(std::uint64_t(d.grid));
        in.u32(std::uint64_t(d.block)); // compression flags
        in.metaMap(std::uint64_t(d.block));
    }
}

} // namespace

void checkOutputPath(const std::string& path)
{
    if (path.empty()) ioError("(output)", "the output path is empty");
    std::error_code ec;
    if (fs::is_directory(path, ec)) ioError(path, "is a folder; give a file name such as out.vdb");
    if (fs::exists(path, ec) && !fs::is_regular_file(path, ec)) {
        ioError(path, "exists and is not a regular file (a device or a socket?); give a file path");
    }
    const std::string dir = folderOf(path);
    if (!fs::is_directory(dir, ec)) {
        ioError(path, "the folder '" + dir + "' does not exist; create it first");
    }
    if (::access(dir.c_str(), W_OK) != 0) {
        ioError(path, "the folder '" + dir + "' is not writable (" + std::strerror(errno) + ")");
    }
}

void removePendingTemporaryFile() noexcept
{
    if (gPendingSet) ::unlink(gPendingPath);
}

void writeFileAtomically(const std::string& path,
                         const std::function<void(std::ostream&)>& write)
{
    checkOutputPath(path);
    static std::atomic<unsigned> counter{0};
    const fs::path target(path);
    const std::string tmp = (fs::path(folderOf(path)) /
        ("." + target.filename().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
         std::to_string(counter++))).string();
    // Cleared on every way out: the temporary file is renamed or removed by then.
    struct PendingGuard { ~PendingGuard() { clearPending(); } } pendingGuard;
    setPending(tmp);
    try {
        {
            std::ofstream os;
            os.exceptions(std::ios::badbit | std::ios::failbit);
            os.open(tmp, std::ios::out | std::ios::binary | std::ios::trunc);
            write(os);
            os.flush();
            os.close();
        }
        const int fd = ::open(tmp.c_str(), O_RDONLY);
        if (fd < 0 || ::fsync(fd) != 0) {
            const int err = errno;
            if (fd >= 0) ::close(fd);
            ioError(path, std::string("cannot sync the written file: ") + std::strerror(err));
        }
        ::close(fd);
        if (std::rename(tmp.c_str(), path.c_str()) != 0) {
            ioError(path, std::string("cannot rename the temporary file into place: ") +
                              std::strerror(errno));
        }
    } catch (const openvdb::IoError&) {
        std::remove(tmp.c_str());
        throw;
    } catch (const std::ios_base::failure&) {
        const int err = errno;
        std::remove(tmp.c_str());
        ioError(path, std::string("cannot write: ") + (err ? std::strerror(err) : "stream error") +
                          " (is the disk full?)");
    } catch (const std::exception& e) {
        std::remove(tmp.c_str());
        ioError(path, std::string("cannot write: ") + e.what());
    }
}

void writeVdb(const std::string& path, const openvdb::GridCPtrVec& grids,
              const openvdb::MetaMap& fileMetadata)
{
    writeFileAtomically(path, [&](std::ostream& os) {
        CheckedArchive().writeTo(os, grids, fileMetadata);
    });
}

openvdb::GridPtrVec readVdb(const std::string& path)
{
    std::error_code ec;
    if (!fs::exists(path, ec)) ioError(path, "no such file");
    if (fs::is_directory(path, ec)) ioError(path, "is a folder, not a .vdb file");
    if (::access(path.c_str(), R_OK) != 0) {
        ioError(path, std::string("cannot read: ") + std::strerror(errno));
    }
    if (!fs::is_regular_file(path, ec)) ioError(path, "is not a regular file");
    validateLayout(path);
    openvdb::GridPtrVecPtr grids;
    try {
        // Delayed loading: topology now, voxel buffers when first touched, so the (single-
        // threaded) decompression happens inside the parallel operations that read them. The
        // layout was checked above, so every grid's bytes are in the file.
        openvdb::io::File file(path);
        file.open(/*delayLoad=*/true);
        grids = file.getGrids();
        file.close();
    } catch (const std::exception& e) {
        ioError(path, "not a readable .vdb file: " + util::errorText(e));
    }
    if (!grids || grids->empty()) ioError(path, "holds no grids");
    return *grids;
}

openvdb::GridBase::Ptr selectGrid(const openvdb::GridPtrVec& grids, const std::string& path,
                                  const std::string& name)
{
    std::string held;
    for (const auto& g : grids) {
        if (!name.empty() && g->getName() == name) return g;
        if (name.empty() && g->getGridClass() == openvdb::GRID_LEVEL_SET) return g;
        held += (held.empty() ? "" : ", ") + std::string("'") + g->getName() + "' (" +
                openvdb::GridBase::gridClassToString(g->getGridClass()) + ", " + g->valueType() + ")";
    }
    if (name.empty()) {
        OPENVDB_THROW(openvdb::LookupError, path + ": holds no level set grid (it holds " + held +
                                                "); pick a grid with --grid NAME");
    }
    OPENVDB_THROW(openvdb::LookupError, path + ": no grid named '" + name + "' (it holds " + held +
                                            "); pick one of those with --grid");
}

GridInfo describeGrid(const openvdb::GridBase& grid)
{
    GridInfo info;
    info.name = grid.getName();
    info.gridClass = openvdb::GridBase::gridClassToString(grid.getGridClass());
    info.isLevelSet = grid.getGridClass() == openvdb::GRID_LEVEL_SET;
    info.valueType = grid.valueType();
    info.voxelSize = grid.voxelSize();
    info.activeVoxels = grid.activeVoxelCount();
    info.memoryBytes = grid.memUsage();
    info.indexBox = grid.evalActiveVoxelBoundingBox();
    if (!info.indexBox.empty()) {
        info.worldBox = grid.transform().indexToWorld(info.indexBox);
    }
    info.leafNodes = grid.baseTree().leafCount();
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) {
        info.background = {double(f->background())};
    } else if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) {
        info.background = {d->background()};
    } else if (const auto* v = dynamic_cast<const openvdb::Vec3SGrid*>(&grid)) {
        const openvdb::Vec3s b = v->background();
        info.background = {double(b[0]), double(b[1]), double(b[2])};
    } else if (const auto* w = dynamic_cast<const openvdb::Vec3DGrid*>(&grid)) {
        const openvdb::Vec3d b = w->background();
        info.background = {b[0], b[1], b[2]};
    }
    return info;
}

} // namespace ivdb::io
