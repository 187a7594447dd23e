#!/usr/bin/env python3
"""Tests of bench/flank_grow_pairs and scripts/grow_pairs.py (a change to the fit judged on the
very candidates decompose grows): B with A's own settings grows every candidate exactly as A
(the tool itself checks that A grown again repeats decompose's growth), the summary says so,
and bad input gets one line and a non-zero exit.

Run: /usr/bin/python3 tests/grow_pairs_test.py --pairs build/bench/flank_grow_pairs --flank build/cli/flank
"""

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import unittest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(ROOT, "scripts", "grow_pairs.py")
sys.path.insert(0, os.path.join(ROOT, "scripts"))

spec = importlib.util.spec_from_file_location("grow_pairs", SCRIPT)
gp = importlib.util.module_from_spec(spec)
spec.loader.exec_module(gp)

PAIRS = FLANK = None


class Summary(unittest.TestCase):
    def test_ratios_and_one_sided_counts(self):
        rows = [[10.0, 12.0, 1, 1, 1.0, 0.5], [0.0, 3.0, 0, 1, 1.0, 0.5], [5.0, 0.0, 2, 0, 2.0, 2.0]]
        area, only_a, only_b, time = gp.summarise(rows)
        self.assertAlmostEqual(area, 15.0 / 15.0)
        self.assertEqual((only_a, only_b), (1, 1))
        self.assertAlmostEqual(time, 3.0 / 4.0)


class WholeRun(unittest.TestCase):
    def test_same_settings_same_areas(self):
        with tempfile.TemporaryDirectory() as work:
            proc = subprocess.run([sys.executable, SCRIPT, "--pairs", PAIRS, "--flank", FLANK, "-o", work,
                                   "--same", "spline"], capture_output=True, text=True)
            self.assertEqual(proc.returncode, 0, proc.stderr)
            with open(os.path.join(work, "pairs.json")) as f:
                data = json.load(f)
            rows = data["cases"]["spline"]
            self.assertGreater(len(rows), 0)
            for best_a, best_b, valid_a, valid_b, _, _ in rows:
                self.assertEqual(best_a, best_b)
                self.assertEqual(valid_a, valid_b)
            self.assertIn("| spline | %d | 1.0000 | 0 / 0 |" % len(rows), proc.stdout)
            self.assertTrue(any(valid for _, _, valid, _, _, _ in rows), "no candidate grew a patch")

    def test_bad_input(self):
        with tempfile.TemporaryDirectory() as work:
            missing = os.path.join(work, "missing.stl")
            proc = subprocess.run([PAIRS, missing, "--iterations", "8"], capture_output=True, text=True)
            self.assertNotEqual(proc.returncode, 0)
            self.assertEqual(len(proc.stderr.strip().splitlines()), 1, proc.stderr)
            self.assertIn(missing, proc.stderr)
            proc = subprocess.run([PAIRS, missing, "--samples", "48"], capture_output=True, text=True)
            self.assertNotEqual(proc.returncode, 0)
            self.assertIn("expected TxS", proc.stderr)
            for options in ([], ["--same", "--iterations", "8"]):
                proc = subprocess.run([PAIRS, missing, *options], capture_output=True, text=True)
                self.assertEqual(proc.returncode, 2)
                self.assertIn("give B's fit settings, or --same", proc.stderr)
            proc = subprocess.run([sys.executable, SCRIPT, "--pairs", PAIRS, "-o", work, "spline"],
                                  capture_output=True, text=True)
            self.assertNotEqual(proc.returncode, 0)
            self.assertIn("give at least one B option, or --same", proc.stderr)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--pairs", required=True)
    ap.add_argument("--flank", required=True)
    a, rest = ap.parse_known_args()
    PAIRS, FLANK = os.path.abspath(a.pairs), os.path.abspath(a.flank)
    unittest.main(argv=[sys.argv[0], *rest])
