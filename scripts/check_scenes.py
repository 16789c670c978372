#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Check the true distances of many scenes with `ivdb check-distances` and count the scenes
with a sampled voxel farther than the surface (docs/method.md#checking-distances).

Each scene is rasterized in memory and SAMPLES of its band voxels (near a kink only, with
--near-kinks) are checked against a brute-force search for the surface. One line per scene
(its worst voxel, how many voxels more than 0.01 and 0.1 voxel too far), then how many scenes
have a voxel more than 0.01, 0.05, 0.1 and 0.3 voxel farther than the surface, and how many of
all the voxels sampled are.

Usage: scripts/check_scenes.py [--ivdb BIN] [--samples N] [--near-kinks] [--seed S] SCENE...
For example, the offsets and shells of blends of method.md:
  for s in 1 2 3; do scripts/random_blends.py $s 40 /tmp/o offsets; done
  scripts/check_scenes.py --near-kinks --samples 150 /tmp/o/*.json
"""
import argparse
import json
import os
import subprocess
import sys

THRESHOLDS = [0.01, 0.05, 0.1, 0.3]


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="+", metavar="SCENE")
    parser.add_argument("--ivdb", default=os.path.join(here, "..", "build", "bin", "ivdb"),
                        help="the ivdb binary (default: build/bin/ivdb)")
    parser.add_argument("--samples", type=int, default=200, help="voxels per scene (default 200)")
    parser.add_argument("--seed", type=int, default=1, help="which voxels (default 1)")
    parser.add_argument("--near-kinks", action="store_true",
                        help="only voxels within whose distance the shape may kink")
    args = parser.parse_args()

    beyond = {t: 0 for t in THRESHOLDS}     # scenes
    voxels = {t: 0 for t in THRESHOLDS}     # sampled voxels, all scenes
    sampled = 0
    worst, worst_scene, checked, refused = 0.0, "", 0, []
    for scene in args.scenes:
        cmd = [args.ivdb, "check-distances", scene, "--json", "--samples", str(args.samples),
               "--seed", str(args.seed)] + (["--near-kinks"] if args.near_kinks else [])
        run = subprocess.run(cmd, capture_output=True, text=True)
        if run.returncode < 0:
            sys.exit(f"{scene}: ivdb was killed by signal {-run.returncode}:\n{run.stderr}")
        if run.returncode != 0:
            refused.append(scene)
            print(f"{scene}: refused (exit {run.returncode}): {run.stderr.strip()}")
            continue
        r = json.loads(run.stdout)
        checked += 1
        far = r["worst_farther_voxels"]
        print(f"{scene}: {r['sampled']} of {r['candidates']} voxels, worst {far:.4f} voxel too far, "
              f"{r['farther_than']['0.01']} beyond 0.01, {r['farther_than']['0.1']} beyond 0.1"
              + (f", {r['sign_mismatches']} of the wrong sign" if r["sign_mismatches"] else ""))
        sampled += r["sampled"]
        for t in THRESHOLDS:
            voxels[t] += r["farther_than"][str(t)]
            if far > t:
                beyond[t] += 1
        if far > worst:
            worst, worst_scene = far, scene
    print(f"{checked} scenes checked ({len(refused)} refused), {args.samples} voxels each"
          + (" near a kink" if args.near_kinks else "")
          + f"; worst {worst:.4f} voxel ({worst_scene or 'none'})")
    print("scenes with a voxel farther than the surface by more than "
          + ", ".join(f"{t}: {beyond[t]}" for t in THRESHOLDS) + " voxel")
    print(f"of the {sampled} voxels sampled, farther by more than "
          + ", ".join(f"{t}: {voxels[t]}" for t in THRESHOLDS) + " voxel")
    return 0


if __name__ == "__main__":
    sys.exit(main())
