#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""The distances of a non-uniformly scaled capped cylinder or cone, against a brute-force
distance to its surface: every active voxel of `ivdb rasterize SCENE -o OUT.vdb` against the
nearest of about 35 M points of the mapped surface (its side on a 10,000 x 2,500 grid of angle
and axial position, its caps on a square grid of spacing 3e-4 in child space), found with
scipy's k-d tree. A sample is a surface point, so the surface is at most that far: a voxel whose
|value| exceeds it by more than the samples' spacing (about 0.03 voxel at voxel size 0.01)
answered too far, one below it by more than that too near.

Usage: scripts/capped_cone_accuracy.py SCENE.json OUT.vdb
  where SCENE.json's shape is a `transform` (rotate_deg, scale, translate) of a `capped_cylinder`
  or `capped_cone`. Prints the voxels more than 0.02 voxel too far and more than 0.05 voxel too
  near, with the worst of each, in voxels.
"""
import json
import math
import sys

import numpy as np
import pyopenvdb as vdb
from scipy.spatial import cKDTree


def rotation(deg):
    ax, ay, az = (math.radians(d) for d in deg)
    rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
    ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
    rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx  # R = Rz Ry Rx, as the scene's transform


def main():
    scene = json.load(open(sys.argv[1]))
    shape = scene["shape"]
    child = shape["child"]
    m = rotation(shape.get("rotate_deg", [0, 0, 0])) @ np.diag(shape.get("scale", [1, 1, 1]))
    t = np.array(shape.get("translate", [0, 0, 0]), float)
    a, b = np.array(child["a"], float), np.array(child["b"], float)
    ra = child.get("radius_a", child.get("radius"))
    rb = child.get("radius_b", child.get("radius"))
    length = np.linalg.norm(b - a)
    u = (b - a) / length
    v1 = np.cross(u, [1.0, 0, 0] if abs(u[0]) < 0.9 else [0, 1.0, 0])
    v1 /= np.linalg.norm(v1)
    v2 = np.cross(u, v1)
    theta, s = np.meshgrid(np.linspace(0, 2 * np.pi, 10000, endpoint=False), np.linspace(0, length, 2500))
    radius = ra + (rb - ra) * s / length
    side = (a + s.ravel()[:, None] * u + (radius * np.cos(theta)).ravel()[:, None] * v1
            + (radius * np.sin(theta)).ravel()[:, None] * v2)

    def disc(centre, r):
        if r <= 0:
            return np.zeros((0, 3))
        g = np.arange(-r, r, 3e-4)
        gx, gy = np.meshgrid(g, g)
        inside = gx ** 2 + gy ** 2 <= r * r
        return centre + gx[inside][:, None] * v1 + gy[inside][:, None] * v2

    local = np.concatenate([side, disc(a, ra), disc(b, rb)])
    tree = cKDTree(local @ m.T + t)
    dx = scene["voxel_size"]
    grid = vdb.read(sys.argv[2], "surface")
    coords, values = [], []
    for it in grid.citerOnValues():
        if it.count == 1:
            coords.append(it.min)
            values.append(it.value)
    nearest, _ = tree.query(np.array(coords, float) * dx)
    err = (np.abs(np.array(values)) - nearest) / dx
    print(f"{len(local)} surface samples, {len(values)} active voxels: "
          f"{np.sum(err > 0.02)} more than 0.02 voxel too far (worst {err.max():.3g}), "
          f"{np.sum(err < -0.05)} more than 0.05 voxel too near (worst {-err.min():.3g})")


if __name__ == "__main__":
    main()
