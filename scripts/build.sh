#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Configure (once) and build ivdb in Release into build/, with ccache, on two jobs.
set -euo pipefail
cd "$(dirname "$0")/.."
# Configure every time (quick when nothing changed) so tests and benchmarks are always on.
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DIVDB_BUILD_TESTS=ON -DIVDB_BUILD_BENCHMARKS=ON >/dev/null
cmake --build build -j2 >/dev/null
