// SPDX-License-Identifier: Apache-2.0
#include "BloscLz4.h"

#include "../util/Simd.h"

#include <blosc.h>

#include <algorithm>
#include <cstdint>
#include <cstring>

namespace ivdb::io::detail {

namespace {

using Byte = unsigned char;

// LZ4's block format and its fast compressor's parameters (LZ4 1.9, lib/lz4.c).
constexpr int kMinMatch = 4;      // shortest match
constexpr int kLastLiterals = 5;  // a block ends with at least this many literals
constexpr int kMatchFinderLimit = 12; // no match starts in the last 12 bytes
constexpr int kMinInput = kMatchFinderLimit + 1; // shorter inputs are all literals
constexpr int kSkipTrigger = 6;   // the search step grows by one every 2^6 misses
constexpr unsigned kRunMask = 15; // the token's 4-bit literal and match lengths
constexpr int kHashBits = 13;     // the 16-bit table of 2^13 entries (LZ4_MEMORY_USAGE 14)
constexpr int kMaxPlane = 2048;   // the largest plane compressed here (an 8 kB block)

std::uint32_t read32(const Byte* p)
{
    std::uint32_t v;
    std::memcpy(&v, p, sizeof(v));
    return v;
}

std::uint64_t read64(const Byte* p)
{
    std::uint64_t v;
    std::memcpy(&v, p, sizeof(v));
    return v;
}

void write32(char* p, std::uint32_t v) { std::memcpy(p, &v, sizeof(v)); }

std::uint32_t hashAt(const Byte* p) { return (read32(p) * 2654435761u) >> (32 - kHashBits); }

/// The compressor's table of the last position seen with each hash. LZ4 starts every input
/// from an all-zero table (every hash at position 0), and clearing its 16 kB cost more than
/// compressing a leaf's plane. Here an entry holds a position (11 bits) and its input's number
/// (5 bits): an entry of an earlier input reads as position 0, so every input sees a fresh
/// table, and the table is cleared once every 31 inputs.
struct HashTable
{
    static constexpr int kPositionBits = 11;
    static constexpr std::uint32_t kPositionMask = (1u << kPositionBits) - 1;
    static constexpr std::uint32_t kInputs = 1u << (16 - kPositionBits);

    std::uint16_t slot[1 << kHashBits] = {};
    std::uint32_t input = 0; // the current input's number, 1 to kInputs - 1

    void next()
    {
        if (++input == kInputs) {
            std::fill(std::begin(slot), std::end(slot), std::uint16_t(0));
            input = 1;
        }
    }
};

/// HashTable's use within one input.
class TableWriter
{
public:
    explicit TableWriter(HashTable& t)
        : mSlot(t.slot), mInput((t.next(), t.input << HashTable::kPositionBits)) {}

