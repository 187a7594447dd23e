#!/usr/bin/env python3
"""Scaling report and regression check for the flank "Ladder" benchmarks.

Reads Google Benchmark JSON (``flank_bench --benchmark_out=run.json
--benchmark_out_format=json``, normally with ``--benchmark_repetitions=R
--benchmark_report_aggregates_only=true``).

  report --json RUN.json -o DIR [--baseline BASE.json] [--title TEXT]
      Plots (stages, speed-up, scoring vs raw queries, Gauss-Newton shares),
      report.md and summary.json in DIR.
  check --json RUN.json --baseline BASE.json [--limit 0.10] [--noise-k 2]
      Compares median real times; exit 1 if a benchmark is slower than
      limit + noise_k * max(cv_run, cv_base), 2 if the inputs are unusable.
  pairs --json RUN.json --baseline BASE.json [--limit 0.10]
      Both files are ``merge`` outputs of the same number of processes, run
      interleaved in one session (repetition i of each forms pair i). Exit 1 if
      a benchmark's median per-pair ratio run/base exceeds 1 + limit and every
      pair is slower by more than limit / 2; 2 if the inputs are unusable.

Run with a Python that has matplotlib for ``report`` (Debian: /usr/bin/python3);
``check`` needs only the standard library.
"""

import argparse
import json
import math
import os
import re
import statistics
import sys
from dataclasses import dataclass, field

PROG = "scaling-report"
TIME_UNITS = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}
TIME_TYPE_PARTS = {"real_time", "manual_time", "process_time"}
AGGREGATE_SUFFIX = re.compile(r"_(mean|median|stddev|cv)$")
LADDER_KEY = re.compile(
    r"^Ladder/(?P<stage>[^/]+)/(?P<part>[^/]+)/tri_k:(?P<tri_k>\d+)/threads:(?P<threads>\d+)$")
# bench/fork_join_benchmark.cpp at two threads: one fork and join after an idle spell.
FORK_JOIN_KEY = re.compile(r"^BM_ForkJoin/work_us:(?P<work>\d+)/idle_us:\d+/threads:2$")
# bench/fork_join_benchmark.cpp's chain of parallel steps of a read's kind, as a parallel row.
STEP_CHAIN_ROW = re.compile(r"^BM_StepChain/items:(?P<items>\d+)/gather:(?P<gather>[01])$")
# Benchmarks of the machine, not of flank's code: in the efficiency table as yardsticks, never
# counted as a stage that misses, and not compared with a baseline.
YARDSTICKS = ("BM_ForkJoin/", "BM_StepChain/")
# Keys of a Google Benchmark entry that are not user counters.
STANDARD_KEYS = {
    "name", "family_index", "per_family_instance_index", "run_name", "run_type",
    "repetitions", "repetition_index", "threads", "aggregate_name", "aggregate_unit",
    "iterations", "real_time", "cpu_time", "time_unit", "label", "error_occurred",
    "error_message", "skipped", "skip_message",
}
STAGES = ["read", "index", "query", "scoring", "fit", "decompose", "command"]
# Decompose sub-stages: (counter, label); their values are seconds per stage.
SUB_STAGES = [
    ("seeds_s", "decompose: seeds"),
    ("candidates_s", "decompose: candidates"),
    ("fit_s", "decompose: fit+grow"),
    ("cover_s", "decompose: cover"),
]
# Sub-stages that do work only when decompose grows candidates (the `grown` counter): on a rung
# where nothing was grown they measure an empty loop, so they are left out of plots and slopes.
NEEDS_GROWN = {"fit_s", "finish_s", "cover_s"}
# Decompose's own stages in the parallel-efficiency table, from the seconds it records per
# stage (patches.json's timing_s; the benchmark's counters): the target is >= 0.9 on every
# stage, and the whole decompose's row can hide one that misses behind those that do not.
EFFICIENCY_SUB_STAGES = [
    ("index_s", "index"),
    ("seeds_s", "seeds"),
    ("candidates_s", "candidates"),
    ("fit_s", "fit+grow"),
    ("finish_s", "finish"),
    ("cover_s", "cover"),
]
# bench/runs.h's line_round_trip_ns, recorded beside every two-thread ladder run: a pair whose
# two-thread run saw a round trip over QUIET_FACTOR times the run's quiet level (its tenth
# percentile) ran in one of the spells when data passes between the cores slowly.
LINE_ROUND_TRIP = "line_rt_ns"
QUIET_FACTOR = 2.0
# A sub-stage shorter than this at one thread is left out of the table: its time is a sum of
# pieces of microseconds over the rounds, below what a timer and a fork can resolve.
MIN_SUB_STAGE_S = 1e-3
# The synthetic cone, the subdivided propeller blade, then the real faces of tests/data.
PART_ORDER = ["cone", "blade", "hecc_a", "hecc_b", "rotor_upper", "rotor_lower"]
# Plots with one panel per part wrap into rows of at most this many panels.
PANELS_PER_ROW = 3


class InputError(Exception):
    """A benchmark file that cannot be used; the message names the file."""


@dataclass
class Bench:
    """One benchmark: medians over the repetitions."""
    key: str
    real_s: float
    cpu_s: float
    cv: float | None
    repetitions: int
    counters: dict = field(default_factory=dict)
    # Real seconds per repetition, by repetition index (plain iteration entries only): one
    # process each in the scaling report, so repetition i of two benchmarks ran minutes apart
    # at most, and back to back for the 1- and 2-thread runs of one rung.
    reals: dict = field(default_factory=dict)
    # The same for decompose's stage counters (EFFICIENCY_SUB_STAGES): {counter: {repetition
    # index: seconds}}, so that their efficiency pairs the repetitions as the real time does.
    counter_reps: dict = field(default_factory=dict)
    stage: str | None = None
    part: str | None = None
    tri_k: int | None = None
    threads: int | None = None

    @property
    def triangles(self):
        """Triangle count: the counter if there is one, else tri_k * 1000."""
        if "triangles" in self.counters:
            return self.counters["triangles"]
        return None if self.tri_k is None else self.tri_k * 1000.0


# ----------------------------------------------------------------------------- loading

def benchmark_key(entry):
    """The benchmark's name without aggregate suffix and time-type component."""
    name = entry.get("run_name") or AGGREGATE_SUFFIX.sub("", str(entry.get("name", "")))
    return "/".join(p for p in name.split("/") if p not in TIME_TYPE_PARTS)


def _seconds(entry, what):
    value = entry.get(what)
    unit = entry.get("time_unit", "ns")
    if not isinstance(value, (int, float)) or unit not in TIME_UNITS:
        return None
    return float(value) * TIME_UNITS[unit]


def _counters(entry):
    return {k: float(v) for k, v in entry.items()
            if k not in STANDARD_KEYS and isinstance(v, (int, float)) and not isinstance(v, bool)}


def _from_aggregates(key, aggs):
    """Bench from the mean/median/stddev/cv entries of one benchmark."""
    main = aggs.get("median") or aggs.get("mean")
    if main is None:
        return None
    real, cpu = _seconds(main, "real_time"), _seconds(main, "cpu_time")
    if real is None:
        return None
    if "cv" in aggs and isinstance(aggs["cv"].get("real_time"), (int, float)):
        cv = float(aggs["cv"]["real_time"])  # a fraction, not a time
    elif "mean" in aggs and "stddev" in aggs:
        mean, sd = _seconds(aggs["mean"], "real_time"), _seconds(aggs["stddev"], "real_time")
        cv = sd / mean if mean and sd is not None else None
    else:
        cv = None
    reps = int(main.get("repetitions") or 0)
    return Bench(key, real, cpu if cpu is not None else real, cv, reps, _counters(main))


