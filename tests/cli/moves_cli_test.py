#!/usr/bin/python3
"""`swarf moves` end to end: what it prints for a short program whose moves
are known by hand (text and --json agree), --chords within the tolerance and
on the arc, and the exit codes and messages of bad input.

usage: moves_cli_test.py SWARF_BINARY
"""
import json
import math
import os
import subprocess
import sys
import tempfile
import unittest

SWARF = None

# Line numbers are the file's. Hand-checked moves (tip, mm):
#   2: start at (0, 0, 5); 3: feed down to z -1;
#   4: G2 (clockwise seen from +Z: turns -1) to (10, 0), centre (5, 0);
#   5: G3 P2 back to (0, 0) descending to z -2: two turns begun, +2;
#   6: G18 G2 in XZ: about Y, to (10, 0, -2) with centre (5, 0, -2),
#      clockwise seen from +Y is -1;
#   7: tool change to T2; 8: rapid up; 9: inches: X1 is 25.4 mm.
PROGRAM = """G21 G90 G17
G0 X0 Y0 Z5
G1 Z-1 F100
G2 X10 Y0 I5 J0
G3 X0 Y0 I-5 J0 Z-2 P2
G18 G2 X10 Z-2 I5 K0
T2 M6
G0 Z5
G20 G1 X1
M2
"""

EXPECTED = [
    (2, "start", (0, 0, 5)),
    (3, "feed", (0, 0, -1)),
    (4, "arc", (10, 0, -1), (5, 0, -1), "Z", -1),
    (5, "arc", (0, 0, -2), (5, 0, -1), "Z", 2),
    (6, "arc", (10, 0, -2), (5, 0, -2), "Y", -1),
    (7, "tool", 2),
    (8, "rapid", (10, 0, 5)),
    (9, "feed", (25.4, 0, 5)),
]


def run(*args):
    p = subprocess.run([SWARF, "moves", *args], capture_output=True,
                       text=True, timeout=60)
    return p.returncode, p.stdout, p.stderr


class MovesCliTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.TemporaryDirectory()
        cls.prog = os.path.join(cls.dir.name, "prog.ngc")
        with open(cls.prog, "w") as f:
            f.write(PROGRAM)

    @classmethod
    def tearDownClass(cls):
        cls.dir.cleanup()

    def assertPoint(self, got, want):
        for g, w in zip(got, want):
            self.assertAlmostEqual(g, w, places=6)

    def test_text_rows_are_the_hand_checked_moves(self):
        rc, out, err = run(self.prog)
        self.assertEqual(rc, 0, err)
        rows = [r.split() for r in out.splitlines()]
        self.assertEqual(len(rows), len(EXPECTED))
        for row, want in zip(rows, EXPECTED):
            self.assertEqual(row[0], self.prog)
            self.assertEqual(int(row[1]), want[0])
            self.assertEqual(row[2], want[1])
            if want[1] == "tool":
                self.assertEqual(row[3:], [str(want[2])])
                continue
            self.assertPoint([float(v) for v in row[3:6]], want[2])
            if want[1] == "arc":
                self.assertPoint([float(v) for v in row[6:9]], want[3])
                self.assertEqual(row[9], want[4])
                self.assertEqual(int(row[10]), want[5])
            else:
                self.assertEqual(len(row), 6)

    def test_json_is_the_same_moves(self):
        rc, out, err = run(self.prog, "--json")
        self.assertEqual(rc, 0, err)
        moves = json.loads(out)["moves"]
        self.assertEqual(len(moves), len(EXPECTED))
        for m, want in zip(moves, EXPECTED):
            self.assertEqual(m["file"], self.prog)
            self.assertEqual((m["line"], m["kind"]), want[:2])
            if want[1] == "tool":
                self.assertEqual(m["tool"], want[2])
                continue
            self.assertPoint(m["end"], want[2])
            if want[1] == "arc":
                self.assertPoint(m["centre"], want[3])
                self.assertEqual((m["axis"], m["turns"]), want[4:])

    def test_chords_lie_on_the_arc_within_the_tolerance(self):
        tol = 0.01
        rc, out, err = run(self.prog, "--chords", str(tol))
        self.assertEqual(rc, 0, err)
        rows = [r.split() for r in out.splitlines()]
        self.assertTrue(all(r[2] in ("start", "feed", "rapid") for r in rows))
        line4 = [tuple(map(float, r[3:6])) for r in rows if r[1] == "4"]
        # A half circle of radius 5 in chords of sagitta <= 0.01 mm: at
        # least pi / (2 acos(1 - 0.01 / 5)) = 24.8 chords.
        self.assertGreaterEqual(len(line4), 25)
        self.assertLessEqual(len(line4), 30)  # and not needlessly many
        self.assertPoint(line4[-1], (10, 0, -1))
        prev = (0.0, 0.0, -1.0)
        for p in line4:
            r = math.hypot(p[0] - 5, p[1])
            self.assertAlmostEqual(r, 5, places=5)
            self.assertGreaterEqual(p[1], -1e-9)  # clockwise from (0, 0): y >= 0
            mid = ((p[0] + prev[0]) / 2 - 5, (p[1] + prev[1]) / 2)
            self.assertLessEqual(5 - math.hypot(*mid), tol + 1e-9)
            prev = p
        # The helix: P2 from (10, 0) is one full turn and a half (3 pi)
        # descending 1 mm, z monotone.
        line5 = [tuple(map(float, r[3:6])) for r in rows if r[1] == "5"]
        zs = [p[2] for p in line5]
        self.assertEqual(zs, sorted(zs, reverse=True))
        self.assertPoint(line5[-1], (0, 0, -2))
        step = 2 * math.acos(1 - tol / 5)
        self.assertGreaterEqual(len(line5), math.ceil(3 * math.pi / step))
        for p in line5:
            self.assertAlmostEqual(math.hypot(p[0] - 5, p[1]), 5, places=5)

    def test_bad_line_is_named_and_moves_before_it_printed(self):
        bad = os.path.join(self.dir.name, "bad.ngc")
        with open(bad, "w") as f:
            f.write("G21 G90\nG0 X0 Y0 Z5\nG1 X1 Q\nM2\n")
        rc, out, err = run(bad)
        self.assertEqual(rc, 1)
        self.assertIn(f"{bad}: line 3:", err)
        self.assertEqual(len(out.splitlines()), 1)

    def test_usage_errors(self):
        self.assertEqual(run()[0], 2)
        rc, _, err = run(self.prog, "--chords", "0")
        self.assertEqual(rc, 2)
        self.assertIn("--chords", err)
        rc, _, err = run(os.path.join(self.dir.name, "missing.ngc"))
        self.assertEqual(rc, 1)
        self.assertIn("missing.ngc: cannot open", err)


if __name__ == "__main__":
    SWARF = sys.argv.pop(1)
    unittest.main(verbosity=2)
