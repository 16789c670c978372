// SPDX-License-Identifier: Apache-2.0
// The writer's Blosc blocks (lib/src/io/BloscLz4.h, internal) against c-blosc and LZ4 themselves,
// byte for byte: the .vdb files are identical to io::File's only if every block is.
#include "../../lib/src/io/BloscLz4.h"

#include <ivdb/diff/Differential.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <blosc.h>
#include <lz4.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

using namespace ivdb::io::detail;

namespace {

using Bytes = std::vector<unsigned char>;

/// Data with what LZ4's parser meets: random stretches (literals, sometimes past 15 and 270
/// bytes), copies of earlier bytes at random offsets (matches, sometimes past 19 and 274
/// bytes, overlapping their source), runs of one byte, and repeated 4-byte words.
Bytes mixed(std::mt19937& rng, std::size_t size)
{
    Bytes out;
    out.reserve(size);
    std::uniform_int_distribution<int> kind(0, 3), byte(0, 255);
    auto length = [&](int longest) {
        return std::size_t(std::uniform_int_distribution<int>(1, longest)(rng));
    };
    while (out.size() < size) {
        const int k = kind(rng);
        const std::size_t n = std::min(size - out.size(), length(k == 1 ? 600 : 40));
        if (k == 0 || out.size() < 8) {
            for (std::size_t i = 0; i < n; ++i) out.push_back(static_cast<unsigned char>(byte(rng)));
        } else if (k == 1) {
            const std::size_t back = length(int(std::min<std::size_t>(out.size(), 4000)));
            const std::size_t from = out.size() - back;
            for (std::size_t i = 0; i < n; ++i) out.push_back(out[from + i]);
        } else if (k == 2) {
            out.insert(out.end(), n, static_cast<unsigned char>(byte(rng)));
        } else {
            const unsigned char w[4] = {static_cast<unsigned char>(byte(rng)), 0, 0,
                                        static_cast<unsigned char>(byte(rng))};
            for (std::size_t i = 0; i < n; ++i) out.push_back(w[i % 4]);
        }
    }
    return out;
}

/// Both compressors' result and bytes for @a in into @a capacity bytes.
void expectSameLz4(const Bytes& in, int capacity, const std::string& what)
{
    const int size = int(in.size());
    std::vector<char> theirs(std::size_t(capacity) + 64, 0), ours(theirs.size(), 0);
    const int a = LZ4_compress_fast(reinterpret_cast<const char*>(in.data()), theirs.data(), size,
                                    capacity, 1);
    const int b = lz4CompressLimited(in.data(), size, reinterpret_cast<unsigned char*>(ours.data()),
                                     capacity);
    ASSERT_EQ(a, b) << what << ", size " << size << ", capacity " << capacity;
    ASSERT_EQ(0, std::memcmp(theirs.data(), ours.data(), std::size_t(std::max(a, 0))))
        << what << ", size " << size << ", capacity " << capacity;
}

/// What io::bloscToStream writes for @a bytes bytes at @a data, and what the writer writes.
void expectSameBlosc(const void* data, std::size_t bytes, const std::string& what)
{
    std::vector<char> theirs(bytes + BLOSC_MAX_OVERHEAD, 0), ours(theirs.size(), 0);
    const int a = blosc_compress_ctx(9, BLOSC_SHUFFLE, 4, bytes, data, theirs.data(),
                                     theirs.size(), BLOSC_LZ4_COMPNAME, bytes, 1);
    const int b = bloscLz4Compress(data, bytes, ours.data());
    ASSERT_EQ(a, b) << what << ", " << bytes << " bytes";
    ASSERT_EQ(0, std::memcmp(theirs.data(), ours.data(), std::size_t(std::max(a, 0))))
        << what << ", " << bytes << " bytes";
}

/// Each leaf's values as the writer hands them to Blosc: the active ones, in order.
template<typename GridT>
std::vector<std::vector<typename GridT::ValueType>> activeValues(const GridT& grid)
{
    std::vector<std::vector<typename GridT::ValueType>> out;
    for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
        out.emplace_back();
        for (auto it = leaf->cbeginValueOn(); it; ++it) out.back().push_back(*it);
    }
    return out;
}

} // namespace

