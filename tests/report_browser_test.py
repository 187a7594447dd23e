#!/usr/bin/env python3
"""report.html opened in a real browser (Debian's Chromium, headless) after a real flank run.

Each case makes a part, runs flank on it, then hands the run's report.html to
tests/report_browser_test.mjs (Node + playwright-core), which loads it from its file:// URL
and requires: no console error, no network request, a canvas that is not blank, one table row
per patch in patches.json, and the error view and the cutter slider working. The open time
(navigation start to the first frame) and the file's size are printed; they are measured here,
not judged (speed is the benchmarks' business; bench/write_report_benchmark.cpp times writing).

Cases:
  demo   the demo's part (the exact envelope of a cone 4->7 mm along the Li-Mann-Bedi guides,
         241x61 vertices) decomposed with cylinders and cones, as scripts/demo does
  large  the same envelope at 201x101 vertices: 40,000 triangles, the issue's size
  fit    one hand-placed line fitted with a holder checked (the holder is drawn)
  blade  the Rotor 67 blade face of tests/data at the default tolerance: nine patches of
         several cutter kinds, with uncovered regions
  empty  a run that finds no patch (a cylinder cannot cut the cone's envelope at 1e-6 of the
         diagonal): the page must still open, with an empty table

Usage: report_browser_test.py --flank BIN --node NODE --chromium PATH --modules DIR CASE
                              [--screenshot OUT.png] [--screenshot-error OUT.png] [--work DIR]
Exit 0 when every check passes, 1 otherwise.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
BROWSER = os.path.join(HERE, "report_browser_test.mjs")
GUIDES = ["--guides", "seed003", "--tool", "cone:4,7", "--length", "50"]


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"FAIL: {' '.join(cmd)} exited {p.returncode}: {(p.stdout + p.stderr).strip()[-800:]}")
    return p


def first_ruling(flank, part, work):
    """A start line for fit near the part's middle ruling: the middle control points of the
    axis end curves of decompose's first patch (close to, not on, the ruling; fit moves it)."""
    out = os.path.join(work, "rulings")
    run([flank, "decompose", part, "--tool", "cone", "--no-report", "-q", "-o", out])
    with open(os.path.join(out, "patches.json")) as f:
        motion = json.load(f)["patches"][0]["motion"]
    a, b = motion["a"], motion["b"]
    mid = len(a) // 2
    return ",".join(f"{v:.6f}" for v in a[mid] + b[mid])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--flank", required=True)
    ap.add_argument("--node", required=True)
    ap.add_argument("--chromium", required=True)
    ap.add_argument("--modules", required=True, help="node_modules holding playwright-core")
    ap.add_argument("--screenshot")
    ap.add_argument("--screenshot-error")
    ap.add_argument("--work")
    ap.add_argument("case", choices=["demo", "large", "fit", "empty", "blade"])
    args = ap.parse_args()

    with tempfile.TemporaryDirectory(prefix="flank_report_") as tmp:
        work = args.work or tmp
        os.makedirs(work, exist_ok=True)
        part = os.path.join(work, "part.stl")
        if args.case == "blade":
            part = os.path.join(HERE, "data", "rotor67_blade_upper.stl")
        else:
            resolution = "201x101" if args.case == "large" else "241x61"
            run([args.flank, "synth", *GUIDES, "--resolution", resolution, "-o", part])
        out = os.path.join(work, "out")
        if args.case == "blade":
            run([args.flank, "decompose", part, "-q", "-o", out])
        elif args.case in ("demo", "large"):
            run([args.flank, "decompose", part, "--tool", "cylinder,cone", "-q", "-o", out])
        elif args.case == "fit":
            line = first_ruling(args.flank, part, work)
            run([args.flank, "fit", part, "--line", line, "--tool", "cone", "--holder", "40,12", "-q", "-o", out])
        else:
            run([args.flank, "decompose", part, "--tool", "cylinder", "--tolerance-rel", "1e-6", "-q", "-o", out])
        with open(os.path.join(out, "patches.json")) as f:
            patches = len(json.load(f)["patches"])
        if args.case == "empty" and patches != 0:
            raise SystemExit(f"FAIL: the empty case found {patches} patches; it needs a run with none")
        if args.case != "empty" and patches == 0:
            raise SystemExit("FAIL: no patch found; the page would not show a cutter")
        report = os.path.join(out, "report.html")
        print(f"report.html: {os.path.getsize(report) / 1e6:.2f} MB, {patches} patches")
        cmd = [args.node, BROWSER, "--chromium", args.chromium, "--report", report, "--patches", str(patches),
               "--modules", args.modules]
        if args.screenshot:
            cmd += ["--screenshot", os.path.abspath(args.screenshot)]
        if args.screenshot_error:
            cmd += ["--screenshot-error", os.path.abspath(args.screenshot_error)]
        p = subprocess.run(cmd, capture_output=True, text=True)
        sys.stdout.write(p.stdout)
        sys.stderr.write(p.stderr)
        if p.returncode != 0:
            raise SystemExit(f"FAIL: the browser checks of {args.case} failed (exit {p.returncode})")
    print(f"ok: {args.case}")


if __name__ == "__main__":
    main()
