// End-to-end decompose on forward-model parts (the cone 4→7 envelope of the Li–Mann–Bedi
// part) of about 13k, 50k and 200k vertices, 1 and 2 threads, with the time split per stage;
// and on the four real blade faces of tests/data at the acceptance tolerances, every cutter
// kind (the CLI's defaults).
#include <benchmark/benchmark.h>

#include <map>
#include <memory>

#include "bench/runs.h"
#include "io/read_mesh.h"
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

// The 13k part with the CLI's defaults (every cutter kind), next to the cone-only run above.
void BM_DecomposeEveryKind(benchmark::State& state) {
  const Mesh& mesh = part(13);
  ThreadLimit limit(static_cast<int>(state.range(0)));
  bench::run_decompose(state, mesh, 1e-4, DecomposeOptions{}.kinds);
}
BENCHMARK(BM_DecomposeEveryKind)
    ->ArgNames({"threads"})->Arg(2)
    ->Iterations(1)->UseRealTime()->Unit(benchmark::kSecond);

// The real faces of the acceptance tests (tests/decompose_acceptance.py): index into kFaces,
// tolerance ×1e-4 of the diagonal, threads.
constexpr const char* kFaces[] = {"hecc_splitter_blade_side_a", "hecc_splitter_blade_side_b",
                                  "rotor67_blade_upper", "rotor67_blade_lower"};

const Mesh& face(int i) {
  static std::map<int, Mesh> cache;
  auto it = cache.find(i);
  if (it == cache.end()) {
    const std::string path = std::string(FLANK_TEST_DATA_DIR "/") + kFaces[i] + ".stl";
    it = cache.emplace(i, io::read_mesh(path).mesh).first;
  }
  return it->second;
}

void BM_DecomposeFace(benchmark::State& state) {
  const int i = static_cast<int>(state.range(0));
  state.SetLabel(kFaces[i]);
  ThreadLimit limit(static_cast<int>(state.range(2)));
  bench::run_decompose(state, face(i), 1e-4 * static_cast<double>(state.range(1)),
                       DecomposeOptions{}.kinds);
}
BENCHMARK(BM_DecomposeFace)
    ->ArgNames({"face", "tol_e4", "threads"})
    ->ArgsProduct({{0, 1, 2, 3}, {1, 3}, {1, 2}})
    ->Iterations(1)->UseRealTime()->Unit(benchmark::kSecond);

}  // namespace
}  // namespace flank
