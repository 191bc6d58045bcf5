#!/usr/bin/env python3
# The FreeCAD add-on (client/freecad) end to end, headless: FreeCAD builds a
# Job (make_job.py), simulate-job simulates it, and the results are checked
# against `swarf run` on the same program, tools and stock (bit for bit),
# against analytic heights, and in FreeCAD (the Mesh object).
#
#   addon_test.py --swarf PATH --swarfd PATH [--work DIR]
#
# Exits 77 (ctest's SKIP_RETURN_CODE) when freecadcmd is not installed.
import argparse
import json
import math
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
SIMULATE_JOB = os.path.join(ROOT, "client", "freecad", "simulate-job")
SPACING = "0.25"
ARGS = None


# FreeCAD reads the user's preferences (the add-on's too) from $HOME: the
# tests run with a scratch one, so nobody's settings change their results.
HOME = tempfile.mkdtemp(prefix="swarf-freecad-home-")


def freecadcmd(script, env_extra):
    env = dict(os.environ, HOME=HOME, **env_extra)
    p = subprocess.run(
        ["freecadcmd", "-c", "exec(open(%r).read())" % script], env=env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=120)
    if p.returncode != 0:
        raise AssertionError("freecadcmd %s failed (%d): %s" % (
            script, p.returncode, p.stderr.decode()[-2000:]))


def read_stl(path):
    """Binary STL -> list of triangles ((x, y, z) * 3)."""
    with open(path, "rb") as f:
        data = f.read()
    n = struct.unpack_from("<I", data, 80)[0]
    tris = []
    for i in range(n):
        v = struct.unpack_from("<12f", data, 84 + 50 * i)
        tris.append((v[3:6], v[6:9], v[9:12]))
    return tris


def volume(tris):
    return sum(a[0] * (b[1] * c[2] - b[2] * c[1]) -
               a[1] * (b[0] * c[2] - b[2] * c[0]) +
               a[2] * (b[0] * c[1] - b[1] * c[0]) for a, b, c in tris) / 6


# stats.json figures that are not results: timings, and the paths given.
VOLATILE = {"seconds", "moves_per_second", "file", "files", "server"}


def comparable(stats, program):
    """stats without VOLATILE, the program's path written P."""
    out = {k: v for k, v in stats.items() if k not in VOLATILE}
    if "deviation" in out:
        out["deviation"] = dict(out["deviation"], design=None)
    return json.loads(json.dumps(out).replace(json.dumps(program), '"P"'))


def height_at(tris, x, y):
    """The surface's z above (x, y): the highest triangle over it."""
    best = None
    for a, b, c in tris:
        d = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1])
        if abs(d) < 1e-12:
            continue  # a wall
        l1 = ((b[1] - c[1]) * (x - c[0]) + (c[0] - b[0]) * (y - c[1])) / d
        l2 = ((c[1] - a[1]) * (x - c[0]) + (a[0] - c[0]) * (y - c[1])) / d
        l3 = 1 - l1 - l2
        if min(l1, l2, l3) < -1e-9:
            continue
        z = l1 * a[2] + l2 * b[2] + l3 * c[2]
        best = z if best is None else max(best, z)
    return best


class AddonTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.work = ARGS.work or tempfile.mkdtemp(prefix="swarf-freecad-")
        shutil.rmtree(cls.work, ignore_errors=True)
        os.makedirs(cls.work)
        freecadcmd(os.path.join(HERE, "make_job.py"),
                   {"SWARF_TEST_DIR": cls.work})
        with open(os.path.join(cls.work, "ref", "facts.json")) as f:
            cls.facts = json.load(f)
        cls.addon = os.path.join(cls.work, "addon")
        cls.run_addon = cls.simulate_job(
            "job.FCStd", "--out", cls.addon, "--embedded",
            "--save", os.path.join(cls.work, "simulated.FCStd"))

    @classmethod
    def simulate_job(cls, *args):
        return subprocess.run(
            [sys.executable, SIMULATE_JOB, os.path.join(cls.work, args[0]),
             "--swarf", ARGS.swarf, "--spacing", SPACING] + list(args[1:]),
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=120,
            cwd=cls.work, env=dict(os.environ, HOME=HOME))

    def ref_table(self):
        """The Job's tools as the test knows them (FreeCAD's catalogue
        figures), written in other words than the add-on's."""
        table = os.path.join(self.work, "ref", "tools.tbl")
        with open(table, "w") as f:
            f.write("T1 P1 D5.0 ;endmill flute=30 shank=3\n"
                    "T2 P2 D6.0 ;bullnose r=1.5 flute=40 shank=3\n"
                    "T3 P3 D5.0 ;cone 119\n")
        return table

    def stats(self, out):
        with open(os.path.join(out, "stats.json")) as f:
            return json.load(f)

    def test_simulate_job_succeeds(self):
        r = self.run_addon
        self.assertEqual(r.returncode, 0, r.stderr.decode()[-3000:])
        for name in ("relief.png", "error.png", "marks.png", "marks.svg",
                     "marks.json", "surface.stl", "surface.wrl",
                     "stats.json", "deviation.png", "report.txt",
                     "program.ngc", "tools.tbl", "design.stl", "lines.json"):
            self.assertTrue(os.path.isfile(os.path.join(self.addon, name)),
                            name)

    def test_posted_program_is_freecads(self):
        """program.ngc is FreeCAD's LinuxCNC post of the Job's post list
        (make_job posts it without the add-on); only the time differs."""
        def body(path):
            with open(path) as f:
                return [l for l in f if not l.startswith("(Output Time")]
        self.assertEqual(body(os.path.join(self.addon, "program.ngc")),
                         body(os.path.join(self.work, "ref", "program.ngc")))

    def test_tool_table(self):
        """endmill -> flat, bullnose (flat radius 1.5 of 3) -> bull r=1.5,
        drill 119 degrees -> a cone; FreeCAD's flute and shank kept."""
        with open(os.path.join(self.addon, "tools.tbl")) as f:
            self.assertEqual(f.read(),
                             "T1 P1 D5 ;flat flute=30 shank=3\n"
                             "T2 P2 D6 ;bull r=1.5 flute=40 shank=3\n"
                             "T3 P3 D5 ;vbit angle=119\n")

    def test_equals_swarf_run_bit_for_bit(self):
        """The add-on's files equal `swarf run` on the same program, a tool
        table written here from the ToolBits' catalogue figures, and the
        Job's stock from FreeCAD: surface.stl byte for byte, stats.json
        figure for figure (deviation included)."""
        ref = os.path.join(self.work, "ref")
        table = self.ref_table()
        stock = ",".join(repr(v) for v in self.facts["stock"])
        self.assertEqual(stock, "-1.0,-1.0,41.0,31.0,13.0")
        out = os.path.join(self.work, "direct")
        r = subprocess.run(
            [ARGS.swarf, "run", os.path.join(ref, "program.ngc"),
             "--tools", table, "--stock", stock, "--spacing", SPACING,
             "--design", os.path.join(self.addon, "design.stl"),
             "--out", out], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            timeout=120)
        self.assertEqual(r.returncode, 0, r.stdout.decode()[-2000:])
        for name in ("surface.stl", "surface.wrl", "marks.json"):
            with open(os.path.join(out, name), "rb") as a, \
                    open(os.path.join(self.addon, name), "rb") as b:
                self.assertTrue(a.read() == b.read(), name + " differs")
        self.maxDiff = 5000
        self.assertEqual(
            comparable(self.stats(out), os.path.join(ref, "program.ngc")),
            comparable(self.stats(self.addon),
                       os.path.join(self.addon, "program.ngc")))

    def test_every_node_height_equals_swarf_run(self):
        """With --mesh-tolerance 0 the STL holds every node's height (two
        triangles per element): the add-on's equal `swarf run`'s, byte for
        byte."""
        out = os.path.join(self.work, "full")
        r = self.simulate_job("job.FCStd", "--out", out, "--embedded",
                              "--no-design", "--swarf-arg=--mesh-tolerance",
                              "--swarf-arg=0")
        self.assertEqual(r.returncode, 0, r.stderr.decode()[-3000:])
        direct = os.path.join(self.work, "full-direct")
        r = subprocess.run(
            [ARGS.swarf, "run",
             os.path.join(self.work, "ref", "program.ngc"), "--tools",
             self.ref_table(), "--stock",
             "-1,-1,41,31,13", "--spacing", SPACING, "--mesh-tolerance",
             "0", "--out", direct], stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, timeout=120)
        self.assertEqual(r.returncode, 0, r.stdout.decode()[-2000:])
        stats = self.stats(out)
        nodes = (stats["stock"]["nx"] + 1) * (stats["stock"]["ny"] + 1)
        tris = read_stl(os.path.join(out, "surface.stl"))
        self.assertGreaterEqual(len({v for t in tris for v in t}), nodes)
        with open(os.path.join(out, "surface.stl"), "rb") as a, \
                open(os.path.join(direct, "surface.stl"), "rb") as b:
            self.assertTrue(a.read() == b.read())

    def test_local_swarfd_gives_the_same_surface(self):
        """--swarfd: the add-on starts swarfd on a free port and runs on it;
        the surface is the embedded server's, bit for bit."""
        out = os.path.join(self.work, "swarfd")
        r = self.simulate_job("job.FCStd", "--out", out, "--swarfd",
                              ARGS.swarfd)
        self.assertEqual(r.returncode, 0, r.stderr.decode()[-3000:])
        self.assertIn("simulating on 127.0.0.1:", r.stderr.decode())
        with open(os.path.join(out, "surface.stl"), "rb") as a, \
                open(os.path.join(self.addon, "surface.stl"), "rb") as b:
            self.assertTrue(a.read() == b.read())

    def test_server_with_a_token(self):
        """--server with --token: a swarfd that requires the token gives
        the embedded server's surface; a wrong token is an error naming
        the refusal, and nothing is written."""
        tokens = os.path.join(self.work, "tokens")
        with open(tokens, "w") as f:
            f.write("s3cret-token\n")
        server = subprocess.Popen(
            [ARGS.swarfd, "--listen", "127.0.0.1:0", "--data_dir", "",
             "--auth_tokens_file", tokens, "--drain_seconds", "1"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        try:
            port = None
            for line in server.stdout:
                m = re.search(rb"\(port (\d+)\)", line)
                if m:
                    port = int(m.group(1))
                    break
            self.assertIsNotNone(port)
            address = "127.0.0.1:%d" % port
            out = os.path.join(self.work, "token")
            r = self.simulate_job("job.FCStd", "--out", out, "--server",
                                  address, "--token", "s3cret-token")
            self.assertEqual(r.returncode, 0, r.stderr.decode()[-3000:])
            self.assertIn("simulating on %s" % address, r.stderr.decode())
            with open(os.path.join(out, "surface.stl"), "rb") as a, \
                    open(os.path.join(self.addon, "surface.stl"), "rb") as b:
                self.assertTrue(a.read() == b.read())
            with open(os.path.join(out, "command.txt")) as f:
                self.assertNotIn("s3cret", f.read())
            bad = os.path.join(self.work, "badtoken")
            r = self.simulate_job("job.FCStd", "--out", bad, "--server",
                                  address, "--token", "wrong")
            self.assertEqual(r.returncode, 1)
            self.assertIn("simulate-job: error: swarf run failed",
                          r.stderr.decode())
            self.assertIn("token", r.stderr.decode())
            self.assertFalse(os.path.exists(os.path.join(bad, "stats.json")))
        finally:
            server.terminate()
            server.wait(timeout=10)

    def test_heights(self):
        """Analytic heights in the surface: the faced top at z 12 (the
        model's top), the pocket floor at 8, the drill's point at z 6 at
        the hole's centre (32, 15) and its flank 1 mm out, the stock's top
        where nothing cut, the bull nose's corner beside the profile."""
        tris = read_stl(os.path.join(self.addon, "surface.stl"))
        self.assertAlmostEqual(height_at(tris, 20, 5), 12.0, places=6)
        self.assertAlmostEqual(height_at(tris, 14, 15), 8.0, places=6)
        self.assertAlmostEqual(height_at(tris, 32, 15), 6.0, places=6)
        # The hole's rim: the cone's flank, 119 degrees included.
        flank = 6 + 1.0 / math.tan(math.radians(119 / 2))
        self.assertAlmostEqual(height_at(tris, 33, 15), flank, places=2)
        verts = {v for t in tris for v in t}
        self.assertEqual(max(v[2] for v in verts), 13.0)  # the stock top
        # The profile's last pass: the bull nose (corner 1.5, flat radius
        # 1.5) centred at x -3, tip at z -1; 2.5 mm from its axis the
        # torus: z = -1 + 1.5 - sqrt(1.5^2 - 1^2). The mesh is within its
        # 0.005 mm tolerance of the grid.
        torus = -1 + 1.5 - math.sqrt(1.5 ** 2 - 1.0 ** 2)
        self.assertAlmostEqual(height_at(tris, -0.5, 15), torus, delta=0.006)

    def test_design_is_the_model(self):
        """design.stl is the Job's model: its volume within the
        tessellation's error (the 2.5 mm hole's chords, 0.01 mm)."""
        tris = read_stl(os.path.join(self.addon, "design.stl"))
        v = volume(tris)
        exact = 40 * 30 * 12 - 16 * 10 * 4 - math.pi * 2.5 ** 2 * 6
        self.assertAlmostEqual(self.facts["model_volume"], exact, places=6)
        self.assertLess(abs(v - exact), 2 * math.pi * 2.5 * 6 * 0.01)
        self.assertIn("deviation", self.stats(self.addon))

    def test_line_map(self):
        """Every motion line of the program maps to the operation whose
        block it is in, and the command printed is that line's."""
        with open(os.path.join(self.addon, "lines.json")) as f:
            lines = json.load(f)
        with open(os.path.join(self.addon, "program.ngc")) as f:
            program = f.read().splitlines()
        block = None
        moves = 0
        for n, text in enumerate(program, 1):
            if text.startswith("(begin operation: "):
                block = text[len("(begin operation: "):-1]
            word = text.split()[0] if text.split() else ""
            if word in ("G0", "G1", "G2", "G3", "G81", "M6"):
                moves += 1
                self.assertIn(str(n), lines, "line %d: %s" % (n, text))
                op, index, command = lines[str(n)]
                self.assertEqual(op, block, "line %d" % n)
                self.assertEqual(command.split()[0], word)
                for w in text.split()[1:]:
                    if w[0] in "XYZ":
                        self.assertIn(w[0], command)
        self.assertGreater(moves, 100)
        ops = {v[0] for v in lines.values()}
        for op in self.facts["ops"]:
            self.assertIn(op, ops)

    def test_report(self):
        with open(os.path.join(self.addon, "report.txt")) as f:
            report = f.read()
        self.assertEqual(report, self.run_addon.stdout.decode())
        self.assertIn("verdict: OUT OF TOLERANCE", report)
        self.assertRegex(report, r"line \d+ \((Facing|Pocket|Profile), "
                                 r"command \d+: G[0-3] ")
        self.assertIn("safety: no rapid cuts", report)

    def test_mesh_object_is_watertight(self):
        """The saved document holds the surface as a Mesh feature:
        watertight, the triangles of surface.stl, a colour per vertex."""
        self.check_mesh(os.path.join(self.work, "simulated.FCStd"),
                        "deviation", self.addon)

    def test_height_colours_without_design(self):
        """--no-design --color-by height: no deviation in stats.json, and
        the mesh coloured by height."""
        out = os.path.join(self.work, "height")
        saved = os.path.join(self.work, "height.FCStd")
        r = self.simulate_job("job.FCStd", "--out", out, "--embedded",
                              "--no-design", "--color-by", "height",
                              "--save", saved)
        self.assertEqual(r.returncode, 0, r.stderr.decode()[-3000:])
        self.assertNotIn("deviation", self.stats(out))
        self.assertIn("verdict: no design compared", r.stdout.decode())
        self.check_mesh(saved, "height", out)

    def check_mesh(self, fcstd, coloring, out):
        check = os.path.join(self.work, "check.py")
        result = os.path.join(self.work, "check.json")
        with open(check, "w") as f:
            f.write(
                "def main():\n"
                "    import FreeCAD, json\n"
                "    doc = FreeCAD.openDocument(%r)\n"
                "    m = [o for o in doc.Objects if o.TypeId == "
                "'Mesh::Feature']\n"
                "    o = m[0]\n"
                "    json.dump({'n': len(m), 'solid': o.Mesh.isSolid(),\n"
                "      'nonmanifold': o.Mesh.hasNonManifolds(),\n"
                "      'facets': o.Mesh.CountFacets,\n"
                "      'points': o.Mesh.CountPoints,\n"
                "      'colors': len(o.VertexColors),\n"
                "      'coloring': o.SwarfColoring, 'job': o.SwarfJob,\n"
                "      'volume': o.Mesh.Volume}, open(%r, 'w'))\n"
                "main()\n" % (fcstd, result))
        freecadcmd(check, {})
        with open(result) as f:
            m = json.load(f)
        self.assertEqual(m["n"], 1)
        self.assertTrue(m["solid"])
        self.assertFalse(m["nonmanifold"])
        self.assertEqual(m["facets"], self.stats(out)["mesh"]["triangles"])
        self.assertEqual(m["colors"], m["points"])
        self.assertEqual(m["coloring"], coloring)
        self.assertEqual(m["job"], "Job")
        self.assertGreater(m["volume"], 0)

    def test_own_post_list_is_freecads(self):
        """The add-on's own post list (for FreeCADs whose buildPostList it
        cannot call) gives the program FreeCAD's gives, in its default
        order (Fixture)."""
        script = os.path.join(self.work, "postlist.py")
        result = os.path.join(self.work, "postlist.json")
        with open(script, "w") as f:
            f.write(
                "def main():\n"
                "    import FreeCAD, json, sys\n"
                "    sys.path.insert(0, %r)\n"
                "    from swarf_freecad import compat, post\n"
                "    doc = FreeCAD.openDocument(%r)\n"
                "    job = doc.getObject('Job')\n"
                "    def text(objs):\n"
                "        return [l for l in compat.linuxcnc_post().export(\n"
                "            objs, '-', '--no-show-editor').splitlines()\n"
                "            if not l.startswith('(Output Time')]\n"
                "    json.dump({'order': job.OrderOutputBy,\n"
                "        'freecad': text(compat.freecad_post_list(job)),\n"
                "        'own': text(post._own_post_list(job))},\n"
                "        open(%r, 'w'))\n"
                "main()\n" % (os.path.join(ROOT, "client", "freecad"),
                               os.path.join(self.work, "job.FCStd"), result))
        freecadcmd(script, {})
        with open(result) as f:
            r = json.load(f)
        self.assertEqual(r["order"], "Fixture")
        self.assertGreater(len(r["freecad"]), 100)
        self.assertEqual(r["own"], r["freecad"])

    def test_every_library_toolbit(self):
        """Each ToolBit of FreeCAD's library as a table line (or the error
        naming it), and swarf takes the table: a program cutting with every
        tool reports each as the shape the catalogue describes."""
        script = os.path.join(self.work, "bits.py")
        result = os.path.join(self.work, "bits.json")
        with open(script, "w") as f:
            f.write(
                "def main():\n"
                "    import FreeCAD, glob, json, os, sys\n"
                "    sys.path.insert(0, %r)\n"
                "    from swarf_freecad import tools\n"
                "    from PathScripts import PathToolBit, PathToolController\n"
                "    FreeCAD.newDocument('bits')\n"
                "    out = {}\n"
                "    bits = os.path.join(FreeCAD.getResourceDir(), 'Mod',\n"
                "                        'Path', 'Tools', 'Bit', '*.fctb')\n"
                "    for n, path in enumerate(sorted(glob.glob(bits)), 1):\n"
                "        bit = PathToolBit.Factory.CreateFrom(path, 'B%%d' %% n)\n"
                "        tc = PathToolController.Create('TC%%d' %% n, bit, n)\n"
                "        try:\n"
                "            out[os.path.basename(path)] = tools.table_line(\n"
                "                n, *tools.swarf_tool(tc))\n"
                "        except tools.SwarfError as e:\n"
                "            out[os.path.basename(path)] = 'error: %%s' %% e\n"
                "    json.dump(out, open(%r, 'w'), indent=1)\n"
                "main()\n" % (os.path.join(ROOT, "client", "freecad"),
                               result))
        freecadcmd(script, {})
        with open(result) as f:
            lines = json.load(f)
        self.assertEqual(lines, {
            "45degree_chamfer.fctb":
                "T1 P1 D12.3323 ;vbit angle=45 tip=5 flute=6.35 shank=6.35",
            "5mm-thread-cutter.fctb":
                'error: ToolBit "5mm-thread-cutter" (tool controller "TC2", '
                'T2): shape "thread-mill" has no swarf tool (swarf simulates '
                "endmill, ballend, bullnose, chamfer, v-bit, drill)",
            "5mm_Drill.fctb": "T3 P3 D5 ;vbit angle=119",
            "5mm_Endmill.fctb": "T4 P4 D5 ;flat flute=30 shank=3",
            "60degree_Vbit.fctb":
                "T5 P5 D10 ;vbit angle=60 tip=1 flute=1 shank=5",
            "6mm_Ball_End.fctb": "T6 P6 D6 ;ball flute=40 shank=3",
            "6mm_Bullnose.fctb": "T7 P7 D6 ;bull r=1.5 flute=40 shank=3",
            "probe.fctb":
                'error: ToolBit "Probe" (tool controller "TC8", T8): shape '
                '"probe" has no swarf tool (swarf simulates endmill, ballend, '
                "bullnose, chamfer, v-bit, drill)",
            "slittingsaw.fctb":
                'error: ToolBit "Slitting Saw" (tool controller "TC9", T9): '
                'shape "slittingsaw" has no swarf tool (swarf simulates '
                "endmill, ballend, bullnose, chamfer, v-bit, drill)",
        })
        table = os.path.join(self.work, "library.tbl")
        program = os.path.join(self.work, "library.ngc")
        used = [l for l in lines.values() if not l.startswith("error")]
        with open(table, "w") as f:
            f.write("".join(l + "\n" for l in used))
        with open(program, "w") as f:
            f.write("G21 G90\n")
            for i, l in enumerate(used):
                n = int(l.split()[0][1:])
                f.write("T%d M6\nG0 X%d Y5 Z1\nG1 Z-0.5 F100\nG1 Y15\n"
                        "G0 Z5\n" % (n, 15 * i + 8))
            f.write("M2\n")
        r = subprocess.run(
            [ARGS.swarf, "run", program, "--tools", table, "--stock",
             "0,0,%d,20,0" % (15 * len(used) + 10), "--spacing", "0.5",
             "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            timeout=60)
        self.assertEqual(r.returncode, 0, r.stderr.decode())
        self.assertEqual(json.loads(r.stdout)["tools"], {
            "1": "vbit d=12.3323 angle=45 tip=5", "3": "vbit d=5 angle=119",
            "4": "flat d=5", "5": "vbit d=10 angle=60 tip=1",
            "6": "ball d=6", "7": "bull d=6 r=1.5"})

    def test_unknown_toolbit_shape_is_a_clear_error(self):
        out = os.path.join(self.work, "bad")
        r = self.simulate_job("bad.FCStd", "--out", out, "--embedded")
        self.assertEqual(r.returncode, 1)
        err = r.stderr.decode()
        self.assertIn('simulate-job: error: ToolBit "Slitting Saw" (tool '
                      'controller "TC: Drill", T3): shape "slittingsaw" has '
                      "no swarf tool", err)
        self.assertFalse(os.path.exists(os.path.join(out, "stats.json")))

    def test_missing_swarf_is_a_clear_error(self):
        r = subprocess.run(
            [sys.executable, SIMULATE_JOB,
             os.path.join(self.work, "job.FCStd"), "--out",
             os.path.join(self.work, "noswarf"), "--swarf", "no-such-swarf"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=120,
            env=dict(os.environ, HOME=HOME))
        self.assertEqual(r.returncode, 1)
        self.assertIn("the swarf CLI 'no-such-swarf' is not on PATH",
                      r.stderr.decode())


class ReportTest(unittest.TestCase):
    """swarf_freecad.report on hand-written stats: every line it cites is
    followed by its operation and command."""

    def test_lines_named(self):
        sys.path.insert(0, os.path.join(ROOT, "client", "freecad"))
        from swarf_freecad import report
        lines = {26: ("Facing", 4, "G1 X37.5 Y2.5 Z12 F200"),
                 72: ("Pocket", 5, "G1 X19.5 Y16.0355 Z8 F600")}
        stats = {
            "moves": 10, "source_lines": 80,
            "stock": {"x0": 0, "y0": 0, "x1": 10, "y1": 10, "top": 5,
                      "nx": 20, "ny": 20},
            "tools": {"1": "flat d=5"},
            "deviation": {
                "ok": False, "tolerance": 0.01, "allowance": 0,
                "normal": {"gouge_max": 0.5, "excess_max": 0},
                "gouge": {"max": 0.5, "x": 1, "y": 2, "line": 72},
                "excess": {"lines": []},
                "out_of_tolerance": {"area_mm2": 3, "lines": [
                    {"line": 72, "gouge_max": 0.5, "x": 1, "y": 2,
                     "area_mm2": 3}]}},
            "safety": {"counts": {"rapid_cuts": 1}, "rapid_cuts": [
                {"line": 26, "x": 3, "y": 4, "z": 12, "depth": 1,
                 "volume_mm3": 19.8}]},
        }
        text = report.report("Job", stats, lines)
        self.assertIn("verdict: OUT OF TOLERANCE (tolerance 0.01 mm, "
                      "allowance 0 mm): gouge 0.5 mm, excess 0 mm, 3 mm2 out "
                      "of tolerance\n", text)
        self.assertIn("  gouge 0.5 mm at (1, 2), 3 mm2: line 72 (Pocket, "
                      "command 6: G1 X19.5 Y16.0355 Z8 F600)\n", text)
        self.assertIn("safety: 1 rapid moves cutting material; the first:\n"
                      "  1 mm deep at (3, 4, 12), 19.8 mm3: line 26 (Facing, "
                      "command 5: G1 X37.5 Y2.5 Z12 F200)\n", text)
        self.assertIn("line 99", report.where(99, lines))


class RunnerTest(unittest.TestCase):
    """swarf_freecad.runner without FreeCAD: progress and cancel."""

    @classmethod
    def setUpClass(cls):
        sys.path.insert(0, os.path.join(ROOT, "client", "freecad"))
        from swarf_freecad import runner
        cls.runner = runner
        cls.work = tempfile.mkdtemp(prefix="swarf-runner-")

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.work, ignore_errors=True)

    def test_progress_on_a_terminal(self):
        """With a pty swarf draws its bar; the percentages rise to 100."""
        seen = []
        rc, out = self.runner.run(
            [ARGS.swarf, "run", os.path.join(ROOT, "examples", "relief.nc"),
             "--tool", "ball:d=2", "--stock", "0,0,60,60,0", "--spacing",
             "0.5", "--batch", "2000", "--out",
             os.path.join(self.work, "relief")],
            progress=seen.append, use_pty=True)
        self.assertEqual(rc, 0, out)
        self.assertEqual(seen[-1], 100)
        self.assertLess(seen[0], 100)
        self.assertEqual(seen, sorted(seen))
        self.assertIn("ETA", out)  # the terminal's bar, not quarter lines
        self.assertIn("moves simulated", out)

    def test_cancel_kills_the_process_group(self):
        pids = os.path.join(self.work, "pids")
        fake = os.path.join(self.work, "slow")
        with open(fake, "w") as f:
            f.write("#!/bin/sh\nsleep 60 &\necho $$ $! > %s\n"
                    "echo 'swarf: 25%% (1 of 4 moves, 0.00M moves/s)'\n"
                    "wait\n" % pids)
        os.chmod(fake, 0o755)
        seen = []
        with self.assertRaises(self.runner.Cancelled):
            self.runner.run([fake], progress=seen.append,
                            cancelled=lambda: seen == [25])
        self.assertEqual(seen, [25])
        with open(pids) as f:
            for pid in f.read().split():
                # SIGKILL is asynchronous: the grandchild (not waited for)
                # dies within moments.
                for _ in range(100):
                    try:
                        with open("/proc/%s/stat" % pid) as st:
                            state = st.read().rsplit(")", 1)[1].split()[0]
                    except FileNotFoundError:
                        state = "gone"
                    if state in ("gone", "Z"):
                        break
                    time.sleep(0.05)
                self.assertIn(state, ("gone", "Z"), "process %s" % pid)


def main():
    global ARGS
    p = argparse.ArgumentParser()
    p.add_argument("--swarf", required=True)
    p.add_argument("--swarfd", required=True)
    p.add_argument("--work")
    ARGS, rest = p.parse_known_args()
    ARGS.swarf = os.path.abspath(ARGS.swarf)
    ARGS.swarfd = os.path.abspath(ARGS.swarfd)
    if shutil.which("freecadcmd") is None:
        shutil.rmtree(HOME, ignore_errors=True)
        print("SKIP: freecadcmd is not installed (make test-freecad "
              "installs Debian's freecad and runs this)")
        return 77
    try:
        prog = unittest.main(argv=[sys.argv[0]] + rest, exit=False,
                             verbosity=2)
    finally:
        shutil.rmtree(HOME, ignore_errors=True)
    return 0 if prog.result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
