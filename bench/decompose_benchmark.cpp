// End-to-end decompose on forward-model parts (the cone 4→7 envelope of the Li–Mann–Bedi
// part) of about 13k, 50k and 200k vertices, 1 and 2 threads, with the time split per stage.
#include <benchmark/benchmark.h>

#include <chrono>
#include <map>
#include <memory>

#include "kernels/parallel.h"
#include "solver/decompose.h"
#include "solver/synth.h"

namespace flank {
namespace {

// Grid sizes (rows × cols) for ~13k, ~50k, ~200k vertices.
std::pair<int, int> grid_for(int kilo_vertices) {
  if (kilo_vertices <= 13) return {221, 61};
  if (kilo_vertices <= 50) return {401, 121};
  return {801, 251};
}

const Mesh& part(int kilo_vertices) {
  static std::map<int, std::unique_ptr<Mesh>> cache;
  auto& slot = cache[kilo_vertices];
  if (!slot) {
    SynthOptions so;
    std::tie(so.rows, so.cols) = grid_for(kilo_vertices);
    slot = std::make_unique<Mesh>(synth_envelope(guide_motion(paper_guides(), kPaperToolLength),
                                                 cone_profile(kPaperToolLength, 4, 7), so)
                                      .mesh);
  }
  return *slot;
}

void BM_Decompose(benchmark::State& state) {
  const Mesh& mesh = part(static_cast<int>(state.range(0)));
  ThreadLimit limit(static_cast<int>(state.range(1)));
  StageTimes sum;
  double index_s = 0, coverage = 0, patches = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const SurfaceIndex index(mesh);
    index_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    DecomposeOptions o;
    o.tolerance = 1e-4 * index.diagonal();
    const DecomposeResult r = decompose(index, o);
    sum.seeds += r.times.seeds, sum.candidates += r.times.candidates;
    sum.fit += r.times.fit, sum.cover += r.times.cover;
    coverage = r.coverage;
    patches = static_cast<double>(r.patches.size());
  }
  const double n = static_cast<double>(state.iterations());
  state.counters["vertices"] = static_cast<double>(mesh.vertex_count());
  state.counters["index_s"] = index_s / n;
  state.counters["seeds_s"] = sum.seeds / n;
  state.counters["candidates_s"] = sum.candidates / n;
  state.counters["fit_s"] = sum.fit / n;
  state.counters["cover_s"] = sum.cover / n;
  state.counters["coverage"] = coverage;
  state.counters["patches"] = patches;
}
BENCHMARK(BM_Decompose)
    ->ArgNames({"kverts", "threads"})
    ->Args({13, 1})->Args({13, 2})->Args({50, 1})->Args({50, 2})->Args({200, 1})->Args({200, 2})
    ->Iterations(1)->UseRealTime()->Unit(benchmark::kSecond);

}  // namespace
}  // namespace flank
