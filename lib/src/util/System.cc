// SPDX-License-Identifier: Apache-2.0
#include <ivdb/util/System.h>

#include <ivdb/util/Interrupt.h>

#include "Simd.h"

#include <openvdb/Exceptions.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <thread>

namespace ivdb::util {

namespace {
std::uint64_t readKb(const char* file, const std::string& key)
{
    std::ifstream in(file);
    std::string line;
    while (std::getline(in, line)) {
        if (line.compare(0, key.size(), key) == 0) {
            std::istringstream ss(line.substr(key.size()));
            std::uint64_t kb = 0;
            ss >> kb;
            return kb * 1024;
        }
    }
    return 0;
}
} // namespace

std::uint64_t availableMemory() { return readKb("/proc/meminfo", "MemAvailable:"); }

std::uint64_t peakResidentMemory() { return readKb("/proc/self/status", "VmHWM:"); }

std::uint64_t residentMemory() { return readKb("/proc/self/status", "VmRSS:"); }

double memoryBudget(std::uint64_t limit)
{
    if (limit) return double(limit);
    const double available = double(availableMemory()); // 0 when unknown
    return available > 0.0 ? kMemoryFraction * available : 1e18;
}

MachineInfo machineInfo()
{
    MachineInfo m;
    m.cpu = "unknown";
    std::ifstream in("/proc/cpuinfo");
    std::string line;
    while (std::getline(in, line)) {
        if (line.compare(0, 10, "model name") != 0) continue;
        const auto colon = line.find(':');
        if (colon == std::string::npos) break;
        std::string name = line.substr(colon + 1);
        const auto first = name.find_first_not_of(" \t"), last = name.find_last_not_of(" \t");
        if (first != std::string::npos) m.cpu = name.substr(first, last - first + 1);
        break;
    }
    m.cores = std::thread::hardware_concurrency();
#if defined(IVDB_HAS_VECTOR_CLONES)
    // The loader's choice among IVDB_VECTOR_CLONES' versions: the first the CPU supports.
    __builtin_cpu_init();
    m.vectorCode = __builtin_cpu_supports("avx512f") ? "AVX-512"
                 : __builtin_cpu_supports("avx2")    ? "AVX2"
                                                     : "SSE2";
#elif defined(__x86_64__)
    m.vectorCode = "SSE2 (no run-time choice)";
#else
    m.vectorCode = "the compiler's default (no run-time choice)";
#endif
    return m;
}

std::string MachineInfo::describe() const
{
    return cpu + ", " + (cores ? std::to_string(cores) : std::string("?")) + " cores, vector code " +
           vectorCode;
}

std::string extensionOf(const std::string& path)
{
    std::string e = std::filesystem::path(path).extension().string();
    std::transform(e.begin(), e.end(), e.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return e;
}

std::string formatBytes(double bytes)
{
    const char* units[] = {"B", "kB", "MB", "GB", "TB"};
    int u = 0;
    while (bytes >= 1000.0 && u < 4) {
        bytes /= 1000.0;
        ++u;
    }
    char buf[32];
    std::snprintf(buf, sizeof(buf), u == 0 ? "%.0f %s" : "%.1f %s", bytes, units[u]);
    return buf;
}

std::string errorText(const std::exception& e)
{
    std::string what = e.what();
    // OpenVDB's exceptions read "IoError: message"; drop every such leading type name.
    for (;;) {
        const auto colon = what.find(": ");
        if (colon == std::string::npos || colon == 0) break;
        const std::string head = what.substr(0, colon);
        const bool isType = head.find_first_of(" ./") == std::string::npos &&
                            (head.size() > 5 && (head.compare(head.size() - 5, 5, "Error") == 0 ||
                                                 head.compare(head.size() - 5, 5, "ption") == 0));
        if (!isType) break;
        what = what.substr(colon + 2);
    }
    return what;
}

std::string formatNumber(double v)
{
    char buf[40];
    for (int precision = 6; precision <= 17; ++precision) {
        std::snprintf(buf, sizeof(buf), "%.*g", precision, v);
        if (std::strtod(buf, nullptr) == v) break;
    }
    return buf;
}

void throwInterrupted()
{
    OPENVDB_THROW(openvdb::RuntimeError, "interrupted");
}

} // namespace ivdb::util
