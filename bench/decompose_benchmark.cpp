// End-to-end decompose on forward-model parts (the cone 4→7 envelope of the Li–Mann–Bedi
// part) of about 13k, 50k and 200k vertices, 1 and 2 threads, with the time split per stage;
// and on the four real blade faces of tests/data at the acceptance tolerances, every cutter
// kind (the CLI's defaults); and the closest-point queries of one decompose, replayed alone.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
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

// The closest-point queries of one decompose, replayed alone: the rate of our coherent queries
// against raw cold Embree judged on the stream that matters (points a cutter radius above Φ,
// along lines, sweeps and fits, each with the hint decompose gave it), not on synthetic lines.
// Parts: 0 the 13k cone part (cone cutters, as BM_Decompose), 1 HECC side a, 2 Rotor 67 lower
// (every kind, as BM_DecomposeFace), all at 1e-4, recorded once on one thread (Rotor 67 lower:
// ~6M queries, ~10 s). Replayed on one thread: ten evenly spaced windows of 20,000 consecutive
// queries. engine 0: our box tree, 1: Embree's BVH; hints 1: as recorded, 0: none (cold).
// "Raw cold Embree" is engine 1 with hints 0; the target is engine 0, hints 1 at ≥ 3× its rate.
struct Stream {
  const Mesh* mesh = nullptr;
  std::vector<SurfaceIndex::RecordedQuery> queries;
  std::size_t recorded = 0;
  double median_distance = 0.0;  // of the replayed queries, as a fraction of the diagonal
  std::size_t differ = 0;        // replayed queries whose answer (face, distance) differs by engine
};

const Stream& stream(int which) {
  static std::map<int, Stream> cache;
  auto it = cache.find(which);
  if (it != cache.end()) return it->second;
  Stream st;
  st.mesh = which == 0 ? &part(13) : &face(which == 1 ? 0 : 3);
  SurfaceIndex index(*st.mesh);
  DecomposeOptions o;
  o.tolerance = 1e-4 * index.diagonal();
  if (which == 0) o.kinds = {CutterKind::cone};
  std::vector<SurfaceIndex::RecordedQuery> all;
  {
    ThreadLimit one(1);
    index.record_queries(&all);
    decompose(index, o);
    index.record_queries(nullptr);
  }
  constexpr std::size_t kWindows = 10, kWindow = 20000;
  if (all.size() <= kWindows * kWindow) {
    st.queries = std::move(all);
  } else {
    for (std::size_t w = 0; w < kWindows; ++w) {
      const std::size_t from = w * (all.size() - kWindow) / (kWindows - 1);
      st.queries.insert(st.queries.end(), all.begin() + static_cast<std::ptrdiff_t>(from),
                        all.begin() + static_cast<std::ptrdiff_t>(from + kWindow));
    }
  }
  st.recorded = all.size();
  // The replay is only a fair race if both engines give the same answers.
  const SurfaceIndex embree(*st.mesh, QueryEngine::kEmbree);
  std::vector<double> distances;
  for (const SurfaceIndex::RecordedQuery& q : st.queries) {
    const ClosestPoint a = index.closest_point(q.point, q.hint), b = embree.closest_point(q.point);
    st.differ += a.face != b.face || a.distance != b.distance;
    distances.push_back(a.distance / index.diagonal());
  }
  std::nth_element(distances.begin(), distances.begin() + static_cast<std::ptrdiff_t>(distances.size() / 2),
                   distances.end());
  st.median_distance = distances.empty() ? 0.0 : distances[distances.size() / 2];
  std::fprintf(stderr, "replay stream %d: %zu queries recorded, %zu replayed, median distance %.4f of the diagonal, %zu answers differ\n",
               which, st.recorded, st.queries.size(), st.median_distance, st.differ);
  return cache.emplace(which, std::move(st)).first->second;
}

void BM_ReplayQueries(benchmark::State& state) {
  const Stream& st = stream(static_cast<int>(state.range(0)));
  const bool embree = state.range(1) == 1, hinted = state.range(2) == 1;
  state.SetLabel(state.range(0) == 0 ? "cone_13k" : state.range(0) == 1 ? kFaces[0] : kFaces[3]);
  const SurfaceIndex index(*st.mesh, embree ? QueryEngine::kEmbree : QueryEngine::kBoxTree);
  for (auto _ : state)
    for (const SurfaceIndex::RecordedQuery& q : st.queries)
      benchmark::DoNotOptimize(index.closest_point(q.point, hinted ? q.hint : -1));
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(st.queries.size()));
  state.counters["recorded"] = static_cast<double>(st.recorded);
  state.counters["median_distance"] = st.median_distance;
  state.counters["answers_differ"] = static_cast<double>(st.differ);
}
BENCHMARK(BM_ReplayQueries)
    ->ArgNames({"part", "engine", "hints"})
    ->ArgsProduct({{0, 1, 2}, {0, 1}, {0, 1}})
    ->UseRealTime()->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace flank
