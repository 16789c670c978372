# SPDX-License-Identifier: Apache-2.0
"""ivdb-mpi against plain ivdb (issue 16): for 1 to 4 ranks (oversubscribed on small machines),
`mpirun -np N ivdb-mpi rasterize` writes the file `ivdb rasterize` writes, byte for byte but the
random UUID, for exact distances, true distances (CSG, quadrics, blends, a mesh), the bound mode,
every compression and half floats; pyopenvdb reads it; bad input fails on every rank with one
message and writes nothing. The same for `ivdb-mpi gradient`, `curvature`, `csg` and `blend`
against plain ivdb's, on files ivdb and OpenVDB wrote, and for a keyed scene's frames.

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


class MpiCase(unittest.TestCase):
    """What the suites share: files in self.dir, and running a command under ivdb and ivdb-mpi."""

    def path(self, name):
        return os.path.join(self.dir, name)

    def no_temporaries(self):
        left = [f for f in os.listdir(self.dir) if ".tmp-" in f]
        self.assertEqual(left, [], "temporary files left behind")

    def same_bytes(self, command, source, *options, ranks=(1, 2, 3, 4)):
        """`ivdb COMMAND SOURCE ...` and `ivdb-mpi COMMAND SOURCE ...` on each number of ranks
        write the same file but for its UUID; returns the last ivdb-mpi file."""
        want = self.path("ivdb.vdb")
        r = ivdb(command, source, "-o", want, "-q", *options)
        self.assertEqual(r.returncode, 0, r.stderr)
        expected = masked(want)
        for n in ranks:
            out = self.path("mpi_%d.vdb" % n)
            r = mpi(n, command, source, "-o", out, *options)
            what = "%s %s %s on %d ranks" % (command, os.path.basename(source), " ".join(options), n)
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


class TestMpiRasterize(MpiCase):
    def setUp(self):
        self.dir = tempfile.mkdtemp(prefix="ivdb-mpi-")

    def tearDown(self):
        shutil.rmtree(self.dir, ignore_errors=True)

    def same_as_ivdb(self, scene, *options, ranks=(1, 2, 3, 4)):
        return self.same_bytes("rasterize", scene, *options, ranks=ranks)

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
        # Wider bands, where the voxels the local search does not reach (inside the clipped
        # paraboloid's bowl, beyond the lattice search's window) are fast-swept together (every
        # rank sweeps all of them and keeps its own), as plain ivdb sweeps them: 68 of them, and
        # 11,988 (some leaves left with none in the band), with a fog volume.
        import json
        for options, ranks, least in ((("--voxel-size", "0.04", "--half-width", "5"), (1, 2, 3, 4), 10),
                                      (("--voxel-size", "0.03", "--half-width", "10", "--fog"), (3,), 5000)):
            r = ivdb("rasterize", data("fig2_paraboloid.json"), "-o", self.path("wide.vdb"), *options)
            self.assertEqual(r.returncode, 0, r.stderr)
            swept = int(r.stdout.split("lattice search")[1].split(",")[1].split()[0])
            self.assertGreater(swept, least, r.stdout)
            self.same_as_ivdb(data("fig2_paraboloid.json"), *options, ranks=ranks)
            if "--fog" in options:
                continue
            r = mpi(3, "rasterize", data("fig2_paraboloid.json"), "-o", self.path("wide.vdb"),
                    "--json", *options)
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertEqual(json.loads(r.stdout)["swept_distances"], swept)

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

    def test_fog_volume(self):
        # --fog: the 'density' grid plain ivdb makes (OpenVDB's sdfToFogVolume), each rank
        # turning its own leaves into the fog's: a sphere 666 voxels across (inside tiles active
        # in 128^3 and 4096^3 nodes), a union, half floats with zip, and a sphere 4 voxels across
        # whose voxels never reach the band's inner edge (the ramp ends at its lowest value).
        out = self.same_as_ivdb(data("sphere.json"), "--fog", "--voxel-size", "0.003", ranks=(1, 3))
        import pyopenvdb as vdb
        fog = vdb.read(out, "density")
        self.assertEqual(fog.gridClass, vdb.GridClass.FOG_VOLUME)
        acc = fog.getAccessor()
        self.assertEqual(acc.getValue((0, 0, 0)), 1.0)  # deep inside: an active tile
        self.assertTrue(acc.isValueOn((0, 0, 0)))
        self.assertEqual(acc.getValue((400, 0, 0)), 0.0)  # outside
        self.assertGreater(acc.getValue((332, 0, 0)), 0.0)  # the ramp, just inside the surface
        self.assertLess(acc.getValue((332, 0, 0)), 1.0)
        self.same_as_ivdb(data("fig1_union.json"), "--fog")
        self.same_as_ivdb(data("fig5_blend_union.json"), "--fog", "--half", "--compression", "zip",
                          "--voxel-size", "0.02", ranks=(2, 4))
        tiny = self.path("tiny.json")
        with open(tiny, "w") as f:
            f.write('{"voxel_size": 0.02, "shape": {"type": "sphere", "radius": 0.04}}')
        self.same_as_ivdb(tiny, "--fog", ranks=(1, 3))

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


class TestMpiDifferentiate(MpiCase):
    """gradient and curvature: each rank reads its run of the input's leaves and their
    neighbours, and the ranks write the file plain ivdb writes."""

    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.mkdtemp(prefix="ivdb-mpi-diff-")
        # A sphere 300 voxels across, with inside tiles at every level.
        cls.sphere = os.path.join(cls.dir, "sphere.vdb")
        r = ivdb("rasterize", data("sphere.json"), "-o", cls.sphere, "--voxel-size", "0.0066", "-q")
        assert r.returncode == 0, r.stderr
        cls.union = os.path.join(cls.dir, "union.vdb")
        r = ivdb("rasterize", data("fig1_union.json"), "-o", cls.union, "-q", "--fog",
                 "--compression", "zip", "--half")
        assert r.returncode == 0, r.stderr
        # Written by OpenVDB itself: a fog volume first, then a level set.
        import pyopenvdb as vdb
        fog = vdb.FloatGrid()
        fog.name = "density"
        fog.gridClass = vdb.GridClass.FOG_VOLUME
        fog.fill((0, 0, 0), (20, 20, 20), 1.0)
        ls = vdb.createLevelSetSphere(radius=0.7, center=(0.1, -0.2, 0.3), voxelSize=0.01, halfWidth=3.0)
        ls.name = "ball"
        cls.openvdb = os.path.join(cls.dir, "openvdb.vdb")
        vdb.write(cls.openvdb, grids=[fog, ls])

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.dir, ignore_errors=True)

    def test_gradient(self):
        # Every grid the command writes: the vector grid, its magnitude and the input (with its
        # tiles); a step that reaches two leaves; zip and half floats; OpenVDB's own file, with the
        # level set second and by name.
        self.same_bytes("gradient", self.sphere, "--magnitude", "--with-input")
        self.same_bytes("gradient", self.union, "--step", "12", "--compression", "zip", "--half",
                          ranks=(2, 3))
        # A half-float input copied as it is stored.
        self.same_bytes("gradient", self.union, "--with-input", ranks=(3,))
        self.same_bytes("gradient", self.openvdb, "--with-input", ranks=(3,))
        self.same_bytes("gradient", self.openvdb, "--grid", "ball", "--step", "20",
                          "--compression", "none", ranks=(4,))

    def test_curvature(self):
        for method in ("mean", "gaussian", "principal", "laplacian"):
            self.same_bytes("curvature", self.union, "--method", method, ranks=(3,))
        self.same_bytes("curvature", self.sphere, "--method", "principal", "--with-input",
                          ranks=(1, 4))

    def test_each_rank_reads_its_run_and_a_halo(self):
        # The leaves split evenly; each rank reads its own and only their neighbours (for the
        # curvature's 3x3x3 stencil on a thin band: well under twice its own).
        import json
        r = mpi(4, "curvature", self.sphere, "-o", self.path("k.vdb"), "--json")
        self.assertEqual(r.returncode, 0, r.stderr)
        j = json.loads(r.stdout)
        runs = j["per_rank"]
        self.assertEqual(sum(x["leaves"] for x in runs), j["leaves"])
        self.assertLessEqual(max(x["leaves"] for x in runs) - min(x["leaves"] for x in runs), 1)
        for x in runs:
            self.assertGreaterEqual(x["leaves_read"], x["leaves"], x)
            self.assertLess(x["leaves_read"], 2 * x["leaves"], x)
        self.assertEqual(sum(x["active_voxels"] for x in runs), j["active_voxels"])
        r = mpi(2, "gradient", self.sphere, "-o", self.path("g.vdb"), "--per-rank")
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertEqual(len([l for l in r.stdout.splitlines() if l.strip().startswith("rank ")]), 2)

    def test_bad_input_fails_on_every_rank_and_writes_nothing(self):
        import pyopenvdb as vdb
        self.assertIn("no such file", self.errors(["gradient", self.path("missing.vdb"), "-o", "OUT"]))
        self.assertIn("--step", self.errors(["gradient", self.sphere, "-o", "OUT", "--step", "0"]))
        self.assertIn("--grid", self.errors(["curvature", self.openvdb, "-o", "OUT", "--grid", "nope"]))
        self.assertIn("fog volume", self.errors(["curvature", self.openvdb, "-o", "OUT", "--grid", "density"]))
        # A value that is not finite in the last rank's leaves: that rank finds it, and says so.
        grid = vdb.createLevelSetSphere(radius=0.5, voxelSize=0.02)
        last = max(grid.citerOnValues(), key=lambda v: v.min)
        acc = grid.getAccessor()
        acc.setValueOn(last.min, float("nan"))
        damaged = self.path("nan.vdb")
        vdb.write(damaged, grids=[grid])
        message = self.errors(["gradient", damaged, "-o", "OUT"])
        self.assertIn("not finite", message)
        self.assertIn("rank 2", message)
        r = ivdb("gradient", damaged, "-o", self.path("plain.vdb"))
        self.assertNotEqual(r.returncode, 0)
        self.assertIn("not finite", r.stderr)
        # Active tiles in a level set: plain ivdb takes it, ivdb-mpi says to.
        tiles = vdb.createLevelSetSphere(radius=0.5, voxelSize=0.02)
        tiles.fill((200, 200, 200), (400, 400, 400), 0.01, active=True)
        tiled = self.path("tiles.vdb")
        vdb.write(tiled, grids=[tiles])
        self.assertIn("active tiles", self.errors(["curvature", tiled, "-o", "OUT"], ranks=2))
        r = ivdb("curvature", tiled, "-o", self.path("plain.vdb"), "-q")
        self.assertEqual(r.returncode, 0, r.stderr)


class TestMpiCsg(MpiCase):
    """csg: each rank reads and combines its run of the inputs' 128^3 nodes, and the ranks write
    the file plain ivdb writes."""

    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.mkdtemp(prefix="ivdb-mpi-csg-")
        scenes = {"big": ('{"type": "sphere", "radius": 1}', ["--voxel-size", "0.004"]),
                  "small": ('{"type": "sphere", "center": [0.8, 0.3, 0], "radius": 0.7}',
                            ["--voxel-size", "0.004"]),
                  "torus": ('{"type": "torus", "center": [0, 0, 0.5], "major_radius": 0.8, '
                            '"minor_radius": 0.2}', ["--voxel-size", "0.004"]),
                  # Another band (a wider background), normalized to the first input's.
                  "wide": ('{"type": "sphere", "center": [-0.5, 0, 0.2], "radius": 0.6}',
                           ["--voxel-size", "0.004", "--half-width", "5"]),
                  "far": ('{"type": "sphere", "center": [5, 5, 5], "radius": 0.5}',
                          ["--voxel-size", "0.004"]),
                  "coarse": ('{"type": "sphere", "radius": 0.9}', ["--voxel-size", "0.01"])}
        scenes["halfbig"] = (scenes["big"][0], scenes["big"][1] + ["--half"])
        for name, (shape, options) in scenes.items():
            scene = os.path.join(cls.dir, name + ".json")
            with open(scene, "w") as f:
                f.write('{"voxel_size": 0.004, "shape": %s}' % shape)
            r = ivdb("rasterize", scene, "-o", os.path.join(cls.dir, name + ".vdb"), "-q", *options)
            assert r.returncode == 0, r.stderr

        # Inside tiles that are not -background (OpenVDB keeps whatever tile values a file
        # holds) in 128^3 nodes that also hold leaves: sent whole to rank 0, not as signs.
        import pyopenvdb as vdb
        grid = vdb.read(os.path.join(cls.dir, "big.vdb"), "surface")
        half = -0.5 * grid.background
        for x in (-232, -224):  # inside the big sphere, near its surface, outside "small"
            grid.fill((x, 0, 0), (x + 7, 7, 7), half, active=False)
        assert grid.getAccessor().getValue((-228, 3, 3)) == half
        vdb.write(os.path.join(cls.dir, "odd.vdb"), grids=[grid])

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.dir, ignore_errors=True)

    def csg(self, op, *names, options=(), ranks=(1, 2, 3, 4)):
        inputs = [self.path(n + ".vdb") for n in names]
        return self.same_bytes("csg", op, *inputs, *options, ranks=ranks)

    def test_each_operation(self):
        # A sphere with inside tiles in its 128^3 nodes, with another sphere and a torus.
        self.csg("union", "big", "small")
        self.csg("intersection", "big", "torus", ranks=(2, 3))
        self.csg("difference", "big", "small", ranks=(3, 4))

    def test_more_inputs_another_band_and_options(self):
        # Folded from the left, with the pruning between steps; an input whose band (background)
        # differs is narrowed to the first's, as plain ivdb does.
        self.csg("union", "big", "small", "torus", ranks=(1, 3))
        self.csg("difference", "big", "torus", "wide", ranks=(2, 4))
        self.csg("intersection", "wide", "big", "small", options=("--compression", "zip", "--half"),
                 ranks=(3,))
        # A first input stored as half floats: the result keeps them, as plain ivdb's does.
        self.csg("union", "halfbig", "small", ranks=(1, 3))
        out = self.csg("union", "odd", "small", ranks=(1, 3))
        import pyopenvdb as vdb
        odd = vdb.read(self.path("odd.vdb"), "surface")
        self.assertEqual(vdb.read(out, "surface").getAccessor().getValue((-228, 3, 3)),
                         -0.5 * odd.background)

    def test_fog_volume(self):
        # --fog: the density grid of the result, as plain ivdb's csg makes it (the big sphere's
        # inside tiles active), and of an empty result.
        self.csg("union", "big", "small", options=("--fog",), ranks=(1, 3))
        self.csg("difference", "big", "torus", options=("--fog", "--half"), ranks=(2, 4))
        self.csg("intersection", "big", "far", options=("--fog",), ranks=(3,))

    def test_an_empty_result_is_written_with_a_warning(self):
        self.csg("intersection", "big", "far", ranks=(1, 3))
        r = mpi(3, "csg", "intersection", self.path("big.vdb"), self.path("far.vdb"), "-o",
                self.path("empty.vdb"))
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("ivdb-mpi: warning: the result has no surface", r.stderr)

    def test_per_rank_report(self):
        import json
        r = mpi(3, "csg", "union", self.path("big.vdb"), self.path("small.vdb"), "-o",
                self.path("u.vdb"), "--json")
        self.assertEqual(r.returncode, 0, r.stderr)
        j = json.loads(r.stdout)
        runs = j["per_rank"]
        self.assertEqual(sum(x["nodes"] for x in runs), j["nodes"])
        self.assertEqual(sum(x["leaves"] for x in runs), j["leaves"])
        self.assertEqual(sum(x["active_voxels"] for x in runs), j["active_voxels"])
        self.assertTrue(all(x["leaves_read"] > 0 for x in runs), runs)
        self.assertEqual(j["file_bytes"], os.path.getsize(self.path("u.vdb")))

    def test_bad_input_fails_on_every_rank_and_writes_nothing(self):
        big, coarse = self.path("big.vdb"), self.path("coarse.vdb")
        self.assertIn("at least two", self.errors(["csg", "union", big, "-o", "OUT"]))
        self.assertIn("missing.vdb", self.errors(["csg", "union", big, self.path("missing.vdb"),
                                                  "-o", "OUT"]))
        # Another lattice: plain ivdb resamples it; ivdb-mpi says so.
        message = self.errors(["csg", "union", big, coarse, "-o", "OUT"])
        self.assertIn("coarse.vdb", message)
        self.assertIn("resamples", message)
        self.assertIn("--grid", self.errors(["csg", "union", big, big, "-o", "OUT", "--grid", "x"]))


class TestMpiBlend(MpiCase):
    """blend: the ranks combine their nodes sharply, rank 0 blends around the crease (from the
    inputs' topologies) and sends each rank its part; the file is the one ivdb blend writes."""

    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.mkdtemp(prefix="ivdb-mpi-blend-")
        # Two spheres whose crease circle lies in the plane x = 0, a boundary of 128^3 nodes, and
        # crosses z = 0, another; their leaves stay below y = 0, while a wide blend reaches above
        # it, into nodes neither input holds. A third sphere lies over both.
        shapes = {"a": '{"type": "sphere", "center": [-0.35, -0.75, 0], "radius": 0.6}',
                  "b": '{"type": "sphere", "center": [0.35, -0.75, 0], "radius": 0.6}',
                  "c": '{"type": "sphere", "center": [0, -0.3, 0.3], "radius": 0.4}',
                  "coarse": '{"type": "sphere", "radius": 0.5}'}
        for name, shape in shapes.items():
            scene = os.path.join(cls.dir, name + ".json")
            with open(scene, "w") as f:
                f.write('{"voxel_size": %s, "shape": %s}'
                        % ("0.04" if name == "coarse" else "0.02", shape))
            r = ivdb("rasterize", scene, "-o", os.path.join(cls.dir, name + ".vdb"), "-q")
            assert r.returncode == 0, r.stderr
        # A fog volume on the same lattice, written by OpenVDB.
        import pyopenvdb as vdb
        fog = vdb.read(os.path.join(cls.dir, "a.vdb"), "surface")
        fog.gridClass = vdb.GridClass.FOG_VOLUME
        fog.name = "density"
        vdb.write(os.path.join(cls.dir, "fog.vdb"), grids=[fog])

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.dir, ignore_errors=True)

    def blend(self, op, *names, options=(), ranks=(1, 2, 3, 4)):
        inputs = [self.path(n + ".vdb") for n in names]
        return self.same_bytes("blend", op, *inputs, *options, ranks=ranks)

    def test_super_elliptic_blends(self):
        # Sharp (p = 1000), round (p = 20) and wide (p = 8: the blend reaches 30 voxels beyond the
        # surfaces, into nodes neither input has leaves in).
        self.blend("union", "a", "b", options=("-p", "1000"), ranks=(1, 3))
        self.blend("union", "a", "b", options=("-p", "20"))
        self.blend("union", "a", "b", options=("-p", "8"), ranks=(2, 3))
        self.blend("intersection", "a", "b", options=("-p", "20"), ranks=(1, 3))
        self.blend("difference", "a", "b", options=("-p", "20"), ranks=(2, 4))

    def test_smooth_blends_and_more_inputs(self):
        self.blend("union", "a", "b", options=("-k", "0.1"), ranks=(2, 4))
        self.blend("difference", "a", "b", options=("-k", "0.05", "--half"), ranks=(1, 3))
        # Folded from the left: the second blend's crease is the third sphere's.
        self.blend("union", "a", "b", "c", options=("-p", "20"), ranks=(1, 2, 4))
        self.blend("intersection", "a", "b", "c", options=("-k", "0.08"), ranks=(3,))

    def test_fog_volume(self):
        self.blend("union", "a", "b", options=("-p", "20", "--fog"), ranks=(1, 3))
        self.blend("intersection", "a", "b", "c", options=("-k", "0.08", "--fog"), ranks=(3,))

    def test_summary(self):
        r = mpi(2, "blend", "union", self.path("a.vdb"), self.path("b.vdb"), "-o",
                self.path("u.vdb"), "-p", "20", "--per-rank")
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("blend union p=20 of 2 level sets", r.stdout)
        self.assertIn("rank 1:", r.stdout)

    def test_bad_input_fails_on_every_rank_and_writes_nothing(self):
        a, b = self.path("a.vdb"), self.path("b.vdb")
        self.assertIn("-p", self.errors(["blend", "union", a, b, "-o", "OUT"]))
        self.assertIn("excludes", self.errors(["blend", "union", a, b, "-o", "OUT", "-p", "20",
                                               "-k", "0.1"]))
        self.assertIn("1000", self.errors(["blend", "union", a, b, "-o", "OUT", "-p", "5000"]))
        self.assertIn("at least two", self.errors(["blend", "union", a, "-o", "OUT", "-p", "20"]))
        self.assertIn("coarse.vdb", self.errors(["blend", "union", a, self.path("coarse.vdb"),
                                                 "-o", "OUT", "-p", "20"]))
        self.assertIn("no level set", self.errors(["blend", "union", a, self.path("fog.vdb"),
                                                   "-o", "OUT", "-k", "0.1"]))


