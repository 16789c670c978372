// SPDX-License-Identifier: Apache-2.0
#pragma once

/// @file BloscLz4.h
/// @brief The Blosc block a .vdb file stores for a leaf's values, made without Blosc's per-call
/// costs (internal to the writer; tests reach it by path).

#include <cstddef>

namespace ivdb::io::detail {

/// @brief What blosc_compress_ctx(9, BLOSC_SHUFFLE, 4, @a bytes, @a src, @a dest, @a bytes + 16,
/// "lz4", @a bytes, 1) writes (the call io::bloscToStream makes), byte for byte; returns the
/// bytes written to @a dest (which holds @a bytes + 16), or what that call returns.
/// @details c-blosc 1 and LZ4 1.9 make this block as follows: the 16-byte header, the block's
/// start, then the 4-byte words' bytes shuffled into four planes (first bytes, second bytes,
/// ...) and each plane compressed on its own by LZ4 at acceleration 1 (a plane that does not
/// shrink is stored raw), each after its 4-byte size. Blocks under 512 bytes are one plane.
/// LZ4 clears its 16 kB hash table before every plane: for a 512-byte plane that clearing
/// costs more than the compression. Here each thread keeps a table whose entries carry the
/// number of the plane that wrote them, so that every plane reads the all-zero table LZ4 starts
/// from, and the output is the same. Anything else (under 128 bytes, a size that is not a
/// multiple of 4, over 8 kB, data that does not compress) goes to Blosc itself.
int bloscLz4Compress(const void* src, std::size_t bytes, char* dest);

/// @brief LZ4_compress_fast(@a src, @a dst, @a size, @a capacity, 1)'s result and output for
/// 0 < @a size <= 2048 and @a capacity < LZ4_compressBound(@a size) (LZ4 1.9's limited-output
/// block compressor with its 16-bit hash table); 0 when the block does not fit, -1 for a size
/// out of that range.
int lz4CompressLimited(const unsigned char* src, int size, unsigned char* dst, int capacity);

} // namespace ivdb::io::detail
