#!/usr/bin/env bash
# Configure (once) and build ivdb in Release into build/, with ccache, on two jobs.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -f build/CMakeCache.txt ]; then
  cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
fi
cmake --build build -j2 >/dev/null
