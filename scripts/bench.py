#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Performance figures for the README: run after scripts/build.sh.

Section "core" (rasterizing):

Measures, in one run and interleaved so machine noise hits both sides alike:
  * compute: ivdb's sparse rasterizer vs openvdb::tools::createLevelSetSphere (Google Benchmark,
    build/bin/ivdb_bench, median of repetitions; it restarts itself with the launcher's heap
    tunables, as the commands run, unless IVDB_HUGEPAGES=0 or GLIBC_TUNABLES names hugetlb);
  * end to end: `ivdb rasterize` vs `vdb_tool -sphere ... -write` (start, compute, write);
  * sparse vs dense: wall time and peak memory of `ivdb rasterize` at several resolutions.
Section "csg" (two overlapping radius-400 spheres; also rendering one of them vs vdb_render):
  * combine step: ops::csgInPlace vs openvdb::tools::csgUnion (Google Benchmark);
  * end to end: `ivdb csg union A B` vs `vdb_tool -read A B -union -write`;
  * blend vs sharp (radius 100, p chosen so the band extension is 2 voxels).
Section "diff" (gradient and mean curvature of the radius-400 sphere):
  * compute: diff::gradient / diff::curvature vs openvdb::tools::gradient / meanCurvature;
  * end to end: `ivdb gradient|curvature IN -o OUT` vs `vdb_tool -read IN -grad|-curvature -write OUT`.
Section "distances" (true distances of shapes that are not exact SDFs, docs/method.md):
  * compute and peak memory of `ivdb rasterize` (its own compute figure, median of interleaved
    runs) for a sphere, the same sphere as a quadric, an ellipsoid (as a quadric and as a scaled
    sphere), the union and the blend of two
    spheres and a union of 1000 spheres, each CSG scene in both distance modes, per active voxel
    against the exact sphere; OpenVDB's route (createLevelSetSphere per sphere + csgUnion) for the
    unions, measured by `ivdb bench-run` in the same run.
Section "io" (.vdb reading and writing, issue 15):
  * write and full read of the radius-400 sphere: ivdb's parallel writer and reader (1 and 2
    threads) vs io::File::write and io::File's full load (Google Benchmark, same run);
  * end to end against vdb_tool, as ratios of wall times (ivdb / vdb_tool; lower is better):
    rasterize, gradient, curvature and csg union at radius 400 and rasterize at radius 1600,
    ivdb with --threads 1 and 2, interleaved;
  * rasterize's compute at radius 1600 against 16x its compute at radius 400.
