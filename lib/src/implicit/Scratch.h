// SPDX-License-Identifier: Apache-2.0
#pragma once
// A small per-call buffer (internal to lib/src/implicit).

#include <cstddef>
#include <vector>

namespace ivdb::implicit::detail {

/// A buffer of @a n doubles on the stack for the usual few children, on the heap beyond.
class Scratch
{
public:
    explicit Scratch(std::size_t n): mData(mSmall)
    {
        if (n > kSmall) {
            mBig.resize(n);
            mData = mBig.data();
        }
    }
    double* data() { return mData; }

private:
    static constexpr std::size_t kSmall = 128;
    double mSmall[kSmall];
    std::vector<double> mBig;
    double* mData;
};

} // namespace ivdb::implicit::detail
