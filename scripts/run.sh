#!/usr/bin/env bash
# README command 1: install what is missing, build in Release, and run the main job:
# rasterize every scene in data/ into out/NAME.vdb, one summary line per scene.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh
scripts/build.sh
mkdir -p out
for scene in data/*.json; do
  build/bin/ivdb rasterize "$scene" -o "out/$(basename "$scene" .json).vdb"
done
