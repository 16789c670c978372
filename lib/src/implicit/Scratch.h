// SPDX-License-Identifier: Apache-2.0
#pragma once
// A small per-call buffer (internal to lib/src/implicit).

#include <cstddef>
#include <memory>
#include <utility>
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

/// Rows of a batch (children by points), left uninitialized: every entry is written before it
/// is read (zeroing them cost as much as a child's values). The buffer comes from a per-thread
/// pool and goes back to it at the end of the scope, so a batch allocates nothing once the pool
/// holds as many buffers as calls nest; buffers above kKeep doubles are freed instead.
class BatchRows
{
public:
    explicit BatchRows(std::size_t count)
    {
        auto& free = pool();
        if (!free.empty()) {
            mBuf = std::move(free.back());
            free.pop_back();
        }
        if (mBuf.second < count) mBuf = {std::unique_ptr<double[]>(new double[count]), count};
    }
    ~BatchRows()
    {
        if (mBuf.second <= kKeep) pool().push_back(std::move(mBuf));
    }
    BatchRows(const BatchRows&) = delete;
    BatchRows& operator=(const BatchRows&) = delete;

    double* get() const { return mBuf.first.get(); }

private:
    using Buffer = std::pair<std::unique_ptr<double[]>, std::size_t>;
    static constexpr std::size_t kKeep = std::size_t(1) << 16; // 512 KB
    static std::vector<Buffer>& pool()
    {
        thread_local std::vector<Buffer> buffers;
        return buffers;
    }
    Buffer mBuf;
};

} // namespace ivdb::implicit::detail
