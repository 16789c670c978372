// SPDX-License-Identifier: Apache-2.0
#pragma once

#include <optional>
#include <string>
#include <vector>

namespace ivdb::implicit {

/// @brief The boolean operations, shared by scene trees (implicit::Csg, implicit::Blend) and
/// grid operations (ops::csg, ops::blend). Difference subtracts every following operand from
/// the first.
enum class CsgOp { Union, Intersection, Difference };

/// @brief "union", "intersection" or "difference".
const char* toString(CsgOp op);

/// @brief The operation named @a word, or nothing for any other word.
std::optional<CsgOp> csgOpFromString(const std::string& word);

/// @brief The three names, in the order of the enum.
const std::vector<std::string>& csgOpNames();

} // namespace ivdb::implicit
