#!/usr/bin/env python3
"""A change to the fit, judged on the very candidates decompose grows, over the coverage cases.

scripts/coverage_curves.py compares final coverage, which a small change to the fit moves by a
few points either way: the search is chaotic. This runs build/bench/flank_grow_pairs on each
case (the same parts as coverage_curves.py): decompose with its defaults (A) grows each
candidate, and the tool grows the same candidate again with B's fit settings, and once more
with A's for the time (in alternating order, on the same thread). It prints,
per case and over all, the summed best covered area of B over A, the candidates valid with only
one of them, and the growth time of B over A; and over all candidates the quantiles of B's
best area over A's.

Usage: scripts/grow_pairs.py [--pairs BIN] [--flank BIN] [-o DIR] [B OPTIONS ...] [CASE ...]
B options are flank_grow_pairs's: --iterations N, --refit-iterations N, --samples TxS,
--extrapolations N; or --same (B is A: equal areas, and the time ratio is the noise floor).
Writes DIR/pairs.json (every pair of every case).
"""

import argparse
import json
import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import coverage_curves  # noqa: E402  (the cases and their parts)


def run_case(pairs_bin, flank, case, work, b_options):
    mesh, tol = coverage_curves.part_of(case, flank, work)
    out = os.path.join(work, case.replace("/", "_") + ".pairs.json")
    cmd = [pairs_bin, mesh, "--tolerance-rel", str(tol), "--threads", "2", "--json", out, *b_options]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"grow_pairs.py: {case}: {' '.join(cmd)} failed: {proc.stderr.strip()}")
    with open(out) as f:
        return json.load(f)["pairs"]


def summarise(rows):
    """(best area B/A, valid only with A, only with B, growth time B/A) of a list of pairs."""
    r = np.array(rows, dtype=float).reshape(-1, 6)
    area = r[:, 1].sum() / r[:, 0].sum() if r[:, 0].sum() > 0 else 1.0
    only_a = int(np.sum((r[:, 2] > 0) & (r[:, 3] == 0)))
    only_b = int(np.sum((r[:, 3] > 0) & (r[:, 2] == 0)))
    time = r[:, 5].sum() / r[:, 4].sum() if r[:, 4].sum() > 0 else 1.0
    return area, only_a, only_b, time


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", default=os.path.join(HERE, "..", "build", "bench", "flank_grow_pairs"))
    ap.add_argument("--flank", default=os.path.join(HERE, "..", "build", "cli", "flank"),
                    help="makes the synthetic parts")
    ap.add_argument("-o", "--out", default="grow-pairs")
    ap.add_argument("--iterations")
    ap.add_argument("--refit-iterations")
    ap.add_argument("--samples")
    ap.add_argument("--extrapolations")
    ap.add_argument("--same", action="store_true", help="B is A: the time ratio is the noise floor")
    ap.add_argument("cases", nargs="*")
    a = ap.parse_args()
    b_options = []
    for name in ("iterations", "refit_iterations", "samples", "extrapolations"):
        value = getattr(a, name)
        if value is not None:
            b_options += ["--" + name.replace("_", "-"), value]
    if a.same:
        b_options.append("--same")
    if len(b_options) == 0:
        ap.error("give at least one B option, or --same")
    cases = a.cases or coverage_curves.CASES
    for case in cases:
        if case not in coverage_curves.CASES:
            ap.error(f"unknown case {case}")
    os.makedirs(a.out, exist_ok=True)
    every, table = {}, ["| case | candidates | best area B/A | valid only A / only B | growth time B/A |",
                        "| --- | --- | --- | --- | --- |"]
    print("\n".join(table), flush=True)
    for case in cases:
        rows = run_case(a.pairs, a.flank, case, a.out, b_options)
        every[case] = rows
        area, only_a, only_b, time = summarise(rows)
        line = f"| {case} | {len(rows)} | {area:.4f} | {only_a} / {only_b} | {time:.3f} |"
        table.append(line)
        print(line, flush=True)
    rows = [r for case in cases for r in every[case]]
    area, only_a, only_b, time = summarise(rows)
    line = f"| all | {len(rows)} | {area:.4f} | {only_a} / {only_b} | {time:.3f} |"
    table.append(line)
    print(line)
    r = np.array(rows, dtype=float).reshape(-1, 6)
    both = (r[:, 0] > 0) & (r[:, 1] > 0)
    q = np.quantile(r[both, 1] / r[both, 0], [0.05, 0.25, 0.5, 0.75, 0.95]) if both.any() else []
    quantiles = "B/A of the best area where both are valid, quantiles 5/25/50/75/95%: " + \
        " ".join(f"{x:.4f}" for x in q)
    print(quantiles)
    with open(os.path.join(a.out, "pairs.json"), "w") as f:
        json.dump({"b_options": b_options, "cases": every, "table": table, "quantiles": list(q)}, f)


if __name__ == "__main__":
    main()
