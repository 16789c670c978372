// SPDX-License-Identifier: Apache-2.0
// Transparent huge pages for the command-line programs (docs/performance.md#huge-pages): glibc's
// malloc asks the kernel for 2 MiB pages when GLIBC_TUNABLES holds glibc.malloc.hugetlb=1, read
// once as a process starts. Header-only and free of OpenVDB, for the launcher (tools/ivdb/
// Launcher.cc), which must start in a few milliseconds.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include <gnu/libc-version.h>

namespace ivdb::tools {

/// @brief Add glibc.malloc.hugetlb=1 to GLIBC_TUNABLES (after any tunables already there) where
/// it helps: Linux with transparent huge pages in "madvise" mode and glibc 2.35 or later, unless
/// IVDB_HUGEPAGES=0 or GLIBC_TUNABLES already names glibc.malloc.hugetlb. Returns true if it
/// changed the environment (a program started from now on, or this one restarted, reads it).
inline bool askForHugePages()
{
    const char* opt = std::getenv("IVDB_HUGEPAGES");
    if (opt && std::strcmp(opt, "0") == 0) return false;
    const char* set = std::getenv("GLIBC_TUNABLES");
    const std::string tunables = set ? set : "";
    // Already set (by the user, or by an earlier call: no loop).
    if (tunables.find("glibc.malloc.hugetlb") != std::string::npos) return false;
    // THP "always" needs nothing, "never" gives nothing; "madvise" needs malloc to ask.
    std::FILE* thp = std::fopen("/sys/kernel/mm/transparent_hugepage/enabled", "r");
    if (!thp) return false;
    char modes[128] = {};
    const bool read = std::fgets(modes, sizeof(modes), thp) != nullptr;
    std::fclose(thp);
    if (!read || !std::strstr(modes, "[madvise]")) return false;
    // glibc.malloc.hugetlb came with glibc 2.35 (older ones ignore it).
    int major = 0, minor = 0;
    if (std::sscanf(gnu_get_libc_version(), "%d.%d", &major, &minor) != 2 || major < 2 ||
        (major == 2 && minor < 35)) {
        return false;
    }
    const std::string value =
        (tunables.empty() ? std::string() : tunables + ":") + "glibc.malloc.hugetlb=1";
    return setenv("GLIBC_TUNABLES", value.c_str(), 1) == 0;
}

} // namespace ivdb::tools