Section "mesh" (a mesh as a scene, issue 17):
  * `ivdb rasterize` of a scene holding only data/meshes/knot.obj (voxel size 0.002) vs the same
    in pyopenvdb (the OBJ read in Python, FloatGrid.createLevelSetFromPolygons, i.e. OpenVDB's
    meshToLevelSet, written to a .vdb): compute (each one's own figure) and wall time;
  * `ivdb rasterize data/knot_smooth.json` (the mesh smooth-unioned with implicit shapes):
    compute, and how the true distances were found.
Section "mpi" (ivdb-mpi, issue 16):
  * `ivdb rasterize` and `mpirun -np N ivdb-mpi rasterize` for N = 1..4 (--bind-to none, oversubscribed
    past the cores) of the radius-1600 sphere (400 with --quick): compute, write and total time
    and the largest peak memory of a rank against the one process, interleaved;
  * `ivdb gradient` and `mpirun -np N ivdb-mpi gradient` of that sphere's file, and `ivdb csg
    union` and `ivdb-mpi csg union` of it and a second sphere: read, compute, write and total
    time and the largest peak memory of a rank, interleaved;
  * `ivdb plan` of a sphere of about 10^10 active voxels on 64 and 512 ranks.
Section "mpi-blend": `ivdb blend union -p 1000` and `mpirun -np N ivdb-mpi blend union -p 1000` of
  the "csg" section's two radius-400 spheres: read, blend, write and total time and the largest
  peak memory of a rank, interleaved.
Section "hugepages" (ivdb's restart with transparent huge pages, docs/performance.md#huge-pages):
  `ivdb rasterize` of the radius-400 sphere and `ivdb gradient` of its file, by default, with
  GLIBC_TUNABLES=glibc.malloc.hugetlb=1 alone and with IVDB_HUGEPAGES=0, and
  `vdb_tool -sphere ... -write` with the same GLIBC_TUNABLES, interleaved: each one's own figures
  and peak memory.
Prints Markdown tables. Usage: scripts/bench.py [--section core|csg|diff|distances|hugepages|io|mesh|sequence|mpi|mpi-blend|all]
[--reps N] [--quick]
"""
import argparse
import json
import math
import os
import re
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
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=MPI_ENV)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode()
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{err}")
    return wall, usage.ru_maxrss / 1024.0


def median_runs(cmds, reps):
    """Interleave the commands reps times; median wall time and peak memory of each. Each run
    starts with the page cache's writes flushed (os.sync, not timed), so that no run pays for
    writing back what the one before left unsynced (vdb_tool does not sync its output; ivdb
    syncs its own)."""
    times = {k: [] for k in cmds}
    mems = {k: [] for k in cmds}
    for _ in range(reps):
        for k, cmd in cmds.items():
            os.sync()
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


def machine():
    """The CPU's model, its cores and the version of ivdb's vectorized loops it runs (the first of
    AVX-512, AVX2 and SSE2 its flags allow: util::machineInfo() in the library, which `ivdb bench`
    prints): the ratios between arithmetic-bound shapes and the memory-bound exact sphere move
    with it (docs/performance.md#set-up)."""
    model, flags = "unknown CPU", set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key.strip() == "model name" and model == "unknown CPU":
                    model = value.strip()
                elif key.strip() == "flags" and not flags:
                    flags = set(value.split())
    except OSError:
        pass
    code = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "SSE2"
    return f"{model}, {os.cpu_count()} cores, vector code {code}"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="smaller sizes, fewer repetitions")
    ap.add_argument("--section", choices=["core", "csg", "diff", "distances", "hugepages", "io", "mesh",
                                          "sequence", "mpi",
                                          "mpi-blend", "all"],
                    default="all")
    args = ap.parse_args()
    reps = 3 if args.quick else args.reps
    big = 200 if args.quick else 400

    with tempfile.TemporaryDirectory() as tmp:
        print(f"# ivdb benchmark ({machine()}), medians of {reps} runs\n")
        if args.section in ("csg", "all"):
            bench_csg(tmp, big, reps)
        if args.section in ("diff", "all"):
            bench_diff(tmp, big, reps)
        if args.section in ("core", "all"):
            bench_core(tmp, big, reps, args.quick)
        if args.section in ("distances", "all"):
            bench_distances(tmp, reps, args.quick)
        if args.section in ("hugepages", "all"):
            bench_hugepages(tmp, big, reps)
        if args.section in ("io", "all"):
            bench_io(tmp, big, reps, args.quick)
        if args.section in ("mesh", "all"):
            bench_mesh(tmp, reps)
        if args.section in ("sequence", "all"):
            bench_sequence(tmp, reps)
        if args.section in ("mpi", "all"):
            bench_mpi(tmp, 3 if args.quick else min(reps, 3), args.quick)
        if args.section in ("mpi-blend", "all"):
            bench_mpi_blend(tmp, big, 3 if args.quick else min(reps, 3))


MESH_TO_LEVEL_SET = """
import sys, time, numpy, pyopenvdb as vdb
points, triangles = [], []
t0 = time.perf_counter()
for line in open(sys.argv[1]):
    f = line.split()
    if f and f[0] == "v": points.append([float(x) for x in f[1:4]])
    elif f and f[0] == "f": triangles.append([int(x) - 1 for x in f[1:4]])
t1 = time.perf_counter()
g = vdb.FloatGrid.createLevelSetFromPolygons(numpy.array(points, dtype=numpy.float32),
    triangles=numpy.array(triangles, dtype=numpy.uint32),
    transform=vdb.createLinearTransform(float(sys.argv[2])), halfWidth=3.0)
t2 = time.perf_counter()
g.name = "surface"
vdb.write(sys.argv[3], grids=[g])
print("compute %.4f read %.4f voxels %d" % (t2 - t1, t1 - t0, g.activeVoxelCount()))
"""


def bench_mesh(tmp, reps):
    obj = os.path.join(ROOT, "data", "meshes", "knot.obj")
    scene = os.path.join(tmp, "knot.json")
    with open(scene, "w") as f:
        json.dump({"voxel_size": 0.002, "shape": {"type": "mesh", "file": obj}}, f)
    script = os.path.join(tmp, "m2l.py")
    with open(script, "w") as f:
        f.write(MESH_TO_LEVEL_SET)
    cmds = {"ivdb": [IVDB, "rasterize", scene, "-o", os.path.join(tmp, "k1.vdb")],
            "openvdb": ["/usr/bin/python3", script, obj, "0.002", os.path.join(tmp, "k2.vdb")]}
    compute = {"ivdb": [], "openvdb": []}
    walls = {"ivdb": [], "openvdb": []}
    for _ in range(reps):
        for k, cmd in cmds.items():
            t0 = time.perf_counter()
            out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
            walls[k].append(time.perf_counter() - t0)
            fields = out.replace(",", " ").split()
            compute[k].append(float(fields[fields.index("compute") + 1]))
    c = {k: statistics.median(v) for k, v in compute.items()}
    w = {k: statistics.median(v) for k, v in walls.items()}
    print("| data/meshes/knot.obj (7680 triangles), voxel 0.002 | ivdb rasterize | pyopenvdb meshToLevelSet | ratio |")
    print("|---|---|---|---|")
    print(f"| compute (ivdb: reading the mesh included) | {c['ivdb']:.2f} s | {c['openvdb']:.2f} s | "
          f"**{c['ivdb'] / c['openvdb']:.2f}x the time** |")
    print(f"| wall time (read, compute, write) | {w['ivdb']:.2f} s | {w['openvdb']:.2f} s | "
          f"**{w['ivdb'] / w['openvdb']:.2f}x the time** |\n")
    # The mesh in a smooth union (data/knot_smooth.json): compute, and how its distances were found.
    smooth = os.path.join(ROOT, "data", "knot_smooth.json")
    times, lines = [], ""
    for _ in range(reps):
        res = subprocess.run([IVDB, "rasterize", smooth, "-o", os.path.join(tmp, "ks.vdb")],
                             check=True, capture_output=True, text=True)
        fields = res.stdout.replace(",", " ").split()
        times.append(float(fields[fields.index("compute") + 1]))
        voxels = int(fields[1])
        lines = res.stdout.strip().splitlines()[-1].strip()
    print(f"data/knot_smooth.json: {voxels} active voxels, compute {statistics.median(times):.2f} s "
          f"(median of {reps}); {lines}\n")


def bench_sequence(tmp, reps):
    """Sequences: frames one at a time vs several at once, and a shell loop of vdb_tool."""
    grow = os.path.join(tmp, "grow.json")
    frames, r0, r1 = 24, 0.5, 0.8
    with open(grow, "w") as f:
        json.dump({"voxel_size": 0.004, "frames": {"start": 1, "end": frames},
                   "shape": {"type": "sphere", "radius": {"keys": [[1, r0], [frames, r1]]}}}, f)
    radii = [r0 + (r1 - r0) * (k - 1) / (frames - 1) for k in range(1, frames + 1)]
    loop = "; ".join(f"vdb_tool -sphere voxel=0.004 radius={r:.6f} -write {tmp}/t_{k}.vdb"
                     for k, r in enumerate(radii))
    metaballs = os.path.join(ROOT, "data", "anim_metaballs.json")
    out = os.path.join(tmp, "s_####.vdb")
    cmds = {
        "grow_1": [IVDB, "rasterize", grow, "-o", out, "--parallel-frames", "1", "-q"],
        "grow_auto": [IVDB, "rasterize", grow, "-o", out, "-q"],
        "grow_vdb_tool": ["sh", "-c", loop],
        "meta_1": [IVDB, "rasterize", metaballs, "--frames", "1-48:2", "-o", out,
                   "--parallel-frames", "1", "-q"],
        "meta_auto": [IVDB, "rasterize", metaballs, "--frames", "1-48:2", "-o", out, "-q"],
    }
    t, m = median_runs(cmds, reps)
    print(f"| 24 frames | one frame at a time | frames at once (default) | speed-up | peak memory |")
    print("|---|---|---|---|---|")
    print(f"| growing sphere, voxel 0.004 (1.2-3 M voxels a frame) | {t['grow_1']:.2f} s | "
          f"{t['grow_auto']:.2f} s | **{t['grow_1'] / t['grow_auto']:.2f}x** | "
          f"{m['grow_1']:.0f} / {m['grow_auto']:.0f} MB |")
    print(f"| data/anim_metaballs.json, frames 1-48:2 (blend, 0.5 M voxels a frame) | "
          f"{t['meta_1']:.2f} s | {t['meta_auto']:.2f} s | **{t['meta_1'] / t['meta_auto']:.2f}x** | "
          f"{m['meta_1']:.0f} / {m['meta_auto']:.0f} MB |")
    print(f"\nThe growing sphere by a shell loop of `vdb_tool -sphere ... -write`, one process a "
          f"frame: {t['grow_vdb_tool']:.2f} s; ivdb is **{t['grow_vdb_tool'] / t['grow_auto']:.2f}x "
          f"faster**.\n")
    if not os.path.exists(IVDB_MPI):
        return
    # The same frames handed out to MPI ranks (each rank on cores / ranks threads).
    cmds = {"ivdb": cmds["meta_auto"]}
    for n in (1, 2, 4):
        cmds[n] = ["mpirun", "--bind-to", "none", "--oversubscribe", "-np", str(n), IVDB_MPI,
                   "rasterize", metaballs, "--frames", "1-48:2", "-o", out, "-q"]
    t, m = median_runs(cmds, reps)
    print(f"data/anim_metaballs.json, frames 1-48:2, handed out to `mpirun --bind-to none -np N "
          f"ivdb-mpi rasterize` ranks on {os.cpu_count()} cores (wall time of mpirun, start-up "
          f"included), medians of {reps} interleaved runs:\n")
    print("| run | total | vs ivdb | largest peak memory of a process |")
    print("|---|---|---|---|")
    print(f"| ivdb (one process, frames at once) | {t['ivdb']:.2f} s | 1.00x | {m['ivdb']:.0f} MB |")
    for n in (1, 2, 4):
        print(f"| ivdb-mpi, {n} rank{'s' if n > 1 else ''} | {t[n]:.2f} s | {t['ivdb'] / t[n]:.2f}x | "
              f"{m[n]:.0f} MB |")
    print()