    std::uint32_t get(std::uint32_t h) const
    {
        const std::uint32_t e = mSlot[h];
        return (e & ~HashTable::kPositionMask) == mInput ? (e & HashTable::kPositionMask) : 0u;
    }
    void put(std::uint32_t h, std::uint32_t position) { mSlot[h] = std::uint16_t(mInput | position); }

private:
    std::uint16_t* __restrict mSlot;
    const std::uint32_t mInput;
};

/// Bytes equal from @a in and @a match on, up to @a limit.
unsigned commonBytes(const Byte* in, const Byte* match, const Byte* limit)
{
    const Byte* const start = in;
    while (in + 8 <= limit) {
        const std::uint64_t diff = read64(in) ^ read64(match);
        if (diff) return unsigned(in - start) + unsigned(__builtin_ctzll(diff) >> 3);
        in += 8;
        match += 8;
    }
    while (in < limit && *in == *match) ++in, ++match;
    return unsigned(in - start);
}

/// A length beyond what the token holds: bytes of 255, then the rest.
Byte* extendLength(Byte* op, std::size_t rest)
{
    for (; rest >= 255; rest -= 255) *op++ = 255;
    *op++ = Byte(rest);
    return op;
}

/// LZ4's greedy single-pass parse (acceleration 1): hash the 4 bytes at each position, take
/// the table's earlier position if its 4 bytes are equal, extend the match backwards over the
/// pending literals and forwards as far as it goes, and after each miss search more sparsely
/// (every 2^kSkipTrigger misses the step grows). Output checks are LZ4's own, conservative
/// ones, so that the inputs refused for want of room are the same.
int compressLimited(HashTable& hashTable, const Byte* src, int size, Byte* dst, int capacity)
{
    TableWriter table(hashTable);
    const Byte* ip = src;
    const Byte* anchor = src; // first literal not yet written
    const Byte* const end = src + size;
    // A match starts before searchEnd and ends by matchEnd (inputs too short for one never
    // use them).
    const Byte* const searchEnd = size >= kMinInput ? end - kMatchFinderLimit + 1 : src;
    const Byte* const matchEnd = size >= kMinInput ? end - kLastLiterals : src;
    Byte* op = dst;
    Byte* const outEnd = dst + capacity;

    if (size >= kMinInput) {
        table.put(hashAt(ip), 0);
        ++ip;
        std::uint32_t nextHash = hashAt(ip);
        for (;;) {
            const Byte* match;
            Byte* token;
            {
                const Byte* next = ip;
                int step = 1, misses = 1 << kSkipTrigger;
                for (;;) {
                    const std::uint32_t h = nextHash;
                    const std::uint32_t position = std::uint32_t(next - src);
                    ip = next;
                    next += step;
                    step = misses++ >> kSkipTrigger;
                    if (next > searchEnd) goto lastLiterals;
                    match = src + table.get(h);
                    nextHash = hashAt(next);
                    table.put(h, position);
                    if (read32(match) == read32(ip)) break;
                }
            }
            while (ip > anchor && match > src && ip[-1] == match[-1]) --ip, --match;
            {
                const unsigned literals = unsigned(ip - anchor);
                token = op++;
                if (op + literals + (2 + 1 + kLastLiterals) + literals / 255 > outEnd) return 0;
                if (literals >= kRunMask) {
                    *token = Byte(kRunMask << 4);
                    op = extendLength(op, literals - kRunMask);
                } else {
                    *token = Byte(literals << 4);
                }
                std::memcpy(op, anchor, literals);
                op += literals;
            }
            for (;;) { // a match at ip, its token written (literals included)
                const unsigned offset = unsigned(ip - match);
                *op++ = Byte(offset & 0xff);
                *op++ = Byte(offset >> 8);
                unsigned extra = commonBytes(ip + kMinMatch, match + kMinMatch, matchEnd);
                ip += extra + kMinMatch;
                if (op + (1 + kLastLiterals) + (extra + 240) / 255 > outEnd) return 0;
                if (extra >= kRunMask) {
                    *token = Byte(*token + kRunMask);
                    op = extendLength(op, extra - kRunMask);
                } else {
                    *token = Byte(*token + extra);
                }
                anchor = ip;
                if (ip >= searchEnd) goto lastLiterals;
                table.put(hashAt(ip - 2), std::uint32_t(ip - 2 - src));
                // A match right away continues with no literals.
                const std::uint32_t h = hashAt(ip);
                match = src + table.get(h);
                table.put(h, std::uint32_t(ip - src));
                if (read32(match) != read32(ip)) break;
                token = op++;
                *token = 0;
            }
            nextHash = hashAt(++ip);
        }
    }
lastLiterals:
    const std::size_t literals = std::size_t(end - anchor);
    if (op + literals + 1 + (literals + 255 - kRunMask) / 255 > outEnd) return 0;
    if (literals >= kRunMask) {
        *op++ = Byte(kRunMask << 4);
        op = extendLength(op, literals - kRunMask);
    } else {
        *op++ = Byte(literals << 4);
    }
    std::memcpy(op, anchor, literals);
    op += literals;
    return int(op - dst);
}

struct ThreadState
{
    HashTable table;
    Byte planes[4 * kMaxPlane];
};

ThreadState& threadState()
{
    thread_local ThreadState state;
    return state;
}

/// Blosc's byte shuffle of @a n 4-byte values: byte b of value i goes to b * n + i.
IVDB_VECTOR_CLONES
void shuffleBytes(const Byte* __restrict in, Byte* __restrict out, std::size_t n)
{
    Byte* __restrict p0 = out;
    Byte* __restrict p1 = out + n;
    Byte* __restrict p2 = out + 2 * n;
    Byte* __restrict p3 = out + 3 * n;
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint32_t v = read32(in + 4 * i);
        p0[i] = Byte(v);
        p1[i] = Byte(v >> 8);
        p2[i] = Byte(v >> 16);
        p3[i] = Byte(v >> 24);
    }
}

int viaBlosc(const void* src, std::size_t bytes, char* dest)
{
    return blosc_compress_ctx(9, BLOSC_SHUFFLE, 4, bytes, src, dest, bytes + BLOSC_MAX_OVERHEAD,
                              BLOSC_LZ4_COMPNAME, bytes, 1);
}

} // namespace

