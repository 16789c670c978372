// SPDX-License-Identifier: Apache-2.0
#include <ivdb/util/System.h>

#include <ivdb/util/Interrupt.h>

#include <openvdb/Exceptions.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <cstdlib>
#include <fstream>
#include <sstream>

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
