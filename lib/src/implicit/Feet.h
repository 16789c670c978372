// SPDX-License-Identifier: Apache-2.0
#pragma once
// Helpers of the nodes' footPoints() overrides (internal to lib/src/implicit).

#include <ivdb/implicit/Implicit.h>

namespace ivdb::implicit::detail {

/// @brief The smooth iteration of Implicit::footPoints on @a f's own field, for the points whose
/// @a out.ok is false; the others keep what @a out holds. @a gx, @a gy, @a gz: f's gradients at
/// the n points if the caller has them (else they are evaluated for the points iterated).
void iterateUncertified(const Implicit& f, const double* x, const double* y, const double* z,
                        const double* values, std::size_t n, const FootQuery& query,
                        FootPoints& out, const double* gx = nullptr, const double* gy = nullptr,
                        const double* gz = nullptr);

/// @brief The smooth iteration of Implicit::footPoints at every point, from @a f's values and
/// gradients there.
void smoothFootPoints(const Implicit& f, const double* x, const double* y, const double* z,
                      const double* values, const double* gx, const double* gy,
                      const double* gz, std::size_t n, const FootQuery& query, FootPoints& out);

/// @brief True if @a f is the exact SDF of a convex solid (a sphere, box, rounded box, capped
/// cylinder or cone, moved rigidly or scaled uniformly): its value is a convex function.
bool convexSdf(const Implicit& f);

} // namespace ivdb::implicit::detail
