// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <openvdb/util/NullInterrupter.h>

namespace ivdb::util {

using Interrupter = openvdb::util::NullInterrupter;

/// @brief Throw openvdb::RuntimeError("interrupted"), the library's one way of ending a
/// cancelled operation.
[[noreturn]] void throwInterrupted();

/// @brief True if @a interrupter (may be null) asks to stop; reports @a percent (-1: none).
inline bool wasInterrupted(Interrupter* interrupter, int percent = -1)
{
    return interrupter && interrupter->wasInterrupted(percent);
}

/// @brief throwInterrupted() if @a interrupter (may be null) asks to stop.
inline void checkInterrupt(Interrupter* interrupter, int percent = -1)
{
    if (wasInterrupted(interrupter, percent)) throwInterrupted();
}

/// @brief Calls @a interrupter's start() now and end() when it goes out of scope, the pairing
/// OpenVDB's tools expect around a long operation. A null interrupter is allowed.
class InterruptScope
{
public:
    InterruptScope(Interrupter* interrupter, const char* name): mInterrupter(interrupter)
    {
        if (mInterrupter) mInterrupter->start(name);
    }
    ~InterruptScope() { end(); }
    InterruptScope(const InterruptScope&) = delete;
    InterruptScope& operator=(const InterruptScope&) = delete;

    /// @brief end() now (once) instead of at the end of the scope.
    void end()
    {
        if (mInterrupter) mInterrupter->end();
        mInterrupter = nullptr;
    }

private:
    Interrupter* mInterrupter;
};

} // namespace ivdb::util
