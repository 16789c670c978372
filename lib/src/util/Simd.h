// SPDX-License-Identifier: Apache-2.0
#pragma once

/// @file Simd.h
/// @brief IVDB_VECTOR_CLONES, put before a function whose loops vectorize: the function is
/// compiled three times, for x86-64's baseline (SSE2, two doubles a vector), AVX2 (four) and
/// AVX-512 (eight), and the loader picks the best one the CPU runs (GNU ifunc). The library is
/// built without fused multiply-adds (-ffp-contract=off, lib/CMakeLists.txt), so every version
/// rounds every add, multiply, divide and square root as IEEE 754 says, and a grid's bytes do
/// not depend on the machine that made it. Off under the sanitizers (their run-time starts
/// after the loader has resolved such functions) and off x86-64 Linux.

#if defined(__x86_64__) && defined(__linux__) && (defined(__GNUC__) || defined(__clang__)) && \
    !defined(IVDB_SANITIZED)
#define IVDB_VECTOR_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#define IVDB_HAS_VECTOR_CLONES 1 // util::machineInfo() names the version the loader picks
#else
#define IVDB_VECTOR_CLONES
#endif

/// IVDB_CLONE_INLINE, put before a helper that a function with IVDB_VECTOR_CLONES calls: the
/// helper is always inlined, so each clone compiles it for its own target. A helper the compiler
/// keeps out of line is built once, for the baseline, and the AVX2 clone only calls it.
#if defined(__GNUC__) || defined(__clang__)
#define IVDB_CLONE_INLINE __attribute__((always_inline)) inline
#else
#define IVDB_CLONE_INLINE inline
#endif
