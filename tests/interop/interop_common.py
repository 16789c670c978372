# SPDX-License-Identifier: Apache-2.0
"""Shared set-up of the interoperability tests: the ivdb binary, the programs they need, every
kind of .vdb file ivdb writes (made once per test class in a temporary folder), and readers of
active voxels through pyopenvdb.

A program the tests need and cannot find is a failure, not a skip: `scripts/deps.sh` installs
them all, so a missing one is a broken set-up.
"""

import json
import os
import shutil
import subprocess
import tempfile
import unittest

import numpy as np

IVDB = os.environ.get("IVDB_BINARY", "/work/main/build/bin/ivdb")
DATA_DIR = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..",
                                         "data"))

# Voxel sizes: a few tens of voxels across each shape, so every file is small and quick.
SPHERE_RADIUS = 1.0
SPHERE_VOXEL = 0.05
PAIR_CENTRES = ((-0.35, 0.0, 0.0), (0.35, 0.0, 0.0))  # data/inputs/sphere_{left,right}.json
PAIR_RADIUS = 0.6
BLEND_P = 20.0
BOX_SIZE = (1.2, 0.8, 0.6)
BOX_VOXEL = 0.04


def requireProgram(name, package):
    """The program's path; fails (never skips) when it is missing."""
    path = shutil.which(name)
    if path is None:
        raise AssertionError(f"{name} not found on PATH: install the Debian package {package} "
                             f"(scripts/deps.sh does)")
    return path


def requireIvdb():
    if not (os.path.isfile(IVDB) and os.access(IVDB, os.X_OK)):
        raise AssertionError(f"ivdb binary {IVDB} missing: build it, or set IVDB_BINARY")
    return IVDB


def importPyopenvdb():
    try:
        import pyopenvdb
    except ImportError as e:
        raise AssertionError(f"import pyopenvdb failed ({e}): install python3-openvdb and run "
                             f"the tests with /usr/bin/python3") from e
    return pyopenvdb


