# SPDX-License-Identifier: Apache-2.0
"""OpenVDB's own command-line tools (Debian's libopenvdb-tools) and ivdb read each other's files,
and where vdb_tool computes the same thing (sharp CSG without rebuild, gradient, mean curvature)
ivdb's values equal its values within 1e-5 at every active voxel, with the same active voxels.

Run with /usr/bin/python3: `IVDB_BINARY=build/bin/ivdb /usr/bin/python3 -m unittest -v
test_vdb_tool` from this folder.
"""

import math
import os
import re
import unittest

import numpy as np

import interop_common as ic

SAME_TOL = 1e-5  # ivdb against vdb_tool on the same input

# Enclosed volumes of ivdb's outputs (the `surface` grid): a sphere of radius 1; the two spheres
# of radius 0.6 whose centres are 0.7 apart, their lens and one minus the other; the box.
SPHERE_VOLUME = 4.0 / 3.0 * math.pi
_r, _d = ic.PAIR_RADIUS, 0.7
LENS_VOLUME = math.pi * (4 * _r + _d) * (2 * _r - _d) ** 2 / 12
BALL_VOLUME = 4.0 / 3.0 * math.pi * _r ** 3
SURFACE_VOLUMES = {
    "rasterize": SPHERE_VOLUME, "rasterize_fog": SPHERE_VOLUME, "rasterize_dense": SPHERE_VOLUME,
    "rasterize_box": np.prod(ic.BOX_SIZE), "left": BALL_VOLUME, "right": BALL_VOLUME,
    "rasterize_bound": 2 * BALL_VOLUME - LENS_VOLUME, "csg_union": 2 * BALL_VOLUME - LENS_VOLUME,
    "csg_union_fog": 2 * BALL_VOLUME - LENS_VOLUME, "csg_intersection": LENS_VOLUME,
    "csg_difference": BALL_VOLUME - LENS_VOLUME, "gradient_all": SPHERE_VOLUME,
    "curvature_with_input": SPHERE_VOLUME,
}
# Shapes without sharp edges: their meshes' volumes are within 1%; volumeToMesh cuts the box's
# edges and the CSG creases, at 20-25 voxels a unit, by up to 2%.
SMOOTH = {"rasterize", "rasterize_fog", "rasterize_dense", "left", "right", "gradient_all",
          "curvature_with_input"}
ELLIPSOID_RADII = (0.9, 0.6, 0.4)  # data/fig2_ellipsoid.json


def summaryNumber(pattern, text):
    match = re.search(pattern, text)
    if not match:
        raise AssertionError(f"no '{pattern}' in ivdb's summary line: {text!r}")
    return float(match.group(1))


