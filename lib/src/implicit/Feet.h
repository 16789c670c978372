// SPDX-License-Identifier: Apache-2.0
#pragma once
// Helpers of the nodes' footPoints() overrides (internal to lib/src/implicit).

#include <ivdb/implicit/Implicit.h>

namespace ivdb::implicit::detail {

/// @brief The smooth iteration of Implicit::footPoints on @a f's own field, for the points whose
/// @a out.ok is false; the others keep what @a out holds.
void iterateUncertified(const Implicit& f, const double* x, const double* y, const double* z,
                        const double* values, std::size_t n, const FootQuery& query,
                        FootPoints& out);

} // namespace ivdb::implicit::detail
