// SPDX-License-Identifier: Apache-2.0
// Interval arithmetic is header-only; this unit keeps the header compiled on its own.
#include <ivdb/implicit/Interval.h>
