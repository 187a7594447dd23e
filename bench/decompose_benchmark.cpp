// End-to-end decompose on forward-model parts (the cone 4→7 envelope of the Li–Mann–Bedi
// part) of about 13k, 50k and 200k vertices, 1 and 2 threads, with the time split per stage.
#include <benchmark/benchmark.h>

#include <map>
#include <memory>

#include "bench/runs.h"
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
  bench::run_decompose(state, mesh, 1e-4, {CutterKind::cone});
}
BENCHMARK(BM_Decompose)
    ->ArgNames({"kverts", "threads"})
    ->Args({13, 1})->Args({13, 2})->Args({50, 1})->Args({50, 2})->Args({200, 1})->Args({200, 2})
    ->Iterations(1)->UseRealTime()->Unit(benchmark::kSecond);

}  // namespace
}  // namespace flank
