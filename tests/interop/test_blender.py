# SPDX-License-Identifier: Apache-2.0
"""Blender (Debian 12's blender 3.4, headless) opens every kind of .vdb file ivdb writes as a
Volume object with the expected grids; its Volume to Mesh modifier on `surface` (threshold 0)
encloses the analytic volume of a sphere, an ellipsoid and a box within 0.1%, 0.15% and 0.1%; a `--fog` file
renders a non-empty image in Cycles (CPU, 64x64, 4 samples).

One Blender run does all of it (blender_check.py measures, this file asserts): about 2 s of
Blender, 15 s in all with making the files.
Run with /usr/bin/python3: `IVDB_BINARY=build/bin/ivdb /usr/bin/python3 -m unittest -v
test_blender` from this folder.
"""

import json
import math
import os
import unittest

import interop_common as ic

BLENDER_SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "blender_check.py")
# Volume to Mesh against the analytic volume, relative: what docs/interoperability.md states
# (measured 0.072% sphere, 0.113% ellipsoid, 0.059% box, 0.06-0.072% for the sequence's frames).
VOLUME_TOL = {"sphere": 0.001, "ellipsoid": 0.0015, "box": 0.001, "sequence": 0.001}

# Closed shapes for the volume check, a few tens of voxels across their smallest dimension; the
# box's faces lie between voxel centres (half sizes of 31.25, 21.25 and 16.25 voxels).
VOLUME_SHAPES = {
    "sphere": ({"voxel_size": 0.025,
                "shape": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0}},
               4.0 / 3.0 * math.pi),
    "ellipsoid": ({"voxel_size": 0.02, "bounds": {"min": [-1, -1, -1], "max": [1, 1, 1]},
                   "shape": {"type": "ellipsoid", "center": [0, 0, 0],
                             "radii": [0.9, 0.6, 0.4]}},
                  4.0 / 3.0 * math.pi * 0.9 * 0.6 * 0.4),
    "box": ({"voxel_size": 0.02,
             "shape": {"type": "box", "center": [0, 0, 0], "size": [1.25, 0.85, 0.65]}},
            1.25 * 0.85 * 0.65),
}

BLENDER_TYPES = {"float": "FLOAT", "vec3s": "VECTOR_FLOAT"}

# An animated scene whose volume has a closed form at every frame: two spheres of radius R whose
# centres (at +-s on x) approach linearly from 1.2 apart (disjoint) to coincident over 5 frames.
SEQ_R = 0.5
SEQ_FRAMES = 5
SEQUENCE_SCENE = {
    "voxel_size": 0.0125,
    "frames": {"start": 1, "end": SEQ_FRAMES},
    "shape": {"type": "union", "children": [
        {"type": "sphere", "radius": SEQ_R,
         "center": {"keys": [[1, [-0.6, 0, 0]], [SEQ_FRAMES, [0, 0, 0]]]}},
        {"type": "sphere", "radius": SEQ_R,
         "center": {"keys": [[1, [0.6, 0, 0]], [SEQ_FRAMES, [0, 0, 0]]]}}]},
}
SEQ_CHECKED = [1, 3, 4]


def unionOfTwoBalls(r, d):
    """Volume of the union of two balls of radius r whose centres are d apart."""
    ball = 4.0 / 3.0 * math.pi * r ** 3
    lens = math.pi * (4 * r + d) * (2 * r - d) ** 2 / 12 if d < 2 * r else 0.0
    return 2 * ball - lens


