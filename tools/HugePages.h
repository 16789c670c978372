// SPDX-License-Identifier: Apache-2.0
// Transparent huge pages for the command-line programs (docs/performance.md#huge-pages): glibc's
// malloc asks the kernel for 2 MiB pages when GLIBC_TUNABLES holds glibc.malloc.hugetlb=1, read
// once as a process starts, and its heaps then grow in steps large enough for whole 2 MiB pages
// and keep what they free (the other tunables below). Header-only and free of OpenVDB, for the
// launcher (tools/ivdb/Launcher.cc), which must start in a few milliseconds.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include <gnu/libc-version.h>

namespace ivdb::tools {

/// @brief The tunables askForHugePages() adds, in this order. With hugetlb=1 alone, malloc
/// grows a heap by what each allocation needs (plus 128 KiB), so a heap's memory comes in ranges
/// that often cannot hold a whole 2 MiB page, and it gives back freed memory at a heap's top,
/// which the next allocation faults in again: about a quarter of a run's memory stayed in
/// 4 KiB pages. Heaps that grow 64 MiB at a time (top_pad), are trimmed only past 1 GiB free
/// (trim_threshold), and serve blocks below 32 MiB, glibc's largest mmap threshold, themselves
/// (mmap_threshold, which also stops the threshold from moving) hold nearly all of it in huge
/// pages.
inline constexpr const char* kMallocTunables[] = {
    "glibc.malloc.hugetlb=1", "glibc.malloc.top_pad=67108864",
    "glibc.malloc.trim_threshold=1073741824", "glibc.malloc.mmap_threshold=33554432"};

/// @brief Add kMallocTunables to GLIBC_TUNABLES (after any tunables already there) where they
/// help: Linux with transparent huge pages in "madvise" mode and glibc 2.35 or later, unless
/// IVDB_HUGEPAGES=0 or GLIBC_TUNABLES already names glibc.malloc.hugetlb (the user decides
/// then); a tunable GLIBC_TUNABLES already names keeps its value. Returns true if it changed the
/// environment (a program started from now on, or this one restarted, reads it).
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
    std::string value = tunables;
    for (const char* tunable : kMallocTunables) {
        const std::string name(tunable, std::strchr(tunable, '=') + 1);
        // "name=" at the start or after a ':' (one tunable's name is not another's suffix).
        if (tunables.rfind(name, 0) == 0 || tunables.find(":" + name) != std::string::npos) {
            continue;
        }
        value += (value.empty() ? "" : ":") + std::string(tunable);
    }
    return setenv("GLIBC_TUNABLES", value.c_str(), 1) == 0;
}

} // namespace ivdb::tools
