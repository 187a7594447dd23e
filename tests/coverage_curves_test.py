#!/usr/bin/env python3
"""Tests of scripts/coverage_curves.py: the judgement against A's ±1% tolerance spread, and
one whole run of a case with the same binary as A and B, which must land within A's spread.

Run: /usr/bin/python3 tests/coverage_curves_test.py --flank build/cli/flank
"""

import argparse
import importlib.util
import json
import os
import sys
import tempfile
import unittest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(ROOT, "scripts", "coverage_curves.py")

spec = importlib.util.spec_from_file_location("coverage_curves", SCRIPT)
cc = importlib.util.module_from_spec(spec)
spec.loader.exec_module(cc)

FLANK = None


class Judge(unittest.TestCase):
    def test_below_within_above(self):
        spread = [0.95, 0.93, 0.97]
        self.assertEqual(cc.judge(spread, 0.9299), ("below", 0.93, 0.97))
        self.assertEqual(cc.judge(spread, 0.93)[0], "within")  # the ends belong to the range
        self.assertEqual(cc.judge(spread, 0.97)[0], "within")
        self.assertEqual(cc.judge(spread, 0.9701)[0], "above")

    def test_one_run_is_a_point(self):
        self.assertEqual(cc.judge([0.9], 0.9), ("within", 0.9, 0.9))
        self.assertEqual(cc.judge([0.9], 0.8999)[0], "below")

    def test_no_runs_is_an_error(self):
        with self.assertRaises(ValueError):
            cc.judge([], 0.9)


class WholeRun(unittest.TestCase):
    def test_the_same_binary_is_within_its_own_spread(self):
        flank = FLANK
        if not flank:
            self.skipTest("needs --flank")
        with tempfile.TemporaryDirectory() as out:
            self.assertEqual(cc.main(["--flank", flank, "--flank-b", flank, "--spread", "-o", out, "spline"]), 0)
            with open(os.path.join(out, "curves.json")) as f:
                results = json.load(f)["results"]["spline"]
            self.assertEqual(set(results), {"A", "B", "A x0.99", "A x1.01"})
            # The same binary, input and tolerance: the same patches, so within the spread.
            self.assertEqual(results["A"]["curve"], results["B"]["curve"])
            self.assertEqual(results["B"]["against_spread"], "within")
            with open(os.path.join(out, "curves.md")) as f:
                table = f.read()
            self.assertIn("B below A's spread in 0 of 1 cases", table)
            self.assertIn("A's final coverage at 0.99, 1, 1.01 x tol", table)
            for tag in ("A_x0.99", "A_x1.01"):
                self.assertTrue(os.path.exists(os.path.join(out, tag, "spline", "patches.json")), tag)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--flank", help="the flank binary for the whole run")
    args, rest = ap.parse_known_args()
    FLANK = args.flank
    unittest.main(argv=[sys.argv[0]] + rest)
