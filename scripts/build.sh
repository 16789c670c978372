#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Configure (once) and build ivdb in Release into build/, with ccache, on two jobs.
set -euo pipefail
cd "$(dirname "$0")/.."
# Configure every time (quick when nothing changed) so tests and benchmarks are always on.
# clang (scripts/deps.sh installs it; the sanitizer builds need it too) compiles this code base in
# about half of gcc's time, for code as fast (docs/reliability.md#ci-time); CXX picks another.
compiler=$(command -v "${CXX:-clang++}" || command -v c++) # a full path, as CMake records it
if [ -f build/CMakeCache.txt ] && ! grep -q "^CMAKE_CXX_COMPILER:[A-Z]*=$compiler\$" build/CMakeCache.txt; then
  rm -rf build/CMakeCache.txt build/CMakeFiles # configured with another compiler
fi
cmake -S . -B build -DCMAKE_CXX_COMPILER="$compiler" -DCMAKE_BUILD_TYPE=Release \
  -DIVDB_BUILD_TESTS=ON -DIVDB_BUILD_BENCHMARKS=ON >/dev/null
cmake --build build -j2 >/dev/null
