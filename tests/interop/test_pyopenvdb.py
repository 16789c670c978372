# SPDX-License-Identifier: Apache-2.0
"""OpenVDB's Python module (Debian's python3-openvdb, `import pyopenvdb`) reads every kind of
.vdb file ivdb writes: grid names, classes, value types, transforms and bounding boxes agree with
`ivdb info --json`, and the values at the active voxels agree with closed forms.

Run with /usr/bin/python3 (Debian's pyopenvdb is built for it): from this folder,
`IVDB_BINARY=build/bin/ivdb /usr/bin/python3 -m unittest -v test_pyopenvdb`.
"""

import unittest

import numpy as np

import interop_common as ic

DX = ic.SPHERE_VOXEL
BG = np.float32(3 * DX)  # the default half width, 3 voxels, in world units, as stored (float)
VALUE_TOL = 1e-5  # stored floats against closed forms evaluated in double
DISTANCE_TOL = 1e-8  # exact distances (sphere, box): float rounding of the double value only
CURVATURE_TOL = 0.0014  # the sphere's curvatures at interior voxels, relative (measured 0.138%)


def sphereDistance(ijk, dx=DX, centre=(0.0, 0.0, 0.0), radius=ic.SPHERE_RADIUS):
    return np.linalg.norm(ijk * dx - np.asarray(centre), axis=1) - radius


def boxDistance(ijk, dx, size):
    q = np.abs(ijk * dx) - np.asarray(size) / 2
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)


def pairDistances(ijk):
    """Distances to the left and right spheres of data/inputs/."""
    a, b = ic.PAIR_CENTRES
    return (sphereDistance(ijk, centre=a, radius=ic.PAIR_RADIUS),
            sphereDistance(ijk, centre=b, radius=ic.PAIR_RADIUS))


def clampBand(d):
    """A level set's value at a voxel: the distance in the band, +/- background outside it."""
    return np.clip(d, -float(BG), float(BG))


