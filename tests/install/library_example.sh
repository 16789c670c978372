#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# docs/library.md keeps its word: its first ```cmake block (a CMakeLists.txt) and first ```cpp
# block (a program taking SCENE.json OUT.vdb) build against a prefix install of this build, and
# the program writes the same level set as `ivdb rasterize` (compared value by value with
# pyopenvdb, an independent reader).
# Usage: library_example.sh SOURCE_DIR BUILD_DIR IVDB_BINARY
set -euo pipefail
src=$1 build=$2 ivdb=$3
work=$(mktemp -d "${TMPDIR:-/tmp}/ivdb-library-example.XXXXXX")
trap 'rm -rf "$work"' EXIT

cmake --install "$build" --prefix "$work/prefix" >/dev/null
mkdir -p "$work/example"
/usr/bin/python3 - "$src/docs/library.md" "$work/example" <<'PY'
import re, sys
text = open(sys.argv[1]).read()
def first(lang):
    m = re.search(r"^```" + lang + r"\n(.*?)^```", text, re.S | re.M)
    if not m:
        sys.exit("docs/library.md has no ```" + lang + " block")
    return m.group(1)
open(sys.argv[2] + "/CMakeLists.txt", "w").write(first("cmake"))
open(sys.argv[2] + "/main.cpp", "w").write(first("cpp"))
PY
launcher=()
if command -v ccache >/dev/null; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
# Nothing from the source or build tree on the paths: only the installed package.
cmake -S "$work/example" -B "$work/example/build" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$work/prefix" "${launcher[@]}" >"$work/configure.log" 2>&1 ||
  { cat "$work/configure.log"; exit 1; }
cmake --build "$work/example/build" -j2 >"$work/build.log" 2>&1 || { cat "$work/build.log"; exit 1; }
exe=$(find "$work/example/build" -maxdepth 1 -type f -executable -name 'rasterize_scene')
[ -n "$exe" ] || { echo "the example's CMakeLists.txt made no rasterize_scene program"; exit 1; }

scene=$src/data/sphere.json
"$exe" "$scene" "$work/example.vdb"
# A usage error and a bad scene: non-zero, nothing written.
if "$exe" "$scene" 2>/dev/null; then echo "no usage error without OUT.vdb"; exit 1; fi
echo '{"voxel_size": 0.01, "shape": {"type": "sphere", "radius": -1}}' >"$work/bad.json"
if "$exe" "$work/bad.json" "$work/bad.vdb" 2>"$work/bad.err"; then echo "a bad scene passed"; exit 1; fi
grep -q "shape.radius" "$work/bad.err" || { echo "the error does not name the field:"; cat "$work/bad.err"; exit 1; }
[ ! -e "$work/bad.vdb" ] || { echo "a bad scene left a file"; exit 1; }

# The installed command (its launcher, bin/ivdb, runs libexec/ivdb/ivdb), then the build's.
"$work/prefix/bin/ivdb" rasterize "$scene" -o "$work/cli.vdb" -q
"$ivdb" rasterize "$scene" -o "$work/cli_build.vdb" -q
cmp -s <(tail -c +58 "$work/cli.vdb") <(tail -c +58 "$work/cli_build.vdb") ||
  { echo "the installed ivdb and the build's wrote different files"; exit 1; }
/usr/bin/python3 - "$work/example.vdb" "$work/cli.vdb" <<'PY'
import sys
import pyopenvdb as vdb
a, b = (vdb.read(p, "surface") for p in sys.argv[1:3])
assert a.activeVoxelCount() > 0, "empty level set"
assert a.activeVoxelCount() == b.activeVoxelCount(), (a.activeVoxelCount(), b.activeVoxelCount())
acc = b.getConstAccessor()
for item in a.citerOnValues():
    value, on = acc.probeValue(item.min)
    assert on and value == item.value, (item.min, item.value, value)
print("library example: %d active voxels, equal to ivdb rasterize's" % a.activeVoxelCount())
PY
