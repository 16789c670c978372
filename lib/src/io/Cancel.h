// SPDX-License-Identifier: Apache-2.0
// Reading and writing inside a cancelled TBB task group: refused, not done in part.
#pragma once

#include <openvdb/Exceptions.h>

#include <tbb/task.h>

#include <string>

namespace ivdb::io::detail {

/// @brief Throw openvdb::RuntimeError if the calling task's group is cancelled (a caller's
/// parallel algorithm failed elsewhere): there every parallel loop would skip its work silently,
/// leaving a short file or a half-read grid. Checked before the work (so nothing is allocated
/// that OpenVDB's own parallel destructors could not free) and after its parallel loops.
inline void throwIfCancelled(const std::string& what)
{
    tbb::task_group_context* context = tbb::task::current_context();
    if (context && context->is_group_execution_cancelled()) {
        OPENVDB_THROW(openvdb::RuntimeError, what + " was cancelled (the task group running it "
                      "was cancelled); nothing was done");
    }
}

} // namespace ivdb::io::detail