def _from_iterations(key, runs):
    """Bench from plain iteration entries (one per repetition)."""
    reals = [s for s in (_seconds(r, "real_time") for r in runs) if s is not None]
    if not reals:
        return None
    cpus = [s for s in (_seconds(r, "cpu_time") for r in runs) if s is not None] or reals
    cv = 0.0
    if len(reals) >= 2 and statistics.mean(reals) > 0:
        cv = statistics.stdev(reals) / statistics.mean(reals)
    names = set().union(*(_counters(r).keys() for r in runs))
    counters = {n: statistics.median([_counters(r)[n] for r in runs if n in _counters(r)])
                for n in names}
    return Bench(key, statistics.median(reals), statistics.median(cpus), cv, len(runs), counters,
                 _reals_by_repetition(runs), _counters_by_repetition(runs))


def _by_repetition(runs, value_of):
    """{repetition index: value_of(entry)} of iteration entries; {} unless every one has a
    value and a distinct index (its position where the entry has none)."""
    out = {}
    for position, r in enumerate(runs):
        value, index = value_of(r), r.get("repetition_index")
        if value is None:
            return {}
        out[index if isinstance(index, int) else position] = value
    return out if len(out) == len(runs) else {}


def _reals_by_repetition(runs):
    """{repetition index: real seconds} of iteration entries (_by_repetition)."""
    return _by_repetition(runs, lambda r: _seconds(r, "real_time"))


def _counters_by_repetition(runs):
    """{counter: {repetition index: value}} for the EFFICIENCY_SUB_STAGES counters and the
    cache line's round trip that every iteration entry has (_by_repetition)."""
    out = {}
    for name in [n for n, _ in EFFICIENCY_SUB_STAGES] + [LINE_ROUND_TRIP]:
        values = _by_repetition(runs, lambda r: _counters(r).get(name))
        if values:
            out[name] = values
    return out


def read_gb_json(path):
    """The parsed Google Benchmark JSON document; InputError naming the file if unusable."""
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except OSError as e:
        raise InputError(f"{path}: cannot read it ({e.strerror or e})") from None
    except ValueError as e:
        raise InputError(f"{path}: not valid JSON ({e})") from None
    if not isinstance(data, dict) or not isinstance(data.get("benchmarks"), list):
        raise InputError(f"{path}: no \"benchmarks\" list (not Google Benchmark JSON output)")
    return data


def load_run(path):
    """(context, {key: Bench}) from a Google Benchmark JSON file; InputError if unusable."""
    data = read_gb_json(path)
    groups = {}
    for entry in data["benchmarks"]:
        if not isinstance(entry, dict) or entry.get("error_occurred") or entry.get("skipped"):
            continue
        g = groups.setdefault(benchmark_key(entry), {"aggregates": {}, "iterations": []})
        if entry.get("run_type") == "aggregate":
            g["aggregates"][entry.get("aggregate_name")] = entry
        else:
            g["iterations"].append(entry)
    benches = {}
    for key, g in groups.items():
        b = _from_aggregates(key, g["aggregates"]) if g["aggregates"] else None
        if b is not None:
            b.reals = _reals_by_repetition(g["iterations"])
            b.counter_reps = _counters_by_repetition(g["iterations"])
        elif g["iterations"]:
            b = _from_iterations(key, g["iterations"])
        if b is None:
            continue
        m = LADDER_KEY.match(key)
        if m:
            b.stage, b.part = m["stage"], m["part"]
            b.tri_k, b.threads = int(m["tri_k"]), int(m["threads"])
        benches[key] = b
    if not benches:
        raise InputError(f"{path}: has no benchmarks")
    context = data.get("context") if isinstance(data.get("context"), dict) else {}
    return context, benches


# ----------------------------------------------------------------------------- formulas

def _div(a, b):
    """a / b, or None if either is missing or b is zero."""
    if a is None or b is None or b == 0:
        return None
    return a / b


def sample_query_ratio(lines_per_s, samples, raw_qps):
    """Scoring's sample queries/s (lines/s x samples) over raw cold queries/s."""
    return _div(None if lines_per_s is None or samples is None else lines_per_s * samples, raw_qps)


def speedup(t1, t2):
    """t(1 thread) / t(2 threads)."""
    return _div(t1, t2)


def parallel_efficiency(t1, t2, threads=2):
    """t1 / (threads * t2): 1 is perfect scaling."""
    return _div(t1, None if t2 is None else threads * t2)


def fork_join_cost(benches):
    """What one fork and join of two threads costs on this machine, in seconds: the median over
    BM_ForkJoin's task lengths of the two-thread time's excess over one task, or None."""
    excess = [b.real_s - int(m["work"]) * 1e-6 for key, b in benches.items()
              if (m := FORK_JOIN_KEY.match(key)) and b.real_s is not None]
    return statistics.median(excess) if excess else None


def efficiency_ceiling(t1, cost):
    """The best efficiency a stage of one thread's time t1 can reach with a single fork and
    join of that cost: t1 / (2 · (t1 / 2 + cost)). Stages that fork more reach less."""
    if t1 is None or cost is None or t1 + 2 * cost <= 0:
        return None
    return t1 / (t1 + 2 * cost)


def unavoidable_query_s(gn_iterations, samples, raw_qps):
    """Time the fit's closest-point queries take at the raw cold query rate."""
    if gn_iterations is None or samples is None:
        return None
    return _div(gn_iterations * samples, raw_qps)


def fit_over_unavoidable(fit_s, gn_iterations, samples, raw_qps):
    """Fit time over its unavoidable query time."""
    return _div(fit_s, unavoidable_query_s(gn_iterations, samples, raw_qps))


def slope(points):
    """Least-squares slope of log10(y) vs log10(x); None with < 2 usable points."""
    pts = [(math.log10(x), math.log10(y)) for x, y in points
           if x is not None and y is not None and x > 0 and y > 0]
    if len(pts) < 2:
        return None
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    if sxx == 0:
        return None
    return sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx


# ----------------------------------------------------------------------------- ladder views

def ladder(benches):
    """{(stage, part, tri_k, threads): Bench} for the Ladder benchmarks."""
    return {(b.stage, b.part, b.tri_k, b.threads): b for b in benches.values() if b.stage}


def parts_of(lad):
    """Parts in display order: those of PART_ORDER, then any others."""
    found = {k[1] for k in lad}
    return [p for p in PART_ORDER if p in found] + sorted(found - set(PART_ORDER))


def rungs(lad):
    """Sorted (part, tri_k, threads) present in the ladder."""
    order = {p: i for i, p in enumerate(parts_of(lad))}
    return sorted({k[1:] for k in lad}, key=lambda r: (order[r[0]], r[1], r[2]))


def ordered_keys(benches):
    """Ladder keys by part, stage, size, threads; other keys after them, as found."""
    parts = parts_of(ladder(benches))
    stages = {s: i for i, s in enumerate(STAGES)}

    def rank(item):
        i, (key, b) = item
        if not b.stage:
            return (1, i)
        return (0, parts.index(b.part), stages.get(b.stage, len(STAGES)), b.stage, b.tri_k,
                b.threads)
    return [key for _, (key, _) in sorted(enumerate(benches.items()), key=rank)]


