#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""How strong the tests are: break the code on purpose, one mutation at a time, rebuild the
Release build (build/, as scripts/build.sh makes it) and list the tests that catch each break.
Every file is restored afterwards and the build rebuilt. A mutation that nothing catches needs a
test (docs/reliability.md#how-strong-the-tests-are).

    python3 scripts/mutate.py            # all mutations (about 25 minutes on 2 cores)
    python3 scripts/mutate.py "colour"   # those whose name contains a word
"""
import os
import re
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# (name, file, code, broken code, test binaries, gtest filters for some of them)
M = [
 ('principal curvature order', 'lib/src/diff/Differential.cc',
  'auto k1 = principal(1.0), k2 = principal(-1.0);', 'auto k1 = principal(-1.0), k2 = principal(1.0);',
  ['test_diff', 'test_cli'], {'test_cli': 'TestCliDiff.*'}),
 ('CSG difference sign', 'lib/src/implicit/Csg.cc',
  'case Op::Difference: v = std::max(v, -c); break;', 'case Op::Difference: v = std::max(v, c); break;',
  ['test_implicit', 'test_raster'], {}),
 ("blend log-sum-exp", 'lib/src/implicit/Blend.cc',
  'return e + s * std::log(sum) / p;', 'return e + s * std::log(sum) / (2.0 * p);',
  ['test_implicit', 'test_ops'], {}),
 ('root child origin check (x)', 'lib/src/io/Layout.cc',
  "if ((origin[0] & alignment) || (origin[1] & alignment) || (origin[2] & alignment)) {\n            in.corrupt(where + \"has a root child",
  "if ((origin[1] & alignment) || (origin[2] & alignment)) {\n            in.corrupt(where + \"has a root child",
  ['test_io', 'fuzz_vdb_replay'], {}),
 ('atomic rename (write in place)', 'lib/src/io/AtomicFile.cc',
  'const std::string tmp = (fs::path(folderOf(path)) /',
  'const std::string tmp = path; [[maybe_unused]] const std::string unusedTmp = (fs::path(folderOf(path)) /',
  ['test_io', 'test_cli'], {'test_cli': 'TestCliRobust.*:TestCli.*'}),
 ('sparse pruning interval', 'lib/src/raster/Rasterize.cc',
  'if (iv.lo >= band + eps) return Verdict::Outside;', 'if (iv.lo >= 0.5 * band + eps) return Verdict::Outside;',
  ['test_raster'], {}),
 ('gradient step', 'lib/src/diff/Differential.cc',
  'return openvdb::Vec3s((b(i + step, j, k) - b(i - step, j, k)) * inv,',
  'return openvdb::Vec3s((b(i + 1, j, k) - b(i - 1, j, k)) * inv,',
  ['test_diff', 'test_cli'], {'test_cli': 'TestCliDiff.*'}),
 ('colour range', 'lib/src/render/Render.cc',
  'return {lo, mm.max() > mm.min() ? double(mm.max()) : lo + 1.0};',
  'return {lo, mm.max() > mm.min() ? 2.0 * double(mm.max()) : lo + 1.0};',
  ['test_render', 'test_cli'], {'test_cli': 'TestCliMesh.*'}),
]
only = sys.argv[1:]
missed = 0
for name, path, old, new, tests, filters in M:
    if only and not any(o in name for o in only): continue
    full = os.path.join(ROOT, path)
    src = open(full).read()
    if src.count(old) != 1:
        print(f'## {name}: pattern found {src.count(old)} times in {path}', flush=True); continue
    backup = full + '.mutbak'
    shutil.copy2(full, backup)
    try:
        open(full, 'w').write(src.replace(old, new))
        targets = [t for t in tests if not t.startswith('fuzz')] + ['ivdb_tool']
        b = subprocess.run(['cmake', '--build', 'build', '-j2', '--target'] + targets,
                           cwd=ROOT, capture_output=True, text=True)
        if b.returncode != 0:
            print(f'## {name}: build failed\n{b.stdout[-2000:]}{b.stderr[-2000:]}', flush=True); continue
        caught = []
        for t in tests:
            if t.startswith('fuzz'):
                r = subprocess.run(['ctest', '-R', t, '--output-on-failure'], cwd=ROOT + '/build', capture_output=True, text=True)
                if r.returncode != 0: caught.append(t)
                continue
            args = [f'{ROOT}/build/tests/{t}', '--gtest_brief=1']
            if t in filters: args.append('--gtest_filter=' + filters[t])
            r = subprocess.run(args, cwd=ROOT + '/build', capture_output=True, text=True)
            fails = sorted(set(re.findall(r'^\[  FAILED  \] (\S+?)(?: \(|,|$)', r.stdout, re.M)))
            caught += fails
            if r.returncode != 0 and not fails: caught.append(f'{t} (exit {r.returncode})')
        missed += not caught
        print(f'## {name} ({path}): caught by {len(caught)}: {", ".join(caught) if caught else "NOTHING"}', flush=True)
    finally:
        shutil.move(backup, full)
        os.utime(full, None)
# rebuild the restored sources
subprocess.run(['cmake', '--build', 'build', '-j2'], cwd=ROOT, capture_output=True)
print('## restored and rebuilt', flush=True)
sys.exit(1 if missed else 0)
