#pragma once

#include <cstdint>
#include <string>

namespace ivdb::util {

/// @brief Memory the system can give this process now (MemAvailable), in bytes; 0 if unknown.
std::uint64_t availableMemory();

/// @brief Peak resident memory of this process so far (VmHWM), in bytes.
std::uint64_t peakResidentMemory();

/// @brief "12.3 MB"-style text for a byte count (powers of 1000 for MB/GB, as file sizes).
std::string formatBytes(double bytes);

} // namespace ivdb::util