IVDB_MPI = os.path.join(ROOT, "build", "bin", "ivdb-mpi")
MPI_ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")


def summary_seconds(line, word):
    """The seconds after `word` in a summary line ("compute 1.234 s")."""
    return float(re.search(r"\b%s ([0-9.]+) s\b" % re.escape(word), line).group(1))


def interleaved(runs, reps, out, parse):
    """Each of @runs (name: command) @reps times, interleaved, @out removed before each (no run
    pays for unlinking the previous one's file): per name, the list of parse(name, stdout,
    resource usage) of its runs."""
    rows = {k: [] for k in runs}
    for _ in range(reps):
        for k, cmd in runs.items():
            if os.path.exists(out):
                os.remove(out)
            proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                    env=MPI_ENV)
            _, status, usage = os.wait4(proc.pid, 0)
            stdout, stderr = proc.stdout.read(), proc.stderr.read()
            if os.waitstatus_to_exitcode(status) != 0:
                sys.exit(f"failed: {' '.join(cmd)}\n{stderr}")
            rows[k].append(parse(k, stdout, usage))
    return rows


def bench_mpi_file_op(title, args, out, reps, compute_word):
    """`ivdb ARGS -o OUT` against `mpirun -np N ivdb-mpi ARGS -o OUT --json` for N = 1..4: a table
    of read, compute, write and total time and the largest peak memory of a rank."""
    runs = {"ivdb": [IVDB, *args, "-o", out]}
    for n in range(1, 5):
        runs[n] = ["mpirun", "--bind-to", "none", "--oversubscribe", "-np", str(n), IVDB_MPI,
                   *args, "-o", out, "--json"]

    def parse(k, stdout, usage):
        if k == "ivdb":
            line = stdout.splitlines()[0]
            read, compute = summary_seconds(line, "read"), summary_seconds(line, compute_word)
            total = summary_seconds(line, "total")
            return (read, compute, total - read - compute, total, usage.ru_maxrss / 1024.0)
        j = json.loads(stdout)
        peak = max(r["peak_memory_bytes"] for r in j["per_rank"]) / 2**20
        return (j["read_seconds"], j["compute_seconds"], j["write_seconds"], j["total_seconds"], peak)
    rows = interleaved(runs, reps, out, parse)
    med = {k: [statistics.median(x[i] for x in v) for i in range(5)] for k, v in rows.items()}
    one = med["ivdb"]
    print(f"\n{title}, medians of {reps} interleaved runs:\n")
    print("| run | read | compute | write | total | largest peak memory of a rank | vs one process |")
    print("|---|---|---|---|---|---|---|")
    print(f"| ivdb (one process) | {one[0]:.2f} s | {one[1]:.2f} s | {one[2]:.2f} s | {one[3]:.2f} s | "
          f"{one[4]:.0f} MB | 1.00x |")
    for n in range(1, 5):
        m = med[n]
        print(f"| ivdb-mpi, {n} rank{'s' if n > 1 else ''} | {m[0]:.2f} s | {m[1]:.2f} s | {m[2]:.2f} s | "
              f"{m[3]:.2f} s | {m[4]:.0f} MB | {m[4] / one[4]:.2f}x |")


