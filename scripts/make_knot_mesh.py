#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Writes data/meshes/knot.obj, the example mesh asset: a closed tube around a (2, 3) torus knot
(a trefoil), made here rather than downloaded. Usage: scripts/make_knot_mesh.py [OUT.obj]

The tube's rings follow the knot's Frenet frame, which is periodic on this curve (its curvature
never vanishes), so the last ring joins the first and the mesh is closed: every edge is shared by
exactly two triangles."""
import math
import sys
from pathlib import Path

SAMPLES, SIDES = 240, 16          # rings along the knot, vertices per ring
MAJOR, MINOR, TUBE = 0.45, 0.2, 0.075


def knot(t):
    """The (2, 3) torus knot at parameter t in [0, 2 pi)."""
    r = MAJOR + MINOR * math.cos(3 * t)
    return (r * math.cos(2 * t), r * math.sin(2 * t), MINOR * math.sin(3 * t))


def sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def unit(a):
    n = math.sqrt(sum(x * x for x in a))
    return tuple(x / n for x in a)


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "data/meshes/knot.obj"
    h = 1e-4
    vertices, faces = [], []
    for i in range(SAMPLES):
        t = 2 * math.pi * i / SAMPLES
        p, pp, pm = knot(t), knot(t + h), knot(t - h)
        tangent = unit(sub(pp, pm))
        accel = tuple((a - 2 * b + c) / (h * h) for a, b, c in zip(pp, p, pm))
        binormal = unit(cross(tangent, accel))
        normal = cross(binormal, tangent)
        for j in range(SIDES):
            a = 2 * math.pi * j / SIDES
            c, s = math.cos(a) * TUBE, math.sin(a) * TUBE
            vertices.append(tuple(p[k] + c * normal[k] + s * binormal[k] for k in range(3)))
    for i in range(SAMPLES):
        for j in range(SIDES):
            a = i * SIDES + j
            b = i * SIDES + (j + 1) % SIDES
            c = ((i + 1) % SAMPLES) * SIDES + (j + 1) % SIDES
            d = ((i + 1) % SAMPLES) * SIDES + j
            faces += [(a, b, c), (a, c, d)]
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "w") as f:
        f.write("# A tube around a (2, 3) torus knot: scripts/make_knot_mesh.py\n")
        for v in vertices:
            f.write("v %.6f %.6f %.6f\n" % v)
        for a, b, c in faces:
            f.write("f %d %d %d\n" % (a + 1, b + 1, c + 1))
    print("%s: %d vertices, %d triangles" % (out, len(vertices), len(faces)))


if __name__ == "__main__":
    main()
