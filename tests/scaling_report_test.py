#!/usr/bin/env python3
"""Tests of scripts/scaling_report.py on small synthetic Google Benchmark JSON files.

Run: /usr/bin/python3 tests/scaling_report_test.py
"""

import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import unittest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(ROOT, "scripts", "scaling_report.py")

spec = importlib.util.spec_from_file_location("scaling_report", SCRIPT)
sr = importlib.util.module_from_spec(spec)
spec.loader.exec_module(sr)

try:
    import matplotlib  # noqa: F401
    HAVE_MATPLOTLIB = True
except ImportError:
    HAVE_MATPLOTLIB = False

QUERY = "Ladder/query/cone/tri_k:16/threads:2"


def aggregates(key, median_ms, cv, counters=None, reps=5):
    """The mean/median/stddev/cv entries Google Benchmark writes for one benchmark."""
    run_name = key + "/real_time"
    out = []
    for agg in ("mean", "median", "stddev", "cv"):
        value = {"mean": median_ms, "median": median_ms,
                 "stddev": cv * median_ms, "cv": cv}[agg]
        entry = {
            "name": f"{run_name}_{agg}", "family_index": 0, "per_family_instance_index": 0,
            "run_name": run_name, "run_type": "aggregate", "repetitions": reps, "threads": 1,
            "aggregate_name": agg, "iterations": reps, "real_time": value,
            "cpu_time": value, "time_unit": "ms",
        }
        if agg == "cv":
            entry["aggregate_unit"] = "percentage"
        entry.update({k: (v * cv if agg == "stddev" else v) for k, v in (counters or {}).items()})
        out.append(entry)
    return out


def gb_json(benchmarks, num_cpus=2):
    """A whole Google Benchmark JSON document from {key: (median_ms, cv, counters)}."""
    entries = []
    for key, (ms, cv, counters) in benchmarks.items():
        entries += aggregates(key, ms, cv, counters)
    return {"context": {"date": "2024-01-01T00:00:00+00:00", "host_name": "testhost",
                        "num_cpus": num_cpus, "mhz_per_cpu": 2400,
                        "library_build_type": "release"},
            "benchmarks": entries}


FACES = ("hecc_a", "hecc_b", "rotor_upper", "rotor_lower")


def ladder_run(parts=("cone", "blade"), sizes=(1, 4, 16), tolerance=1e-3, kinds=2):
    """A complete ladder: every stage of each part at each size and 1 and 2 threads; decompose
    at `tolerance` x diagonal with `kinds` cutter kinds."""
    out = {}
    for part in parts:
        for tri_k in sizes:
            tri = tri_k * 1000.0
            for t in (1, 2):
                f = 1.0 if t == 1 else 0.55
                base = f"/{part}/tri_k:{tri_k}/threads:{t}"
                out["Ladder/index" + base] = (0.5 * tri_k * f, 0.01, {"triangles": tri})
                out["Ladder/query" + base] = (2.0 * tri_k ** 0.2 * f, 0.02, {
                    "triangles": tri, "queries": 10000.0,
                    "queries_per_s": 10000 / (0.002 * tri_k ** 0.2 * f)})
                out["Ladder/scoring" + base] = (10.0 * tri_k ** 0.1 * f, 0.02, {
                    "triangles": tri, "samples": 30.0,
                    "lines_per_s": 2048 / (0.01 * tri_k ** 0.1 * f)})
                out["Ladder/fit" + base] = (50.0 * tri_k ** 0.3 * f, 0.03, {
                    "triangles": tri, "gn_iterations": 6.0, "samples": 3000.0,
                    "query_share": 0.4, "assembly_share": 0.3, "factor_share": 0.2,
                    "queries": 20000.0})
                out["Ladder/decompose" + base] = (1000.0 * tri_k ** 0.5 * f, 0.02, {
                    "triangles": tri, "index_s": 0.01, "seeds_s": 0.05 * tri_k ** 0.5,
                    "candidates_s": 0.3 * tri_k ** 0.5, "fit_s": 0.5 * tri_k ** 0.5,
                    "cover_s": 0.1, "patches": 1.0, "coverage": 0.99, "lines_scored": 5e4,
                    "tolerance_rel": tolerance, "cutter_kinds": float(kinds)})
                # The same decompose as its own process: 20% slower inside, and 150 ms around;
                # at one thread on one core, and 20 ms faster on every core.
                command = {"triangles": tri, "decompose_s": 1.2 * tri_k ** 0.5 * f,
                           "page_faults": 2000.0, "peak_mb": 90.0, "tolerance_rel": tolerance}
                if t == 1:
                    command["unpinned_s"] = 1.2 * tri_k ** 0.5 + 0.130
                out["Ladder/command" + base] = (1.2 * 1000.0 * tri_k ** 0.5 * f + 150.0, 0.02,
                                                command)
    return out


class ScalingReportTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.dir = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def write(self, name, doc):
        path = os.path.join(self.dir, name)
        with open(path, "w", encoding="utf-8") as f:
            f.write(doc if isinstance(doc, str) else json.dumps(doc))
        return path

    def run_cli(self, *args):
        return subprocess.run([sys.executable, SCRIPT, *args], capture_output=True, text=True,
                              timeout=300)

    def report(self, run, out, *extra):
        """Runs `report` into `out`; checks it succeeded and drew its four plots. (result, report.md)"""
        r = self.run_cli("report", "--json", run, "-o", out, *extra)
        self.assertEqual(r.returncode, 0, r.stderr)
        for name in ("stages.png", "speedup.png", "scoring_vs_queries.png", "gn_share.png"):
            path = os.path.join(out, name)
            self.assertTrue(os.path.isfile(path), name)
            self.assertGreater(os.path.getsize(path), 1000, name)
        with open(os.path.join(out, "report.md"), encoding="utf-8") as f:
            return r, f.read()

    def check(self, run, base, *extra):
        return self.run_cli("check", "--json", run, "--baseline", base, *extra)

    def small(self, query_ms=10.0, cv=0.01):
        return gb_json({
            QUERY: (query_ms, cv, {"triangles": 16000.0}),
            "Ladder/index/cone/tri_k:16/threads:2": (5.0, 0.01, {"triangles": 16000.0}),
        })

    # --- merge (one process per repetition) ---------------------------------------------------

    def iteration_run(self, ms, counter):
        entry = {"name": QUERY + "/real_time", "run_name": QUERY + "/real_time",
                 "run_type": "iteration", "repetitions": 1, "repetition_index": 0,
                 "iterations": 10, "real_time": ms, "cpu_time": ms, "time_unit": "ms",
                 "triangles": 16000.0, "queries_per_s": counter}
        return {"context": {"num_cpus": 2, "commit": "abc"}, "benchmarks": [entry]}

    def test_merge_takes_median_and_cv_across_processes(self):
        paths = [self.write(f"run{i}.json", self.iteration_run(ms, 1000.0 / ms))
                 for i, ms in enumerate((10.0, 12.0, 11.0))]
        merged = os.path.join(self.dir, "merged.json")
        r = self.run_cli("merge", "-o", merged, *paths)
        self.assertEqual(r.returncode, 0, r.stderr)
        context, benches = sr.load_run(merged)
        self.assertEqual(context["repetition_processes"], 3)
        self.assertEqual(context["commit"], "abc")
        b = benches[QUERY]
        self.assertEqual(b.repetitions, 3)
        self.assertAlmostEqual(b.real_s, 0.011)
        self.assertAlmostEqual(b.cv, 1.0 / 11.0)  # stdev(10, 12, 11) / mean
        self.assertAlmostEqual(b.counters["queries_per_s"], 1000.0 / 11.0)

    def test_efficiency_pairs_the_repetitions(self):
        # Three processes, each running one rung at 1 then 2 threads back to back; the machine
        # was 1.6x slower during the second, and the third's 2-thread run was lucky. Each
        # process's ratio says 1.82 but for the lucky one; the ratio of the medians (1.3 s /
        # 0.55 s) would claim a superlinear 2.36.
        key = "Ladder/index/cone/tri_k:4/threads:"
        paths = []
        for i, (t1, t2) in enumerate(((1.0, 0.55), (1.6, 0.88), (1.3, 0.5))):
            entries = [{"name": f"{key}{t}/real_time", "run_name": f"{key}{t}/real_time",
                        "run_type": "iteration", "repetitions": 1, "repetition_index": 0,
                        "iterations": 1, "real_time": ms, "cpu_time": ms, "time_unit": "s"}
                       for t, ms in ((1, t1), (2, t2))]
            paths.append(self.write(f"run{i}.json", {"context": {"num_cpus": 2}, "benchmarks": entries}))
        merged = os.path.join(self.dir, "merged.json")
        self.assertEqual(self.run_cli("merge", "-o", merged, *paths).returncode, 0)
        _, benches = sr.load_run(merged)
        self.assertEqual(benches[key + "1"].reals, {0: 1.0, 1: 1.6, 2: 1.3})
        row = sr.parallel_rows(benches)[0]
        self.assertEqual(row["pairs"], 3)
        self.assertAlmostEqual(row["speedup"], 1.0 / 0.55)
        self.assertAlmostEqual(row["efficiency"], 1.0 / 1.1)
        # The pairs' range: 1 / 1.1 twice, 1.3 / 1.0 once.
        self.assertAlmostEqual(row["low"], 1.0 / 1.1)
        self.assertAlmostEqual(row["high"], 1.3)
        # Aggregates alone (no repetitions to pair): the ratio of the medians.
        _, benches = sr.load_run(self.write("agg.json", gb_json(ladder_run(sizes=(4,)))))
        par = {r["benchmark"]: r for r in sr.parallel_rows(benches)}
        self.assertEqual(par["Ladder/index/cone/tri_k:4"]["pairs"], 0)
        self.assertAlmostEqual(par["Ladder/index/cone/tri_k:4"]["efficiency"], 1 / (2 * 0.55))

    def test_decompose_stages_get_rows_of_their_own(self):
        # Two repetitions of one decompose rung: the whole decompose scales (0.95), its seeds
        # and cover do not (serial: the same time at two threads), candidates do; the index is
        # under MIN_SUB_STAGE_S and is left out; the second repetition lacks finish_s, so
        # finish's row is the ratio of the medians, unpaired.
        key = "Ladder/decompose/hecc_a/tri_k:24/threads:"
        entries = []
        for rep, slow in ((0, 1.0), (1, 1.2)):
            for t in (1, 2):
                c = {"index_s": 0.0005, "seeds_s": 0.014 * slow, "candidates_s": 1.2 * slow / t,
                     "cover_s": 0.004 * slow, "grown": 40.0}
                if rep == 0:
                    c["finish_s"] = 0.9 / t
                real = 3.2 * slow / (1 if t == 1 else 1.9)
                entries.append({"name": f"{key}{t}/real_time", "run_name": f"{key}{t}/real_time",
                                "run_type": "iteration", "repetitions": 2, "repetition_index": rep,
                                "iterations": 1, "real_time": real, "cpu_time": real,
                                "time_unit": "s", **c})
        _, benches = sr.load_run(self.write("sub.json", {"context": {}, "benchmarks": entries}))
        self.assertEqual(benches[key + "1"].counter_reps["seeds_s"], {0: 0.014, 1: 0.014 * 1.2})
        self.assertNotIn("finish_s", benches[key + "1"].counter_reps)
        rows = sr.parallel_rows(benches)
        names = [r["benchmark"] for r in rows]
        base = "Ladder/decompose/hecc_a/tri_k:24"
        self.assertEqual(names, [base, base + " · seeds", base + " · candidates",
                                 base + " · finish", base + " · cover"])
        par = {r["benchmark"]: r for r in rows}
        self.assertAlmostEqual(par[base]["efficiency"], 0.95)
        self.assertEqual(par[base + " · seeds"]["pairs"], 2)
        self.assertAlmostEqual(par[base + " · seeds"]["efficiency"], 0.5)
        self.assertAlmostEqual(par[base + " · candidates"]["efficiency"], 1.0)
        self.assertEqual(par[base + " · finish"]["pairs"], 0)
        self.assertEqual(par[base + " · seeds"]["stage"], "decompose: seeds")
        # Serial stages miss in every pair; the report names them beside the benchmarks.
        self.assertEqual(sr.below_in_every_pair(rows), ([], [base + " · seeds", base + " · cover"]))
        md = sr.build_markdown("t", "run.json", {}, benches, None, None, sr.ladder(benches))
        self.assertIn(f"| `{base} · cover` | 4.40 ms | 4.40 ms | 1.00 | 0.500 | 0.500–0.500 |", md)
        # A rung that grew nothing has no fit, finish or cover to judge.
        for e in entries:
            e["grown"] = 0.0
        _, benches = sr.load_run(self.write("none.json", {"context": {}, "benchmarks": entries}))
        names = [r["benchmark"] for r in sr.parallel_rows(benches)]
        self.assertEqual(names, [base, base + " · seeds", base + " · candidates"])

    def test_quiet_pairs_leave_out_the_slow_spells(self):
        # Four repetitions of a decompose rung. The two-thread runs of repetitions 2 and 3 saw
        # the cache line's round trip at 450-460 ns, against 130-140 in the others: their pairs
        # (efficiency 0.5) count in the efficiency column, not in the quiet one. The one-thread
        # runs carry no round trip. The cover stage misses in every quiet pair (0.6 and 0.7).
        key = "Ladder/decompose/hecc_a/tri_k:24/threads:"
        entries = []
        for rep, (trip, eff, cover_eff) in enumerate(((130.0, 0.95, 0.6), (140.0, 0.93, 0.7),
                                                      (450.0, 0.5, 0.9), (460.0, 0.5, 0.95))):
            for t in (1, 2):
                real = 2.0 if t == 1 else 1.0 / eff
                c = {"cover_s": 0.002 if t == 1 else 0.001 / cover_eff, "grown": 40.0}
                if t == 2:
                    c["line_rt_ns"] = trip
                entries.append({"name": f"{key}{t}/real_time", "run_name": f"{key}{t}/real_time",
                                "run_type": "iteration", "repetitions": 4, "repetition_index": rep,
                                "iterations": 1, "real_time": real, "cpu_time": real,
                                "time_unit": "s", **c})
        _, benches = sr.load_run(self.write("quiet.json", {"context": {}, "benchmarks": entries}))
        self.assertEqual(sr.quiet_level(benches), 130.0)  # the tenth percentile of four: the least
        par = {r["benchmark"]: r for r in sr.parallel_rows(benches)}
        base = "Ladder/decompose/hecc_a/tri_k:24"
        self.assertAlmostEqual(par[base]["efficiency"], (0.93 + 0.5) / 2)
        self.assertEqual(par[base]["quiet_pairs"], 2)
        self.assertAlmostEqual(par[base]["quiet"], 0.94)
        self.assertAlmostEqual(par[base + " · cover"]["quiet"], 0.65)
        self.assertAlmostEqual(par[base + " · cover"]["quiet_high"], 0.7)
        rows = list(par.values())
        self.assertEqual(sr.below_in_every_quiet_pair(rows), [base + " · cover"])
        self.assertEqual(sr.below_in_every_pair(rows), ([], []))  # its slow-spell pairs reach 0.9
        md = sr.build_markdown("t", "run.json", {}, benches, None, None, sr.ladder(benches))
        self.assertIn("quiet level in this run (the tenth percentile over every two-thread run) "
                      "was 130 ns", md)
        self.assertIn("| 0.940 (2) |", md)
        self.assertIn(f"under 0.9 in every quiet pair: `{base} · cover`", md)
        # Without round trips (an older run) there is no quiet column to fill.
        for e in entries:
            e.pop("line_rt_ns", None)
        _, benches = sr.load_run(self.write("loud.json", {"context": {}, "benchmarks": entries}))
        self.assertIsNone(sr.quiet_level(benches))
        row = sr.parallel_rows(benches)[0]
        self.assertEqual((row["quiet"], row["quiet_pairs"]), (None, 0))
        md = sr.build_markdown("t", "run.json", {}, benches, None, None, sr.ladder(benches))
        self.assertNotIn("quiet level", md)

    def test_a_row_misses_only_when_every_pair_does(self):
        def row(name, low, high, ceiling):
            return {"benchmark": name, "low": low, "high": high, "ceiling": ceiling}
        rows = [row("Ladder/index/cone/tri_k:1", 0.53, 0.63, 0.55),    # too short to reach it
                row("Ladder/command/cone/tri_k:16", 0.67, 0.75, 0.99),  # a miss for its length
                row("Ladder/decompose/cone/tri_k:16", 0.81, 0.91, 0.99),  # one pair reaches it
                row("Ladder/index/blade/tri_k:8", 0.85, 0.88, None),    # no BM_ForkJoin: unknown
                row("Ladder/fit/cone/tri_k:1", None, None, 0.99),       # no pairs: not judged
                row("BM_ForkJoin/work_us:100/idle_us:1000", 0.5, 0.56, 0.52)]  # the yardstick
        short, slow = sr.below_in_every_pair(rows)
        self.assertEqual(short, ["Ladder/index/cone/tri_k:1"])
        self.assertEqual(slow, ["Ladder/command/cone/tri_k:16", "Ladder/index/blade/tri_k:8"])
        self.assertEqual(sr.below_in_every_pair(rows, target=0.5), ([], []))

    def test_fork_join_sets_each_stage_a_ceiling(self):
        # One fork and join cost 90 µs over one task at every task length (0.1-2 ms); the 1k
        # index takes 0.2 ms on one thread, 0.19 ms on two: under 0.9, and so is its ceiling.
        runs = {}
        for work in (100, 500, 2000):
            for threads, ms in ((1, 2 * work / 1e3), (2, (work + 90) / 1e3)):
                runs[f"BM_ForkJoin/work_us:{work}/idle_us:1000/threads:{threads}"] = (ms, 0.01, {})
        runs["Ladder/index/cone/tri_k:1/threads:1"] = (0.2, 0.01, {"triangles": 968})
        runs["Ladder/index/cone/tri_k:1/threads:2"] = (0.19, 0.01, {"triangles": 968})
        _, benches = sr.load_run(self.write("fj.json", gb_json(runs)))
        self.assertAlmostEqual(sr.fork_join_cost(benches), 90e-6)
        par = {r["benchmark"]: r for r in sr.parallel_rows(benches)}
        index = par["Ladder/index/cone/tri_k:1"]
        self.assertAlmostEqual(index["ceiling"], 0.2e-3 / (0.2e-3 + 180e-6))
        self.assertLess(index["ceiling"], 0.9)
        # The benchmark's own rows: the ceiling is its efficiency, by construction.
        fj = par["BM_ForkJoin/work_us:2000/idle_us:1000"]
        self.assertAlmostEqual(fj["ceiling"], fj["efficiency"])
        # 0.9 needs t1 >= 18 x the cost: 1.62 ms here.
        self.assertAlmostEqual(sr.efficiency_ceiling(18 * 90e-6, 90e-6), 0.9)
        md = sr.build_markdown("t", "run.json", {}, benches, None, None, sr.ladder(benches))
        self.assertIn("costs 90.0 µs on this machine", md)
        self.assertIn("0.9 needs t1 ≥ 1.62 ms", md)
        # Aggregates alone have no pairs: no range, and no row is called a miss.
        self.assertIn("| n/a | 0.526 | medians |", md)
        self.assertIn("- too short for this machine (ceiling under 0.9 too): none", md)
        # Without the benchmark in the run: no ceiling, and the table says so.
        del benches["BM_ForkJoin/work_us:100/idle_us:1000/threads:2"]
        del benches["BM_ForkJoin/work_us:500/idle_us:1000/threads:2"]
        del benches["BM_ForkJoin/work_us:2000/idle_us:1000/threads:2"]
        self.assertIsNone(sr.fork_join_cost(benches))
        self.assertIsNone(sr.parallel_rows(benches)[0]["ceiling"])

    def test_step_chain_is_a_yardstick_not_a_miss(self):
        # The machine's chain of steps: streaming scales 0.95, gathering 0.85 (under 0.9);
        # a read at 0.87 beside it. The chain's rows are shown and said, never called a miss.
        runs = {}
        for items, gather, t1 in ((73728, 0, 0.24), (73728, 1, 1.0)):
            eff = 0.95 if gather == 0 else 0.85
            base = f"BM_StepChain/items:{items}/gather:{gather}"
            runs[base + "/threads:1"] = (t1, 0.01, {"steps": 24})
            runs[base + "/threads:2"] = (t1 / (2 * eff), 0.01, {"steps": 24})
        runs["Ladder/read/hecc_a/tri_k:24/threads:1"] = (1.5, 0.01, {"triangles": 24000})
        runs["Ladder/read/hecc_a/tri_k:24/threads:2"] = (1.5 / (2 * 0.87), 0.01,
                                                         {"triangles": 24000})
        _, benches = sr.load_run(self.write("chain.json", gb_json(runs)))
        rows = sr.parallel_rows(benches)
        chain = sr.step_chain_rows(rows)
        self.assertEqual([(r["items"], r["gather"]) for r in chain],
                         [(73728, False), (73728, True)])
        self.assertAlmostEqual(chain[1]["efficiency"], 0.85)
        for r in rows:  # every pair under 0.9: only the read counts as a miss
            r["low"], r["high"] = r["efficiency"], r["efficiency"]
        self.assertEqual(sr.below_in_every_pair(rows)[1], ["Ladder/read/hecc_a/tri_k:24"])
        md = sr.build_markdown("t", "run.json", {}, benches, None, None, sr.ladder(benches))
        self.assertIn("In this run: streaming over 73,728 items 0.950; gathering over 73,728 "
                      "items 0.850.", md)
        self.assertIn("| `BM_StepChain/items:73728/gather:1` |", md)
        # Without the chain in the run, nothing is said of it.
        for key in list(benches):
            if key.startswith("BM_StepChain/"):
                del benches[key]
        md = sr.build_markdown("t", "run.json", {}, benches, None, None, sr.ladder(benches))
        self.assertNotIn("BM_StepChain", md)

    def test_merge_bad_input(self):
        good = self.write("good.json", self.iteration_run(10.0, 100.0))
        bad = self.write("bad.json", "{ truncated")
        merged = os.path.join(self.dir, "merged.json")
        r = self.run_cli("merge", "-o", merged, good, bad)
        self.assertEqual(r.returncode, 2)
        self.assertIn("bad.json", r.stderr)
        self.assertFalse(os.path.exists(merged))

    # --- pairs (the paired check: baseline built beside, run interleaved) --------------------

    def paired(self, name, times_ms, key=QUERY):
        """A merge output: one iteration entry per repetition, as `merge` writes them."""
        entries = [{"name": key + "/real_time", "run_name": key + "/real_time",
                    "run_type": "iteration", "repetitions": len(times_ms),
                    "repetition_index": i, "iterations": 10, "real_time": ms,
                    "cpu_time": ms, "time_unit": "ms"} for i, ms in enumerate(times_ms)]
        return self.write(name, {"context": {"num_cpus": 2}, "benchmarks": entries})

    def pairs(self, run_ms, base_ms, *extra):
        run = self.paired("run.json", run_ms)
        base = self.paired("base.json", base_ms)
        return self.run_cli("pairs", "--json", run, "--baseline", base, *extra)

    def test_pairs_identical_pass(self):
        r = self.pairs([10.0, 11.0, 9.5, 10.2], [10.0, 11.0, 9.5, 10.2])
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("ok", r.stdout)
        self.assertIn("1 benchmarks compared in 4 interleaved pairs, 0 slower", r.stdout)

    def test_pairs_machine_slower_than_baseline_file_passes(self):
        # Both sides slow together (another machine, a busy day): the ratios stay near 1.
        r = self.pairs([14.0, 15.1, 13.3, 14.4], [14.1, 15.0, 13.2, 14.5])
        self.assertEqual(r.returncode, 0, r.stderr)

    def test_pairs_20_percent_slower_in_every_pair_fails(self):
        r = self.pairs([12.0, 13.2, 11.4, 12.3], [10.0, 11.0, 9.5, 10.2])
        self.assertEqual(r.returncode, 1, r.stdout)
        self.assertIn("SLOWER", r.stdout)
        self.assertIn(QUERY, r.stderr)
        self.assertIn("20.0% slower", r.stderr)

    def test_pairs_one_lucky_pair_passes(self):
        # Median 20% slower, but one pair faster, or within half the limit: noise.
        r = self.pairs([12.0, 9.0, 12.0, 12.0], [10.0, 10.0, 10.0, 10.0])
        self.assertEqual(r.returncode, 0, r.stdout)
        r = self.pairs([12.0, 10.4, 12.0, 12.0], [10.0, 10.0, 10.0, 10.0])
        self.assertEqual(r.returncode, 0, r.stdout)

    def test_pairs_5_percent_slower_passes_and_limit_tightens(self):
        self.assertEqual(self.pairs([10.5] * 3, [10.0] * 3).returncode, 0)
        self.assertEqual(self.pairs([10.5] * 3, [10.0] * 3, "--limit", "0.04").returncode, 1)

    def test_pairs_faster_is_reported_not_failed(self):
        r = self.pairs([7.0, 7.5, 7.2], [10.0, 10.0, 10.0])
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("faster", r.stdout)

    def test_pairs_mismatched_repetitions(self):
        r = self.pairs([10.0, 10.0, 10.0], [10.0, 10.0])
        self.assertEqual(r.returncode, 2)
        self.assertIn("not paired", r.stderr)

    def test_pairs_no_overlap_and_garbage(self):
        run = self.paired("run.json", [10.0], key="Ladder/index/cone/tri_k:1/threads:1")
        base = self.paired("base.json", [10.0])
        r = self.run_cli("pairs", "--json", run, "--baseline", base)
        self.assertEqual(r.returncode, 2)
        self.assertIn("nothing to compare", r.stderr)
        bad = self.write("bad.json", "{ truncated")
        r = self.run_cli("pairs", "--json", run, "--baseline", bad)
        self.assertEqual(r.returncode, 2)
        self.assertIn("bad.json", r.stderr)

    # --- check -----------------------------------------------------------------------------

    def test_check_identical_passes(self):
        base = self.write("base.json", self.small())
        run = self.write("run.json", self.small())
        r = self.check(run, base)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("ok", r.stdout)
        self.assertIn(QUERY, r.stdout)

    def test_check_20_percent_slower_low_noise_fails(self):
        base = self.write("base.json", self.small(10.0, 0.01))
        run = self.write("run.json", self.small(12.0, 0.01))
        r = self.check(run, base)
        self.assertEqual(r.returncode, 1)
        self.assertIn("SLOWER", r.stdout)
        self.assertIn(f"{QUERY} is 20.0% slower than the baseline", r.stderr)
        self.assertIn("limit 10% + noise 2.0%", r.stderr)

    def test_check_20_percent_slower_high_noise_passes(self):
        base = self.write("base.json", self.small(10.0, 0.10))
        run = self.write("run.json", self.small(12.0, 0.10))
        r = self.check(run, base)
        self.assertEqual(r.returncode, 0, r.stderr)

    def test_check_5_percent_slower_passes(self):
        base = self.write("base.json", self.small(10.0, 0.0))
        run = self.write("run.json", self.small(10.5, 0.0))
        r = self.check(run, base)
        self.assertEqual(r.returncode, 0, r.stderr)

    def test_check_limit_option(self):
        base = self.write("base.json", self.small(10.0, 0.0))
        run = self.write("run.json", self.small(10.5, 0.0))
        self.assertEqual(self.check(run, base, "--limit", "0.02").returncode, 1)

    def test_check_faster_passes(self):
        base = self.write("base.json", self.small(10.0, 0.01))
        run = self.write("run.json", self.small(5.0, 0.01))
        r = self.check(run, base)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("faster", r.stdout)

    def test_check_missing_baseline(self):
        run = self.write("run.json", self.small())
        missing = os.path.join(self.dir, "nope.json")
        r = self.check(run, missing)
        self.assertEqual(r.returncode, 2)
        self.assertIn("nope.json", r.stderr)

    def test_check_garbage_baseline(self):
        run = self.write("run.json", self.small())
        garbage = self.write("garbage.json", "this is { not json")
        r = self.check(run, garbage)
        self.assertEqual(r.returncode, 2)
        self.assertIn("garbage.json", r.stderr)

    def test_check_baseline_without_benchmarks(self):
        run = self.write("run.json", self.small())
        empty = self.write("empty.json", {"context": {}, "benchmarks": []})
        r = self.check(run, empty)
        self.assertEqual(r.returncode, 2)
        self.assertIn("empty.json", r.stderr)

    def test_check_no_overlap(self):
        base = self.write("base.json", gb_json({"Other/thing": (1.0, 0.0, {})}))
        run = self.write("run.json", self.small())
        r = self.check(run, base)
        self.assertEqual(r.returncode, 2)
        self.assertIn("nothing to compare", r.stderr)

    def test_check_not_run_and_no_baseline(self):
        base_doc = self.small()
        base_doc["benchmarks"] += aggregates("Ladder/fit/cone/tri_k:16/threads:2", 50.0, 0.01)
        base = self.write("base.json", base_doc)
        run_doc = self.small()
        run_doc["benchmarks"] += aggregates("Ladder/fit/blade/tri_k:16/threads:2", 50.0, 0.01)
        run = self.write("run.json", run_doc)
        r = self.check(run, base)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("not run", r.stdout)
        self.assertIn("no baseline", r.stdout)

    def test_check_warns_on_num_cpus(self):
        base = self.write("base.json", gb_json({QUERY: (10.0, 0.01, {})}, num_cpus=8))
        run = self.write("run.json", gb_json({QUERY: (10.0, 0.01, {})}, num_cpus=2))
        r = self.check(run, base)
        self.assertEqual(r.returncode, 0)
        self.assertIn("num_cpus", r.stderr)

    # --- loading and formulas --------------------------------------------------------------

    def test_load_units_cv_and_counters(self):
        doc = gb_json({QUERY: (12.5, 0.04, {"triangles": 16000.0, "queries_per_s": 8e5})})
        _, benches = sr.load_run(self.write("run.json", doc))
        b = benches[QUERY]
        self.assertAlmostEqual(b.real_s, 0.0125)
        self.assertAlmostEqual(b.cv, 0.04)
        self.assertEqual(b.counters["queries_per_s"], 8e5)
        self.assertEqual((b.stage, b.part, b.tri_k, b.threads), ("query", "cone", 16, 2))
        self.assertEqual(b.repetitions, 5)

    def test_load_cv_from_stddev_and_seconds(self):
        entries = [e for e in aggregates(QUERY, 2.0, 0.05) if e["aggregate_name"] != "cv"]
        for e in entries:
            e["time_unit"] = "s"
        _, benches = sr.load_run(self.write("run.json", {"benchmarks": entries}))
        self.assertAlmostEqual(benches[QUERY].real_s, 2.0)
        self.assertAlmostEqual(benches[QUERY].cv, 0.05)

    def test_load_plain_iteration(self):
        entry = {"name": QUERY, "run_name": QUERY, "run_type": "iteration", "repetitions": 1,
                 "iterations": 3, "real_time": 250.0, "cpu_time": 240.0, "time_unit": "ms",
                 "triangles": 16000.0}
        _, benches = sr.load_run(self.write("run.json", {"benchmarks": [entry]}))
        self.assertAlmostEqual(benches[QUERY].real_s, 0.25)
        self.assertEqual(benches[QUERY].cv, 0.0)
        self.assertEqual(benches[QUERY].triangles, 16000.0)

    def test_formulas(self):
        # 1000 lines/s x 30 samples = 30,000 sample queries/s vs 120,000 raw: 0.25.
        self.assertAlmostEqual(sr.sample_query_ratio(1000.0, 30.0, 120000.0), 0.25)
        # 1.8 s on 1 thread, 1.0 s on 2: speed-up 1.8, efficiency 0.9.
        self.assertAlmostEqual(sr.speedup(1.8, 1.0), 1.8)
        self.assertAlmostEqual(sr.parallel_efficiency(1.8, 1.0), 0.9)
        # 5 iterations x 3000 samples at 1e6 queries/s = 15 ms unavoidable; 60 ms fit: 4.
        self.assertAlmostEqual(sr.unavoidable_query_s(5, 3000, 1e6), 0.015)
        self.assertAlmostEqual(sr.fit_over_unavoidable(0.060, 5, 3000, 1e6), 4.0)
        self.assertIsNone(sr.sample_query_ratio(1000.0, 30.0, None))
        self.assertIsNone(sr.fit_over_unavoidable(0.06, 5, 3000, 0.0))

    def test_slope(self):
        pts = [(1e3, 2e-3), (1e4, 2e-2), (1e5, 2e-1)]
        self.assertAlmostEqual(sr.slope(pts), 1.0)
        self.assertIsNone(sr.slope([(1e3, 1.0)]))

    def test_rows_on_ladder(self):
        _, benches = sr.load_run(self.write("run.json", gb_json(ladder_run())))
        lad = sr.ladder(benches)
        rows = {(r["part"], r["tri_k"], r["threads"]): r for r in sr.scoring_rows(lad)}
        r = rows[("cone", 16, 2)]
        lps = 2048 / (0.01 * 16 ** 0.1 * 0.55)
        qps = 10000 / (0.002 * 16 ** 0.2 * 0.55)
        self.assertAlmostEqual(r["ratio"], lps * 30 / qps)
        par = {r["benchmark"]: r for r in sr.parallel_rows(benches)}
        self.assertAlmostEqual(par["Ladder/index/cone/tri_k:4"]["efficiency"], 1 / (2 * 0.55))
        fit = {(r["part"], r["tri_k"], r["threads"]): r for r in sr.fit_rows(lad)}
        f = fit[("blade", 4, 1)]
        fit_s = 0.050 * 4 ** 0.3
        qps = 10000 / (0.002 * 4 ** 0.2)
        self.assertAlmostEqual(f["fit_over_unavoidable"], fit_s / (6 * 3000 / qps))
        slopes = {(r["part"], r["stage"]): r for r in sr.slope_rows(lad)}
        self.assertAlmostEqual(slopes[("cone", "index")]["slope_threads_2"], 1.0)
        self.assertAlmostEqual(slopes[("blade", "decompose: fit+grow")]["slope_threads_1"], 0.5)
        # The whole command beside the warm loop: what lies outside its own decompose.
        cmd = {(r["part"], r["tri_k"], r["threads"]): r for r in sr.command_rows(lad)}
        c = cmd[("cone", 16, 2)]
        self.assertAlmostEqual(c["decompose_warm_s"], 1.0 * 16 ** 0.5 * 0.55)
        self.assertAlmostEqual(c["decompose_in_command_s"], 1.2 * 16 ** 0.5 * 0.55)
        self.assertAlmostEqual(c["outside_decompose_s"], 0.150)
        self.assertEqual((c["page_faults"], c["peak_mb"]), (2000.0, 90.0))
        self.assertIsNone(c["unpinned_s"])
        self.assertAlmostEqual(cmd[("cone", 16, 1)]["unpinned_s"], 1.2 * 16 ** 0.5 + 0.130)
        self.assertAlmostEqual(par["Ladder/command/blade/tri_k:1"]["t1_s"], 1.2 + 0.150)
        # A run without the stage (a baseline from before it) has no rows for it.
        older = {k: v for k, v in ladder_run().items() if not k.startswith("Ladder/command/")}
        _, old_benches = sr.load_run(self.write("older.json", gb_json(older)))
        self.assertEqual(sr.command_rows(sr.ladder(old_benches)), [])

    def test_sig3(self):
        self.assertEqual(sr.sig3(0.123456), "0.123")
        self.assertEqual(sr.sig3(12.345), "12.3")
        self.assertEqual(sr.sig3(1234.5), "1230")
        self.assertEqual(sr.sig3(2.345e7), "2.35e7")
        self.assertEqual(sr.sig3(None), "n/a")
        self.assertEqual(sr.human_time(0.0123), "12.3 ms")

    # --- report ----------------------------------------------------------------------------

    @unittest.skipUnless(HAVE_MATPLOTLIB, "matplotlib is not installed")
    def test_report_writes_everything(self):
        run = self.write("run.json", gb_json(ladder_run()))
        slower = {k: (ms * 1.1, cv, c) for k, (ms, cv, c) in ladder_run().items()}
        del slower["Ladder/fit/blade/tri_k:16/threads:2"]
        base = self.write("base.json", gb_json(slower))
        out = os.path.join(self.dir, "report")
        r, md = self.report(run, out, "--baseline", base, "--title", "Test ladder")
        self.assertEqual(r.stdout.strip(), os.path.join(out, "report.md"))
        self.assertIn("# Test ladder", md)
        self.assertIn("![stages](stages.png)", md)
        self.assertIn("Ratios against limits (same run)", md)
        self.assertIn("testhost", md)
        with open(os.path.join(out, "summary.json"), encoding="utf-8") as f:
            summary = json.load(f)
        for section in ("scoring_vs_queries", "parallel", "fit_vs_unavoidable", "command", "slopes"):
            self.assertTrue(summary[section], section)
        self.assertIn("### The whole command, cold", md)
        self.assertIn("| cone | 16 | 2 | 2.79 s | 2.64 s | 150 ms | 2.20 s | 2000 | 90 MB |  |", md)
        self.assertIn(
            "| cone | 16 | 1 | 4.95 s | 4.80 s | 150 ms | 4.00 s | 2000 | 90 MB | 4.93 s |", md)

    @unittest.skipUnless(HAVE_MATPLOTLIB, "matplotlib is not installed")
    def test_report_with_the_real_faces(self):
        # Six parts: cone and blade at 1e-3, the four faces native (24k) and subdivided (96k)
        # at the acceptance tolerance with every cutter kind.
        run_doc = ladder_run()
        run_doc.update(ladder_run(FACES, (24, 96), tolerance=1e-4, kinds=4))
        run = self.write("run.json", gb_json(run_doc))
        _, benches = sr.load_run(run)
        b = benches["Ladder/decompose/rotor_upper/tri_k:96/threads:2"]
        self.assertEqual((b.stage, b.part, b.tri_k, b.threads), ("decompose", "rotor_upper", 96, 2))
        lad = sr.ladder(benches)
        self.assertEqual(sr.parts_of(lad), ["cone", "blade", *FACES])
        self.assertIn(("rotor_upper", 24, 2), {(r["part"], r["tri_k"], r["threads"])
                                               for r in sr.fit_rows(lad)})
        slopes = {(r["part"], r["stage"]): r for r in sr.slope_rows(lad)}
        self.assertAlmostEqual(slopes[("rotor_upper", "index")]["slope_threads_2"], 1.0)
        self.assertEqual(sr.panel_grid(6), (2, 3))  # at most 3 panels to a row
        self.assertEqual(sr.panel_grid(2), (1, 2))

        _, md = self.report(run, os.path.join(self.dir, "report"))
        # The decompose rows say the tolerance and cutter kinds each part ran at.
        self.assertIn("| rotor_upper | 96 | 2 | 1e-4 | 4 |", md)
        self.assertIn("| hecc_a | 24 | 1 | 1e-4 | 4 |", md)
        self.assertIn("| cone | 16 | 2 | 1e-3 | 2 |", md)
        self.assertIn("`Ladder/fit/rotor_lower/tri_k:24/threads:2`", md)


if __name__ == "__main__":
    unittest.main()
