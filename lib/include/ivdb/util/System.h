// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <cstdint>
#include <exception>
#include <string>

namespace ivdb::util {

/// @brief Memory the system can give this process now (MemAvailable), in bytes; 0 if unknown.
std::uint64_t availableMemory();

/// @brief Peak resident memory of this process so far (VmHWM), in bytes.
std::uint64_t peakResidentMemory();

/// @brief Resident memory of this process now (VmRSS), in bytes.
std::uint64_t residentMemory();

/// @brief The share of the available memory a large allocation may take by default.
inline constexpr double kMemoryFraction = 0.8;

/// @brief Bytes an operation may allocate: @a limit if it is not 0, else kMemoryFraction of
/// availableMemory() (or no limit when that is unknown). The one memory rule of the library.
double memoryBudget(std::uint64_t limit = 0);

/// @brief A path's extension in lower case, with its dot (".vdb"), or "" if it has none.
std::string extensionOf(const std::string& path);

/// @brief "12.3 MB"-style text for a byte count (powers of 1000 for MB/GB, as file sizes).
std::string formatBytes(double bytes);

/// @brief An exception's message without OpenVDB's leading type name ("IoError: ...").
std::string errorText(const std::exception& e);

/// @brief The machine that runs this process, as benchmarks should name it: speed ratios
/// between arithmetic-bound work (quadrics, blends) and memory-bound work (an exact sphere)
/// depend on the CPU's vector width (docs/performance.md#set-up).
struct MachineInfo
{
    std::string cpu;        ///< the CPU's model name (/proc/cpuinfo), or "unknown"
    unsigned cores = 0;     ///< hardware threads (0 if unknown)
    std::string vectorCode; ///< the version of the vectorized loops this CPU runs: "AVX-512",
                            ///< "AVX2" or "SSE2" on x86-64, "... (no run-time choice)" where
                            ///< the library has no per-CPU versions (sanitizers, other CPUs)
    /// "AMD EPYC 7B13, 2 cores, vector code AVX2".
    std::string describe() const;
};

/// @brief The running machine (MachineInfo).
MachineInfo machineInfo();

/// @brief A number as a person writes it: -1, 0.25, 1e-07 (shortest form that reads back).
std::string formatNumber(double v);

} // namespace ivdb::util