def series(lad, name, part, threads):
    """[(triangles, seconds)] for a stage or decompose sub-stage, sorted by size."""
    counter = name if name in dict(SUB_STAGES) else None
    stage = "decompose" if counter else name
    pts = []
    for (s, p, _, t), b in lad.items():
        if s == stage and p == part and t == threads:
            value = b.counters.get(counter) if counter else b.real_s
            if counter in NEEDS_GROWN and not b.counters.get("grown", 1):
                continue
            if value is not None and b.triangles:
                pts.append((b.triangles, value))
    return sorted(pts)


def stage_names():
    """[(series name, label)] of stages and decompose sub-stages."""
    return [(s, s) for s in STAGES] + list(SUB_STAGES)


def _counter(b, name):
    return None if b is None else b.counters.get(name)


def scoring_rows(lad):
    """Scoring sample queries/s vs raw cold queries/s per part/size/threads."""
    rows = []
    for part, tri_k, t in rungs(lad):
        sc, q = lad.get(("scoring", part, tri_k, t)), lad.get(("query", part, tri_k, t))
        if sc is None and q is None:
            continue
        lps, samples, qps = _counter(sc, "lines_per_s"), _counter(sc, "samples"), _counter(q, "queries_per_s")
        rows.append({
            "part": part, "tri_k": tri_k, "threads": t,
            "triangles": (sc or q).triangles,
            "lines_per_s": lps, "samples": samples,
            "sample_queries_per_s": None if lps is None or samples is None else lps * samples,
            "raw_queries_per_s": qps,
            "ratio": sample_query_ratio(lps, samples, qps),
        })
    return rows


def pair_values(t1s, t2s, formula):
    """formula(t1_i, t2_i) for every repetition i both have, in order; [] with fewer than two.
    The machine's speed drifts by tens of percent over a run; the 1- and 2-thread runs of one
    repetition ran back to back, so their ratio does not see the drift that a ratio of medians
    taken minutes apart does."""
    common = sorted(set(t1s) & set(t2s))
    values = [formula(t1s[i], t2s[i]) for i in common]
    if len(values) < 2 or any(v is None for v in values):
        return []
    return values


def paired(t1s, t2s, formula):
    """Median over the repetitions both have of formula(t1_i, t2_i), and how many; (None, 0)
    with fewer than two (pair_values)."""
    values = pair_values(t1s, t2s, formula)
    return (statistics.median(values), len(values)) if values else (None, 0)


