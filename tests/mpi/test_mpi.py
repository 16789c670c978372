# SPDX-License-Identifier: Apache-2.0
"""ivdb-mpi against plain ivdb (issue 16): for 1 to 4 ranks (oversubscribed on small machines),
`mpirun -np N ivdb-mpi rasterize` writes the file `ivdb rasterize` writes, byte for byte but the
random UUID, for exact distances, true distances (CSG, quadrics, blends, a mesh), the bound mode,
every compression and half floats; pyopenvdb reads it; bad input fails on every rank with one
message and writes nothing.

Run by ctest with IVDB_BINARY and IVDB_MPI_BINARY set; mpirun must be on PATH (openmpi-bin)."""

import os
import shutil
import subprocess
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "..", "data")
IVDB = os.environ["IVDB_BINARY"]
IVDB_MPI = os.environ["IVDB_MPI_BINARY"]

# Open MPI refuses to run as root without these; more ranks than cores need oversubscription.
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_rmaps_base_oversubscribe="1")

# The UUID: 36 bytes after the magic number, the format and library versions and a flag.
UUID = slice(21, 57)


def data(name):
    return os.path.join(DATA, name)


def mpi(ranks, *args):
    return subprocess.run(["mpirun", "--oversubscribe", "--bind-to", "none", "-np", str(ranks), IVDB_MPI, *args],
                          capture_output=True, text=True, env=ENV, timeout=600)


def ivdb(*args):
    return subprocess.run([IVDB, *args], capture_output=True, text=True, timeout=600)


def masked(path):
    with open(path, "rb") as f:
        b = bytearray(f.read())
    b[UUID] = b"-" * 36
    return bytes(b)


