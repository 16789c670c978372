// SPDX-License-Identifier: Apache-2.0
// Force-included into every file of a ThreadSanitizer build (see the top-level CMakeLists.txt).
//
// OpenVDB 10 declares its common template instantiations (tools, trees, node managers) extern and
// ships them compiled in libopenvdb, which is neither instrumented nor built with
// TBB_USE_PROFILING_TOOLS=2. A parallel_for started from there runs our instrumented bodies but
// waits without telling TSan, which then reports the caller's next access as a race with the
// workers'. Without the extern declarations, every template ivdb uses is compiled here, with both.
#pragma once
#include <openvdb/version.h>
#undef OPENVDB_USE_EXPLICIT_INSTANTIATION
