#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Random scene files of one blend or smooth CSG node of two primitives, for timing and
checking the true distances of blends (docs/performance.md#true-distances).

Each scene: a `blend` (p 10 to 60) or `smooth` (k 0.04 to 0.2) union, intersection or
difference of two of capped_cylinder, capped_cone, capsule, torus, sphere and box, each moved
(rotated, translated, sometimes scaled uniformly) with probability 0.6, the node itself with
probability 0.3; voxel size 0.02. The same seed writes the same scenes.

Usage: scripts/random_blends.py SEED COUNT DIR   (writes DIR/s{SEED}_{i}.json)
Timing, against another binary: ivdb bench-run DIR/s5_0.json --method sparse --voxel-size 0.02

With a fourth argument, `boxes` or `rounded`: blends of a box (a rounded box) or a capped
cylinder with a sphere, capsule, box, capped cylinder or torus, either moved with probability
0.5, in either order; union (3 in 5), intersection or difference; voxel 0.01 (writes
DIR/b{SEED}_{i}.json or DIR/r{SEED}_{i}.json): the scenes the blend sheets were checked on
(docs/method.md#offsets-shells-blends-and-grid-shapes). With `offsets`: the plain scenes with
each blend shrunk (`offset`, distance -0.01 to -0.06; 3 in 4) or shelled (`shell`, thickness
0.04 to 0.12) before it is moved (writes DIR/o{SEED}_{i}.json): the scenes its kink rule was
checked on there.
"""
import json
import os
import random
import sys


def point(rng, s=0.4):
    """A point with coordinates in [-s, s]."""
    return [round(rng.uniform(-s, s), 3) for _ in range(3)]


def sizes(rng, lo, hi):
    """Three edge lengths in [lo, hi]."""
    return [round(rng.uniform(lo, hi), 3) for _ in range(3)]


def common_primitive(rng, t):
    """A capped cylinder, capsule, torus or sphere (type t, else a sphere): both kinds of
    scene draw these alike, in the same order of random numbers."""
    if t == "capped_cylinder":
        return {"type": t, "a": point(rng), "b": point(rng), "radius": round(rng.uniform(0.12, 0.35), 3)}
    if t == "capsule":
        return {"type": t, "a": point(rng), "b": point(rng), "radius": round(rng.uniform(0.1, 0.3), 3)}
    if t == "torus":
        major = rng.uniform(0.2, 0.45)
        return {"type": t, "center": point(rng, 0.2), "major_radius": round(major, 3),
                "minor_radius": round(rng.uniform(0.06, 0.8 * major), 3)}
    return {"type": "sphere", "center": point(rng), "radius": round(rng.uniform(0.1, 0.4), 3)}


def capped(seed, count, out, rounded):
    """The `boxes` and `rounded` scenes."""
    rng = random.Random(seed)

    def v(s=0.4):
        return point(rng, s)

    def first():
        if rng.random() < (0.7 if rounded else 0.6):
            if not rounded:
                return {"type": "box", "center": v(0.1), "size": sizes(rng, 0.3, 0.8)}
            size = sizes(rng, 0.3, 0.8)
            return {"type": "rounded_box", "center": v(0.1), "size": size,
                    "radius": round(rng.uniform(0.01, min(size) / 2 - 0.01), 3)}
        return common_primitive(rng, "capped_cylinder")

    def other():
        t = rng.choice(["sphere", "capsule", "box", "capped_cylinder", "torus"])
        if t == "box":
            return {"type": t, "center": v(0.3), "size": sizes(rng, 0.2, 0.6)}
        return common_primitive(rng, t)

    def moved(shape):
        if rng.random() < 0.5:
            return shape
        t = {"type": "transform", "child": shape,
             "rotate_deg": [round(rng.uniform(-60, 60), 1) for _ in range(3)], "translate": v(0.1)}
        if rng.random() < 0.3:
            t["scale"] = round(rng.uniform(0.7, 1.3), 3)
        return t

    os.makedirs(out, exist_ok=True)
    for i in range(count):
        children = [moved(first()), moved(other())]
        if rng.random() < 0.3:
            children.reverse()
        op = rng.choice(["union", "union", "union", "intersection", "difference"])
        if rng.random() < 0.5:
            node = {"type": "smooth", "op": op, "k": round(rng.uniform(0.03, 0.2), 3), "children": children}
        else:
            node = {"type": "blend", "op": op, "p": round(rng.uniform(10, 80), 1), "children": children}
        name = ("r" if rounded else "b") + f"{seed}_{i}.json"
        with open(os.path.join(out, name), "w") as f:
            json.dump({"voxel_size": 0.01, "shape": node}, f)


def main():
    if len(sys.argv) == 5 and sys.argv[4] in ("boxes", "rounded"):
        return capped(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4] == "rounded")
    if len(sys.argv) == 5 and sys.argv[4] == "offsets":
        return blends(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], True)
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    return blends(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], False)


def blends(seed, count, out, offsets):
    """The plain scenes, or with @a offsets each blend shrunk or shelled."""
    rng = random.Random(seed)

    def v(s=0.4):
        return point(rng, s)

    def primitive():
        t = rng.choice(["capped_cylinder", "capped_cone", "capped_cone", "capsule", "torus", "sphere", "box"])
        if t == "capped_cone":
            return {"type": t, "a": v(), "b": v(), "radius_a": round(rng.uniform(0.1, 0.45), 3),
                    "radius_b": round(rng.uniform(0.05, 0.4), 3)}
        if t == "box":
            return {"type": t, "center": v(0.2), "size": sizes(rng, 0.2, 0.7)}
        return common_primitive(rng, t)

    def moved(shape):
        r = rng.random()
        if r < 0.4:
            return shape
        t = {"type": "transform", "child": shape,
             "rotate_deg": [round(rng.uniform(-60, 60), 1) for _ in range(3)], "translate": v(0.1)}
        if r > 0.75:
            t["scale"] = round(rng.uniform(0.7, 1.3), 3)
        return t

    os.makedirs(out, exist_ok=True)
    for i in range(count):
        children = [moved(primitive()) for _ in range(2)]
        op = rng.choice(["union", "union", "intersection", "difference"])
        if rng.random() < 0.5:
            node = {"type": "smooth", "op": op, "k": round(rng.uniform(0.04, 0.2), 3), "children": children}
        else:
            node = {"type": "blend", "op": op, "p": round(rng.uniform(10, 60), 1), "children": children}
        if offsets:
            if rng.random() < 0.75:
                node = {"type": "offset", "child": node, "distance": round(-rng.uniform(0.01, 0.06), 3)}
            else:
                node = {"type": "shell", "child": node, "thickness": round(rng.uniform(0.04, 0.12), 3)}
        if rng.random() < 0.3:
            node = moved(node)
        name = ("o" if offsets else "s") + f"{seed}_{i}.json"
        with open(os.path.join(out, name), "w") as f:
            json.dump({"voxel_size": 0.02, "shape": node}, f)


if __name__ == "__main__":
    main()