class BlenderOpensIvdbFiles(ic.TempDirTestCase):

    @classmethod
    def setUpClass(cls):
        ic.requireIvdb()
        cls.blender = ic.requireProgram("blender", "blender")
        super().setUpClass()
        cls.outputs = ic.makeIvdbOutputs(cls.tmp)
        cls.shapes = {}
        for name, (scene, volume) in VOLUME_SHAPES.items():
            path = cls.path(f"v_{name}.vdb")
            ic.ivdb("rasterize", ic.writeJson(cls.path(f"v_{name}.json"), scene), "-o", path,
                    "-q")
            cls.shapes[name] = (path, volume, scene["voxel_size"])
        fog = cls.outputs["rasterize_fog"][0]
        info = ic.ivdbInfo(fog)["grids"][0]["world_bbox"]
        cls.empties = ic.makeEmptyGridFile(cls.tmp)
        os.makedirs(cls.path("seq"))
        ic.ivdb("rasterize", ic.writeJson(cls.path("seq.json"), SEQUENCE_SCENE), "-o",
                cls.path("seq/balls_####.vdb"), "-q")
        cls.sequenceFirst = cls.path("seq/balls_0001.vdb")
        job = {
            "imports": [path for path, _ in cls.outputs.values()] + list(cls.empties.values()),
            "meshes": [{"file": path, "grid": "surface", "threshold": 0.0}
                       for path, _, _ in cls.shapes.values()],
            "sequences": [{"file": cls.sequenceFirst, "grid": "surface", "threshold": 0.0,
                           "files": [cls.path(f"seq/balls_{k:04d}.vdb")
                                     for k in range(1, SEQ_FRAMES + 1)],
                           "frames": SEQ_CHECKED}],
            "render": {"file": fog, "grid": "density", "size": 64, "samples": 4,
                       "output": cls.path("fog.png"), "bbox_min": info["min"],
                       "bbox_max": info["max"]},
        }
        jobPath = ic.writeJson(cls.path("job.json"), job)
        resultPath = cls.path("result.json")
        proc = ic.run([cls.blender, "-b", "--factory-startup", "--python", BLENDER_SCRIPT,
                       "--", jobPath, resultPath], timeout=600)
        if not os.path.exists(resultPath):
            raise AssertionError(f"blender wrote no result:\n{proc.stdout}\n{proc.stderr}")
        with open(resultPath) as f:
            cls.result = json.load(f)
        if "error" in cls.result:
            raise AssertionError(f"blender_check.py failed:\n{cls.result['error']}")

    def testEveryOutputOpensAsAVolumeWithItsGrids(self):
        imports = {r["file"]: r for r in self.result["imports"]}
        for kind, (path, names) in self.outputs.items():
            with self.subTest(kind=kind):
                r = imports[path]
                self.assertEqual(r["object_type"], "VOLUME")
                self.assertEqual(r["error_message"], "")
                self.assertTrue(r["is_loaded"])
                info = {g["name"]: g for g in ic.ivdbInfo(path)["grids"]}
                self.assertEqual(sorted(g["name"] for g in r["grids"]), sorted(names))
                for grid in r["grids"]:
                    self.assertTrue(grid["is_loaded"], grid["name"])
                    self.assertEqual(grid["data_type"],
                                     BLENDER_TYPES[info[grid["name"]]["value_type"]])
                    # index to object: the voxel size on the diagonal, no offset
                    dx = info[grid["name"]]["voxel_size"][0]
                    m = grid["matrix_object"]
                    for i in range(4):
                        for j in range(4):
                            expected = (dx if i < 3 else 1.0) if i == j else 0.0
                            self.assertAlmostEqual(m[i][j], expected, places=6)

    def testFilesWithAnEmptyGridOpen(self):
        """An empty grid beside a level set, re-saved by `ivdb convert` with each compression
        and half floats: Blender opens the file with both grids."""
        imports = {r["file"]: r for r in self.result["imports"]}
        for kind, path in self.empties.items():
            with self.subTest(kind=kind):
                r = imports[path]
                self.assertEqual(r["object_type"], "VOLUME")
                self.assertEqual(r["error_message"], "")
                self.assertEqual(sorted(g["name"] for g in r["grids"]), ["ball", "empty"])
                self.assertTrue(all(g["is_loaded"] for g in r["grids"]))

    def testVolumeToMeshEnclosesTheAnalyticVolume(self):
        meshes = {r["file"]: r for r in self.result["meshes"]}
        for name, (path, volume, dx) in self.shapes.items():
            with self.subTest(shape=name):
                r = meshes[path]
                self.assertGreater(r["faces"], 1000)
                error = (abs(r["volume"]) - volume) / volume
                self.assertLess(abs(error), VOLUME_TOL[name],
                                f"{name}: Blender's mesh encloses {r['volume']:.6f}, analytic "
                                f"{volume:.6f} ({100 * error:+.3f}%)")
                # centred on the origin within a voxel (Blender 3.4 moves the mesh by half a
                # voxel along each axis, to align it with its voxel display)
                for lo, hi in zip(r["bbox_min"], r["bbox_max"]):
                    self.assertLess(abs((lo + hi) / 2), dx)

    def testSequenceImportsAsOneVolumeThatPlaysTheFrames(self):
        """The frames of a keyed scene import as one Volume object with the sequence's frame
        range; at three scene frames Blender loads that frame's file, and its Volume to Mesh
        encloses the closed-form volume of the union at that frame within 0.1%."""
        r = self.result["sequences"][0]
        self.assertEqual(r["objects_added"], 1)
        self.assertEqual(r["object_type"], "VOLUME")
        self.assertTrue(r["is_sequence"])
        self.assertEqual(r["frame_start"], 1)
        self.assertEqual(r["frame_duration"], SEQ_FRAMES)
        for m in r["frames"]:
            frame = m["scene_frame"]
            with self.subTest(frame=frame):
                self.assertEqual(os.path.realpath(m["frame_filepath"]),
                                 os.path.realpath(self.path(f"seq/balls_{frame:04d}.vdb")))
                s = 0.6 * (SEQ_FRAMES - frame) / (SEQ_FRAMES - 1)
                volume = unionOfTwoBalls(SEQ_R, 2 * s)
                error = (abs(m["volume"]) - volume) / volume
                self.assertLess(abs(error), VOLUME_TOL["sequence"],
                                f"frame {frame}: Blender's mesh encloses {m['volume']:.6f}, "
                                f"analytic {volume:.6f} ({100 * error:+.3f}%)")

    def testFogRendersInCycles(self):
        r = self.result["render"]
        self.assertEqual(r["engine"], "CYCLES")
        self.assertEqual((r["width"], r["height"]), (64, 64))
        self.assertTrue(os.path.getsize(r["output"]) > 0)
        # the unit sphere covers about 30% of the frame; the centre is opaque
        self.assertGreater(r["covered_pixels"], 300)
        self.assertLess(r["covered_pixels"], 64 * 64)
        self.assertGreater(r["centre_alpha"], 0.5)


if __name__ == "__main__":
    unittest.main()
