# SPDX-License-Identifier: Apache-2.0
"""NanoVDB's own tools (Debian's libnanovdb-tools) read the .nvdb files `ivdb convert` writes:
nanovdb_validate passes every grid, nanovdb_print lists them, and nanovdb_convert turns them back
into .vdb files whose values, read by pyopenvdb, equal the source's at every active voxel.

Run with /usr/bin/python3: from this folder,
`IVDB_BINARY=build/bin/ivdb /usr/bin/python3 -m unittest -v test_nanovdb`.
"""

import re
import unittest

import interop_common as ic

# A level set, a fog volume beside one, a vector grid with its magnitude and a level set, and
# half floats: the grid kinds ivdb writes.
KINDS = ("rasterize", "rasterize_fog", "gradient_all", "curvature_principal", "rasterize_half",
         "csg_union_fog_half")


class NanoVdbReadsIvdbExports(ic.TempDirTestCase):

    @classmethod
    def setUpClass(cls):
        ic.requireIvdb()
        cls.validate = ic.requireProgram("nanovdb_validate", "libnanovdb-tools")
        cls.print = ic.requireProgram("nanovdb_print", "libnanovdb-tools")
        cls.convert = ic.requireProgram("nanovdb_convert", "libnanovdb-tools")
        super().setUpClass()
        cls.outputs = ic.makeIvdbOutputs(cls.tmp)
        cls.nvdb = {}
        for kind in KINDS:
            path = cls.path(kind + ".nvdb")
            ic.ivdb("convert", cls.outputs[kind][0], "-o", path, "-q")
            cls.nvdb[kind] = path

    def testValidateAndPrintEveryGrid(self):
        for kind, path in self.nvdb.items():
            names = self.outputs[kind][1]
            with self.subTest(kind=kind):
                out = ic.run([self.validate, "-v", path]).stdout
                for name in names:
                    self.assertIn(f'Grid named "{name}": passed', out)
                self.assertNotIn("failed", out)
                listing = ic.run([self.print, path]).stdout
                rows = re.findall(r"^\d+\s+(\S+)\s+(\S+)\s+(\S+)", listing, re.M)
                self.assertEqual(sorted(r[0] for r in rows), sorted(names))
                info = {g["name"]: g for g in ic.ivdbInfo(self.outputs[kind][0])["grids"]}
                for name, nanoType, nanoClass in rows:
                    self.assertEqual(nanoType, {"float": "float", "vec3s": "Vec3f"}[
                        info[name]["value_type"]], name)
                    if info[name]["class"] == "level set":
                        self.assertEqual(nanoClass, "SDF", name)
                    self.assertIn(str(info[name]["active_voxels"]), listing)

    def testNanoVdbConvertBackGivesTheSourceValues(self):
        for kind, path in self.nvdb.items():
            with self.subTest(kind=kind):
                back = self.path(f"back_{kind}.vdb")
                ic.run([self.convert, "-f", path, back])
                source, again = ic.readGrids(self.outputs[kind][0]), ic.readGrids(back)
                self.assertEqual(sorted(again), sorted(source))
                for name in source:
                    ic.compareVoxels(self, again[name], source[name], 0.0, f"{kind}:{name}")


if __name__ == "__main__":
    unittest.main()
