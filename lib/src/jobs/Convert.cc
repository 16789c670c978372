// SPDX-License-Identifier: Apache-2.0
#include <ivdb/jobs/Convert.h>

#include <ivdb/io/NanoVdbFile.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Inputs.h>
#include <ivdb/util/Params.h>
#include <ivdb/util/System.h>

#include <algorithm>
#include <cctype>
#include <filesystem>

namespace ivdb::jobs {

FileFormat outputFormat(const std::string& path)
{
    std::string ext = std::filesystem::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    if (ext == ".vdb") return FileFormat::Vdb;
    if (ext == ".nvdb") return FileFormat::NanoVdb;
    throw ParamError(param::kOutput, "'" + path + "' must end in .vdb (OpenVDB) or .nvdb (NanoVDB)");
}

ConvertResult convert(const ConvertOptions& opt)
{
    Stopwatch clock;
    ConvertResult result;
    result.format = outputFormat(opt.output);
    if (result.format == FileFormat::NanoVdb) {
        if (opt.compression) {
            throw ParamError(param::kCompression, "does not apply to a NanoVDB file, which is "
                             "written uncompressed (what NanoVDB's tools and GPU loaders read)");
        }
        if (opt.half) {
            throw ParamError(param::kHalf, "is for .vdb output only; a NanoVDB file stores "
                             "full floats");
        }
    }
    io::checkOutputPath(opt.output);
    const openvdb::GridPtrVec grids = io::readVdb(opt.input);
    if (opt.grid.empty()) {
        result.grids = grids;
    } else {
        result.grids = {io::selectGrid(grids, opt.input, opt.grid)};
    }
    openvdb::GridCPtrVec out;
    for (const auto& g : result.grids) {
        io::checkGridValues(*g, opt.input);
        if (result.format == FileFormat::NanoVdb && !io::nanoVdbHolds(*g)) {
            throw ParamError(param::kGrid, "'" + g->getName() + "' holds " + g->valueType() +
                             " values, which a NanoVDB file cannot hold (it holds float, double, "
                             "int32, int64, uint32, vec3s, bool and mask grids); name "
                             "another grid", opt.input);
        }
        out.push_back(g);
    }
    result.readSeconds = clock.lap();
    if (result.format == FileFormat::NanoVdb) {
        io::writeNanoVdb(opt.output, out);
    } else {
        io::WriteOptions write;
        write.compression = opt.compression.value_or(io::Compression::Blosc);
        write.half = opt.half;
        io::writeVdbStamped(opt.output, out, write);
    }
    result.writeSeconds = clock.lap();
    std::error_code ec;
    const auto size = std::filesystem::file_size(opt.output, ec);
    result.fileBytes = ec ? 0 : std::uint64_t(size);
    result.totalSeconds = clock.total();
    return result;
}

} // namespace ivdb::jobs
