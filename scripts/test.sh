#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# README command 2: install what is missing, build, and run the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh
deps=$SECONDS
scripts/build.sh
built=$SECONDS
cd build
ctest --output-on-failure --no-tests=error -j2
echo "test.sh: packages ${deps} s, build $((built - deps)) s, tests $((SECONDS - built)) s" >&2