class TestMpiSequence(MpiCase):
    """A keyed scene's frames handed out to the ranks: the files plain ivdb writes, a line per
    frame in frame order, --resume, a failing frame, an interruption."""

    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.mkdtemp(prefix="ivdb-mpi-seq-")
        # The report's blended spheres passing through each other, on a coarse lattice.
        cls.scene = data("anim_metaballs.json")
        cls.ivdb_dir = os.path.join(cls.dir, "ivdb")
        os.mkdir(cls.ivdb_dir)
        r = ivdb("rasterize", cls.scene, "--frames", "1-48:6", "--voxel-size", "0.03",
                 "-o", os.path.join(cls.ivdb_dir, "m_####.vdb"))
        assert r.returncode == 0, r.stderr

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.dir, ignore_errors=True)

    FRAMES = list(range(1, 49, 6))

    def expected(self, frame):
        return masked(os.path.join(self.ivdb_dir, "m_%04d.vdb" % frame))

    def sequence(self, ranks, *options, frames="1-48:6"):
        out = os.path.join(self.dir, "r%d" % ranks)
        os.makedirs(out, exist_ok=True)
        r = mpi(ranks, "rasterize", self.scene, "--frames", frames, "--voxel-size", "0.03",
                "-o", os.path.join(out, "m_####.vdb"), *options)
        return r, out

    def test_frames_equal_plain_ivdbs(self):
        import json
        for n in (1, 2, 3, 4):
            r, out = self.sequence(n, "--json")
            self.assertEqual(r.returncode, 0, r.stderr)
            j = json.loads(r.stdout)
            self.assertEqual(j["ranks"], n)
            self.assertEqual(j["written"], len(self.FRAMES))
            self.assertEqual([f["frame"] for f in j["frames"]], self.FRAMES, "in frame order")
            self.assertTrue(all(0 <= f["rank"] < n for f in j["frames"]), j["frames"])
            self.assertEqual(sum(x["frames"] for x in j["per_rank"]), len(self.FRAMES))
            made = {f["rank"] for f in j["frames"]}
            self.assertEqual(made, {x["rank"] for x in j["per_rank"] if x["frames"] > 0})
            for frame in self.FRAMES:
                path = os.path.join(out, "m_%04d.vdb" % frame)
                self.assertEqual(masked(path), self.expected(frame), "frame %d on %d ranks" % (frame, n))
                self.assertEqual(os.path.getsize(path), j["frames"][self.FRAMES.index(frame)]["file_bytes"])
            self.assertEqual(sorted(os.listdir(out)), ["m_%04d.vdb" % f for f in self.FRAMES])
        # The summary lines: one per frame, in frame order, naming the rank that made it.
        r, out = self.sequence(3, "--per-rank")
        self.assertEqual(r.returncode, 0, r.stderr)
        lines = [l for l in r.stdout.splitlines() if " frame " in l and "active voxels" in l]
        self.assertEqual([int(l.split(" frame ")[1].split()[0]) for l in lines], self.FRAMES)
        self.assertTrue(all("(rank " in l for l in lines), lines)
        self.assertIn("%d frames written, 0 skipped on 3 ranks" % len(self.FRAMES), r.stdout)
        self.assertEqual(len([l for l in r.stdout.splitlines() if l.startswith("  rank ")]), 3)

    def test_frames_with_a_fog_volume(self):
        # --fog on a sequence: each frame's file holds the level set and its fog, as plain ivdb's.
        plain = os.path.join(self.dir, "fog_ivdb")
        os.makedirs(plain, exist_ok=True)
        r = ivdb("rasterize", self.scene, "--frames", "1-48:12", "--voxel-size", "0.03", "--fog",
                 "-o", os.path.join(plain, "m_####.vdb"), "-q")
        self.assertEqual(r.returncode, 0, r.stderr)
        out = os.path.join(self.dir, "fog_mpi")
        os.makedirs(out, exist_ok=True)
        r = mpi(3, "rasterize", self.scene, "--frames", "1-48:12", "--voxel-size", "0.03", "--fog",
                "-o", os.path.join(out, "m_####.vdb"))
        self.assertEqual(r.returncode, 0, r.stderr)
        for frame in range(1, 49, 12):
            name = "m_%04d.vdb" % frame
            self.assertEqual(masked(os.path.join(out, name)), masked(os.path.join(plain, name)), name)

    def test_more_ranks_than_frames(self):
        import json
        r, out = self.sequence(4, "--json", frames="7-13:6")
        self.assertEqual(r.returncode, 0, r.stderr)
        j = json.loads(r.stdout)
        self.assertEqual([f["frame"] for f in j["frames"]], [7, 13])
        self.assertEqual(sum(x["frames"] for x in j["per_rank"]), 2)
        for frame in (7, 13):
            self.assertEqual(masked(os.path.join(out, "m_%04d.vdb" % frame)), self.expected(frame))
        # Every frame already written: nothing to make.
        r, out = self.sequence(4, "--json", "--resume", frames="7-13:6")
        self.assertEqual(r.returncode, 0, r.stderr)
        j = json.loads(r.stdout)
        self.assertEqual((j["written"], j["skipped"]), (0, 2))

    def test_resume_makes_only_the_missing_frames(self):
        r, out = self.sequence(2)
        self.assertEqual(r.returncode, 0, r.stderr)
        os.remove(os.path.join(out, "m_0013.vdb"))
        with open(os.path.join(out, "m_0025.vdb"), "r+b") as f:
            f.truncate(1000)  # cut short: not a whole frame, made again
        r, out = self.sequence(2, "--resume", "--json")
        self.assertEqual(r.returncode, 0, r.stderr)
        import json
        j = json.loads(r.stdout)
        self.assertEqual(j["written"], 2)
        self.assertEqual(j["skipped"], len(self.FRAMES) - 2)
        self.assertEqual([f["frame"] for f in j["frames"] if not f["skipped"]], [13, 25])
        for frame in self.FRAMES:
            self.assertEqual(masked(os.path.join(out, "m_%04d.vdb" % frame)), self.expected(frame))

    def test_a_failing_frame_stops_the_handing_out(self):
        # Frame 4 would need terabytes: refused when it is made. The frames written before stay
        # whole; every rank fails with one message. Frames from 5 on take a while (radius 150
        # voxels), so that rank 0 hears of the failure long before a rank asks for frame 7.
        scene = self.path("grow.json")
        with open(scene, "w") as f:
            f.write('{"voxel_size": 0.04, "frames": {"start": 1, "end": 9}, "shape": {"type": '
                    '"sphere", "radius": {"keys": [[1, 0.5], [4, 2000], [5, 6]], '
                    '"interpolation": "step"}}}')
        out = self.path("grow")
        os.mkdir(out)
        r = mpi(3, "rasterize", scene, "-o", os.path.join(out, "g_#.vdb"), "--parallel-frames", "1")
        self.assertNotEqual(r.returncode, 0)
        errors = [l for l in r.stderr.splitlines() if "error:" in l]
        self.assertEqual(len(errors), 1, r.stderr)
        self.assertIn("would need about", errors[0])
        self.assertNotIn("g_4.vdb", os.listdir(out))
        # No frame is handed out once frame 4 failed: the ranks were making at most frames 5
        # and 6 (one each, --parallel-frames 1) when it did.
        self.assertEqual([n for n in os.listdir(out) if n in ("g_7.vdb", "g_8.vdb", "g_9.vdb")], [])
        for name in os.listdir(out):
            self.assertRegex(name, r"^g_\d\.vdb$")
            want = self.path("want.vdb")
            frame = int(name[2])
            r = ivdb("rasterize", scene, "--frames", str(frame), "-o", want)
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertEqual(masked(os.path.join(out, name)), masked(want), name)

    def test_an_interruption_leaves_whole_frames(self):
        # SIGINT to mpirun, which passes SIGTERM to every rank, once frames are being written:
        # each rank stops its frames, rank 0 says how many were written, every file is whole and
        # no temporary file is left; --resume then finishes the sequence.
        import signal
        import time
        out = self.path("stop")
        os.mkdir(out)
        # mpirun gives the ranks 1 s after its SIGTERM before it kills them; they stop at their
        # frames' next progress check, well within it.
        args = ["mpirun", "--oversubscribe", "--bind-to", "none", "-np", "3", IVDB_MPI,
                "rasterize", self.scene, "--voxel-size", "0.008", "-o",
                os.path.join(out, "m_####.vdb")]
        p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
        deadline = time.time() + 300
        while len([n for n in os.listdir(out) if n.endswith(".vdb")]) < 2 and time.time() < deadline:
            time.sleep(0.05)
        p.send_signal(signal.SIGINT)
        stdout, stderr = p.communicate(timeout=120)
        self.assertNotEqual(p.returncode, 0, stdout)
        written = sorted(n for n in os.listdir(out))
        self.assertLess(len(written), 48, "interrupted before the end")
        self.assertGreaterEqual(len(written), 2)
        self.assertIn("ivdb-mpi: error: interrupted; ", stderr)
        self.assertIn(" of 48 frames are written whole", stderr)
        said = int(stderr.split("interrupted; ")[1].split(" of 48")[0])
        self.assertEqual(said, len(written), stderr)
        self.assertEqual([n for n in written if not n.startswith("m_")], [], "temporary files left")
        import pyopenvdb as vdb
        for name in written:
            grid = vdb.read(os.path.join(out, name), "surface")
            self.assertGreater(grid.activeVoxelCount(), 0, name)
        r = mpi(2, "rasterize", self.scene, "--voxel-size", "0.008", "--frames", "1-48:4", "--resume",
                "-o", os.path.join(out, "m_####.vdb"), "--json")
        self.assertEqual(r.returncode, 0, r.stderr)

    def test_bad_input_fails_on_every_rank_and_writes_nothing(self):
        scene = self.scene
        self.assertIn("--frames", self.errors(["rasterize", scene, "-o", "OUT", "--frames", "3-1"]))
        # Several frames need # in the output's name; a keyed scene needs frames to write.
        message = self.errors(["rasterize", scene, "-o", "OUT", "--frames", "1-3"])
        self.assertIn("needs #", message)
        self.assertIn("--frames", self.errors(["rasterize", scene, "-o", "OUT"]))
        self.assertIn("no keyed value", self.errors(["rasterize", data("sphere.json"), "-o", "OUT",
                                                     "--frames", "1-3"]))
        self.assertIn("--parallel-frames", self.errors(["rasterize", scene, "-o", "OUT",
                                                        "--frames", "1", "--parallel-frames", "-1"]))
        # A keyed value that is bad at one frame: checked before any frame is made.
        bad = self.path("bad.json")
        with open(bad, "w") as f:
            f.write('{"voxel_size": 0.05, "shape": {"type": "sphere", "radius": '
                    '{"keys": [[1, 0.5], [5, -1]]}}}')
        out = self.path("bad")
        os.mkdir(out)
        r = mpi(3, "rasterize", bad, "--frames", "1-5", "-o", os.path.join(out, "b_#.vdb"))
        self.assertNotEqual(r.returncode, 0)
        self.assertEqual(len([l for l in r.stderr.splitlines() if "error:" in l]), 1, r.stderr)
        self.assertIn("bad.json", r.stderr)
        self.assertEqual(os.listdir(out), [])


if __name__ == "__main__":
    unittest.main()
