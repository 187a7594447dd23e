#!/usr/bin/env python3
"""Coverage curves of `flank decompose`, rebuilt independently, for one flank or two side by side.

A speed change must not change what decompose finds. This runs each case with each binary
(`--threads 2`, the CLI's defaults otherwise), rebuilds every patch's machined surface from
patches.json with tests/check_patches.py (NumPy/SciPy, no flank code) and prints the coverage
after 1, 2, ..., k patches, the largest rebuilt max |e| against the tolerance, and the run's
wall time, one row per case and binary. With two binaries the runs alternate A B per case, so
that both see the same machine load, and the last columns give the change.

Cases (all by default; name some to run only those):
  hecc_a/1e-4 hecc_b/1e-4 rotor_upper/1e-4 rotor_lower/1e-4   the NASA faces of tests/data
  hecc_a/3e-4 hecc_b/3e-4 rotor_upper/3e-4 rotor_lower/3e-4
  freeform/1 ... freeform/6   made-up blade faces (tests/freeform_parts.py, seeds 1-6) at 1e-4
  cone13k      the 13.5k-vertex exact cone 4->7 envelope (flank synth --resolution 221x61)
  spline       the exact envelope of a free-form cutter (tests/decompose_acceptance.py)
  noisy_barrel a barrel envelope with noise and two holes, at 3e-4 (the same)

How much of a difference is noise: the search is chaotic (a small change picks other lines,
then other patches), so `--tol-scale 1.001` reruns every case at a tolerance 0.1% larger.
`--spread` runs A twice more per case, at tolerances 1% smaller and 1% larger. The range of
A's three final coverages is the yardstick. With B, each case says whether B's final
coverage is below, within or above that range, and a last line counts the cases below. A
change of the search moves single cases by a few points either way, as a 1% change of the
tolerance does. A change is judged by how many cases fall below A's spread, and how far.

Usage: scripts/coverage_curves.py --flank BIN [--flank-b BIN] [--tol-scale F] [--spread] [-o DIR] [CASE ...]
Writes DIR/curves.json (every figure) and DIR/curves.md (the table) and prints the table.
"""

import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
TESTS = os.path.join(HERE, "..", "tests")
sys.path.insert(0, TESTS)
import check_patches  # noqa: E402  (the independent checker)
import decompose_acceptance  # noqa: E402  (its synthetic parts)
import freeform_parts  # noqa: E402  (made-up blade faces)

FACES = {"hecc_a": "hecc_splitter_blade_side_a", "hecc_b": "hecc_splitter_blade_side_b",
         "rotor_upper": "rotor67_blade_upper", "rotor_lower": "rotor67_blade_lower"}
FREEFORM = [f"freeform/{seed}" for seed in range(1, 7)]
CASES = [f"{f}/{t}" for t in ("1e-4", "3e-4") for f in FACES] + FREEFORM + ["cone13k", "spline", "noisy_barrel"]


def part_of(case, flank, work):
    """(mesh path, relative tolerance) of a case; synthetic parts are made once in `work`."""
    if case in FREEFORM:
        path = os.path.join(work, case.replace("/", "_") + ".stl")
        if not os.path.exists(path):
            freeform_parts.write_stl(path, *freeform_parts.blade(int(case.split("/")[1])))
        return path, 1e-4
    if "/" in case:
        face, tol = case.split("/")
        return os.path.join(TESTS, "data", FACES[face] + ".stl"), float(tol)
    path = os.path.join(work, case + ".stl")
    if case == "noisy_barrel":
        return decompose_acceptance.noisy_barrel(flank, work), 3e-4
    if not os.path.exists(path):
        tool = {"cone13k": "cone:4,7", "spline": decompose_acceptance.SPLINE_TOOL}[case]
        extra = ["--resolution", "221x61"] if case == "cone13k" else []
        decompose_acceptance.run([flank, "synth", "--guides", "seed003", "--tool", tool, *extra, "-o", path])
    return path, 1e-4


def run_case(flank, mesh, tol, out):
    start = time.perf_counter()
    decompose_acceptance.run([flank, "decompose", mesh, "-o", out, "--tolerance-rel", str(tol),
                              "--threads", "2", "-q", "--no-report"])
    wall = time.perf_counter() - start
    with open(os.path.join(out, "patches.json")) as f:
        data = json.load(f)
    res = check_patches.check(os.path.join(out, "patches.json"), mesh)
    worst = max((r["max_abs"] or 0.0 for r in res["patches"]), default=0.0)
    return {"wall_s": wall, "solver_s": data["timing_s"]["total"], "patches": len(data["patches"]),
            "curve": res["coverage_curve"], "coverage": res["coverage"],
            "worst_max_e_over_tol": worst / res["tolerance"],
            "kinds": [p["tool"]["kind"] for p in data["patches"]]}


# The tolerances A also runs at with --spread, as factors of the case's tolerance.
SPREAD = (0.99, 1.01)


