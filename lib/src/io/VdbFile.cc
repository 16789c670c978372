#include <ivdb/io/VdbFile.h>

#include <openvdb/io/Archive.h>
#include <openvdb/io/File.h>

#include <atomic>
#include <cerrno>
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

} // namespace

void checkOutputPath(const std::string& path)
{
    if (path.empty()) ioError("(output)", "the output path is empty");
    std::error_code ec;
    if (fs::is_directory(path, ec)) ioError(path, "is a folder; give a file name such as out.vdb");
    const std::string dir = folderOf(path);
    if (!fs::is_directory(dir, ec)) {
        ioError(path, "the folder '" + dir + "' does not exist; create it first");
    }
    if (::access(dir.c_str(), W_OK) != 0) {
        ioError(path, "the folder '" + dir + "' is not writable (" + std::strerror(errno) + ")");
    }
}

void writeVdb(const std::string& path, const openvdb::GridCPtrVec& grids,
              const openvdb::MetaMap& fileMetadata)
{
    checkOutputPath(path);
    static std::atomic<unsigned> counter{0};
    const fs::path target(path);
    const std::string tmp = (fs::path(folderOf(path)) /
        ("." + target.filename().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
         std::to_string(counter++))).string();
    try {
        {
            std::ofstream os;
            os.exceptions(std::ios::badbit | std::ios::failbit);
            os.open(tmp, std::ios::out | std::ios::binary | std::ios::trunc);
            CheckedArchive().writeTo(os, grids, fileMetadata);
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

openvdb::GridPtrVec readVdb(const std::string& path)
{
    std::error_code ec;
    if (!fs::exists(path, ec)) ioError(path, "no such file");
    if (fs::is_directory(path, ec)) ioError(path, "is a folder, not a .vdb file");
    if (::access(path.c_str(), R_OK) != 0) {
        ioError(path, std::string("cannot read: ") + std::strerror(errno));
    }
    try {
        openvdb::io::File file(path);
        file.open(/*delayLoad=*/false);
        openvdb::GridPtrVecPtr grids = file.getGrids();
        file.close();
        if (!grids) ioError(path, "holds no grids");
        return *grids;
    } catch (const openvdb::IoError& e) {
        std::string what = e.what();
        if (what.find(path) == std::string::npos) what = path + ": " + what;
        OPENVDB_THROW(openvdb::IoError, what + " (not a readable .vdb file?)");
    } catch (const std::exception& e) {
        ioError(path, std::string("not a readable .vdb file: ") + e.what());
    }
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
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&grid)) {
        info.background = f->background();
        info.leafNodes = f->tree().leafCount();
    } else if (const auto* d = dynamic_cast<const openvdb::DoubleGrid*>(&grid)) {
        info.background = d->background();
        info.leafNodes = d->tree().leafCount();
    }
    return info;
}

} // namespace ivdb::io
