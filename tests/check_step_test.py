#!/usr/bin/env python3
"""Self-tests of tests/check_step.py: it passes patches.step as flank writes it and fails it
when a face is moved, missing or unreadable.

A spline cutter's exact envelope (flank synth) is decomposed with every tool kind at 1e-4 of
the diagonal; its faces are then read and measured by the checker, as written and after one
pole of a face is moved by a twentieth of the tolerance (the face moves by about a thirtieth of
the tolerance near that pole: three times the 1% limit).

Run: /usr/bin/python3 tests/check_step_test.py --flank BIN      (exit status non-zero on failure)
"""

import argparse
import io
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import unittest
from contextlib import redirect_stdout

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import check_step  # noqa: E402

FLANK = None
SPLINE_TOOL = "spline:3,3.6,4.4,5,5.2,5,4.6,4.2,4,3.8"


def run_checker(*args):
    out = io.StringIO()
    with redirect_stdout(out):
        code = check_step.main(list(args))
    return code, out.getvalue()


class CheckStep(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.work = tempfile.mkdtemp(prefix="flank-check-step-")
        mesh = os.path.join(cls.work, "spline.stl")
        cls.out = os.path.join(cls.work, "out")
        subprocess.run([FLANK, "synth", "--guides", "seed003", "--tool", SPLINE_TOOL, "-o", mesh],
                       check=True, capture_output=True)
        subprocess.run([FLANK, "decompose", mesh, "-o", cls.out, "--tolerance-rel", "1e-4", "-q",
                        "--no-report"], check=True, capture_output=True)
        with open(os.path.join(cls.out, "patches.json")) as f:
            cls.data = json.load(f)
        with open(os.path.join(cls.out, "patches.step"), encoding="latin-1") as f:
            cls.step = f.read()

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.work, ignore_errors=True)

    def variant(self, text):
        path = os.path.join(self.work, f"variant-{self.id().split('.')[-1]}.step")
        with open(path, "w", encoding="latin-1") as f:
            f.write(text)
        return path

    def test_faces_as_written_pass(self):
        result, tol = check_step.check(os.path.join(self.out, "patches.json"))
        self.assertEqual(len(result), len(self.data["patches"]))
        for pid, dev in result.items():
            self.assertIsNotNone(dev, pid)
            self.assertLessEqual(dev, 0.01 * tol, pid)
            self.assertGreater(dev, 0.0, pid)  # a fit, not the rebuild compared with itself
        code, text = run_checker(os.path.join(self.out, "patches.json"))
        self.assertEqual(code, 0, text)

    def test_a_moved_pole_fails(self):
        tol = self.data["coverage"]["tolerance"]
        m = re.search(r"B_SPLINE_SURFACE_WITH_KNOTS\('[^']*',3,3,\(\s*\(", self.step)
        self.assertIsNotNone(m)
        rows = self.step[m.end() - 1:self.step.index(".UNSPECIFIED.", m.end())]
        refs = re.findall(r"#\d+", rows)
        pole = refs[len(refs) // 2]  # one in the middle of the face
        pm = re.search(re.escape(pole) + r" = CARTESIAN_POINT\('[^']*',\(([^)]*)\)\);", self.step)
        self.assertIsNotNone(pm)
        xyz = [float(v) for v in pm.group(1).split(",")]
        xyz[2] += 0.05 * tol
        moved = self.step[:pm.start(1)] + ",".join(repr(v) for v in xyz) + self.step[pm.end(1):]
        code, text = run_checker(os.path.join(self.out, "patches.json"), "--step", self.variant(moved))
        self.assertEqual(code, 1, text)
        self.assertIn("FAILS", text)

    def test_a_missing_face_fails(self):
        renamed = re.sub(r"PRODUCT\('P(\d+)','P\d+'", r"PRODUCT('Q\1','Q\1'", self.step)
        code, text = run_checker(os.path.join(self.out, "patches.json"), "--step", self.variant(renamed))
        self.assertEqual(code, 1, text)
        self.assertIn("no face", text)

    def test_an_unreadable_file_is_refused(self):
        code, _ = run_checker(os.path.join(self.out, "patches.json"), "--step",
                              os.path.join(self.work, "missing.step"))
        self.assertEqual(code, 2)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--flank", required=True)
    a, rest = ap.parse_known_args()
    FLANK = a.flank
    unittest.main(argv=[sys.argv[0]] + rest)