def quiet_level(benches):
    """The run's quiet cache-line round trip in ns: the tenth percentile of every two-thread
    run's line_rt_ns over the repetitions; None where no run has one."""
    trips = sorted(v for b in benches.values()
                   for v in b.counter_reps.get(LINE_ROUND_TRIP, {}).values() if v > 0)
    return trips[len(trips) // 10] if trips else None


def parallel_rows(benches):
    """Speed-up and efficiency for every key with threads:1 and threads:2 runs: the median of
    the per-repetition ratios where both have two or more repetitions, else the ratio of the
    medians ("pairs" 0); "low" and "high" are the lowest and highest efficiency of one pair
    (None without pairs): the machine's noise on that row; "ceiling" is what one fork and
    join's cost (fork_join_cost) leaves a stage of that length at best, None without
    BM_ForkJoin in the run; "quiet" and "quiet_pairs" are the median efficiency over the pairs
    whose two-thread run saw the cache line's round trip within QUIET_FACTOR of the run's quiet
    level (quiet_level), and how many (None and 0 without round trips). After each decompose row
    come its own stages' rows (sub_stage_rows)."""
    rows = []
    cost = fork_join_cost(benches)
    level = quiet_level(benches)
    for key in ordered_keys(benches):
        b1 = benches[key]
        if not key.endswith("/threads:1"):
            continue
        base = key[: -len("/threads:1")]
        b2 = benches.get(base + "/threads:2")
        if b2 is None:
            continue
        first = len(rows)
        rows.append(_parallel_row(base, b1, b1.real_s, b2.real_s, b1.reals, b2.reals, cost))
        if b1.stage == "decompose":
            rows += sub_stage_rows(base, b1, b2, cost)
        for row in rows[first:]:
            _add_quiet(row, b2.counter_reps.get(LINE_ROUND_TRIP, {}), level)
    return rows


def _add_quiet(row, trips, level):
    """row's "quiet" efficiency and "quiet_pairs" (parallel_rows) from its pairs' efficiencies
    (row["pair_efficiency"]: {repetition: efficiency}) and the two-thread runs' round trips."""
    quiet = [e for i, e in row["pair_efficiency"].items()
             if level is not None and i in trips and trips[i] <= QUIET_FACTOR * level]
    row["quiet"] = statistics.median(quiet) if quiet else None
    row["quiet_high"] = max(quiet) if quiet else None
    row["quiet_pairs"] = len(quiet)


def _parallel_row(name, b1, t1, t2, t1s, t2s, cost):
    """One row of parallel_rows: medians t1, t2 and per-repetition times t1s, t2s."""
    row = {"benchmark": name, "stage": b1.stage, "part": b1.part, "tri_k": b1.tri_k,
           "triangles": b1.triangles, "t1_s": t1, "t2_s": t2, "pairs": 0,
           "ceiling": efficiency_ceiling(t1, cost)}
    for what, formula in (("speedup", speedup), ("efficiency", parallel_efficiency)):
        value, pairs = paired(t1s, t2s, formula)
        row[what] = value if pairs else formula(t1, t2)
        row["pairs"] = pairs
    values = pair_values(t1s, t2s, parallel_efficiency)
    row["low"], row["high"] = (min(values), max(values)) if values else (None, None)
    row["pair_efficiency"] = dict(zip(sorted(set(t1s) & set(t2s)), values)) if values else {}
    row["quiet"], row["quiet_high"], row["quiet_pairs"] = None, None, 0
    return row


def sub_stage_rows(base, b1, b2, cost):
    """Rows for decompose's own stages (EFFICIENCY_SUB_STAGES), named "BASE · LABEL", from the
    1- and 2-thread runs' counters: those that take MIN_SUB_STAGE_S or more at one thread,
    and, for the stages that only grown candidates feed (NEEDS_GROWN), where both runs grew
    some. Paired by repetition where both runs' counters have them."""
    rows = []
    for counter, label in EFFICIENCY_SUB_STAGES:
        t1, t2 = b1.counters.get(counter), b2.counters.get(counter)
        if t1 is None or t2 is None or t1 < MIN_SUB_STAGE_S:
            continue
        if counter in NEEDS_GROWN and not (b1.counters.get("grown", 1) and b2.counters.get("grown", 1)):
            continue
        row = _parallel_row(f"{base} · {label}", b1, t1, t2, b1.counter_reps.get(counter, {}),
                            b2.counter_reps.get(counter, {}), cost)
        row["stage"] = f"decompose: {label}"
        rows.append(row)
    return rows


def is_yardstick(name):
    """True for a benchmark of the machine (YARDSTICKS), not of flank's code."""
    return name.startswith(YARDSTICKS)


def step_chain_rows(rows):
    """The parallel_rows of BM_StepChain, each with its "items" and "gather" (bool), in the
    order of the rows."""
    chain = []
    for r in rows:
        if m := STEP_CHAIN_ROW.match(r["benchmark"]):
            chain.append(dict(r, items=int(m["items"]), gather=m["gather"] == "1"))
    return chain


def below_in_every_quiet_pair(rows, target=0.9):
    """The parallel_rows long enough to reach target (ceiling unknown or at least target; see
    below_in_every_pair) that have quiet pairs (parallel_rows), every one of them under it."""
    return [r["benchmark"] for r in rows
            if r["quiet_pairs"] and r["quiet_high"] < target
            and not is_yardstick(r["benchmark"])
            and (r["ceiling"] is None or r["ceiling"] >= target)]


def below_in_every_pair(rows, target=0.9):
    """The parallel_rows whose every pair's efficiency is under target (their "high"; rows
    without pairs are left out: one ratio of medians cannot tell a miss from the noise), as
    two lists of benchmark names: those whose ceiling is under target too (too short for the
    machine's fork and join), and the rest (ceiling unknown or at least target)."""
    short, slow = [], []
    for r in rows:
        if r["high"] is None or r["high"] >= target or is_yardstick(r["benchmark"]):
            continue
        (short if r["ceiling"] is not None and r["ceiling"] < target else slow).append(r["benchmark"])
    return short, slow


def fit_rows(lad):
    """Fit time over unavoidable query time, plus the Gauss-Newton shares."""
    rows = []
    for part, tri_k, t in rungs(lad):
        fit, q = lad.get(("fit", part, tri_k, t)), lad.get(("query", part, tri_k, t))
        if fit is None:
            continue
        gn, samples, qps = _counter(fit, "gn_iterations"), _counter(fit, "samples"), _counter(q, "queries_per_s")
        rows.append({
            "part": part, "tri_k": tri_k, "threads": t, "triangles": fit.triangles,
            "fit_s": fit.real_s, "gn_iterations": gn, "samples": samples,
            "queries": _counter(fit, "queries"), "raw_queries_per_s": qps,
            "unavoidable_s": unavoidable_query_s(gn, samples, qps),
            "fit_over_unavoidable": fit_over_unavoidable(fit.real_s, gn, samples, qps),
            "query_share": _counter(fit, "query_share"),
            "assembly_share": _counter(fit, "assembly_share"),
            "factor_share": _counter(fit, "factor_share"),
        })
    return rows


def command_rows(lad):
    """The whole command (its own process, timed from outside) beside the same rung's warm
    decompose loop: what a user's cold run pays beyond the work."""
    rows = []
    for part, tri_k, t in rungs(lad):
        c, d = lad.get(("command", part, tri_k, t)), lad.get(("decompose", part, tri_k, t))
        if c is None:
            continue
        own = _counter(c, "decompose_s")
        rows.append({
            "part": part, "tri_k": tri_k, "threads": t, "command_s": c.real_s,
            "decompose_in_command_s": own,
            "outside_decompose_s": None if own is None else c.real_s - own,
            "decompose_warm_s": None if d is None else d.real_s,
            "page_faults": _counter(c, "page_faults"), "peak_mb": _counter(c, "peak_mb"),
            "unpinned_s": _counter(c, "unpinned_s"),
        })
    return rows


def slope_rows(lad):
    """Slope of log time vs log triangles per part, stage and thread count."""
    rows = []
    for part in parts_of(lad):
        for name, label in stage_names():
            row = {"part": part, "stage": label}
            for t in (2, 1):
                pts = series(lad, name, part, t)
                row[f"slope_threads_{t}"] = slope(pts)
                row[f"points_threads_{t}"] = len(pts)
            if row["points_threads_2"] or row["points_threads_1"]:
                rows.append(row)
    return rows


# ----------------------------------------------------------------------------- formatting

def sig3(x):
    """x with 3 significant figures; "n/a" for None."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    if x == 0:
        return "0"
    exp = math.floor(math.log10(abs(x)))
    rounded = round(x, 2 - exp)  # 0.9999 -> 1.0 moves the leading digit
    if rounded != 0:
        exp = math.floor(math.log10(abs(rounded)))
    if exp >= 6 or exp < -3:
        mantissa = x / 10 ** exp
        if abs(round(mantissa, 2)) >= 10:
            mantissa, exp = mantissa / 10, exp + 1
        return f"{mantissa:.2f}e{exp}"
    if exp >= 3:
        return str(int(round(x, 2 - exp)))
    return f"{x:.{2 - exp}f}"


def human_time(s):
    """Seconds in s/ms/us/ns with 3 significant figures."""
    if s is None:
        return "n/a"
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("µs", 1e-6)):
        if abs(s) >= scale:
            return f"{sig3(s / scale)} {unit}"
    return f"{sig3(s / 1e-9)} ns"


def tolerance_text(x):
    """A relative tolerance as 1e-4, 3e-4; "n/a" for None."""
    if x is None:
        return "n/a"
    mantissa, exponent = f"{x:.0e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def count_text(x):
    """A count as a whole number; "n/a" for None."""
    return "n/a" if x is None else str(round(x))


def pct(x):
    return "n/a" if x is None else f"{sig3(100 * x)} %"


def md_table(header, rows):
    """A GitHub markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- plots

def _colour(i):
    import matplotlib.pyplot as plt
    return plt.get_cmap("tab10")(i % 10)


def _panels(plt, nrows, ncols, height=4.2):
    fig, axes = plt.subplots(nrows, ncols, figsize=(6.4 * ncols, height * nrows), squeeze=False)
    return fig, axes


def panel_grid(count):
    """(rows, columns) of `count` per-part panels, at most PANELS_PER_ROW to a row."""
    count = max(count, 1)
    cols = min(count, PANELS_PER_ROW)
    return math.ceil(count / cols), cols


def _part_panels(plt, parts, height, stacked=1):
    """A figure with `stacked` panels one above the other per part, the parts wrapped into
    rows of at most PANELS_PER_ROW; [[axes of the part, top to bottom]] in the parts' order.
    The cells the last row leaves empty are removed."""
    rows, cols = panel_grid(len(parts))
    fig, axes = _panels(plt, rows * stacked, cols, height)
    per_part = []
    for i in range(rows * cols):
        row, col = divmod(i, cols)
        cell = [axes[row * stacked + k][col] for k in range(stacked)]
        if i < len(parts):
            per_part.append(cell)
        else:
            for ax in cell:
                fig.delaxes(ax)
    return fig, per_part


def _no_data(ax):
    ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)


def _log_x(ax):
    """Log x axis; a single size gets a factor-2 margin instead of a decade on one side."""
    xs = [x for line in ax.lines for x in line.get_xdata() if x > 0]
    ax.set_xscale("log")
    if xs and min(xs) == max(xs):
        ax.set_xlim(min(xs) / 2, max(xs) * 2)


def _slope_text(s):
    """A slope with 2 decimals (exponents near 0 would be noise in 3 significant figures)."""
    return "n/a" if s is None else f"{s:.2f}"


def _decorate(ax, ylabel, title, legend_columns):
    """Triangles on x, grid, and the legend below the panel."""
    ax.set_xlabel("triangles")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=legend_columns, fontsize=8)


def _save(plt, fig, path):
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def plot_stages(plt, lad, path):
    """Log-log time vs triangles per part; solid 2 threads, dashed 1 thread."""
    parts = parts_of(lad)
    fig, panels = _part_panels(plt, parts, 5.0)
    for (ax,), part in zip(panels, parts):
        drawn = False
        for i, (name, label) in enumerate(stage_names()):
            marker = ("D" if name == "query" else "o") if name in STAGES else "s"
            p2, p1 = series(lad, name, part, 2), series(lad, name, part, 1)
            if p2:
                ax.plot(*zip(*p2), "-", marker=marker, color=_colour(i),
                        label=f"{label} (slope {_slope_text(slope(p2))})")
            if p1:
                ax.plot(*zip(*p1), "--", marker=marker, color=_colour(i), alpha=0.7, mfc="none",
                        label=None if p2 else f"{label}, 1 thread (slope {_slope_text(slope(p1))})")
            drawn = drawn or bool(p1 or p2)
        if not drawn:
            _no_data(ax)
            continue
        _log_x(ax)
        ax.set_yscale("log")
        _decorate(ax, "median time (s)",
                  f"{part}: time per stage (solid 2 threads, dashed 1 thread)", 2)
    fig.tight_layout()  # the legends below a row of panels push the next row down
    _save(plt, fig, path)


