// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <string>
#include <vector>

namespace ivdb::util {

/// @brief What a child process printed and how it ended.
struct ProcessResult
{
    int status = 0; ///< the exit status, or -N when signal N ended it
    std::string out, err;
};

/// @brief Run @a args (args[0] is the executable's path) in a child process, capturing its
/// standard output and error, and wait for it.
/// @throw openvdb::RuntimeError if the process cannot be started
ProcessResult runProcess(const std::vector<std::string>& args);

/// @brief The path of this process's executable (/proc/self/exe).
/// @throw openvdb::RuntimeError if it cannot be found
std::string executablePath();

} // namespace ivdb::util
