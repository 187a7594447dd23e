// Closest-point queries on a smooth height field, as movability and fitting issue them:
// lines of 30 samples about 5 mm above Φ, cold (no hint) or warm-started from the previous
// sample's footpoint face; sizes × threads × engine (0: our box tree, 1: Embree, the
// reference rate: "raw cold Embree" is engine 1 with warm 0).
#include <benchmark/benchmark.h>

#include <cmath>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <utility>
#include <vector>

#include "kernels/parallel.h"
#include "kernels/surface_index.h"

namespace flank {
namespace {

constexpr double kSize = 100.0;       // mm
constexpr double kClearance = 5.0;    // query height above Φ
constexpr double kLineLength = 10.0;  // mm
constexpr int kSamplesPerLine = 30;   // DESIGN: n = 30 samples per line
constexpr int kIndexLines = 2048;

double height(double x, double y) { return 5.0 * std::sin(x / 20.0) * std::cos(y / 15.0); }

// About `triangles_k` thousand triangles: n × n cells, two triangles each.
Mesh wavy_grid(int triangles_k) {
  const int n = static_cast<int>(std::lround(std::sqrt(triangles_k * 1000.0 / 2.0)));
  Mesh m;
  m.V.resize((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = kSize * i / n, y = kSize * j / n;
      m.V.row(j * (n + 1) + i) << x, y, height(x, y);
    }
  m.F.resize(2 * n * n, 3);
  int f = 0;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int v00 = j * (n + 1) + i, v10 = v00 + 1, v01 = v00 + n + 1, v11 = v01 + 1;
      m.F.row(f++) << v00, v10, v11;
      m.F.row(f++) << v00, v11, v01;
    }
  return m;
}

// kIndexLines lines of kSamplesPerLine consecutive query points (row l * kSamplesPerLine + i).
Points line_queries(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> pos(10.0, kSize - 10.0);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * std::numbers::pi);
  Points Q(kIndexLines * kSamplesPerLine, 3);
  for (int l = 0; l < kIndexLines; ++l) {
    const double x0 = pos(rng), y0 = pos(rng), t = angle(rng);
    for (int i = 0; i < kSamplesPerLine; ++i) {
      const double s = kLineLength * i / (kSamplesPerLine - 1);
      const double x = x0 + s * std::cos(t), y = y0 + s * std::sin(t);
      Q.row(l * kSamplesPerLine + i) << x, y, height(x, y) + kClearance;
    }
  }
  return Q;
}

struct Workload {
  std::unique_ptr<SurfaceIndex> index;
  Points queries;
};

QueryEngine engine_arg(std::int64_t arg) {
  return arg == 1 ? QueryEngine::kEmbree : QueryEngine::kBoxTree;
}

const Workload& workload(int triangles_k, QueryEngine engine = QueryEngine::kBoxTree) {
  static std::map<std::pair<int, QueryEngine>, Workload> cache;
  const auto key = std::make_pair(triangles_k, engine);
  auto it = cache.find(key);
  if (it == cache.end()) {
    Workload w{std::make_unique<SurfaceIndex>(wavy_grid(triangles_k), engine), line_queries(1234)};
    it = cache.emplace(key, std::move(w)).first;
  }
  return it->second;
}

// Args: {triangles_k, threads, warm, engine}. One task walks a line; warm passes the previous
// footpoint face as the hint.
void BM_ClosestPoints(benchmark::State& state) {
  const Workload& w = workload(static_cast<int>(state.range(0)), engine_arg(state.range(3)));
  const ThreadLimit limit(static_cast<int>(state.range(1)));
  const bool warm = state.range(2) != 0;
  const SurfaceIndex& index = *w.index;
  std::vector<int> faces(static_cast<std::size_t>(w.queries.rows()));
  for (auto _ : state) {
    parallel_for(
        0, kIndexLines,
        [&](std::size_t begin, std::size_t end) {
          for (std::size_t l = begin; l < end; ++l) {
            int hint = -1;
            for (int i = 0; i < kSamplesPerLine; ++i) {
              const auto row = static_cast<Eigen::Index>(l * kSamplesPerLine + i);
              const ClosestPoint cp = index.closest_point(w.queries.row(row), warm ? hint : -1);
              hint = cp.face;
              faces[static_cast<std::size_t>(row)] = cp.face;
            }
          }
        },
        2);
    benchmark::DoNotOptimize(faces.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * w.queries.rows());
  state.counters["triangles"] = static_cast<double>(index.mesh().face_count());
}
BENCHMARK(BM_ClosestPoints)
    ->ArgNames({"tri_k", "threads", "warm", "engine"})
    ->ArgsProduct({{13, 300}, {1, 2}, {0, 1}, {0, 1}})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

// The batch API (cold, parallel over queries). Args: {triangles_k, threads, engine}.
void BM_ClosestPointsBatch(benchmark::State& state) {
  const Workload& w = workload(static_cast<int>(state.range(0)), engine_arg(state.range(2)));
  const ThreadLimit limit(static_cast<int>(state.range(1)));
  const std::vector<int> cold(static_cast<std::size_t>(w.queries.rows()), -1);  // no chaining either
  for (auto _ : state) {
    std::vector<ClosestPoint> out = w.index->closest_points(w.queries, cold);
    benchmark::DoNotOptimize(out.data());
  }
  state.SetItemsProcessed(state.iterations() * w.queries.rows());
}
BENCHMARK(BM_ClosestPointsBatch)
    ->ArgNames({"tri_k", "threads", "engine"})
    ->ArgsProduct({{13, 300}, {1, 2}, {0, 1}})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

// The search structure's build plus adjacency: the box tree, or Embree's BVH
// (RTC_BUILD_QUALITY_HIGH). Args: {triangles_k, engine}.
void BM_SurfaceIndexBuild(benchmark::State& state) {
  const Mesh mesh = wavy_grid(static_cast<int>(state.range(0)));
  const QueryEngine engine = engine_arg(state.range(1));
  for (auto _ : state) {
    SurfaceIndex index(mesh, engine);
    benchmark::DoNotOptimize(&index);
  }
  state.SetItemsProcessed(state.iterations() * mesh.face_count());
}
BENCHMARK(BM_SurfaceIndexBuild)
    ->ArgNames({"tri_k", "engine"})
    ->ArgsProduct({{13, 300}, {0, 1}})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

// The index Ω gets for its bounded queries (SurfaceIndex::within_reach: the faces' adjacency
// and a cell table), built once for each patch the finish stage evaluates: a sheet of
// 26k triangles like a patch's Ω, reach 0.5 mm. Args: {threads}.
void BM_SurfaceIndexWithinReach(benchmark::State& state) {
  const ThreadLimit limit(static_cast<int>(state.range(0)));
  const Mesh mesh = wavy_grid(26);
  for (auto _ : state) {
    SurfaceIndex index = SurfaceIndex::within_reach(mesh, 0.5);
    benchmark::DoNotOptimize(&index);
  }
  state.SetItemsProcessed(state.iterations() * mesh.face_count());
}
BENCHMARK(BM_SurfaceIndexWithinReach)
    ->ArgNames({"threads"})
    ->Arg(1)
    ->Arg(2)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace flank