class VdbToolInterop(ic.TempDirTestCase):

    @classmethod
    def setUpClass(cls):
        ic.requireIvdb()
        cls.vdbTool = ic.requireProgram("vdb_tool", "libopenvdb-tools")
        cls.vdbPrint = ic.requireProgram("vdb_print", "libopenvdb-tools")
        cls.vdb = ic.importPyopenvdb()
        super().setUpClass()
        cls.outputs = ic.makeIvdbOutputs(cls.tmp)

        # Files made by OpenVDB's own tools: {name: (path, grid name, analytic enclosed volume)}.
        p = cls.path
        cls.theirs = {}
        cls.tool("-sphere", "voxel=0.05", "radius=1", "-write", p("vt_sphere.vdb"))
        cls.theirs["sphere"] = (p("vt_sphere.vdb"), "sphere", SPHERE_VOLUME)
        cls.tool("-platonic", "faces=6", "voxel=0.05", "scale=1.2", "-write", p("vt_cube.vdb"))
        cls.theirs["cube"] = (p("vt_cube.vdb"), "Cube", 1.2 ** 3)
        cls.tool("-platonic", "faces=4", "voxel=0.05", "-write", p("vt_tetra.vdb"))
        cls.theirs["tetrahedron"] = (p("vt_tetra.vdb"), "Tetrahedron", None)
        # half floats: vdb_tool's 16-bit write sets the grids' saveFloatAsHalf
        cls.tool("-sphere", "voxel=0.05", "radius=0.8", "center=(0.3,0,0)", "-write", "bits=16",
                 p("vt_half.vdb"))
        cls.theirs["half"] = (p("vt_half.vdb"), "sphere", 4.0 / 3.0 * math.pi * 0.8 ** 3)
        # a mesh from ivdb (OBJ) turned into a level set by vdb_tool
        ellipsoid = p("ellipsoid.vdb")
        ic.ivdb("rasterize", os.path.join(ic.DATA_DIR, "fig2_ellipsoid.json"), "--voxel-size",
                "0.04", "-o", ellipsoid, "-q")
        ic.ivdb("mesh", ellipsoid, "-o", p("ellipsoid.obj"), "-q")
        cls.tool("-read", p("ellipsoid.obj"), "-mesh2ls", "voxel=0.04", "-write",
                 p("vt_mesh2ls.vdb"))
        cls.theirs["mesh2ls"] = (p("vt_mesh2ls.vdb"), "mesh2ls_ellipsoid",
                                 4.0 / 3.0 * math.pi * np.prod(ELLIPSOID_RADII))
        cls.ellipsoid = ellipsoid
        # two grids, the vector one first
        cls.tool("-sphere", "voxel=0.05", "radius=1", "-grad", "keep=1", "-write",
                 p("vt_multi.vdb"))
        cls.theirs["multi"] = (p("vt_multi.vdb"), "sphere", SPHERE_VOLUME)

    @classmethod
    def tool(cls, *args):
        return ic.run([cls.vdbTool, "-quiet", *args])

    # --- OpenVDB's tools read ivdb's files --------------------------------------------------------

    def testVdbPrintListsEveryIvdbOutput(self):
        for kind, (path, names) in self.outputs.items():
            with self.subTest(kind=kind):
                out = ic.run([self.vdbPrint, "-l", "-m", path]).stdout
                self.assertEqual(re.findall(r"^Name: (\S+)$", out, re.M), names)
                self.assertIn("creator: ivdb", out)

    def testVdbPrintListsEmptyGridsIvdbResaves(self):
        """`ivdb convert` keeps an empty grid with each compression and half floats."""
        for kind, path in ic.makeEmptyGridFile(self.tmp).items():
            with self.subTest(kind=kind):
                out = ic.run([self.vdbPrint, "-l", "-m", path]).stdout
                self.assertEqual(re.findall(r"^Name: (\S+)$", out, re.M), ["ball", "empty"])
                empty = out[out.index("Name: empty"):]
                self.assertIn("Tree is empty!", empty)
                self.assertIn("Background value: 0.5", empty)

    def testVdbToolMeshesEveryIvdbLevelSet(self):
        """`vdb_tool -read OUT.vdb -ls2mesh -write x.obj` on every output holding a level set,
        with the enclosed volume within 1% of the analytic one (3% with sharp edges)."""
        for kind, (path, names) in self.outputs.items():
            if "surface" not in names:
                continue
            with self.subTest(kind=kind):
                obj = self.path(f"ls2mesh_{kind}.obj")
                self.tool("-read", path, "-ls2mesh", "-write", obj)
                volume, verts, faces = ic.meshObjVolume(obj)
                volume = abs(volume)  # vdb_tool's OBJ faces are clockwise seen from outside
                self.assertGreater(faces, 500)
                if kind in SURFACE_VOLUMES:
                    expected = SURFACE_VOLUMES[kind]
                    tol = 0.01 if kind in SMOOTH else 0.03
                    self.assertLess(abs(volume - expected) / expected, tol,
                                    f"vdb_tool's mesh of {kind}: volume {volume}, analytic "
                                    f"{expected}")

    def testVdbToolReadsAndRewritesEveryIvdbOutput(self):
        """Files without a level set too (gradients, curvatures): vdb_tool reads every grid and
        writes them back unchanged."""
        for kind, (path, names) in self.outputs.items():
            with self.subTest(kind=kind):
                copy = self.path(f"rewritten_{kind}.vdb")
                self.tool("-read", path, "-write", copy)
                mine, theirs = ic.readGrids(path), ic.readGrids(copy)
                self.assertEqual(sorted(theirs), sorted(names))
                for name in names:
                    ic.assertSameGrid(self, mine[name], theirs[name], f"{kind}:{name}")

    # --- ivdb reads OpenVDB's files ---------------------------------------------------------------

    def testIvdbInfoDescribesVdbToolFiles(self):
        for key, (path, name, _) in self.theirs.items():
            with self.subTest(file=key):
                info = {g["name"]: g for g in ic.ivdbInfo(path)["grids"]}
                grid = ic.readGrids(path)[name]
                self.assertEqual(info[name]["class"], "level set")
                self.assertEqual(info[name]["value_type"], "float")
                self.assertEqual(info[name]["active_voxels"], grid.activeVoxelCount())
                lo, hi = grid.evalActiveVoxelBoundingBox()
                self.assertEqual(info[name]["index_bbox"], {"min": list(lo), "max": list(hi)})
        half = ic.readGrids(self.theirs["half"][0])["sphere"]
        self.assertIs(half.metadata.get("is_saved_as_half_float"), True)

    def testIvdbGradientCurvatureMeshRenderOnVdbToolFiles(self):
        """gradient, curvature, mesh and render on each file, the level set picked by default
        (and by --grid NAME for two files); the mesh's enclosed volume is analytic's within
        1%."""
        for key, (path, name, volume) in self.theirs.items():
            named = [["--grid", name]] if key in ("multi", "cube") else []
            for gridArgs in [[]] + named:
                with self.subTest(file=key, grid=gridArgs):
                    tag = f"{key}{'_named' if gridArgs else ''}"
                    source = ic.readGrids(path)[name]
                    grad = self.path(f"{tag}_grad.vdb")
                    ic.ivdb("gradient", path, "-o", grad, "-q", *gridArgs)
                    g = ic.readGrids(grad)["gradient"]
                    self.assertEqual(g.activeVoxelCount(), source.activeVoxelCount())
                    self.assertEqual(g.metadata.get("ivdb_source"), f"{path}:{name}")
                    curv = self.path(f"{tag}_curv.vdb")
                    ic.ivdb("curvature", path, "-o", curv, "-q", *gridArgs)
                    c = ic.readGrids(curv)["curvature"]
                    self.assertEqual(c.activeVoxelCount(), source.activeVoxelCount())
                    obj = self.path(f"{tag}.obj")
                    out = ic.ivdb("mesh", path, "-o", obj, *gridArgs).stdout
                    enclosed = summaryNumber(r"enclosed volume ([-0-9.e+]+)", out)
                    if volume is not None:
                        # mesh2ls is meshed twice (ivdb's OBJ, then this): 2%, else 1%
                        tol = 0.02 if key == "mesh2ls" else 0.01
                        self.assertLess(abs(enclosed - volume) / volume, tol,
                                        f"ivdb mesh {path}: volume {enclosed}, analytic {volume}")
                    png = self.path(f"{tag}.png")
                    out = ic.ivdb("render", path, "-o", png, "--size", "64x48", *gridArgs).stdout
                    self.assertGreater(summaryNumber(r"(\d+) pixels on the surface", out), 100)
                    self.assertGreater(os.path.getsize(png), 100)

    def testIvdbCurvatureAndGradientOfVdbToolSpheresAreAnalytic(self):
        """On vdb_tool's spheres (full and half float), at voxels whose stencil stays in the
        band: the gradient is the unit normal within 0.01, the mean curvature 1/rho within 0.5%
        (3% from half floats: their rounding, up to 6e-5 at 0.1, is amplified by the second
        differences)."""
        for key, radius, centre, tol in (("sphere", 1.0, (0, 0, 0), 0.005),
                                         ("half", 0.8, (0.3, 0, 0), 0.03)):
            with self.subTest(file=key):
                path = self.theirs[key][0]
                grad, curv = self.path(f"an_{key}_grad.vdb"), self.path(f"an_{key}_curv.vdb")
                ic.ivdb("gradient", path, "-o", grad, "-q")
                ic.ivdb("curvature", path, "-o", curv, "-q")
                ijk, g = ic.activeVoxels(ic.readGrids(grad)["gradient"])
                x = ijk * 0.05 - np.asarray(centre)
                rho = np.linalg.norm(x, axis=1)
                inner = np.abs(rho - radius) < 0.15 - 2 * 0.05
                self.assertLess(np.abs(g[inner] - (x / rho[:, None])[inner]).max(), 0.01)
                ijk, k = ic.activeVoxels(ic.readGrids(curv)["curvature"])
                rho = np.linalg.norm(ijk * 0.05 - np.asarray(centre), axis=1)
                inner = np.abs(rho - radius) < 0.15 - 2 * 0.05
                self.assertLess(np.abs(k[inner] * rho[inner] - 1).max(), tol)

    def testIvdbCsgAndBlendOnVdbToolFiles(self):
        """Inputs named other than `surface`, with different names, half floats, and different
        voxel sizes (mesh2ls at 0.04 with spheres at 0.05: resampled)."""
        t = self.theirs
        cases = [
            ("csg", "union", t["sphere"][0], t["cube"][0]),
            ("csg", "difference", t["mesh2ls"][0], t["half"][0]),
            ("csg", "intersection", t["tetrahedron"][0], t["multi"][0]),
            ("blend", "union", t["sphere"][0], t["half"][0]),
            ("blend", "difference", t["cube"][0], t["tetrahedron"][0]),
        ]
        for command, op, a, b in cases:
            with self.subTest(command=command, op=op, a=os.path.basename(a),
                              b=os.path.basename(b)):
                out = self.path(f"{command}_{op}_{os.path.basename(a)}")
                extra = ["-p", "20"] if command == "blend" else []
                ic.ivdb(command, op, a, b, "-o", out, "-q", *extra)
                grid = ic.readGrids(out)["surface"]
                self.assertEqual(grid.gridClass, "level set")
                self.assertGreater(grid.activeVoxelCount(), 1000)

    def testIvdbReadsAHalfFloatFileWrittenByPyopenvdb(self):
        """ivdb's own sphere written back by pyopenvdb with saveFloatAsHalf: every command
        reads it, and its gradient equals the gradient of the half-rounded values."""
        grid = ic.readGrids(self.outputs["rasterize"][0])["surface"]
        grid.saveFloatAsHalf = True
        half = self.path("py_half.vdb")
        self.vdb.write(half, grids=[grid])
        ic.ivdb("info", half)
        ic.ivdb("csg", "union", half, self.outputs["left"][0], "-o", self.path("py_u.vdb"), "-q")
        ic.ivdb("blend", "union", half, self.outputs["left"][0], "-p", "20", "-o",
                self.path("py_b.vdb"), "-q")
        ic.ivdb("mesh", half, "-o", self.path("py_half.obj"), "-q")
        ic.ivdb("render", half, "-o", self.path("py_half.png"), "--size", "32x32", "-q")
        ic.ivdb("gradient", half, "-o", self.path("py_half_grad.vdb"), "-q")
        self.tool("-read", half, "-grad", "-write", self.path("py_half_vt_grad.vdb"))
        ic.compareVoxels(self, ic.readGrids(self.path("py_half_grad.vdb"))["gradient"],
                         self.vdb.readAll(self.path("py_half_vt_grad.vdb"))[0][0], SAME_TOL,
                         "gradient of a half-float file")

    # --- the same operation, ivdb against vdb_tool ----------------------------------------------

    def compareWithVdbTool(self, ivdbArgs, toolArgs, ivdbGrid, what):
        mine, theirs = self.path(f"cmp_{what}_ivdb.vdb"), self.path(f"cmp_{what}_vt.vdb")
        ic.ivdb(*ivdbArgs, "-o", mine, "-q")
        self.tool(*toolArgs, "-write", theirs)
        theirGrids = self.vdb.readAll(theirs)[0]
        self.assertEqual(len(theirGrids), 1)
        return ic.compareVoxels(self, ic.readGrids(mine)[ivdbGrid], theirGrids[0], SAME_TOL,
                                what)

    def testCsgEqualsVdbToolWithoutRebuild(self):
        """`vdb_tool -union/-intersection/-difference rebuild=false` keeps OpenVDB's combined
        values, as `ivdb csg` does. vdb_tool's difference is (age 0) minus (age 1), so
        A - B reads B first."""
        pairs = {"ivdb": (self.outputs["left"][0], self.outputs["right"][0]),
                 "vdbtool": (self.theirs["sphere"][0], self.theirs["cube"][0])}
        for source, (a, b) in pairs.items():
            for op in ("union", "intersection", "difference"):
                with self.subTest(inputs=source, op=op):
                    first, second = (b, a) if op == "difference" else (a, b)
                    self.compareWithVdbTool(
                        ["csg", op, a, b], ["-read", first, second, f"-{op}", "rebuild=false"],
                        "surface", f"csg_{op}_{source}")

    def testGradientEqualsVdbToolGrad(self):
        for key, path in (("ivdb_ellipsoid", self.ellipsoid),
                          ("mesh2ls", self.theirs["mesh2ls"][0]),
                          ("half", self.theirs["half"][0])):
            with self.subTest(input=key):
                self.compareWithVdbTool(["gradient", path], ["-read", path, "-grad"],
                                        "gradient", f"grad_{key}")

    def testMeanCurvatureEqualsVdbToolCurvature(self):
        for key, path in (("ivdb_ellipsoid", self.ellipsoid),
                          ("mesh2ls", self.theirs["mesh2ls"][0]),
                          ("half", self.theirs["half"][0])):
            with self.subTest(input=key):
                self.compareWithVdbTool(["curvature", path, "--method", "mean"],
                                        ["-read", path, "-curvature"], "curvature",
                                        f"curvature_{key}")


if __name__ == "__main__":
    unittest.main()
