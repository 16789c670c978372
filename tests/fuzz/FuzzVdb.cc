// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: bytes as a .vdb file through the jobs' reading path (the layout check,
// OpenVDB's reader with delayed loading, grid selection, the level-set and value checks), then
// `info`'s description of every grid and a gradient of a small level set.
//
// A bad file must end in an exception (the CLI prints it as `ivdb: error: FILE: ...`); a signal,
// a sanitizer report or a hang is a bug.
#include <ivdb/diff/Differential.h>
#include <ivdb/io/VdbFile.h>
#include <ivdb/jobs/Inputs.h>

#include <openvdb/openvdb.h>

#include <cstdint>
#include <cstdio>
#include <exception>
#include <string>

#include <unistd.h>

namespace {

std::string gPath;

bool writeInput(const std::uint8_t* data, size_t size)
{
    std::FILE* f = std::fopen(gPath.c_str(), "wb");
    if (!f) return false;
    const bool ok = std::fwrite(data, 1, size, f) == size;
    return std::fclose(f) == 0 && ok;
}

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    openvdb::initialize();
    const char* dir = std::getenv("TMPDIR");
    gPath = std::string(dir && *dir ? dir : "/tmp") + "/ivdb-fuzz-vdb-" +
            std::to_string(::getpid()) + ".vdb";
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size)
{
    if (size > 1 << 20 || !writeInput(data, size)) return 0;
    try {
        for (const auto& g : ivdb::io::readVdb(gPath)) {
            ivdb::io::checkGridValues(*g, gPath);
            (void)ivdb::io::describeGrid(*g);
        }
    } catch (const std::exception&) {
    }
    try {
        const openvdb::FloatGrid::Ptr phi = ivdb::jobs::readLevelSet(gPath);
        if (phi->activeVoxelCount() < 100000) (void)ivdb::diff::gradient(*phi, 1, false);
    } catch (const std::exception&) {
    }
    std::remove(gPath.c_str());
    return 0;
}