def plot_speedup(plt, lad, path):
    """Speed-up t1/t2 vs triangles per part and stage."""
    parts = parts_of(lad)
    fig, panels = _part_panels(plt, parts, 4.6)
    for (ax,), part in zip(panels, parts):
        ymax = 2.2
        for i, (name, label) in enumerate(stage_names()):
            s1, s2 = dict(series(lad, name, part, 1)), dict(series(lad, name, part, 2))
            pts = [(x, speedup(s1[x], s2[x])) for x in sorted(set(s1) & set(s2))]
            pts = [(x, y) for x, y in pts if y is not None]
            if pts:
                ax.plot(*zip(*pts), "-" if name in STAGES else ":",
                        marker="o" if name in STAGES else "s", color=_colour(i), label=label)
                ymax = max(ymax, max(y for _, y in pts) * 1.1)
        ax.axhline(2.0, color="grey", linestyle="--", label="ideal, 2 cores")
        ax.axhline(1.0, color="grey", linestyle=":", linewidth=0.8)
        _log_x(ax)
        ax.set_ylim(0, ymax)
        _decorate(ax, "speed-up  t(1 thread) / t(2 threads)", f"{part}: 2-thread speed-up", 3)
    fig.tight_layout()  # the legends below a row of panels push the next row down
    _save(plt, fig, path)


def plot_scoring_vs_queries(plt, lad, path):
    """Scoring's sample queries/s vs raw cold queries/s, and their ratio."""
    parts = parts_of(lad)
    rows = scoring_rows(lad)
    fig, panels = _part_panels(plt, parts, 4.0, stacked=2)
    for (top, bottom), part in zip(panels, parts):
        ratio_max = 1.0
        for t, style in ((2, "-"), (1, "--")):
            rs = [r for r in rows if r["part"] == part and r["threads"] == t and r["triangles"]]
            for what, label, colour in (("sample_queries_per_s", "scoring: lines/s × samples", 0),
                                        ("raw_queries_per_s", "raw cold queries/s", 1)):
                pts = [(r["triangles"], r[what]) for r in rs if r[what]]
                if pts:
                    top.plot(*zip(*pts), style, marker="o", color=_colour(colour),
                             mfc=None if t == 2 else "none",
                             label=f"{label}, {t} thread{'s' if t > 1 else ''}")
            pts = [(r["triangles"], r["ratio"]) for r in rs if r["ratio"] is not None]
            if pts:
                bottom.plot(*zip(*pts), style, marker="o", color=_colour(2),
                            mfc=None if t == 2 else "none",
                            label=f"{t} thread{'s' if t > 1 else ''}")
                ratio_max = max(ratio_max, max(y for _, y in pts))
        for ax in (top, bottom):
            _log_x(ax)
            ax.set_xlabel("triangles")
            ax.grid(True, which="both", alpha=0.3)
        top.set_yscale("log")
        top.set_ylabel("closest-point queries / s")
        top.set_title(f"{part}: query rates", fontsize=10)
        bottom.axhline(1.0, color="grey", linestyle=":", linewidth=0.8)
        bottom.set_ylim(0, 1.15 * ratio_max)
        bottom.set_ylabel("scoring sample queries/s ÷ raw cold queries/s")
        bottom.set_title(f"{part}: ratio (> 1: warm starts beat cold queries)", fontsize=10)
        if bottom.lines:
            bottom.legend(loc="best", fontsize=8)
        for ax in (top, bottom):
            if not ax.lines:
                _no_data(ax)
    fig.tight_layout()
    # The rate panels share their labels: one legend above the figure, clear of the data.
    handles = {}
    for top, _ in panels:
        for h, label in zip(*top.get_legend_handles_labels()):
            handles.setdefault(label, h)
    if handles:
        fig.legend(list(handles.values()), list(handles), loc="lower center",
                   bbox_to_anchor=(0.5, 1.0), ncol=4, fontsize=8)
    _save(plt, fig, path)


def plot_gn_share(plt, lad, path):
    """Stacked bars of the fit's time shares, one bar per part/size; 2 and 1 threads."""
    rows = fit_rows(lad)
    names = [("query_share", "closest-point queries"), ("assembly_share", "assembly"),
             ("factor_share", "factorisation (CHOLMOD)"), ("other", "other")]
    # One bar per rung, 0.6 inch apart so that their slanted labels do not overlap, plus the
    # legend beside: wider than a panel when there are many (the six parts have 20 rungs).
    bars = max(sum(1 for r in rows if r["threads"] == t) for t in (1, 2))
    fig, axes = _panels(plt, 2, 1, 3.8)
    fig.set_figwidth(max(6.4, 2.0 + 0.6 * bars))
    for ax, t in zip(axes[:, 0], (2, 1)):
        rs = [r for r in rows if r["threads"] == t
              and any(r[n] is not None for n, _ in names[:3])]
        if not rs:
            _no_data(ax)
            ax.set_title(f"fit time shares, {t} thread{'s' if t > 1 else ''}", fontsize=10)
            continue
        x = list(range(len(rs)))
        bottom = [0.0] * len(rs)
        for i, (name, label) in enumerate(names):
            if name == "other":
                vals = [max(0.0, 1.0 - b) for b in bottom]
            else:
                vals = [r[name] or 0.0 for r in rs]
            ax.bar(x, vals, bottom=bottom, color=_colour(i), label=label, width=0.7)
            bottom = [b + v for b, v in zip(bottom, vals)]
        ax.set_xticks(x)
        ax.set_xticklabels([f"{r['part']} {r['tri_k']}k" for r in rs], rotation=30, ha="right")
        ax.set_ylim(0, max(1.0, max(bottom)) * 1.02)
        ax.set_ylabel("share of fit time")
        ax.set_title(f"fit time shares, {t} thread{'s' if t > 1 else ''}", fontsize=10)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.tight_layout()
    _save(plt, fig, path)


# ----------------------------------------------------------------------------- report

PLOT_TEXT = [
    ("stages", "Median time of each stage against mesh size, log-log, one panel per part; "
     "solid lines are 2 threads, dashed 1 thread. The slope in the legend is the exponent: "
     "0 is independent of size, 1 is linear in the triangle count."),
    ("speedup", "Speed-up from 1 to 2 threads per stage; the dashed line at 2 is the ideal on "
     "this 2-core machine, values near 1 mean the stage does not parallelise."),
    ("scoring_vs_queries", "Top: closest-point queries per second made inside candidate "
     "scoring (lines/s × samples per line) against raw cold queries per second. Bottom: their "
     "ratio; above 1, warm starts make scoring's queries cheaper than cold ones."),
    ("gn_share", "Where one Gauss–Newton motion fit spends its time, per part and size; "
     "\"other\" is whatever the three measured parts do not cover."),
]


def _rep_text(benches):
    reps = sorted({b.repetitions for b in benches.values()})
    return ", ".join(str(r) for r in reps) if reps else "n/a"