int lz4CompressLimited(const unsigned char* src, int size, unsigned char* dst, int capacity)
{
    if (size <= 0 || size > kMaxPlane) return -1;
    return compressLimited(threadState().table, src, size, dst, capacity);
}

int bloscLz4Compress(const void* src, std::size_t bytes, char* dest)
{
    // Blosc's constants (blosc.h, blosc.c): a 16-byte header; 128-byte buffers or smaller are
    // copied; a block splits into one plane per byte of the type when it holds >= 128 values.
    constexpr std::size_t kHeader = BLOSC_MAX_OVERHEAD, kMinBuffer = 128, kType = 4;
    if (bytes < kMinBuffer || bytes % kType != 0 || bytes > kType * kMaxPlane) {
        return viaBlosc(src, bytes, dest);
    }
    const bool split = bytes / kType >= kMinBuffer;
    const int planes = split ? int(kType) : 1;
    const int planeBytes = int(bytes) / planes;
    const int limit = int(bytes + kHeader);

    ThreadState& state = threadState();
    const std::size_t n = bytes / kType;
    shuffleBytes(static_cast<const Byte*>(src), state.planes, n);
    const Byte* const p0 = state.planes;

    dest[0] = 2; // Blosc's format version
    dest[1] = 1; // its LZ4 format version
    dest[2] = char(BLOSC_DOSHUFFLE | (split ? 0 : 0x10) | (BLOSC_LZ4_FORMAT << 5));
    dest[3] = char(kType);
    write32(dest + 4, std::uint32_t(bytes));
    write32(dest + 8, std::uint32_t(bytes)); // one block
    int at = int(kHeader) + 4;
    write32(dest + kHeader, std::uint32_t(at)); // the block's start
    for (int j = 0; j < planes; ++j) {
        at += 4;
        const int room = std::min(planeBytes, limit - at);
        if (room <= 0) return viaBlosc(src, bytes, dest);
        const Byte* plane = p0 + std::size_t(j) * std::size_t(planeBytes);
        int stored = compressLimited(state.table, plane, planeBytes,
                                     reinterpret_cast<Byte*>(dest + at), room);
        if (stored == 0 || stored == planeBytes) { // stored raw
            if (at + planeBytes > limit) return viaBlosc(src, bytes, dest);
            std::memcpy(dest + at, plane, std::size_t(planeBytes));
            stored = planeBytes;
        }
        write32(dest + at - 4, std::uint32_t(stored));
        at += stored;
    }
    write32(dest + 12, std::uint32_t(at));
    return at;
}

} // namespace ivdb::io::detail