class PyopenvdbReadsIvdb(ic.TempDirTestCase):

    @classmethod
    def setUpClass(cls):
        ic.requireIvdb()
        cls.vdb = ic.importPyopenvdb()
        super().setUpClass()
        cls.outputs = ic.makeIvdbOutputs(cls.tmp)

    def grids(self, kind):
        return ic.readGrids(self.outputs[kind][0])

    def grid(self, kind, name):
        return self.grids(kind)[name]

    # --- what every file says about itself ------------------------------------------------------

    def testEveryFileAgreesWithIvdbInfo(self):
        """Names (in order), class, value type, voxel size, active voxels, memory, background,
        index and world bounding boxes: pyopenvdb and `ivdb info --json` agree on every grid."""
        for kind, (path, expectedNames) in self.outputs.items():
            with self.subTest(kind=kind):
                grids, fileMeta = self.vdb.readAll(path)
                info = ic.ivdbInfo(path)["grids"]
                self.assertEqual([g.name for g in grids], expectedNames)
                self.assertEqual([g["name"] for g in info], expectedNames)
                self.assertTrue(str(fileMeta.get("creator", "")).startswith("ivdb "), fileMeta)
                for grid, gi in zip(grids, info):
                    where = f"{kind}: grid {grid.name}"
                    self.assertEqual(gi["class"], grid.gridClass, where)
                    self.assertEqual(gi["value_type"], grid.valueTypeName, where)
                    self.assertEqual(grid.metadata.get("name"), grid.name, where)
                    self.assertEqual(gi["active_voxels"], grid.activeVoxelCount(), where)
                    # in-core memory: what OpenVDB recorded when the file was written
                    self.assertEqual(gi["memory_bytes"], grid.metadata["file_mem_bytes"], where)
                    for a, b in zip(gi["voxel_size"], grid.transform.voxelSize()):
                        self.assertAlmostEqual(a, b, places=12, msg=where)
                    lo, hi = grid.evalActiveVoxelBoundingBox()
                    self.assertEqual(gi["index_bbox"]["min"], list(lo), where)
                    self.assertEqual(gi["index_bbox"]["max"], list(hi), where)
                    for key, corner in (("min", lo), ("max", hi)):
                        world = grid.transform.indexToWorld(corner)
                        for a, b in zip(gi["world_bbox"][key], world):
                            self.assertAlmostEqual(a, b, places=6, msg=where)
                    if grid.valueTypeName == "float":
                        self.assertAlmostEqual(gi["background"], grid.background, places=7,
                                               msg=where)

    def testIvdbInfoReportsLeafCountAndBackgroundOfEveryGrid(self):
        """`ivdb info` counts the leaves and gives the background of every grid, vector grids
        included (it once reported 0 leaves and no background for vec3s grids)."""
        for kind, (path, _) in self.outputs.items():
            grids = {g.name: g for g in self.vdb.readAll(path)[0]}
            for gi in ic.ivdbInfo(path)["grids"]:
                with self.subTest(kind=kind, grid=gi["name"], field="leaf_nodes"):
                    self.assertEqual(gi["leaf_nodes"], grids[gi["name"]].leafCount())
                with self.subTest(kind=kind, grid=gi["name"], field="background"):
                    self.assertIn("background", gi)

    def testTransformsAreUniformScaleWithVoxelCentresAtIndexTimesVoxelSize(self):
        for kind, (path, _) in self.outputs.items():
            for grid in self.vdb.readAll(path)[0]:
                with self.subTest(kind=kind, grid=grid.name):
                    t = grid.transform
                    self.assertTrue(t.isLinear)
                    self.assertEqual(t.typeName, "UniformScaleMap")
                    dx = t.voxelSize()[0]
                    for ijk in ((0, 0, 0), (3, -5, 7), (-20, 11, 2)):
                        for a, b in zip(t.indexToWorld(ijk), ijk):
                            self.assertAlmostEqual(a, b * dx, places=12)

    def testClassesAndMetadataOfEachKindOfGrid(self):
        """Level sets are `level set`, fog volumes `fog volume` with background 0, gradients
        covariant world-space vectors; the metadata the README lists is there."""
        for kind, (path, _) in self.outputs.items():
            for grid in self.vdb.readAll(path)[0]:
                with self.subTest(kind=kind, grid=grid.name):
                    meta = grid.metadata
                    self.assertIn("ivdb_version", meta)
                    self.assertIn("ivdb_source", meta)
                    for key in ("file_bbox_min", "file_bbox_max", "file_voxel_count",
                                "file_mem_bytes", "file_compression"):
                        self.assertIn(key, meta)
                    if grid.name == "surface":
                        self.assertEqual(grid.gridClass, "level set")
                        bg = float(BG) if kind != "rasterize_box" else 3 * ic.BOX_VOXEL
                        # Half floats round the background too, as OpenVDB writes them.
                        half = meta.get("is_saved_as_half_float", False)
                        self.assertAlmostEqual(grid.background, bg,
                                               delta=bg * 2.0 ** -11 if half else 1e-6)
                    elif grid.name == "density":
                        self.assertEqual(grid.gridClass, "fog volume")
                        self.assertEqual(grid.background, 0.0)
                    elif grid.name == "gradient":
                        self.assertEqual(grid.valueTypeName, "vec3s")
                        self.assertEqual(grid.vectorType, "covariant")
                        self.assertEqual(meta.get("vector_type"), "covariant")
                        self.assertIs(meta.get("is_local_space"), False)
                        self.assertIn("ivdb_step_voxels", meta)
                    elif grid.name in ("curvature", "k1", "k2"):
                        self.assertIn("ivdb_curvature", meta)
                    if kind.startswith("rasterize"):
                        self.assertIn("ivdb_scene", meta)
                        self.assertIn("ivdb_sampling", meta)

    # --- Houdini's conventions (Houdini itself is not available; see the README) ----------------

    def testHoudiniConventions(self):
        """What Houdini's VDB primitive reads: the grid name (its `name` attribute), `class`
        (vdb_class: level sets display as surfaces, fog volumes as smoke), `vector_type` and
        `is_local_space` on vector grids (vdb_vector_type: how Transform moves them; a gradient
        is covariant), uniform voxels for level sets, fog values in [0, 1], and metadata of
        types Houdini turns into primitive attributes (string, bool, int, float, vectors)."""
        vectorTypes = {"invariant", "covariant", "covariant normalize", "contravariant relative",
                       "contravariant absolute"}
        for kind, (path, _) in self.outputs.items():
            for grid in self.vdb.readAll(path)[0]:
                with self.subTest(kind=kind, grid=grid.name):
                    meta = grid.metadata
                    self.assertEqual(meta.get("name"), grid.name)
                    for key, value in meta.items():
                        self.assertIsInstance(value, (str, bool, int, float, tuple), key)
                    if grid.gridClass == "level set":
                        self.assertEqual(grid.valueTypeName, "float")
                        dx = grid.transform.voxelSize()
                        self.assertEqual(dx[0], dx[1])
                        self.assertEqual(dx[0], dx[2])
                        self.assertGreater(grid.background, 0)
                    if grid.gridClass == "fog volume":
                        lo, hi = grid.evalMinMax()
                        self.assertGreaterEqual(lo, 0.0)
                        self.assertLessEqual(hi, 1.0)
                    if grid.valueTypeName == "vec3s":
                        self.assertIn(meta.get("vector_type"), vectorTypes)
                        self.assertIn("is_local_space", meta)
                    if grid.name in ("surface", "density"):
                        self.assertIn(grid.gridClass, ("level set", "fog volume"))

    def testEveryGridNamesItsCreator(self):
        """Houdini convention: OpenVDB's grid-level `creator` metadata (GridBase::setCreator;
        Houdini's vdb_creator intrinsic) names ivdb on every grid, besides the file's."""
        for kind, (path, _) in self.outputs.items():
            for grid in self.vdb.readAll(path)[0]:
                with self.subTest(kind=kind, grid=grid.name):
                    self.assertTrue(grid.creator.startswith("ivdb "), repr(grid.creator))

    # --- values against closed forms ------------------------------------------------------------

    def testSphereIsItsSignedDistanceOnExactlyTheBand(self):
        """|x| - r at every active voxel; active exactly where |d| < background (in float)."""
        for kind in ("rasterize", "rasterize_dense"):
            with self.subTest(kind=kind):
                grid = self.grid(kind, "surface")
                ijk, values = ic.activeVoxels(grid)
                err = np.abs(values - sphereDistance(ijk)).max()
                self.assertLess(err, DISTANCE_TOL)
                r = np.arange(-25, 26)
                every = np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3)
                inBand = np.abs(np.float32(sphereDistance(every))) < BG
                self.assertEqual(int(inBand.sum()), grid.activeVoxelCount())

    def testBoxIsItsSignedDistance(self):
        ijk, values = ic.activeVoxels(self.grid("rasterize_box", "surface"))
        err = np.abs(values - boxDistance(ijk, ic.BOX_VOXEL, ic.BOX_SIZE)).max()
        self.assertLess(err, DISTANCE_TOL)

    def testFogIsTheRampInsideTheSurface(self):
        """sdfToFogVolume: min(1, -d / background) inside, active exactly where d < 0."""
        for kind, distance in (("rasterize_fog", lambda ijk: sphereDistance(ijk)),
                               ("csg_union_fog", lambda ijk: np.minimum(*pairDistances(ijk)))):
            with self.subTest(kind=kind):
                grid = self.grid(kind, "density")
                ijk, values = ic.activeVoxels(grid)
                d = distance(ijk)
                self.assertLess(np.abs(values - np.clip(-d / float(BG), 0, 1)).max(), VALUE_TOL)
                self.assertTrue(np.all(np.float32(d) <= 0))
        grid = self.grid("rasterize_fog", "density")
        r = np.arange(-25, 26)
        every = np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3)
        self.assertEqual(int((np.float32(sphereDistance(every)) < 0).sum()),
                         grid.activeVoxelCount())

    def testSharpCsgIsMinMaxOfTheInputDistances(self):
        """csg union = min, intersection = max, difference = max(A, -B), of the spheres'
        distances clamped to the band; `rasterize --distance bound` of fig1_union the same min."""
        ops = {"csg_union": lambda a, b: np.minimum(a, b),
               "csg_intersection": lambda a, b: np.maximum(a, b),
               "csg_difference": lambda a, b: np.maximum(a, -b),
               "rasterize_bound": lambda a, b: np.minimum(a, b)}
        for kind, op in ops.items():
            with self.subTest(kind=kind):
                ijk, values = ic.activeVoxels(self.grid(kind, "surface"))
                self.assertGreater(len(values), 1000)
                expected = clampBand(op(*pairDistances(ijk)))
                self.assertLess(np.abs(values - expected).max(), VALUE_TOL)

    def testBlendIsSharpAwayFromTheCreaseAndSignedRightNearIt(self):
        """Away from the crease (the two terms more than 0.6 apart, beyond the blend's reach of
        0.35 at p = 20) the blend equals the sharp operation; everywhere its sign is the analytic
        blend's where both are over a voxel from zero, and near the surface it is within half a
        voxel of the first-order distance f / |grad f|."""
        p = ic.BLEND_P
        for op in ("union", "intersection", "difference"):
            with self.subTest(op=op):
                ijk, values = ic.activeVoxels(self.grid("blend_" + op, "surface"))
                a, b = pairDistances(ijk)
                if op == "difference":
                    b = -b
                sign = -1.0 if op == "union" else 1.0  # union: soft min; others: soft max
                sharp = np.minimum(a, b) if op == "union" else np.maximum(a, b)
                far = np.abs(a - b) > 0.6
                self.assertGreater(far.sum(), 20)
                self.assertLess(np.abs(values[far] - clampBand(sharp[far])).max(), VALUE_TOL)
                # f = s (1/p) ln(exp(s p a) + exp(s p b)), evaluated around the extreme term.
                m = np.maximum(sign * p * a, sign * p * b)
                f = sign * (m + np.log(np.exp(sign * p * a - m) + np.exp(sign * p * b - m))) / p
                wa = np.exp(sign * p * a - m)
                wb = np.exp(sign * p * b - m)
                centres = [np.asarray(c) for c in ic.PAIR_CENTRES]
                x = ijk * DX
                na = (x - centres[0]) / np.linalg.norm(x - centres[0], axis=1)[:, None]
                nb = (x - centres[1]) / np.linalg.norm(x - centres[1], axis=1)[:, None]
                if op == "difference":
                    nb = -nb
                grad = (wa[:, None] * na + wb[:, None] * nb) / (wa + wb)[:, None]
                estimate = f / np.linalg.norm(grad, axis=1)
                clear = (np.abs(values) > DX) & (np.abs(f) > DX)
                self.assertTrue(np.all(np.sign(values[clear]) == np.sign(f[clear])))
                near = np.abs(estimate) < 0.5 * DX
                self.assertGreater(near.sum(), 100)
                self.assertLess(np.abs(values[near] - estimate[near]).max(), 0.5 * DX)

    def testShrunkNotchIsNeverFartherThanItsSurface(self):
        """`offset` -0.05 of a box minus a box over one of its corners, rotated: the smaller box
        minus the notch grown by 0.05 (a rounded box). Against 2 M points of that surface (the
        smaller box's faces outside the grown notch, the grown notch's surface inside the smaller
        box, 1.5e-3 apart): no voxel farther than its nearest surface point (before: 2,922
        voxels up to 0.8 voxel too far), none nearer than the samples' spacing allows, signs
        right, and the band whole."""
        from scipy.spatial import cKDTree
        dx, delta, h = 0.01, 0.05, 0.0015
        bigC, bigHalf = np.zeros(3), np.array([1.0, 0.8, 0.6]) / 2
        cutC, cutHalf = np.array([0.4, 0.3, 0.2]), np.array([0.25, 0.25, 0.25])
        rotate = [10.0, 20.0, 30.0]
        scene = ic.writeJson(self.path("notch_offset.json"), {
            "voxel_size": dx, "shape": {"type": "transform", "rotate_deg": rotate, "child": {
                "type": "offset", "distance": -delta, "child": {"type": "difference", "children": [
                    {"type": "box", "center": list(bigC), "size": list(bigHalf * 2)},
                    {"type": "box", "center": list(cutC), "size": list(cutHalf * 2)}]}}}})
        out = self.path("notch_offset.vdb")
        ic.ivdb("rasterize", scene, "-o", out, "-q")
        ijk, values = ic.activeVoxels(ic.readGrids(out)["surface"])

        def boxDist(p, c, half):
            q = np.abs(p - c) - half
            return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)

        def faces(c, half, step):
            pts = []
            for k in range(3):
                u, v = [e for e in range(3) if e != k]
                gu, gv = (np.linspace(c[e] - half[e], c[e] + half[e],
                                      int(np.ceil(2 * half[e] / step)) + 1) for e in (u, v))
                U, V = np.meshgrid(gu, gv, indexing="ij")
                for s in (-1.0, 1.0):
                    p = np.zeros((U.size, 3))
                    p[:, u], p[:, v], p[:, k] = U.ravel(), V.ravel(), c[k] + s * half[k]
                    pts.append(p)
            return np.concatenate(pts)

        inner = bigHalf - delta
        smaller = faces(bigC, inner, h)
        smaller = smaller[boxDist(smaller, cutC, cutHalf) >= delta]
        # The grown notch's surface: each point of the box grown by delta moved onto it along
        # the direction from its nearest point of the notch (flat faces stay h/2 apart, the
        # rounded edges and corners closer).
        grown = faces(cutC, cutHalf + delta, h / 2)
        foot = np.clip(grown, cutC - cutHalf, cutC + cutHalf)
        away = grown - foot
        grown = foot + away * (delta / np.linalg.norm(away, axis=1)[:, None])
        grown = grown[boxDist(grown, bigC, inner) <= 0]
        tree = cKDTree(np.concatenate([smaller, grown]))
        a, b, c = np.radians(rotate)
        rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
        ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
        rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
        local = (ijk * dx) @ (rz @ ry @ rx)  # R^T p, row by row
        nearest, _ = tree.query(local)
        excess = (np.abs(values) - nearest) / dx
        self.assertLess(excess.max(), 1e-4)                 # never farther than the surface
        self.assertGreater(excess.min(), -h / np.sqrt(2) / dx)  # a sample within h / sqrt(2)
        inside = (boxDist(local, bigC, inner) < 0) & (boxDist(local, cutC, cutHalf) > delta)
        clear = nearest > h
        self.assertTrue(np.all((values[clear] < 0) == inside[clear]))
        # The band whole: every voxel of a cube around the shape within 3 voxels (less the
        # samples' spacing) of the surface samples is active.
        r = np.arange(-64, 65)  # the smaller box's half diagonal is 58 voxels
        every = np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3)
        d, _ = tree.query((every * dx) @ (rz @ ry @ rx), distance_upper_bound=3 * dx)
        want = {tuple(v) for v in every[d < 3 * dx - h].tolist()}
        self.assertEqual(want - set(map(tuple, ijk.tolist())), set())

    def testGradientIsTheCentralDifferenceOfTheClampedDistance(self):
        """(phi(x + K) - phi(x - K)) / (2 K dx) per axis, phi the sphere's distance clamped to
        the band (neighbours outside it read the clamped background), at every active voxel."""
        for kind, step in (("gradient", 1), ("gradient_step2", 2), ("gradient_all", 1)):
            with self.subTest(kind=kind):
                ijk, values = ic.activeVoxels(self.grid(kind, "gradient"))
                expected = np.empty_like(values)
                for axis in range(3):
                    e = np.zeros(3, dtype=np.int64)
                    e[axis] = step
                    phi = lambda c: clampBand(np.float32(sphereDistance(c)))
                    expected[:, axis] = (phi(ijk + e) - phi(ijk - e)) / (2 * step * DX)
                self.assertLess(np.abs(values - expected).max(), VALUE_TOL)
                # and the unit normal x/|x| where the stencil stays in the band
                inner = np.abs(sphereDistance(ijk)) < float(BG) - (step + 0.5) * DX
                normal = ijk * DX / np.linalg.norm(ijk * DX, axis=1)[:, None]
                self.assertLess(np.abs(values[inner] - normal[inner]).max(), 0.01)
        grids = self.grids("gradient_all")
        gradient = ic.voxelMap(grids["gradient"])
        magnitude = ic.voxelMap(grids["gradient_magnitude"])
        self.assertEqual(set(gradient), set(magnitude))
        worst = max(abs(np.linalg.norm(gradient[k]) - magnitude[k]) for k in gradient)
        self.assertLess(worst, 1e-6)
        ic.compareVoxels(self, grids["surface"], self.grid("rasterize", "surface"), 0.0,
                         "gradient --with-input: the copied surface")

    def testCurvaturesAreTheSpheresAtInteriorVoxels(self):
        """At voxels whose 3x3x3 stencil stays in the band, on the iso-sphere of radius
        rho = |x|: mean 1/rho, Gaussian 1/rho^2, principal 1/rho each, Laplacian 2/rho, within
        0.14% (second-order stencils at 20 voxels a unit)."""
        cases = [("curvature_mean", "curvature", 1), ("curvature_with_input", "curvature", 1),
                 ("curvature_gaussian", "curvature", 2), ("curvature_laplacian", "curvature", 1),
                 ("curvature_principal", "k1", 1), ("curvature_principal", "k2", 1)]
        for kind, name, power in cases:
            with self.subTest(kind=kind, grid=name):
                grid = self.grid(kind, name)
                ijk, values = ic.activeVoxels(grid)
                self.assertEqual(len(values), self.grid("rasterize", "surface").activeVoxelCount())
                rho = np.linalg.norm(ijk * DX, axis=1)
                inner = np.abs(rho - ic.SPHERE_RADIUS) < float(BG) - 2 * DX
                self.assertGreater(inner.sum(), 5000)
                expected = (2.0 if kind == "curvature_laplacian" else 1.0) / rho ** power
                rel = np.abs(values[inner] - expected[inner]) / expected[inner]
                self.assertLess(rel.max(), CURVATURE_TOL)
        ic.compareVoxels(self, self.grid("curvature_with_input", "surface"),
                         self.grid("rasterize", "surface"), 0.0,
                         "curvature --with-input: the copied surface")

    def testAHalfFloatCopyWrittenByPyopenvdbKeepsTheValues(self):
        """pyopenvdb writes ivdb's level set back with saveFloatAsHalf (the
        `is_saved_as_half_float` metadata) and reads it again: values within half precision."""
        grid = self.grid("rasterize", "surface")
        grid.saveFloatAsHalf = True
        path = self.path("half_copy.vdb")
        self.vdb.write(path, grids=[grid])
        again = self.vdb.read(path, "surface")
        self.assertIs(again.metadata.get("is_saved_as_half_float"), True)
        ic.compareVoxels(self, again, self.grid("rasterize", "surface"), 2e-4,
                         "half-float copy")

    def testOutputOptionsKeepTheValues(self):
        """Each compression and `--half`, on every kind of grid: the values of the default
        (blosc) file, exactly, or within half precision (2^-11 relative; absolute near zero)."""
        for kind, (base, half) in ic.VARIANTS.items():
            grids, baseGrids = self.grids(kind), self.grids(base)
            for name, grid in grids.items():
                with self.subTest(kind=kind, grid=name):
                    self.assertIs(bool(grid.metadata.get("is_saved_as_half_float", False)), half)
                    ia, va = ic.sortedVoxels(grid)
                    ib, vb = ic.sortedVoxels(baseGrids[name])
                    self.assertTrue(np.array_equal(ia, ib), "active voxels differ")
                    if not half:
                        self.assertTrue(np.array_equal(va, vb), "values differ")
                    else:
                        err = np.abs(va - vb)
                        bound = np.maximum(np.abs(vb), 6.2e-5) * 2.0 ** -11
                        self.assertTrue(np.all(err <= bound), f"max error {err.max():.3g}")

    def testEmptyGridsSurviveEveryOutputOption(self):
        """An empty grid (made by pyopenvdb) re-saved by `ivdb convert` with each compression
        and half floats: still there, empty, with its background; the level set beside it
        unchanged (exactly, or within half precision)."""
        for kind, path in ic.makeEmptyGridFile(self.tmp).items():
            with self.subTest(kind=kind):
                grids = ic.readGrids(path)
                self.assertEqual(sorted(grids), ["ball", "empty"])
                self.assertEqual(grids["empty"].activeVoxelCount(), 0)
                self.assertAlmostEqual(grids["empty"].background, 0.5)
                original = ic.readGrids(self.path("empty_source.vdb"))["ball"]
                ic.compareVoxels(self, grids["ball"], original,
                                 3 * 0.1 * 2.0 ** -11 if kind == "empty_half" else 0.0, kind)


if __name__ == "__main__":
    unittest.main()