def time_table(benches, base):
    """Rows of the "Time per stage" table (run keys, then keys only in the baseline)."""
    rows = []
    for key in ordered_keys(benches):
        b = benches[key]
        row = [f"`{key}`", human_time(b.real_s), sig3(None if b.cv is None else 100 * b.cv)]
        if base is not None:
            o = base.get(key)
            row += [human_time(o.real_s) if o else "n/a", sig3(_div(b.real_s, o.real_s)) if o else "n/a"]
        rows.append(row)
    if base is not None:
        rows += [[f"`{k}`", "not run", "n/a", human_time(o.real_s), "n/a"]
                 for k, o in base.items() if k not in benches]
    return rows


def build_markdown(title, run_path, context, benches, base_path, base, lad):
    """The text of report.md."""
    out = [f"# {title}", ""]
    out.append(f"- Run: `{run_path}`")
    out.append(f"- Date: {context.get('date', 'n/a')}; host: {context.get('host_name', 'n/a')}; "
               f"num_cpus: {context.get('num_cpus', 'n/a')}; "
               f"MHz per CPU: {context.get('mhz_per_cpu', 'n/a')}; "
               f"Google Benchmark library build: {context.get('library_build_type', 'n/a')}")
    out.append(f"- flank commit: {context.get('commit', 'n/a')}; mode: {context.get('mode', 'n/a')}; "
               f"machine: {context.get('machine', 'n/a')}")
    where = ("one process each; " if context.get("repetition_processes")
             else "in one process; ")
    out.append(f"- Repetitions: {_rep_text(benches)} ({where}all values are medians; cv = stddev / mean "
               "of the repetitions' real time)")
    if base_path:
        out.append(f"- Baseline: `{base_path}`")
    out.append("")
    out.append("## Plots")
    for name, text in PLOT_TEXT:
        out += ["", f"![{name}]({name}.png)", "", text]

    out += ["", "## Ratios against limits (same run)", "",
            "### Scoring's sample queries vs raw cold queries", "",
            "ratio = lines/s × samples ÷ raw cold queries/s (query stage, same part, size and "
            "threads).", ""]
    out.append(md_table(
        ["part", "tri_k", "threads", "lines/s", "samples", "sample queries/s",
         "raw cold queries/s", "ratio"],
        [[r["part"], r["tri_k"], r["threads"], sig3(r["lines_per_s"]), sig3(r["samples"]),
          sig3(r["sample_queries_per_s"]), sig3(r["raw_queries_per_s"]), sig3(r["ratio"])]
         for r in scoring_rows(lad)]))

    out += ["", "### Parallel efficiency", "",
            "speed-up = t1 ÷ t2, efficiency = t1 ÷ (2 · t2) (1 = perfect use of both cores): the "
            "median over the repetitions of each one's ratio (its 1- and 2-thread runs back to "
            "back in one process), so that the machine's drift over the run stays out of it; "
            "the times shown are the medians.", ""]
    cost = fork_join_cost(benches)
    if cost is not None:
        out += [f"One fork and join of two threads, after the other thread was idle, costs "
                f"{human_time(cost)} on this machine (`BM_ForkJoin`: two spun tasks; the "
                f"two-thread time's excess over one task, median over the task lengths). A stage "
                f"that forks once reaches at best t1 ÷ (t1 + 2 × that): 0.9 needs "
                f"t1 ≥ {human_time(18 * cost)}. The ceiling column is that bound for each row; "
                f"where the efficiency is under 0.9 and so is the ceiling, the stage is too short "
                f"for this machine's thread wake-ups, whatever its code.", ""]
    rows = parallel_rows(benches)
    chain = step_chain_rows(rows)
    if chain:
        def said(r):
            kind = "gathering" if r["gather"] else "streaming"
            quiet = "" if r["quiet"] is None else f", {sig3(r['quiet'])} in its quiet pairs"
            return f"{kind} over {r['items']:,} items {sig3(r['efficiency'])}{quiet}"
        out += ["`BM_StepChain` rows are a yardstick of the machine, not of flank's code: 24 "
                "parallel steps over an array of doubles, in pieces of equal work, with no "
                "shared counter and no serial work between the steps, each reading what the step "
                "before wrote on both threads, in order (streaming, as a parse or a copy) or at "
                "random (gathering, as a read's weld and edges and a cover's sums do). In this "
                f"run: {'; '.join(said(r) for r in chain)}. The gathering rows are what plain "
                "steps of that kind reach on this machine: a stage made of them, with as little "
                "work per item, can be expected to reach about as much. These rows are never "
                "counted as a miss below.", ""]
    out += ["Rows `… · index`, `· seeds`, `· candidates`, `· fit+grow`, `· finish` and `· cover` "
            "under a decompose row are that decompose's own stages, from the seconds it records "
            "for each (its `patches.json`'s `timing_s`), paired by repetition in the same way; "
            f"a stage under {human_time(MIN_SUB_STAGE_S)} at one thread is left out. Each sums "
            "the stage over the rounds, so it forks many times: the ceiling, one fork's, is "
            "only an upper bound for it.", ""]
    level = quiet_level(benches)
    if level is not None:
        out += [f"Before each two-thread run the ladder times a cache line's round trip from one "
                f"core to the other (`line_rt_ns`, bench/runs.h). Its quiet level in this run "
                f"(the tenth percentile over every two-thread run) was {level:.0f} ns. In spells "
                f"when it is two to four times that, stages whose threads share data run up to "
                f"twice as long at two threads, while work on each core's own data does not slow "
                f"down: the machine, not the code. The quiet column is the median efficiency "
                f"over the pairs whose two-thread run saw at most {QUIET_FACTOR:g} × the quiet "
                f"level, and how many of the pairs those were; the efficiency column counts every "
                f"pair.", ""]
    out.append(md_table(
        ["benchmark", "t (1 thread)", "t (2 threads)", "speed-up", "efficiency", "pairs' range",
         "ceiling", "pairs", "quiet"],
        [[f"`{r['benchmark']}`", human_time(r["t1_s"]), human_time(r["t2_s"]),
          sig3(r["speedup"]), sig3(r["efficiency"]),
          "n/a" if r["low"] is None else f"{sig3(r['low'])}–{sig3(r['high'])}",
          sig3(r["ceiling"]), str(r["pairs"] or "medians"),
          "n/a" if r["quiet"] is None else f"{sig3(r['quiet'])} ({r['quiet_pairs']})"]
         for r in rows]))
    short, slow = below_in_every_pair(rows)
    out += ["", "Under 0.9 in every pair (the pairs' range is the machine's noise on a row: a "
            "median under 0.9 whose best pair reaches it is not yet a miss):", ""]
    out += [f"- too short for this machine (ceiling under 0.9 too): "
            f"{', '.join(f'`{b}`' for b in short) or 'none'}",
            f"- long enough to reach it: {', '.join(f'`{b}`' for b in slow) or 'none'}"]
    if level is not None:
        quiet_slow = below_in_every_quiet_pair(rows)
        out += [f"- long enough to reach it, under 0.9 in every quiet pair: "
                f"{', '.join(f'`{b}`' for b in quiet_slow) or 'none'}"]

    out += ["", "### Fit time vs unavoidable query time", "",
            "unavoidable = gn_iterations × samples ÷ raw cold queries/s (same part, size and "
            "threads); ratio = fit median time ÷ unavoidable.", ""]
    out.append(md_table(
        ["part", "tri_k", "threads", "fit", "GN iterations", "samples / iteration",
         "raw cold queries/s", "unavoidable", "fit ÷ unavoidable", "query share",
         "assembly share", "factor share"],
        [[r["part"], r["tri_k"], r["threads"], human_time(r["fit_s"]), sig3(r["gn_iterations"]),
          sig3(r["samples"]), sig3(r["raw_queries_per_s"]), human_time(r["unavoidable_s"]),
          sig3(r["fit_over_unavoidable"]), pct(r["query_share"]), pct(r["assembly_share"]),
          pct(r["factor_share"])] for r in fit_rows(lad)]))

    commands = command_rows(lad)
    if commands:
        out += ["", "### The whole command, cold", "",
                "`flank decompose FILE` in a process of its own, timed from outside: starting "
                "(loading the libraries), reading the file, "
                "decompose, writing every output. Its decompose is the time the process reports "
                "in patches.json; the warm loop is this run's decompose stage on the same mesh, "
                "repeated in one long process. The difference between those two is what a cold "
                "process pays (threads created, pages faulted in afresh, and the share of a "
                "core that the thread opening the CAD module, Open CASCADE, takes meanwhile). "
                "At one thread the command runs on one core, as at two it runs on two, so that "
                "its efficiency compares one core's time with two cores': left free, the "
                "one-thread command opens the CAD module on the idle core. The last column is "
                "that run, right after, on every core, as a user runs `--threads 1`.", ""]
        out.append(md_table(
            ["part", "tri_k", "threads", "command", "its decompose", "the rest",
             "decompose, warm loop", "page faults", "peak memory", "1 thread, every core"],
            [[r["part"], r["tri_k"], r["threads"], human_time(r["command_s"]),
              human_time(r["decompose_in_command_s"]), human_time(r["outside_decompose_s"]),
              human_time(r["decompose_warm_s"]), sig3(r["page_faults"]),
              "n/a" if r["peak_mb"] is None else f"{r['peak_mb']:.0f} MB",
              "" if r["threads"] != 1 else human_time(r["unpinned_s"])] for r in commands]))

    out += ["", "## Time per stage", ""]
    header = ["benchmark", "median", "cv %"]
    if base is not None:
        header += ["baseline median", "run ÷ baseline"]
    out.append(md_table(header, time_table(benches, base)))

    out += ["", "## What decompose did on each rung", "",
            "Decompose's time depends on what it finds as well as on the mesh: a rung where no "
            "line was good enough to grow has no fit stage. Read its times with these counts, "
            "and with the tolerance and cutter kinds the part ran at: 1e-3 × diagonal on cone "
            "and blade, so that most rungs grow candidates; the acceptance tolerance 1e-4 × "
            "diagonal with every cutter kind (the command line's defaults) on the real faces. "
            "Runs that did not record them (n/a) ran at 1e-3.", ""]
    order = {p: i for i, p in enumerate(parts_of(lad))}
    out.append(md_table(
        ["part", "tri_k", "threads", "tolerance × diagonal", "cutter kinds", "total",
         "candidates", "fit+grow", "lines scored", "grown", "patches", "coverage"],
        [[p, k, t, tolerance_text(b.counters.get("tolerance_rel")),
          count_text(b.counters.get("cutter_kinds")), human_time(b.real_s),
          human_time(b.counters.get("candidates_s")),
          human_time(b.counters.get("fit_s")), sig3(b.counters.get("lines_scored")),
          sig3(b.counters.get("grown")), sig3(b.counters.get("patches")),
          pct(b.counters.get("coverage"))]
         for (st, p, k, t), b in sorted(lad.items(), key=lambda kv: (order[kv[0][1]], kv[0][2],
                                                                     kv[0][3]))
         if st == "decompose"]))

    out += ["", "## Slopes", "",
            "Least-squares slope of log10(time) vs log10(triangles); points = sizes measured "
            "at 2 / 1 threads.", ""]
    out.append(md_table(
        ["part", "stage", "slope (2 threads)", "slope (1 thread)", "points"],
        [[r["part"], r["stage"], _slope_text(r["slope_threads_2"]),
          _slope_text(r["slope_threads_1"]),
          f"{r['points_threads_2']} / {r['points_threads_1']}"] for r in slope_rows(lad)]))
    return "\n".join(out) + "\n"