def bench_mpi(tmp, reps, quick):
    """ivdb-mpi on 1 to 4 ranks against one ivdb process (rasterize, gradient, csg), and ivdb plan
    at 10^10 voxels."""
    radius = 400 if quick else 1600
    scene = sphere_scene(tmp, radius)
    out = os.path.join(tmp, "mpi.vdb")
    runs = {"ivdb": [IVDB, "rasterize", scene, "-o", out]}
    for n in range(1, 5):
        runs[n] = ["mpirun", "--bind-to", "none", "--oversubscribe", "-np", str(n), IVDB_MPI,
                   "rasterize", scene, "-o", out]
    for n in range(1, 5):
        runs[n].append("--json")
    def parse(k, stdout, usage):
        if k == "ivdb":
            line = stdout.splitlines()[0]
            compute, total = summary_seconds(line, "compute"), summary_seconds(line, "total")
            return (compute, total - compute, total, usage.ru_maxrss / 1024.0)
        j = json.loads(stdout)
        peak = max(r["peak_memory_bytes"] for r in j["per_rank"]) / 2**20
        return (j["compute_seconds"], j["write_seconds"], j["total_seconds"], peak)
    rows = interleaved(runs, reps, out, parse)
    med = {k: [statistics.median(x[i] for x in v) for i in range(4)] for k, v in rows.items()}
    one = med["ivdb"]
    print(f"Radius-{radius} sphere, `mpirun --bind-to none --oversubscribe -np N ivdb-mpi rasterize` "
          f"on {os.cpu_count()} cores (each rank on cores / ranks threads, at least one), medians of "
          f"{reps} interleaved runs:\n")
    print("| run | compute | write | total | largest peak memory of a rank | vs one process |")
    print("|---|---|---|---|---|---|")
    print(f"| ivdb (one process) | {one[0]:.2f} s | {one[1]:.2f} s | {one[2]:.2f} s | {one[3]:.0f} MB | 1.00x |")
    for n in range(1, 5):
        m = med[n]
        print(f"| ivdb-mpi, {n} rank{'s' if n > 1 else ''} | {m[0]:.2f} s | {m[1]:.2f} s | {m[2]:.2f} s | "
              f"{m[3]:.0f} MB | {m[3] / one[3]:.2f}x |")
    # The gradient of that sphere's file: ivdb gradient against ivdb-mpi gradient, each rank
    # reading its run of leaves and their neighbours.
    source = os.path.join(tmp, "mpi_source.vdb")
    subprocess.run([IVDB, "rasterize", scene, "-o", source, "-q"], check=True)
    bench_mpi_file_op(f"`ivdb gradient` of that sphere's file against `mpirun ... -np N ivdb-mpi "
                      f"gradient`", ["gradient", source], out, reps, "compute")
    # Its union with a second sphere (radius 3/4, centred half a radius away), each rank
    # combining its run of 128^3 nodes.
    second = os.path.join(tmp, "mpi_second.json")
    with open(second, "w") as f:
        json.dump({"voxel_size": 1.0 / radius, "half_width": 3,
                   "shape": {"type": "sphere", "center": [0.5, 0.2, 0.1], "radius": 0.75}}, f)
    other = os.path.join(tmp, "mpi_second.vdb")
    subprocess.run([IVDB, "rasterize", second, "-o", other, "-q"], check=True)
    bench_mpi_file_op(f"`ivdb csg union` of that sphere and a second one (radius {3 * radius // 4} "
                      f"voxels) against `mpirun ... -np N ivdb-mpi csg union`",
                      ["csg", "union", source, other], out, reps, "combine")
    os.remove(other)
    # Sizing a cluster: a sphere of about 10^10 active voxels (6 voxels across its surface).
    big = 11500
    print(f"\n`ivdb plan` of a radius-{big} sphere (voxel size 1/{big}):\n")
    print("| ranks | leaves | estimated active voxels | memory | per rank: voxels | memory | balance | plan time |")
    print("|---|---|---|---|---|---|---|---|")
    for ranks in (64, 512):
        r = subprocess.run([IVDB, "plan", os.path.join(ROOT, "data", "sphere.json"), "--ranks", str(ranks),
                            "--voxel-size", repr(1.0 / big), "--json"], capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(r.stderr)
        p = json.loads(r.stdout)
        share = max(p["per_rank"], key=lambda x: x["leaves"])
        print(f"| {ranks} | {p['leaves']:,} | {p['active_voxels']:.3g} | {p['memory_bytes'] / 1e9:.1f} GB | "
              f"{share['active_voxels']:.3g} | {share['memory_bytes'] / 1e9:.2f} GB | "
              f"{p['balance']:.3f} | {p['seconds']:.1f} s |")
    print()


def bench_mpi_blend(tmp, big, reps):
    """ivdb blend against ivdb-mpi blend on 1 to 4 ranks: rank 0 blends around the crease alone."""
    a, b = two_spheres(tmp, big, "ba.vdb", "bb.vdb")
    bench_mpi_file_op(f"`ivdb blend union -p 1000` of two radius-{big} spheres against `mpirun ... "
                      f"-np N ivdb-mpi blend union -p 1000`",
                      ["blend", "union", a, b, "-p", "1000"], os.path.join(tmp, "mpi_blend.vdb"),
                      reps, "blend")
    print()


def gbench_medians(pattern, reps):
    res = subprocess.run([BENCH, f"--benchmark_filter={pattern}", f"--benchmark_repetitions={reps}",
                          "--benchmark_format=json"], check=True, capture_output=True, text=True)
    return {b["run_name"].split("/")[0]: b["real_time"]
            for b in json.loads(res.stdout)["benchmarks"] if b.get("aggregate_name") == "median"}


def two_spheres(tmp, big, name_a, name_b):
    """Two radius-@big-voxel spheres, centres 0.7 radii apart along x, written to @tmp."""
    paths = [os.path.join(tmp, name_a), os.path.join(tmp, name_b)]
    for path, cx in zip(paths, (-0.35, 0.35)):
        scene = os.path.join(tmp, "s.json")
        with open(scene, "w") as f:
            json.dump({"voxel_size": 1.0 / big, "shape": {"type": "sphere", "center": [cx, 0, 0],
                                                          "radius": 1}}, f)
        run([IVDB, "rasterize", scene, "-o", path, "-q"])
    return paths


def bench_csg(tmp, big, reps):
    med = gbench_medians_full("(CsgUnion|BlendUnion)", reps)
    ours, ref = med[f"BM_CsgUnion/{big}/real_time"], med[f"BM_OpenVDB_CsgUnion/{big}/real_time"]
    print("| compute only (Google Benchmark), two spheres | ivdb | OpenVDB / sharp | ratio |")
    print("|---|---|---|---|")
    print(f"| csg union (radius {big}) vs tools::csgUnion | {ours:.1f} ms | {ref:.1f} ms | "
          f"**{ours / ref:.2f}x the time** |")
    # p = 1000: a 2-voxel band extension at radius 100 and 200, 3 at 400; p = 0.8 * radius: 6.
    def extension(r, p):  # as ops::blend: ceil(w + reach + ln(2)/p) + 1 - w voxels, w = 3
        reach = max(0.0, math.log(1.0 / (p * 0.05 / r)) / p) * r + math.log(2.0) / p * r
        return math.ceil(3.0 + reach) + 1 - 3
    for r, p in ((100, 1000), (big, 1000), (100, 80), (big, int(0.8 * big))):
        ext = extension(r, p)
        blend, sharp = med[f"BM_BlendUnion/{r}/{p}/real_time"], med[f"BM_CsgUnion/{r}/real_time"]
        print(f"| blend union p = {p}, {ext}-voxel band extension (radius {r}) vs sharp csg union | "
              f"{blend:.0f} ms | {sharp:.1f} ms | **{blend / sharp:.0f}x the time** |")
    print()
    a, b = two_spheres(tmp, big, "a.vdb", "b.vdb")
    out_a, out_b = os.path.join(tmp, "ua.vdb"), os.path.join(tmp, "ub.vdb")
    t, m = median_runs({
        "ivdb": [IVDB, "csg", "union", a, b, "-o", out_a, "-q"],
        "vdb_tool": ["vdb_tool", "-read", a, b, "-union", "-write", out_b],
    }, reps)
    print("| end to end, union of two radius-%d spheres | ivdb csg union | vdb_tool -union | ivdb is |" % big)
    print("|---|---|---|---|")
    print(f"| wall time | {t['ivdb']:.2f} s | {t['vdb_tool']:.2f} s | **{t['vdb_tool'] / t['ivdb']:.2f}x faster** |")
    print(f"| peak memory | {m['ivdb']:.0f} MB | {m['vdb_tool']:.0f} MB | {m['vdb_tool'] / m['ivdb']:.2f}x less |\n")
    # Rendering one of the spheres at 640x480 with the same camera (issue 5's comparison).
    png_a, png_b = os.path.join(tmp, "ra.png"), os.path.join(tmp, "rb.png")
    t, m = median_runs({
        "ivdb": [IVDB, "render", a, "-o", png_a, "-q", "--camera",
                 "eye=-0.35,0,4,target=-0.35,0,0,fov=40"],
        "vdb_render": ["vdb_render", a, png_b, "-res", "640x480", "-translate", "-0.35,0,4",
                       "-lookat", "-0.35,0,0", "-fov", "40"],
    }, reps)
    print("| end to end, render a radius-%d sphere at 640x480 | ivdb render | vdb_render | ivdb is |" % big)
    print("|---|---|---|---|")
    print(f"| wall time | {t['ivdb']:.2f} s | {t['vdb_render']:.2f} s | **{t['vdb_render'] / t['ivdb']:.2f}x faster** |\n")
    p6 = int(0.8 * big)
    t, m = median_runs({
        "csg": [IVDB, "csg", "union", a, b, "-o", out_a, "-q"],
        "blend1000": [IVDB, "blend", "union", a, b, "-p", "1000", "-o", out_b, "-q"],
        "blend6": [IVDB, "blend", "union", a, b, "-p", str(p6), "-o", out_b, "-q"],
    }, reps)
    print("| end to end, two radius-%d spheres | ivdb blend union | ivdb csg union | ratio |" % big)
    print("|---|---|---|---|")
    print(f"| p = 1000 (3-voxel extension) | {t['blend1000']:.2f} s | {t['csg']:.2f} s | "
          f"**{t['blend1000'] / t['csg']:.1f}x the time** |")
    print(f"| p = {p6} (6-voxel extension) | {t['blend6']:.2f} s | {t['csg']:.2f} s | "
          f"**{t['blend6'] / t['csg']:.1f}x the time** |\n")


def bench_diff(tmp, big, reps):
    med = gbench_medians(f"(Gradient|Curvature)/{big}", reps)
    print("| compute only (Google Benchmark), sphere radius %d voxels | ivdb | OpenVDB | ivdb is |" % big)
    print("|---|---|---|---|")
    for name, ours, ref in (("gradient vs tools::gradient", "BM_Gradient", "BM_OpenVDB_Gradient"),
                            ("mean curvature vs tools::meanCurvature", "BM_MeanCurvature",
                             "BM_OpenVDB_MeanCurvature")):
        print(f"| {name} | {med[ours]:.0f} ms | {med[ref]:.0f} ms | **{med[ref] / med[ours]:.2f}x faster** |")
    print()
    scene = sphere_scene(tmp, big)
    src = os.path.join(tmp, "in.vdb")
    run([IVDB, "rasterize", scene, "-o", src, "-q"])
    out_a, out_b = os.path.join(tmp, "a.vdb"), os.path.join(tmp, "b.vdb")
    t, m = median_runs({
        "ivdb gradient": [IVDB, "gradient", src, "-o", out_a, "-q"],
        "vdb_tool -grad": ["vdb_tool", "-read", src, "-grad", "-write", out_b],
        "ivdb curvature": [IVDB, "curvature", src, "-o", out_a, "-q"],
        "vdb_tool -curvature": ["vdb_tool", "-read", src, "-curvature", "-write", out_b],
    }, reps)
    print("| end to end (read, compute, write), sphere radius %d voxels | ivdb | vdb_tool | ivdb is |" % big)
    print("|---|---|---|---|")
    for op in ("gradient", "curvature"):
        a, b = f"ivdb {op}", "vdb_tool -grad" if op == "gradient" else "vdb_tool -curvature"
        print(f"| {op}: wall time | {t[a]:.2f} s | {t[b]:.2f} s | **{t[b] / t[a]:.2f}x faster** |")
        print(f"| {op}: peak memory | {m[a]:.0f} MB | {m[b]:.0f} MB | {m[b] / m[a]:.2f}x less |")
    print()


def bench_core(tmp, big, reps, quick):
    out = os.path.join(tmp, "out.vdb")
    med = gbench_medians(f"(Rasterize_Sparse|CreateLevelSetSphere|Rasterize_Dense)/{big}/", reps)
    ours, ref = med["BM_Rasterize_Sparse"], med["BM_OpenVDB_CreateLevelSetSphere"]
    dense = med["BM_Rasterize_Dense"]
    print("| compute only (Google Benchmark), sphere radius %d voxels | time | ivdb sparse is |" % big)
    print("|---|---|---|")
    print(f"| ivdb sparse | {ours:.0f} ms | |")
    print(f"| openvdb::tools::createLevelSetSphere | {ref:.0f} ms | **{ref / ours:.2f}x faster** |")
    print(f"| ivdb dense | {dense:.0f} ms | **{dense / ours:.1f}x faster** |\n")

    # End to end with write.
    scene = sphere_scene(tmp, big)
    t, m = median_runs({
        "ivdb": [IVDB, "rasterize", scene, "-o", out, "-q"],
        "vdb_tool": ["vdb_tool", "-sphere", f"voxel={1.0 / big}", "radius=1", "-write",
                     os.path.join(tmp, "tool.vdb")],
    }, reps)
    print("| end to end, sphere radius %d voxels | ivdb rasterize | vdb_tool -sphere -write | ivdb is |" % big)
    print("|---|---|---|---|")
    print(f"| wall time | {t['ivdb']:.2f} s | {t['vdb_tool']:.2f} s | **{t['vdb_tool'] / t['ivdb']:.2f}x faster** |")
    print(f"| peak memory | {m['ivdb']:.0f} MB | {m['vdb_tool']:.0f} MB | {m['vdb_tool'] / m['ivdb']:.2f}x less |\n")

    # Sparse vs dense, end to end.
    print("| radius (voxels) | sparse time | dense time | time ratio | sparse memory | dense memory | memory ratio |")
    print("|---|---|---|---|---|---|---|")
    for r in ([50, 100, 200] if quick else [50, 100, 200, 400]):
        scene = sphere_scene(tmp, r)
        t, m = median_runs({
            "sparse": [IVDB, "rasterize", scene, "-o", out, "-q"],
            "dense": [IVDB, "rasterize", scene, "-o", out, "-q", "--sampling", "dense"],
        }, reps if r < 400 else min(reps, 3))
        print(f"| {r} | {t['sparse']:.3f} s | {t['dense']:.3f} s | **{t['dense'] / t['sparse']:.1f}x** "
              f"| {m['sparse']:.0f} MB | {m['dense']:.0f} MB | **{m['dense'] / m['sparse']:.1f}x** |")
    print()

    # Scaling of the sparse compute with resolution.
    rows = sorted((int(name.split("/")[1]), ms) for name, ms in
                  gbench_medians_full("Rasterize_Sparse/", reps).items())
    print("| radius (voxels) | sparse compute | x per doubling |")
    print("|---|---|---|")
    prev = None
    for r, ms in rows:
        print(f"| {r} | {ms:.1f} ms | {f'{ms / prev:.2f}' if prev else '-'} |")
        prev = ms


def bench_distances(tmp, reps, quick):
    import random
    k = 4 if quick else 1  # --quick: voxels 4x larger
    sph = lambda c, r: {"type": "sphere", "center": c, "radius": r}
    two = [sph([-0.35, 0, 0], 0.6), sph([0.35, 0, 0], 0.6)]
    rng = random.Random(20261201)
    many = [sph([rng.uniform(-1, 1) for _ in range(3)], rng.uniform(0.05, 0.15)) for _ in range(1000)]
    scenes = [  # name, shape, voxel size, distance mode, OpenVDB route
        ("sphere radius 1 (exact)", sph([0, 0, 0], 1), 0.0025, None, False),
        ("sphere radius 1 (exact), voxel 0.01", sph([0, 0, 0], 1), 0.01, None, False),
        ("sphere radius 1 (exact), voxel 0.004", sph([0, 0, 0], 1), 0.004, None, False),
        ("sphere as a quadric", {"type": "quadric", "matrix": [[1, 0, 0, 0], [0, 1, 0, 0],
                                 [0, 0, 1, 0], [0, 0, 0, -1]]}, 0.01, None, False),
        ("ellipsoid radii 1, 0.8, 0.6", {"type": "ellipsoid", "radii": [1, 0.8, 0.6]}, 0.0025, None, False),
        ("sphere radius 1 scaled 1, 0.8, 0.6 (the same ellipsoid)",
         {"type": "transform", "scale": [1, 0.8, 0.6], "child": sph([0, 0, 0], 1)}, 0.0025, None, False),
        ("union of two spheres", {"type": "union", "children": two}, 0.0025, None, True),
        ("union of two spheres, bound", {"type": "union", "children": two}, 0.0025, "bound", True),
        ("blend of two spheres, p = 20", {"type": "blend", "op": "union", "p": 20, "children": two},
         0.0025, None, False),
        ("blend of two spheres, p = 20, bound", {"type": "blend", "op": "union", "p": 20, "children": two},
         0.0025, "bound", False),
        ("union of 1000 spheres", {"type": "union", "children": many}, 0.004, None, True),
        ("union of 1000 spheres, bound", {"type": "union", "children": many}, 0.004, "bound", True),
    ]
    rows = []
    for i, (name, shape, dx, mode, route) in enumerate(scenes):
        scene = {"voxel_size": dx * k, "shape": shape}
        if mode:
            scene["distance"] = mode
        path = os.path.join(tmp, f"distances_{i}.json")
        with open(path, "w") as f:
            json.dump(scene, f)
        rows.append((name, path, dx * k, route))

    def compute(path):
        res = subprocess.run([IVDB, "rasterize", path, "-o", os.path.join(tmp, "d.vdb")],
                             check=True, capture_output=True, text=True).stdout
        words = res.split()
        active = int(words[1])
        seconds = float(words[words.index("compute") + 1])
        peak = res.split("peak memory ")[1].split(",")[0]
        grid = res.split("grid ")[1].split(",")[0]
        return active, seconds, peak, grid

    def rasterizing_memory(path, dx):
        # ivdb bench-run: the rasterization alone, no file written (the writer holds the
        # compressed file before it writes it): peak and its growth over the start-up.
        res = subprocess.run([IVDB, "bench-run", path, "--method", "sparse", "--voxel-size", repr(dx),
                              "--reps", "1"], check=True, capture_output=True, text=True).stdout.split()
        return int(res[2]), int(res[3]), int(res[5])

    def openvdb(path, dx):
        res = subprocess.run([IVDB, "bench-run", path, "--method", "openvdb", "--voxel-size", repr(dx),
                              "--reps", "3"], check=True, capture_output=True, text=True).stdout
        return float(res.split()[0])

    times = {name: [] for name, *_ in rows}
    info = {}
    for _ in range(reps):
        for name, path, dx, _ in rows:
            active, seconds, peak, grid = compute(path)
            times[name].append(seconds)
            info[name] = (active, peak, grid)
    # Per active voxel against the exact sphere at the same voxel size (a coarser grid has fewer
    # voxels to spread the fixed costs over), and against the finest one.
    base = {dx: statistics.median(times[name]) / info[name][0]
            for name, _, dx, _ in rows if name.startswith("sphere radius 1 (exact)")}
    print("| scene | active voxels | compute | per voxel vs the exact sphere (same voxel size) "
          "| per voxel vs the finest exact sphere | peak memory rasterizing: start-up + work "
          "(work / grid) | peak memory with the write | OpenVDB's route |")
    print("|---|---|---|---|---|---|---|---|")
    mb = lambda b: f"{b / 1e6:.1f} MB"
    for name, path, dx, route in rows:
        t = statistics.median(times[name])
        active, peak, grid = info[name]
        rpeak, work, gridBytes = rasterizing_memory(path, dx)
        ovdb = f"{openvdb(path, dx):.3f} s" if route else "-"
        print(f"| {name} | {active / 1e6:.2f} M | {t:.3f} s | {t / active / base[dx]:.1f}x "
              f"| {t / active / base[rows[0][2]]:.1f}x | {mb(rpeak - work)} + {mb(work)} "
              f"({work / gridBytes:.2f}x) | {peak} ({grid}) | {ovdb} |")
    print()


def bench_hugepages(tmp, big, reps):
    scene = sphere_scene(tmp, big)
    src = os.path.join(tmp, "hp_in.vdb")
    run([IVDB, "rasterize", scene, "-o", src, "-q"])
    out = os.path.join(tmp, "hp_out.vdb")
    base = {k: v for k, v in os.environ.items() if k not in ("GLIBC_TUNABLES", "IVDB_HUGEPAGES")}
    # ivdb's default, the launcher's four tunables (tools/HugePages.h, kMallocTunables); hugetlb=1
    # alone (a GLIBC_TUNABLES that names hugetlb is left as it is: the previous release's
    # setting); none. vdb_tool gets the same GLIBC_TUNABLES, to show what they do for it.
    tunables = ("glibc.malloc.hugetlb=1:glibc.malloc.top_pad=67108864:"
                "glibc.malloc.trim_threshold=1073741824:glibc.malloc.mmap_threshold=33554432")
    hugetlb = "glibc.malloc.hugetlb=1"
    ivdb_env = {"default": base, "hugetlb": dict(base, GLIBC_TUNABLES=hugetlb),
                "off": dict(base, IVDB_HUGEPAGES="0")}
    tool_env = {"default": dict(base, GLIBC_TUNABLES=tunables),
                "hugetlb": dict(base, GLIBC_TUNABLES=hugetlb), "off": base}
    figures = {k: {} for k in ivdb_env}

    def timed(cmd, env):
        if os.path.exists(out):
            os.remove(out)  # no run pays for unlinking the previous one's output
        os.sync()
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        text = proc.stdout.read() + proc.stderr.read()
        if os.waitstatus_to_exitcode(status) != 0:
            sys.exit(f"failed: {' '.join(cmd)}\n{text}")
        return wall, usage.ru_maxrss / 1024.0, text

    def add(mode, name, value):
        figures[mode].setdefault(name, []).append(value)

    for _ in range(reps):
        for mode in ivdb_env:
            wall, peak, text = timed([IVDB, "rasterize", scene, "-o", out], ivdb_env[mode])
            add(mode, "ivdb rasterize: compute", summary_seconds(text, "compute"))
            add(mode, "ivdb rasterize: wall", wall)
            add(mode, "ivdb rasterize: peak memory (MB)", peak)
            wall, peak, text = timed([IVDB, "gradient", src, "-o", out], ivdb_env[mode])
            add(mode, "ivdb gradient: read", summary_seconds(text, "read"))
            add(mode, "ivdb gradient: compute", summary_seconds(text, "compute"))
            add(mode, "ivdb gradient: wall", wall)
            add(mode, "ivdb gradient: peak memory (MB)", peak)
            wall, peak, _ = timed(["vdb_tool", "-sphere", f"voxel={1.0 / big}", "radius=1", "-write", out],
                                  tool_env[mode])
            add(mode, "vdb_tool -sphere -write: wall", wall)
            add(mode, "vdb_tool -sphere -write: peak memory (MB)", peak)
    modes = list(ivdb_env)
    print(f"| radius-{big} sphere, medians of {reps} interleaved runs | huge pages (ivdb's default: the "
          "four tunables; vdb_tool with them) | glibc.malloc.hugetlb=1 alone | without "
          "(IVDB_HUGEPAGES=0; vdb_tool as it is) | default / without | default / hugetlb=1 alone |")
    print("|---|---|---|---|---|---|")
    for name in figures[modes[0]]:
        a, h, b = (statistics.median(figures[m][name]) for m in modes)
        unit = "" if "MB" in name else " s"
        fmt = (lambda v: f"{v:.0f}") if "MB" in name else (lambda v: f"{v:.3f}")
        print(f"| {name} | {fmt(a)}{unit} | {fmt(h)}{unit} | {fmt(b)}{unit} | {a / b:.2f} | {a / h:.2f} |")
    print()


def bench_io(tmp, big, reps, quick):
    med = gbench_medians_full("(WriteVdb|FileWrite|ReadVdb|FileRead)", reps)
    g = lambda name: med[f"{name}/real_time"]
    print(f"| .vdb I/O, sphere radius {big} voxels (Google Benchmark) | time | vs OpenVDB |")
    print("|---|---|---|")
    ref = g(f"BM_OpenVDB_FileWrite/{big}")
    print(f"| io::File::write (Blosc) | {ref:.0f} ms | |")
    for t in (1, 2):
        ours = g(f"BM_WriteVdb/{big}/{t}")
        print(f"| ivdb writer, {t} thread{'s' if t > 1 else ''} | {ours:.0f} ms | **{ref / ours:.2f}x faster** |")
    ref = g(f"BM_OpenVDB_FileRead/{big}")
    delayed = g(f"BM_OpenVDB_FileReadDelayed/{big}")
    print(f"| io::File full load | {ref:.0f} ms | |")
    print(f"| io::File delayed load, then every leaf touched on all threads | {delayed:.0f} ms | |")
    for t in (1, 2):
        ours = g(f"BM_ReadVdb/{big}/{t}")
        print(f"| ivdb reader (layout check included), {t} thread{'s' if t > 1 else ''} | {ours:.0f} ms "
              f"| **{ref / ours:.2f}x faster** (delayed: {delayed / ours:.2f}x) |")
    print()

    # End to end against vdb_tool.
    src = os.path.join(tmp, "io_in.vdb")
    run([IVDB, "rasterize", sphere_scene(tmp, big), "-o", src, "-q"])
    a, b = os.path.join(tmp, "io_a.vdb"), os.path.join(tmp, "io_b.vdb")
    for path, cx in ((a, -0.35), (b, 0.35)):
        scene = os.path.join(tmp, "io_s.json")
        with open(scene, "w") as f:
            json.dump({"voxel_size": 1.0 / big, "shape": {"type": "sphere", "center": [cx, 0, 0],
                                                          "radius": 1}}, f)
        run([IVDB, "rasterize", scene, "-o", path, "-q"])
    out, ref = os.path.join(tmp, "io_out.vdb"), os.path.join(tmp, "io_ref.vdb")
    ops = [
        (f"rasterize, radius {big}", ["rasterize", sphere_scene(tmp, big)],
         ["-sphere", f"voxel={1.0 / big}", "radius=1"]),
        ("gradient", ["gradient", src], ["-read", src, "-grad"]),
        ("curvature", ["curvature", src], ["-read", src, "-curvature"]),
        ("csg union of two spheres", ["csg", "union", a, b], ["-read", a, b, "-union"]),
    ]
    if not quick:
        ops.append(("rasterize, radius 1600", ["rasterize", sphere_scene(tmp, 1600)],
                    ["-sphere", "voxel=0.000625", "radius=1"]))
    print("| end to end (read, compute, write) | vdb_tool | ivdb, 1 thread | ivdb, 2 threads "
          "| ratio ivdb / vdb_tool (2 threads) |")
    print("|---|---|---|---|---|")
    for name, ours, theirs in ops:
        n = reps if "1600" not in name else min(reps, 3)
        t, _ = median_runs({
            "tool": ["vdb_tool", *theirs, "-write", ref],
            "1": [IVDB, "--threads", "1", *ours, "-o", out, "-q"],
            "2": [IVDB, *ours, "-o", out, "-q"],
        }, n)
        print(f"| {name} | {t['tool']:.2f} s | {t['1']:.2f} s | {t['2']:.2f} s "
              f"| **{t['2'] / t['tool']:.2f}** |")
    print()

    if quick:
        return
    # Compute scaling with the active voxels: radius 1600 has 16.0x the voxels of radius 400.
    def compute(r):
        res = subprocess.run([IVDB, "rasterize", sphere_scene(tmp, r), "-o", out], check=True,
                             capture_output=True, text=True).stdout
        words = res.split()
        return int(words[1]), float(words[words.index("compute") + 1])
    times = {400: [], 1600: []}
    voxels = {}
    for _ in range(min(reps, 3)):
        for r in (400, 1600):
            voxels[r], seconds = compute(r)
            times[r].append(seconds)
    c4, c16 = statistics.median(times[400]), statistics.median(times[1600])
    v = voxels[1600] / voxels[400]
    print("| rasterize compute | radius 400 | radius 1600 | voxels ratio | time ratio | vs linear |")
    print("|---|---|---|---|---|---|")
    print(f"| sphere | {c4:.3f} s | {c16:.3f} s | {v:.1f}x | {c16 / c4:.1f}x | **{c16 / c4 / v:.2f}x** |")
    print()


def gbench_medians_full(pattern, reps):
    """Like gbench_medians, keyed by the full run name (with its arguments)."""
    res = subprocess.run([BENCH, f"--benchmark_filter={pattern}", f"--benchmark_repetitions={reps}",
                          "--benchmark_format=json"], check=True, capture_output=True, text=True)
    return {b["run_name"]: b["real_time"]
            for b in json.loads(res.stdout)["benchmarks"] if b.get("aggregate_name") == "median"}


if __name__ == "__main__":
    main()