def run(args, cwd=None, expectOk=True, timeout=300):
    """Runs a command; on an unexpected exit status fails with the command and its output."""
    proc = subprocess.run([str(a) for a in args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)
    if expectOk and proc.returncode != 0:
        raise AssertionError(f"command failed with status {proc.returncode}:\n  "
                             f"{' '.join(str(a) for a in args)}\nstdout:\n{proc.stdout}"
                             f"\nstderr:\n{proc.stderr}")
    return proc


def ivdb(*args, **kwargs):
    return run([IVDB, *args], **kwargs)


def ivdbInfo(path):
    return json.loads(ivdb("info", path, "--json").stdout)


def writeJson(path, obj):
    with open(path, "w") as f:
        json.dump(obj, f)
    return path


def makeIvdbOutputs(folder):
    """Every kind of .vdb file ivdb writes, from small scenes. Returns {kind: (path, grid names
    in the order ivdb writes them)}; the inputs (sphere, pair, box) are kinds too."""
    join = lambda name: os.path.join(folder, name)
    sphereScene = os.path.join(DATA_DIR, "sphere.json")
    left = os.path.join(DATA_DIR, "inputs", "sphere_left.json")
    right = os.path.join(DATA_DIR, "inputs", "sphere_right.json")
    boxScene = writeJson(join("box.json"), {
        "voxel_size": BOX_VOXEL, "shape": {"type": "box", "center": [0, 0, 0],
                                           "size": list(BOX_SIZE)}})
    v = str(SPHERE_VOXEL)
    out = {}

    def make(kind, grids, *args):
        path = join(kind + ".vdb")
        ivdb(*args, "-o", path, "-q")
        out[kind] = (path, grids)

    make("rasterize", ["surface"], "rasterize", sphereScene, "--voxel-size", v)
    make("rasterize_fog", ["density", "surface"], "rasterize", sphereScene, "--voxel-size", v,
         "--fog")
    make("rasterize_dense", ["surface"], "rasterize", sphereScene, "--voxel-size", v,
         "--sampling", "dense")
    make("rasterize_box", ["surface"], "rasterize", boxScene)
    make("left", ["surface"], "rasterize", left, "--voxel-size", v)
    make("right", ["surface"], "rasterize", right, "--voxel-size", v)
    make("rasterize_bound", ["surface"], "rasterize", os.path.join(DATA_DIR, "fig1_union.json"),
         "--voxel-size", v, "--distance", "bound")
    a, b = out["left"][0], out["right"][0]
    for op in ("union", "intersection", "difference"):
        make("csg_" + op, ["surface"], "csg", op, a, b)
        make("blend_" + op, ["surface"], "blend", op, a, b, "-p", str(BLEND_P))
    make("csg_union_fog", ["density", "surface"], "csg", "union", a, b, "--fog")
    make("blend_union_fog", ["density", "surface"], "blend", "union", a, b, "-p", str(BLEND_P),
         "--fog")
    s = out["rasterize"][0]
    make("gradient", ["gradient"], "gradient", s)
    make("gradient_step2", ["gradient"], "gradient", s, "--step", "2")
    make("gradient_all", ["gradient", "gradient_magnitude", "surface"], "gradient", s,
         "--magnitude", "--with-input")
    for method in ("mean", "gaussian", "laplacian"):
        make("curvature_" + method, ["curvature"], "curvature", s, "--method", method)
    make("curvature_principal", ["k1", "k2"], "curvature", s, "--method", "principal")
    make("curvature_with_input", ["curvature", "surface"], "curvature", s, "--with-input")
    # The output options (issue 15): each compression, half floats, on level sets, fog volumes
    # and vector grids; and `ivdb convert` re-saving files of several grids.
    make("rasterize_zip", ["surface"], "rasterize", sphereScene, "--voxel-size", v,
         "--compression", "zip")
    make("rasterize_none", ["surface"], "rasterize", sphereScene, "--voxel-size", v,
         "--compression", "none")
    make("rasterize_half", ["surface"], "rasterize", sphereScene, "--voxel-size", v, "--half")
    make("gradient_half", ["gradient"], "gradient", s, "--half")
    make("gradient_zip", ["gradient", "gradient_magnitude"], "gradient", s, "--magnitude",
         "--compression", "zip")
    make("csg_union_fog_half", ["density", "surface"], "csg", "union", a, b, "--fog", "--half")
    make("convert_none", ["gradient", "gradient_magnitude", "surface"], "convert",
         out["gradient_all"][0], "--compression", "none")
    make("convert_zip_half", ["density", "surface"], "convert", out["csg_union_fog"][0],
         "--compression", "zip", "--half")
    return out


# What each output-option kind re-saves, and how close its values must be (half floats: within
# 2^-11 of the value, relative, plus the smallest normal half's spacing near zero).
VARIANTS = {
    "rasterize_zip": ("rasterize", False), "rasterize_none": ("rasterize", False),
    "rasterize_half": ("rasterize", True), "gradient_half": ("gradient", True),
    "gradient_zip": ("gradient_all", False), "csg_union_fog_half": ("csg_union_fog", True),
    "convert_none": ("gradient_all", False), "convert_zip_half": ("csg_union_fog", True),
}


def makeEmptyGridFile(folder):
    """A file with an empty float grid beside a small level set, made by pyopenvdb, re-saved by
    `ivdb convert` with each compression and with half floats. Returns {kind: path}."""
    vdb = importPyopenvdb()
    empty = vdb.FloatGrid(0.5)
    empty.name = "empty"
    ball = vdb.createLevelSetSphere(radius=0.5, center=(0, 0, 0), voxelSize=0.1, halfWidth=3)
    ball.name = "ball"
    source = os.path.join(folder, "empty_source.vdb")
    vdb.write(source, grids=[empty, ball])
    out = {}
    for kind, args in (("empty_blosc", []), ("empty_zip", ["--compression", "zip"]),
                       ("empty_none", ["--compression", "none"]), ("empty_half", ["--half"])):
        path = os.path.join(folder, kind + ".vdb")
        ivdb("convert", source, "-o", path, "-q", *args)
        out[kind] = path
    return out


def activeVoxels(grid):
    """(ijk int64 N x 3, values N or N x 3) of every active voxel, active tiles expanded."""
    coords, values = [], []
    for item in grid.iterOnValues():
        lo, hi = item["min"], item["max"]
        if item["count"] == 1:
            coords.append(lo)
            values.append(item["value"])
        else:
            r = [np.arange(lo[i], hi[i] + 1) for i in range(3)]
            ijk = np.stack(np.meshgrid(*r, indexing="ij"), -1).reshape(-1, 3)
            coords.extend(map(tuple, ijk))
            values.extend([item["value"]] * len(ijk))
    return np.asarray(coords, dtype=np.int64).reshape(-1, 3), np.asarray(values, dtype=np.float64)


def voxelMap(grid):
    """{(i, j, k): value} of every active voxel."""
    ijk, values = activeVoxels(grid)
    return {tuple(c): val for c, val in zip(ijk.tolist(), values)}


def readGrids(path):
    """{name: grid} of a file, read with pyopenvdb."""
    vdb = importPyopenvdb()
    grids, _ = vdb.readAll(path)
    return {g.name: g for g in grids}


def sortedVoxels(grid):
    """activeVoxels sorted by (i, j, k)."""
    ijk, values = activeVoxels(grid)
    order = np.lexsort((ijk[:, 2], ijk[:, 1], ijk[:, 0]))
    return ijk[order], values[order]


def compareVoxels(testCase, gridA, gridB, tol, what):
    """Asserts the same active voxels and values within tol; returns (voxels, max |difference|)."""
    (ia, va), (ib, vb) = sortedVoxels(gridA), sortedVoxels(gridB)
    if ia.shape != ib.shape or not np.array_equal(ia, ib):
        a, b = set(map(tuple, ia.tolist())), set(map(tuple, ib.tolist()))
        onlyA, onlyB = sorted(a - b), sorted(b - a)
        testCase.fail(f"{what}: active voxels differ: {len(onlyA)} only in the first, "
                      f"{len(onlyB)} only in the second (e.g. {onlyA[:3]} / {onlyB[:3]})")
    worst = float(np.abs(va - vb).max()) if len(va) else 0.0
    testCase.assertLessEqual(worst, tol, f"{what}: max |difference| {worst:.3g} over "
                             f"{len(va)} voxels")
    return len(va), worst


def denseValues(grid, lo, hi):
    """The grid's values (active or not) over the index box [lo, hi], as a dense array."""
    shape = tuple(int(b - a + 1) for a, b in zip(lo, hi))
    if grid.valueTypeName == "vec3s":
        shape += (3,)
    array = np.zeros(shape, dtype=np.float32)
    grid.copyToArray(array, ijk=tuple(lo))
    return array


def assertSameGrid(testCase, gridA, gridB, what):
    """Same type, class, transform, active voxel count and bounding box, and bit-identical
    values over that box (one pass through OpenVDB's copyToArray, quicker than voxel maps)."""
    testCase.assertEqual(gridA.valueTypeName, gridB.valueTypeName, what)
    testCase.assertEqual(gridA.gridClass, gridB.gridClass, what)
    testCase.assertEqual(gridA.transform.info(), gridB.transform.info(), what)
    testCase.assertEqual(gridA.activeVoxelCount(), gridB.activeVoxelCount(), what)
    box = gridA.evalActiveVoxelBoundingBox()
    testCase.assertEqual(box, gridB.evalActiveVoxelBoundingBox(), what)
    testCase.assertTrue(np.array_equal(denseValues(gridA, *box), denseValues(gridB, *box)),
                        f"{what}: values differ")


def meshObjVolume(path):
    """Enclosed volume of an OBJ mesh (fan-triangulated faces, divergence theorem)."""
    verts, faces = [], []
    with open(path) as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                verts.append([float(x) for x in parts[1:4]])
            elif parts[0] == "f":
                faces.append([int(p.split("/")[0]) - 1 for p in parts[1:]])
    v = np.asarray(verts)
    total = 0.0
    for face in faces:
        p0 = v[face[0]]
        for i in range(1, len(face) - 1):
            total += np.dot(p0, np.cross(v[face[i]], v[face[i + 1]])) / 6.0
    return total, len(verts), len(faces)


class TempDirTestCase(unittest.TestCase):
    """A test class with its own temporary folder (removed at the end)."""

    @classmethod
    def setUpClass(cls):
        cls._tmp = tempfile.TemporaryDirectory(prefix="ivdb_interop_")
        cls.tmp = cls._tmp.name

    @classmethod
    def tearDownClass(cls):
        cls._tmp.cleanup()

    @classmethod
    def path(cls, name):
        return os.path.join(cls.tmp, name)