def build_summary(run_path, context, benches, base, lad):
    """The content of summary.json."""
    return {
        "run": run_path,
        "context": {k: context.get(k) for k in ("date", "host_name", "num_cpus", "mhz_per_cpu",
                                                 "library_build_type")},
        "scoring_vs_queries": scoring_rows(lad),
        "parallel": parallel_rows(benches),
        "fit_vs_unavoidable": fit_rows(lad),
        "command": command_rows(lad),
        "slopes": slope_rows(lad),
        "benchmarks": [{
            "key": k, "stage": b.stage, "part": b.part, "tri_k": b.tri_k, "threads": b.threads,
            "triangles": b.triangles, "median_s": b.real_s, "cpu_s": b.cpu_s, "cv": b.cv,
            "repetitions": b.repetitions,
            "baseline_s": base[k].real_s if base and k in base else None,
            "ratio": _div(b.real_s, base[k].real_s) if base and k in base else None,
        } for k, b in benches.items()],
    }


def _clean(x):
    """Non-finite floats to None so that summary.json stays valid JSON."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_clean(v) for v in x]
    return x


def cmd_report(args):
    try:
        context, benches = load_run(args.json)
        base = load_run(args.baseline)[1] if args.baseline else None
    except InputError as e:
        print(f"{PROG} report: {e}", file=sys.stderr)
        return 2
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(args.output, exist_ok=True)
    lad = ladder(benches)
    if lad:
        plot_stages(plt, lad, os.path.join(args.output, "stages.png"))
        plot_speedup(plt, lad, os.path.join(args.output, "speedup.png"))
        plot_scoring_vs_queries(plt, lad, os.path.join(args.output, "scoring_vs_queries.png"))
        plot_gn_share(plt, lad, os.path.join(args.output, "gn_share.png"))
    else:
        print(f"{PROG} report: {args.json}: no Ladder/<stage>/<part>/tri_k:N/threads:T "
              "benchmarks, no plots", file=sys.stderr)
    title = args.title or "flank scaling report"
    md = build_markdown(title, args.json, context, benches, args.baseline, base, lad)
    md_path = os.path.join(args.output, "report.md")
    with open(md_path, "w", encoding="utf-8") as f:
        f.write(md)
    with open(os.path.join(args.output, "summary.json"), "w", encoding="utf-8") as f:
        json.dump(_clean(build_summary(args.json, context, benches, base, lad)), f, indent=1)
        f.write("\n")
    print(md_path)
    return 0


# ----------------------------------------------------------------------------- check

def compare(run, base, limit, noise_k):
    """[(key, status, ratio, noise)]; status ok/SLOWER/faster/not run/no baseline."""
    out = []
    for key in ordered_keys(run):
        b, o = run[key], base.get(key)
        if o is None:
            out.append((key, "no baseline", None, None))
            continue
        ratio = _div(b.real_s, o.real_s)
        noise = noise_k * max(b.cv or 0.0, o.cv or 0.0)
        allowed = limit + noise
        if ratio is None:
            status = "no baseline"
        elif ratio - 1 > allowed:
            status = "SLOWER"
        elif 1 - ratio > allowed:
            status = "faster"
        else:
            status = "ok"
        out.append((key, status, ratio, noise))
    out += [(key, "not run", None, None) for key in base if key not in run]
    return out


def cmd_check(args):
    try:
        run_ctx, run = load_run(args.json)
        base_ctx, base = load_run(args.baseline)
    except InputError as e:
        print(f"{PROG} --check: {e}", file=sys.stderr)
        return 2
    if not set(run) & set(base):
        print(f"{PROG} --check: no benchmark of {args.json} is in {args.baseline}; "
              "nothing to compare", file=sys.stderr)
        return 2
    if run_ctx.get("num_cpus") != base_ctx.get("num_cpus"):
        print(f"{PROG} --check: warning: num_cpus differs (run {run_ctx.get('num_cpus')}, "
              f"baseline {base_ctx.get('num_cpus')}); timings may not be comparable",
              file=sys.stderr)
    failures = []
    rows = compare(run, base, args.limit, args.noise_k)
    for key, status, ratio, noise in rows:
        if ratio is None:
            print(f"{status:<11} {key}")
            continue
        print(f"{status:<11} {key}  run/base {ratio:.3f}  "
              f"threshold {1 + args.limit + noise:.3f}")
        if status == "SLOWER":
            failures.append((key, ratio, noise))
    compared = sum(1 for _, _, ratio, _ in rows if ratio is not None)
    print(f"{PROG} --check: {compared} benchmarks compared, {len(failures)} slower than the "
          f"baseline beyond {100 * args.limit:g}% + noise")
    sys.stdout.flush()
    for key, ratio, noise in failures:
        print(f"{PROG} --check: {key} is {100 * (ratio - 1):.1f}% slower than the baseline "
              f"(limit {100 * args.limit:g}% + noise {100 * noise:.1f}%)", file=sys.stderr)
    return 1 if failures else 0


def pair_times(path):
    """{key: {repetition_index: real seconds}} from a ``merge`` output; InputError if unusable."""
    data = read_gb_json(path)
    out = {}
    for entry in data["benchmarks"]:
        if not isinstance(entry, dict) or entry.get("error_occurred") or entry.get("skipped"):
            continue
        if entry.get("run_type", "iteration") != "iteration":
            continue
        seconds = _seconds(entry, "real_time")
        index = entry.get("repetition_index")
        if seconds is None or not isinstance(index, int):
            continue
        out.setdefault(benchmark_key(entry), {})[index] = seconds
    if not out:
        raise InputError(f"{path}: has no benchmarks")
    return out


def compare_pairs(run, base, limit):
    """[(key, status, median ratio, min ratio, max ratio, pairs)], status ok/SLOWER/faster.

    A benchmark is SLOWER when its median run/base ratio over the pairs exceeds 1 + limit and
    every pair is slower by at least half the limit: one noisy pair can neither fail it nor
    hide a regression that shows in all the others' median. (Two builds of the same source
    differ by a few percent on the smallest rungs, from code layout alone: seen here on an
    unchanged tree, 1.05-1.15 on a 40 ms benchmark.) Keys in only one side are left out (the
    caller says so)."""
    rows = []
    for key in [k for k in run if k in base]:
        common = sorted(set(run[key]) & set(base[key]))
        ratios = [run[key][i] / base[key][i] for i in common if base[key][i] > 0]
        if not ratios:
            continue
        med = statistics.median(ratios)
        if med > 1 + limit and min(ratios) > 1 + limit / 2:
            status = "SLOWER"
        elif med < 1 - limit and max(ratios) < 1 - limit / 2:
            status = "faster"
        else:
            status = "ok"
        rows.append((key, status, med, min(ratios), max(ratios), len(ratios)))
    return rows


def cmd_pairs(args):
    try:
        run = pair_times(args.json)
        base = pair_times(args.baseline)
    except InputError as e:
        print(f"{PROG} --check: {e}", file=sys.stderr)
        return 2
    common = [k for k in run if k in base]
    if not common:
        print(f"{PROG} --check: no benchmark of {args.json} is in {args.baseline}; "
              "nothing to compare", file=sys.stderr)
        return 2
    for key in common:
        if set(run[key]) != set(base[key]):
            print(f"{PROG} --check: {key} has repetitions {sorted(run[key])} in {args.json} "
                  f"but {sorted(base[key])} in {args.baseline}; the runs are not paired",
                  file=sys.stderr)
            return 2
    rows = compare_pairs(run, base, args.limit)
    pairs = max(n for *_, n in rows)
    for key, status, med, lo, hi, _ in rows:
        print(f"{status:<7} {key}  run/base median {med:.3f} (pairs {lo:.3f}-{hi:.3f})")
    for key in sorted(set(run) ^ set(base)):
        print(f"{'only in ' + ('run' if key in run else 'baseline'):<7} {key}")
    failures = [r for r in rows if r[1] == "SLOWER"]
    print(f"{PROG} --check: {len(rows)} benchmarks compared in {pairs} interleaved pairs, "
          f"{len(failures)} slower than the baseline beyond {100 * args.limit:g}%")
    sys.stdout.flush()
    for key, _, med, lo, _, _ in failures:
        print(f"{PROG} --check: {key} is {100 * (med - 1):.1f}% slower than the baseline "
              f"(median of the pairs; every pair slower, the least by {100 * (lo - 1):.1f}%)",
              file=sys.stderr)
    return 1 if failures else 0


def merge_runs(paths):
    """One Google Benchmark JSON document from several runs of the same binary, one process
    each: their iteration entries side by side, numbered as repetitions, so that the median
    and cv are taken across processes (which also varies the memory layout of the meshes and
    spreads the repetitions over the whole run, unlike repetitions inside one process)."""
    merged, context = [], None
    for index, path in enumerate(paths):
        data = read_gb_json(path)
        if context is None:
            context = data.get("context", {})
        for entry in data["benchmarks"]:
            if isinstance(entry, dict) and entry.get("run_type", "iteration") == "iteration":
                merged.append(dict(entry, repetitions=len(paths), repetition_index=index))
    context = dict(context or {}, repetition_processes=len(paths))
    return {"context": context, "benchmarks": merged}


def cmd_merge(args):
    try:
        doc = merge_runs(args.inputs)
    except InputError as e:
        print(f"{PROG} merge: {e}", file=sys.stderr)
        return 2
    tmp = args.output + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(doc, f, indent=1)
    os.replace(tmp, args.output)
    return 0


# ----------------------------------------------------------------------------- main

def main(argv=None):
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rep = sub.add_parser("report", help="plots, report.md and summary.json")
    rep.add_argument("--json", required=True, help="Google Benchmark JSON of the run")
    rep.add_argument("-o", "--output", required=True, help="output directory")
    rep.add_argument("--baseline", help="Google Benchmark JSON to compare times with")
    rep.add_argument("--title", help="report title")
    chk = sub.add_parser("check", help="fail if a benchmark got slower than the baseline")
    chk.add_argument("--json", required=True, help="Google Benchmark JSON of the run")
    chk.add_argument("--baseline", required=True, help="Google Benchmark JSON of the baseline")
    chk.add_argument("--limit", type=float, default=0.10,
                     help="allowed slow-down as a fraction (default 0.10)")
    chk.add_argument("--noise-k", type=float, default=2.0,
                     help="noise allowance = K x max(cv run, cv baseline) (default 2)")
    prs = sub.add_parser("pairs", help="fail if a benchmark got slower than the baseline "
                         "run interleaved with it")
    prs.add_argument("--json", required=True, help="merged JSON of the run")
    prs.add_argument("--baseline", required=True, help="merged JSON of the baseline")
    prs.add_argument("--limit", type=float, default=0.10,
                     help="allowed slow-down as a fraction (default 0.10)")
    mrg = sub.add_parser("merge", help="one JSON from runs of the benchmark binary, one "
                         "process per repetition")
    mrg.add_argument("-o", "--output", required=True, help="merged JSON file")
    mrg.add_argument("inputs", nargs="+", help="Google Benchmark JSON of each run")
    args = parser.parse_args(argv)
    commands = {"report": cmd_report, "check": cmd_check, "pairs": cmd_pairs, "merge": cmd_merge}
    return commands[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
