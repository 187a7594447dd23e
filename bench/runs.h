// Benchmark bodies shared by the fixed-size benchmarks and the scaling ladder: one decompose
// or one motion fit per iteration, with the counters the scaling report reads.
#pragma once

#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>
#include <vector>

#include "kernels/cutter.h"
#include "kernels/mesh.h"
#include "kernels/surface_index.h"
#include "solver/decompose.h"
#include "solver/fit_motion.h"

namespace flank::bench {

// Spins on the calling thread for `span`, reading the clock: work of a known length, or a
// wait during which the other threads find nothing to do and go idle.
inline void spin_for(std::chrono::microseconds span) {
  const auto until = std::chrono::steady_clock::now() + span;
  while (std::chrono::steady_clock::now() < until) {
  }
}

// How long a cache line takes to pass from this core to another and back, in nanoseconds:
// one thread of its own and this one hand a word to each other `trips` times; the least of
// nine such batches, a millisecond apart (a core kept busy for a few milliseconds, as by the
// kernel writing out the files the last command left, slows some batches, not the link). On
// the 2-core virtual machines here it was 71-160 ns in quiet hours and 440-490 ns in the
// spells when every two-thread stage that shares data between its threads ran up to twice as
// long, while work on each core's own data ran as fast as ever (issue 13, fifty-first part).
// The scaling report records it beside every two-thread ladder run, so that a pair run in
// such a spell can be told from the code's own scaling.
inline double line_round_trip_ns(int trips = 1000) {
  alignas(64) std::atomic<int> word{0};
  double least = 0.0;
  for (int batch = 0; batch < 9; ++batch) {
    if (batch > 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    word.store(0);
    std::thread other([&] {
      for (int i = 0; i < trips; ++i) {
        while (word.load(std::memory_order_acquire) != 2 * i + 1) {
        }
        word.store(2 * i + 2, std::memory_order_release);
      }
    });
    const auto start = std::chrono::steady_clock::now();
    for (int i = 0; i < trips; ++i) {
      word.store(2 * i + 1, std::memory_order_release);
      while (word.load(std::memory_order_acquire) != 2 * i + 2) {
      }
    }
    const auto end = std::chrono::steady_clock::now();
    other.join();
    const double trip = std::chrono::duration<double, std::nano>(end - start).count() / trips;
    least = batch == 0 ? trip : std::min(least, trip);
  }
  return least;
}

// decompose on `mesh` (its BVH built inside the timing) at tolerance_rel × diagonal.
// Counters: seconds per stage, triangles, patches, coverage, lines scored, candidates grown,
// growths and searches reused.
inline void run_decompose(benchmark::State& state, const Mesh& mesh, double tolerance_rel,
                          const std::vector<CutterKind>& kinds) {
  StageTimes sum;
  double index_s = 0, coverage = 0, patches = 0, lines_scored = 0, grown = 0, regrown = 0, seeds_reused = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const SurfaceIndex index(mesh);
    index_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    DecomposeOptions o;
    o.tolerance = tolerance_rel * index.diagonal();
    o.kinds = kinds;
    const DecomposeResult result = decompose(index, o);
    sum.seeds += result.times.seeds, sum.candidates += result.times.candidates;
    sum.fit += result.times.fit, sum.cover += result.times.cover, sum.finish += result.times.finish;
    coverage = result.coverage;
    patches = static_cast<double>(result.patches.size());
    lines_scored = static_cast<double>(result.lines_scored);
    grown = result.grown;
    regrown = result.regrown;
    seeds_reused = result.seeds_reused;
  }
  const double n = static_cast<double>(state.iterations());
  state.counters["triangles"] = static_cast<double>(mesh.face_count());
  state.counters["vertices"] = static_cast<double>(mesh.vertex_count());
  state.counters["index_s"] = index_s / n;
  state.counters["seeds_s"] = sum.seeds / n;
  state.counters["candidates_s"] = sum.candidates / n;
  state.counters["fit_s"] = sum.fit / n;
  state.counters["cover_s"] = sum.cover / n;
  state.counters["finish_s"] = sum.finish / n;
  state.counters["coverage"] = coverage;
  state.counters["patches"] = patches;
  state.counters["lines_scored"] = lines_scored;
  state.counters["grown"] = grown;  // candidates propagated and fitted: the fit stage's work
  state.counters["regrown"] = regrown;  // candidates an earlier round had grown, reused
  state.counters["seeds_reused"] = seeds_reused;  // seeds whose earlier search was reused
}

// fit_motion from `start`. Counters: GN iterations, samples per iteration, closest-point
// queries made, the shares of the fit's time in queries, assembly and CHOLMOD, the
// factorisations per fit and the share of them made ahead on a second thread.
inline void run_fit(benchmark::State& state, const SurfaceIndex& index, const Motion& start,
                    const FitOptions& options) {
  FitTiming sum;
  long long iterations = 0;
  for (auto _ : state) {
    const FitResult result = fit_motion(index, start, options);
    benchmark::DoNotOptimize(result.final_cost);
    sum.query_s += result.timing.query_s;
    sum.assembly_s += result.timing.assembly_s;
    sum.factor_s += result.timing.factor_s;
    sum.total_s += result.timing.total_s;
    sum.queries += result.timing.queries;
    sum.factorisations += result.timing.factorisations;
    sum.made_ahead += result.timing.made_ahead;
    iterations += result.iterations;
  }
  const double n = static_cast<double>(state.iterations());
  state.counters["triangles"] = static_cast<double>(index.mesh().face_count());
  state.counters["gn_iterations"] = static_cast<double>(iterations) / n;
  state.counters["samples"] = static_cast<double>(options.samples_t) * options.samples_s;
  state.counters["queries"] = static_cast<double>(sum.queries) / n;
  state.counters["query_share"] = sum.query_s / sum.total_s;
  state.counters["assembly_share"] = sum.assembly_s / sum.total_s;
  state.counters["factor_share"] = sum.factor_s / sum.total_s;
  state.counters["factorisations"] = static_cast<double>(sum.factorisations) / n;
  state.counters["made_ahead"] = static_cast<double>(sum.made_ahead) / std::max(1, sum.factorisations);
  state.counters["ms_per_iteration"] = 1e3 * sum.total_s / std::max(1.0, static_cast<double>(iterations));
}

}  // namespace flank::bench
