// SPDX-License-Identifier: Apache-2.0
#pragma once
// What a node combining its children by min, max or a blend's convex weights inherits from them
// (internal to lib/src/implicit: Csg and Blend).

#include <ivdb/implicit/Implicit.h>

#include <algorithm>
#include <vector>

namespace ivdb::implicit::detail {

/// Whether every one of @a children never exceeds its distance: then neither does their min,
/// max or blend (Implicit::isDistanceBound).
inline bool allDistanceBound(const std::vector<Implicit::Ptr>& children)
{
    return std::all_of(children.begin(), children.end(),
                       [](const Implicit::Ptr& c) { return c->isDistanceBound(); });
}

/// The largest of @a children's Lipschitz bounds, at least 1: min, max and a blend (whose
/// gradient is a convex combination of the children's) change no faster than their fastest
/// child (Implicit::lipschitzBound).
inline double largestLipschitzBound(const std::vector<Implicit::Ptr>& children)
{
    double most = 1.0;
    for (const auto& c : children) most = std::max(most, c->lipschitzBound());
    return most;
}

} // namespace ivdb::implicit::detail