TEST(TestBloscLz4, Lz4BlocksEqualLz4sOwnForEverySizeAndRoom)
{
    std::mt19937 rng(20261203);
    int refused = 0;
    for (int round = 0; round < 4000; ++round) {
        const std::size_t size = round < 700 ? std::size_t(round + 1)
            : std::size_t(std::uniform_int_distribution<int>(1, 2048)(rng));
        const Bytes in = mixed(rng, size);
        // Room from far too little to just under LZ4's bound (the limited-output path).
        const int bound = LZ4_compressBound(int(size));
        for (const int capacity : {bound - 1, int(size), int(size) - 1, int(size) * 3 / 4,
                                   int(size) / 2, int(size) / 4, 1}) {
            if (capacity < 1 || capacity >= bound) continue;
            expectSameLz4(in, capacity, "mixed data");
            if (round % 50 == 0) {
                std::vector<char> probe(static_cast<std::size_t>(capacity));
                refused += LZ4_compress_fast(reinterpret_cast<const char*>(in.data()), probe.data(),
                                             int(size), capacity, 1) == 0;
            }
        }
    }
    EXPECT_GT(refused, 0); // the output checks were reached
    // All zeros, all one byte, incompressible.
    for (const std::size_t size : {13, 64, 512, 1536, 2048}) {
        expectSameLz4(Bytes(size, 0), int(size), "zeros");
        expectSameLz4(Bytes(size, 7), int(size), "sevens");
        Bytes noise(size);
        for (auto& b : noise) b = static_cast<unsigned char>(rng());
        expectSameLz4(noise, int(size), "noise");
    }
}

TEST(TestBloscLz4, BlocksEqualBloscsForLevelSetsVectorsAndEdgeSizes)
{
    auto sphere = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(40.0f,
        openvdb::Vec3f(0.3f, -0.2f, 0.1f), 1.0f, 3.0f);
    std::size_t blocks = 0;
    for (const auto& values : activeValues(*sphere)) {
        expectSameBlosc(values.data(), values.size() * sizeof(float), "level set leaf");
        ++blocks;
    }
    const auto gradient = ivdb::diff::gradient(*sphere, 1);
    for (const auto& values : activeValues(*gradient)) {
        expectSameBlosc(values.data(), values.size() * sizeof(openvdb::Vec3f), "gradient leaf");
        ++blocks;
    }
    EXPECT_GT(blocks, 1000u);

    // Every size around Blosc's thresholds (128 bytes: copied below; 512: one plane below),
    // sizes that are not whole words, the 8 kB the fast path takes and beyond.
    std::mt19937 rng(7);
    std::vector<float> ramp(20000);
    for (std::size_t i = 0; i < ramp.size(); ++i) ramp[i] = 0.001f * float(i % 700);
    for (std::size_t bytes = 0; bytes <= 1100; ++bytes) {
        expectSameBlosc(ramp.data(), bytes, "ramp");
        const Bytes m = mixed(rng, bytes);
        expectSameBlosc(m.data(), bytes, "mixed");
    }
    for (const std::size_t bytes : {6144, 8188, 8192, 8196, 65536}) {
        expectSameBlosc(ramp.data(), bytes, "ramp");
        const Bytes m = mixed(rng, bytes);
        expectSameBlosc(m.data(), bytes, "mixed");
    }
    // Incompressible planes (stored raw) and an incompressible block (Blosc's plain copy).
    std::vector<float> noise(512);
    for (auto& v : noise) v = std::uniform_real_distribution<float>(-3.0f, 3.0f)(rng);
    for (const std::size_t count : {32, 100, 128, 400, 512}) {
        expectSameBlosc(noise.data(), count * sizeof(float), "noise");
        std::vector<float> half(noise.begin(), noise.begin() + std::ptrdiff_t(count));
        for (std::size_t i = 0; i < count; i += 2) half[i] = 1.0f;
        expectSameBlosc(half.data(), count * sizeof(float), "half noise");
    }
}
