#!/usr/bin/env python3
"""Core performance figures for the README (issue 2): run after scripts/build.sh.

Measures, in one run and interleaved so machine noise hits both sides alike:
  * compute: ivdb's sparse rasterizer vs openvdb::tools::createLevelSetSphere (Google Benchmark,
    build/bin/ivdb_bench, median of repetitions);
  * end to end: `ivdb rasterize` vs `vdb_tool -sphere ... -write` (start, compute, write);
  * sparse vs dense: wall time and peak memory of `ivdb rasterize` at several resolutions.
Prints a Markdown table. Usage: scripts/bench_core.py [--reps N] [--quick]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
IVDB = os.path.join(ROOT, "build", "bin", "ivdb")
BENCH = os.path.join(ROOT, "build", "bin", "ivdb_bench")


def run(cmd):
    """Wall time (s) and peak RSS (MB) of one command."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode()
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{err}")
    return wall, usage.ru_maxrss / 1024.0


def median_runs(cmds, reps):
    """Interleave the commands reps times; median wall time and peak memory of each."""
    times = {k: [] for k in cmds}
    mems = {k: [] for k in cmds}
    for _ in range(reps):
        for k, cmd in cmds.items():
            w, m = run(cmd)
            times[k].append(w)
            mems[k].append(m)
    return ({k: statistics.median(v) for k, v in times.items()},
            {k: statistics.median(v) for k, v in mems.items()})


def sphere_scene(folder, radius_voxels):
    path = os.path.join(folder, f"sphere_{radius_voxels}.json")
    with open(path, "w") as f:
        json.dump({"voxel_size": 1.0 / radius_voxels, "half_width": 3,
                   "shape": {"type": "sphere", "center": [0, 0, 0], "radius": 1}}, f)
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="smaller sizes, fewer repetitions")
    args = ap.parse_args()
    reps = 3 if args.quick else args.reps
    big = 200 if args.quick else 400

    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "out.vdb")
        print(f"# ivdb core benchmark ({os.cpu_count()} cores), medians of {reps} runs\n")

        # Compute only, Google Benchmark, same binary.
        res = subprocess.run([BENCH, f"--benchmark_filter=(Rasterize_Sparse|CreateLevelSetSphere)/{big}/",
                              f"--benchmark_repetitions={reps}", "--benchmark_format=json"],
                             check=True, capture_output=True, text=True)
        med = {b["run_name"].split("/")[0]: b["real_time"]
               for b in json.loads(res.stdout)["benchmarks"] if b.get("aggregate_name") == "median"}
        ours, ref = med["BM_Rasterize_Sparse"], med["BM_OpenVDB_CreateLevelSetSphere"]
        print("| compute, sphere radius %d voxels | ivdb sparse | createLevelSetSphere | ratio |" % big)
        print("|---|---|---|---|")
        print(f"| wall time | {ours:.0f} ms | {ref:.0f} ms | **{ref / ours:.2f}x faster** |\n")

        # End to end with write.
        scene = sphere_scene(tmp, big)
        t, m = median_runs({
            "ivdb": [IVDB, "rasterize", scene, "-o", out, "-q"],
            "vdb_tool": ["vdb_tool", "-sphere", f"voxel={1.0 / big}", "radius=1", "-write",
                         os.path.join(tmp, "tool.vdb")],
        }, reps)
        print("| end to end, sphere radius %d voxels | ivdb rasterize | vdb_tool -sphere -write | ratio |" % big)
        print("|---|---|---|---|")
        print(f"| wall time | {t['ivdb']:.2f} s | {t['vdb_tool']:.2f} s | **{t['vdb_tool'] / t['ivdb']:.2f}x faster** |")
        print(f"| peak memory | {m['ivdb']:.0f} MB | {m['vdb_tool']:.0f} MB | {m['vdb_tool'] / m['ivdb']:.2f}x |\n")

        # Sparse vs dense, end to end.
        sizes = [50, 100, 200] if args.quick else [50, 100, 200, 400]
        print("| radius (voxels) | sparse time | dense time | time ratio | sparse memory | dense memory | memory ratio |")
        print("|---|---|---|---|---|---|---|")
        prev = None
        for r in sizes:
            scene = sphere_scene(tmp, r)
            t, m = median_runs({
                "sparse": [IVDB, "rasterize", scene, "-o", out, "-q"],
                "dense": [IVDB, "rasterize", scene, "-o", out, "-q", "--sampling", "dense"],
            }, reps if r < 400 else max(1, min(reps, 3)))
            print(f"| {r} | {t['sparse']:.3f} s | {t['dense']:.3f} s | **{t['dense'] / t['sparse']:.1f}x** "
                  f"| {m['sparse']:.0f} MB | {m['dense']:.0f} MB | **{m['dense'] / m['sparse']:.1f}x** |")
        print()

        # Scaling of the sparse compute with resolution (Google Benchmark).
        res = subprocess.run([BENCH, "--benchmark_filter=Rasterize_Sparse/", f"--benchmark_repetitions={reps}",
                              "--benchmark_format=json"], check=True, capture_output=True, text=True)
        rows = [(int(b["run_name"].split("/")[1]), b["real_time"])
                for b in json.loads(res.stdout)["benchmarks"] if b.get("aggregate_name") == "median"]
        print("| radius (voxels) | sparse compute | x per doubling |")
        print("|---|---|---|")
        prev = None
        for r, ms in sorted(rows):
            ratio = f"{ms / prev:.2f}" if prev else "-"
            print(f"| {r} | {ms:.1f} ms | {ratio} |")
            prev = ms


if __name__ == "__main__":
    main()
