#!/usr/bin/python3
# SPDX-License-Identifier: Apache-2.0
"""Plot `ivdb bench` results: log-log time and memory against resolution.

Usage: plot_bench.py BENCH.csv BENCH.png

One line per scene and method (sparse, dense, openvdb), with the least-squares slope of
log(value) against log(resolution) in the legend: about 2 for sparse sampling (cost grows with the
surface), about 3 for dense (with the volume). Memory is the work memory: the peak resident memory
of the measuring process minus what it held before the work. Runs marked skipped or failed are
left out. Prints the fitted slopes, one line per scene and method.
"""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLORS = {"sparse": "tab:blue", "dense": "tab:red", "openvdb": "tab:green"}
MARKERS = ["o", "s", "^", "D", "v", "P", "X", "*"]


def slope(xs, ys):
    """Least-squares slope of log(y) against log(x); None with fewer than two points."""
    pts = [(math.log(x), math.log(y)) for x, y in zip(xs, ys) if x > 0 and y > 0]
    if len(pts) < 2:
        return None
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    if sxx == 0:
        return None
    return sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx


def main(argv):
    if len(argv) != 3:
        sys.stderr.write("usage: plot_bench.py BENCH.csv BENCH.png\n")
        return 2
    csv_path, png_path = argv[1], argv[2]
    series = {}
    with open(csv_path, newline="") as f:
        for row in csv.DictReader(f):
            if row["status"] != "ok":
                continue
            key = (row["scene"], row["method"])
            series.setdefault(key, []).append(
                (int(row["resolution"]), float(row["time_s"]), int(row["work_memory_bytes"])))
    if not series:
        sys.stderr.write(f"{csv_path}: no successful runs to plot\n")
        return 1

    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(13, 5.5))
    scenes = sorted({k[0] for k in series})
    for (scene, method), pts in sorted(series.items()):
        pts.sort()
        res = [p[0] for p in pts]
        times = [p[1] for p in pts]
        mem = [p[2] / 1e6 for p in pts]
        marker = MARKERS[scenes.index(scene) % len(MARKERS)]
        style = dict(color=COLORS.get(method, "black"), marker=marker, linewidth=1.5)
        st, sm = slope(res, times), slope(res, mem)
        label = lambda s: f"{scene} {method}" + (f" (slope {s:.2f})" if s is not None else "")
        ax_t.plot(res, times, label=label(st), **style)
        ax_m.plot(res, mem, label=label(sm), **style)
        print(f"{scene} {method}: time slope {st if st is None else round(st, 2)}, "
              f"memory slope {sm if sm is None else round(sm, 2)}")
    for ax, what in ((ax_t, "time (s, median)"), (ax_m, "work memory (MB, peak)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("resolution (voxels across)")
        ax.set_ylabel(what)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    ax_t.set_title("Rasterization time")
    ax_m.set_title("Memory")
    fig.suptitle("ivdb bench: sparse vs dense sampling")
    fig.tight_layout()
    tmp = os.path.join(os.path.dirname(os.path.abspath(png_path)),
                       "." + os.path.basename(png_path) + ".tmp.png")
    fig.savefig(tmp, dpi=110)
    os.replace(tmp, png_path)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