class TestMpiRasterize(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.mkdtemp(prefix="ivdb-mpi-")

    def tearDown(self):
        shutil.rmtree(self.dir, ignore_errors=True)

    def path(self, name):
        return os.path.join(self.dir, name)

    def no_temporaries(self):
        left = [f for f in os.listdir(self.dir) if ".tmp-" in f]
        self.assertEqual(left, [], "temporary files left behind")

    def same_as_ivdb(self, scene, *options, ranks=(1, 2, 3, 4)):
        want = self.path("ivdb.vdb")
        r = ivdb("rasterize", scene, "-o", want, "-q", *options)
        self.assertEqual(r.returncode, 0, r.stderr)
        expected = masked(want)
        for n in ranks:
            out = self.path("mpi_%d.vdb" % n)
            r = mpi(n, "rasterize", scene, "-o", out, *options)
            what = "%s %s on %d ranks" % (os.path.basename(scene), " ".join(options), n)
            self.assertEqual(r.returncode, 0, what + ": " + r.stderr)
            self.assertIn("on %d ranks" % n, r.stdout, what)
            got = masked(out)
            self.assertEqual(len(got), len(expected), what)
            if got != expected:
                first = next(i for i in range(len(got)) if got[i] != expected[i])
                self.fail("%s: first difference at byte %d of %d" % (what, first, len(got)))
            with open(want, "rb") as a, open(out, "rb") as b:
                self.assertNotEqual(a.read()[UUID], b.read()[UUID], what + ": a new UUID")
        self.no_temporaries()
        return out

    def test_exact_distances(self):
        # Inside tiles at every level: a sphere 300 voxels across.
        self.same_as_ivdb(data("sphere.json"), "--voxel-size", "0.0066")
        self.same_as_ivdb(data("torus_box.json"), "--voxel-size", "0.02", ranks=(2, 3))

    def test_true_distances(self):
        self.same_as_ivdb(data("fig1_union.json"))
        self.same_as_ivdb(data("fig1_difference.json"), ranks=(3,))
        self.same_as_ivdb(data("fig2_ellipsoid.json"), "--voxel-size", "0.02")
        self.same_as_ivdb(data("fig5_blend_union.json"), "--voxel-size", "0.02", ranks=(2, 4))
        self.same_as_ivdb(data("fig2_cylinder.json"), "--voxel-size", "0.04", ranks=(3,))
        # A wider band, where plain ivdb fast-sweeps the voxels the local search does not reach
        # near the clipping box's edges: refused, not approximated.
        r = ivdb("rasterize", data("fig2_cylinder.json"), "-o", self.path("wide.vdb"),
                 "--voxel-size", "0.04", "--half-width", "5")
        self.assertEqual(r.returncode, 0, r.stderr)
        swept = int(r.stdout.split("lattice search")[1].split(",")[1].split()[0])
        self.assertGreater(swept, 0, r.stdout)
        message = self.errors(["rasterize", data("fig2_cylinder.json"), "-o", "OUT",
                               "--voxel-size", "0.04", "--half-width", "5"])
        self.assertIn("%d voxels" % swept, message)

    def test_mesh_and_bound_mode(self):
        self.same_as_ivdb(data("knot_smooth.json"), "--voxel-size", "0.02", ranks=(2, 3))
        self.same_as_ivdb(data("fig1_union.json"), "--distance", "bound", ranks=(2, 3))

    def test_a_level_set_on_the_lattice_is_copied(self):
        # A scene that is only a .vdb level set on the output's lattice and band is its own
        # raster: rank 0 copies it, as ivdb does.
        source = self.path("source.vdb")
        r = ivdb("rasterize", data("sphere.json"), "-o", source, "-q")
        self.assertEqual(r.returncode, 0, r.stderr)
        scene = self.path("copy.json")
        with open(scene, "w") as f:
            f.write('{"voxel_size": 0.01, "shape": {"type": "vdb", "file": "source.vdb"}}')
        self.same_as_ivdb(scene, ranks=(1, 3))

    def test_compression_and_half_floats(self):
        self.same_as_ivdb(data("fig1_union.json"), "--compression", "zip", "--half", ranks=(3,))
        out = self.same_as_ivdb(data("sphere.json"), "--compression", "none", ranks=(2,))
        import pyopenvdb as vdb
        grid = vdb.read(out, "surface")
        self.assertEqual(grid.gridClass, vdb.GridClass.LEVEL_SET)
        self.assertGreater(grid.activeVoxelCount(), 100000)

    def test_per_rank_report(self):
        r = mpi(3, "rasterize", data("sphere.json"), "-o", self.path("s.vdb"), "--per-rank")
        self.assertEqual(r.returncode, 0, r.stderr)
        lines = [l for l in r.stdout.splitlines() if l.strip().startswith("rank ")]
        self.assertEqual(len(lines), 3, r.stdout)
        voxels = sum(int(l.split(",")[1].split()[0]) for l in lines)
        total = int(r.stdout.split(":")[1].split()[0])
        self.assertEqual(voxels, total)
        # --json: the same figures, with bytes; the leaves split evenly and add up.
        import json
        r = mpi(3, "rasterize", data("sphere.json"), "-o", self.path("s.vdb"), "--json")
        self.assertEqual(r.returncode, 0, r.stderr)
        j = json.loads(r.stdout)
        self.assertEqual(j["ranks"], 3)
        self.assertEqual(j["active_voxels"], total)
        self.assertEqual(j["file_bytes"], os.path.getsize(self.path("s.vdb")))
        self.assertEqual([x["rank"] for x in j["per_rank"]], [0, 1, 2])
        self.assertEqual(sum(x["active_voxels"] for x in j["per_rank"]), total)
        self.assertLessEqual(sum(x["leaves"] for x in j["per_rank"]), j["leaves"])
        self.assertTrue(all(x["peak_memory_bytes"] > 10**6 for x in j["per_rank"]))

    def test_plan_estimates_each_ranks_voxels(self):
        # `ivdb plan --ranks 4` is the split ivdb-mpi uses: its estimate of each rank's active
        # voxels within 10% of what the rank builds (issue 16's acceptance), for exact and true
        # distances, a blend and a mesh.
        import json
        for scene, options in ((data("sphere.json"), []), (data("fig1_union.json"), []),
                               (data("fig2_ellipsoid.json"), []),
                               (data("fig5_blend_union.json"), []),
                               (data("knot_smooth.json"), ["--voxel-size", "0.016"])):
            r = ivdb("plan", scene, "--ranks", "4", "--json", *options)
            self.assertEqual(r.returncode, 0, r.stderr)
            plan = json.loads(r.stdout)
            r = mpi(4, "rasterize", scene, "-o", self.path("p.vdb"), "--json", *options)
            self.assertEqual(r.returncode, 0, r.stderr)
            built = json.loads(r.stdout)
            self.assertEqual(plan["leaves"], built["leaves"], scene)
            for p, b in zip(plan["per_rank"], built["per_rank"]):
                self.assertLess(abs(p["active_voxels"] / b["active_voxels"] - 1.0), 0.10,
                                "%s rank %d: %s" % (scene, b["rank"], (p, b)))

    def test_ranks_bound_to_one_core_get_a_note(self):
        # mpirun binds up to two ranks to one core each by default: their threads would share
        # it. Rank 0 says how to give them the machine's cores.
        if (os.cpu_count() or 1) < 2:
            self.skipTest("one core: nothing to share")
        out = self.path("s.vdb")
        r = subprocess.run(["mpirun", "--bind-to", "core", "-np", "1", IVDB_MPI, "rasterize",
                            data("sphere.json"), "-o", out, "-q"],
                           capture_output=True, text=True, env=ENV, timeout=600)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("ivdb-mpi: note: mpirun bound each rank to 1 of", r.stderr)
        self.assertIn("--bind-to none", r.stderr)
        r = mpi(1, "rasterize", data("sphere.json"), "-o", out, "-q")
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertNotIn("note:", r.stderr)

    def test_a_killed_rank_ends_the_run_and_writes_nothing(self):
        # Rank 1 is killed (SIGKILL) while the ranks rasterize: Open MPI stops the others, the run
        # fails, and the output keeps its old contents.
        scene = self.path("big.json")
        with open(scene, "w") as f:
            f.write('{"voxel_size": 0.001, "shape": {"type": "sphere", "radius": 1}}')
        out = self.path("kept.vdb")
        with open(out, "wb") as f:
            f.write(b"old contents")
        rank = ('if [ "$OMPI_COMM_WORLD_RANK" = 1 ]; then "$0" "$@" & sleep 1; kill -9 $!; wait; '
                'exit 137; fi; exec "$0" "$@"')
        r = subprocess.run(["mpirun", "--oversubscribe", "--bind-to", "none", "-np", "3", "sh", "-c",
                            rank, IVDB_MPI, "rasterize", scene, "-o", out],
                           capture_output=True, text=True, env=ENV, timeout=600)
        self.assertNotEqual(r.returncode, 0, r.stdout)
        self.assertNotIn("active voxels", r.stdout)
        with open(out, "rb") as f:
            self.assertEqual(f.read(), b"old contents")

    def errors(self, args, ranks=3):
        """Run a failing command: every rank fails, rank 0 says why once, nothing is written and an
        existing output is left as it was."""
        out = self.path("kept.vdb")
        with open(out, "wb") as f:
            f.write(b"old contents")
        r = mpi(ranks, *[a.replace("OUT", out) for a in args])
        self.assertNotEqual(r.returncode, 0, r.stdout)
        errors = [l for l in r.stderr.splitlines() if "error:" in l]
        self.assertEqual(len(errors), 1, repr(r.stderr))
        self.assertTrue(errors[0].startswith("ivdb-mpi: error: "), r.stderr)
        with open(out, "rb") as f:
            self.assertEqual(f.read(), b"old contents")
        self.no_temporaries()
        return errors[0]

    def test_bad_input_fails_on_every_rank_and_writes_nothing(self):
        self.assertIn("missing.json", self.errors(["rasterize", self.path("missing.json"), "-o", "OUT"]))
        self.assertIn("--voxel-size", self.errors(["rasterize", data("sphere.json"), "-o", "OUT",
                                                    "--voxel-size", "-1"]))
        self.assertIn("--sampling", self.errors(["rasterize", data("sphere.json"), "-o", "OUT",
                                                 "--sampling", "dense"]))
        bad = self.path("bad.json")
        with open(bad, "w") as f:
            f.write('{"voxel_size": 0.01, "shape": {"type": "sphere", "radius": -1}}')
        self.assertIn("bad.json", self.errors(["rasterize", bad, "-o", "OUT"]))
        # Zero sets without an inside (a point, a double plane), found only once the ranks have
        # built their leaves: no rank saw a negative value, so the grid is empty.
        for matrix in ("[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,0]]",
                       "[[1,0,0,0],[0,0,0,0],[0,0,0,0],[0,0,0,0]]"):
            point = self.path("point.json")
            with open(point, "w") as f:
                f.write('{"voxel_size": 0.05, "bounds": {"min": [-1, -1, -1], "max": [1, 1, 1]}, '
                        '"shape": {"type": "quadric", "matrix": %s}}' % matrix)
            self.assertIn("no voxels", self.errors(["rasterize", point, "-o", "OUT"]))
        self.assertIn("unknown command", self.errors(["plan", data("sphere.json")]))
        # An output folder that does not exist.
        r = mpi(2, "rasterize", data("sphere.json"), "-o", self.path("nowhere/out.vdb"))
        self.assertNotEqual(r.returncode, 0)
        self.assertEqual(len([l for l in r.stderr.splitlines() if "error:" in l]), 1, r.stderr)


if __name__ == "__main__":
    unittest.main()
