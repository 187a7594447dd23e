// Benchmark bodies shared by the fixed-size benchmarks and the scaling ladder: one decompose
// or one motion fit per iteration, with the counters the scaling report reads.
#pragma once

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
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