def judge(spread, coverage):
    """Where `coverage` lies against the final coverages in `spread` (A's runs at the case's
    tolerance and at SPREAD times it): ("below" | "within" | "above", lowest, highest)."""
    if not spread:
        raise ValueError("judge needs at least one coverage to compare with")
    lo, hi = min(spread), max(spread)
    verdict = "below" if coverage < lo else "above" if coverage > hi else "within"
    return verdict, lo, hi


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flank", required=True, help="the flank binary (A)")
    ap.add_argument("--flank-b", help="a second flank binary (B), run alternately with A")
    ap.add_argument("--tol-scale", type=float, default=1.0, help="multiply every case's tolerance")
    ap.add_argument("--spread", action="store_true",
                    help="also run A at tolerances 1%% smaller and larger, and judge B against that range")
    ap.add_argument("-o", "--out", default="coverage-curves", help="output folder")
    ap.add_argument("cases", nargs="*", help="cases to run (default: all)")
    a = ap.parse_args(argv)
    cases = a.cases or CASES
    for c in cases:
        if c not in CASES:
            ap.error(f"unknown case {c!r}; known: {' '.join(CASES)}")
    os.makedirs(a.out, exist_ok=True)
    work = os.path.join(a.out, "parts")
    os.makedirs(work, exist_ok=True)
    bins = [("A", a.flank)] + ([("B", a.flank_b)] if a.flank_b else [])
    results = {}

    def record(case, tag, r):
        results.setdefault(case, {})[tag] = r
        print(f"{case} {tag}: {r['patches']} patches, {100 * r['coverage']:.1f}%, {r['wall_s']:.2f} s",
              file=sys.stderr)

    for c in cases:
        mesh, tol = part_of(c, a.flank, work)
        tol *= a.tol_scale
        for tag, flank in bins:
            out = os.path.join(a.out, tag, c.replace("/", "_"))
            record(c, tag, run_case(flank, mesh, tol, out))
        if a.spread:
            for f in SPREAD:
                out = os.path.join(a.out, f"A_x{f:g}", c.replace("/", "_"))
                record(c, f"A x{f:g}", run_case(a.flank, mesh, tol * f, out))
    lines = ["| case | run | time (s) | patches | coverage after 1, 2, ... patches (rebuilt, %) | worst max abs e / tol |",
             "| --- | --- | --- | --- | --- | --- |"]
    for c in cases:
        for tag in results[c]:
            r = results[c][tag]
            curve = " ".join(f"{100 * x:.1f}" for x in r["curve"])
            lines.append(f"| {c} | {tag} | {r['wall_s']:.2f} | {r['patches']} | {curve} | {r['worst_max_e_over_tol']:.3f} |")
    if a.spread:
        factors = (SPREAD[0], 1.0, SPREAD[1])
        lines += ["", f"| case | A's final coverage at {', '.join(f'{f:g}' for f in factors)} x tol (%) | range (points) |",
                  "| --- | --- | --- |"]
        for c in cases:
            covs = [results[c]["A" if f == 1.0 else f"A x{f:g}"]["coverage"] for f in factors]
            lines.append(f"| {c} | {' / '.join(f'{100 * x:.1f}' for x in covs)} | {100 * (max(covs) - min(covs)):.1f} |")
    if a.flank_b:
        head = "| case | time B / A | coverage B - A (points) | patches A -> B |"
        rule = "| --- | --- | --- | --- |"
        if a.spread:
            head += f" A's range at {SPREAD[0]:g}-{SPREAD[1]:g} x tol (%) | B against it |"
            rule += " --- | --- |"
        lines += ["", head, rule]
        below = []
        for c in cases:
            ra, rb = results[c]["A"], results[c]["B"]
            row = (f"| {c} | {rb['wall_s'] / ra['wall_s']:.2f} | {100 * (rb['coverage'] - ra['coverage']):+.1f} "
                   f"| {ra['patches']} -> {rb['patches']} |")
            if a.spread:
                spread = [ra["coverage"]] + [results[c][f"A x{f:g}"]["coverage"] for f in SPREAD]
                verdict, lo, hi = judge(spread, rb["coverage"])
                results[c]["B"]["against_spread"] = verdict
                if verdict == "below":
                    below.append(f"{c} ({100 * (rb['coverage'] - lo):+.1f})")
                row += f" {100 * lo:.1f}..{100 * hi:.1f} | {verdict} |"
            lines.append(row)
        if a.spread:
            lines += ["", f"B below A's spread in {len(below)} of {len(cases)} cases"
                      + (": " + ", ".join(below) + " (points below its lowest)" if below else "")]
    table = "\n".join(lines)
    with open(os.path.join(a.out, "curves.md"), "w") as f:
        f.write(f"A: {a.flank}\n" + (f"B: {a.flank_b}\n" if a.flank_b else "") + "\n" + table + "\n")
    with open(os.path.join(a.out, "curves.json"), "w") as f:
        json.dump({"A": a.flank, "B": a.flank_b, "results": results}, f, indent=1)
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
