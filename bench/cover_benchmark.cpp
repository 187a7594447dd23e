// The cover stage on its own, at 1 and 2 threads: a decomposition's cover is a few
// milliseconds summed over its rounds, one sample per decompose run, and on the 2-core
// machines here a run's cover time varies by half from run to run; this runs the same calls
// thousands of times, so that a change to them is judged on medians, in one run.
//
// The pool is made, not grown: on a real face (HECC a, Rotor 67 upper), the Φ vertices within
// a random distance of a random vertex (3-15% of the diagonal, small ones more often), 48
// entries (decompose's pools on these faces hold some 40-50), each list in vertex order as
// evaluate_patch makes them. Its overlaps are those of patches on one surface, without the minutes
// of fitting.
//
//   Cover/extend/<part>/idle_us:<0|1000>/threads:<1|2>   extend_cover from an empty cover
//                            (decompose's covers of the whole pool: greedy picks, 8 swaps)
//   Cover/improve/<part>/idle_us:<0|1000>/threads:<1|2>  improve_cover of that greedy cover
//                            (a round's swaps and order)
//
// idle_us: before each call, untimed, the calling thread spins that long alone, so that the
// other thread has gone to sleep, as in decompose, where a cover follows serial work and
// the crew's helper must be woken (kernels/parallel.h, with_crew); 0: calls back to back.
//
// On 2026-11-30 (medians of five repetitions, one run; 1 / 2 threads, idle 0 and 1000 µs):
// extend on HECC a 519 / 300 and 539 / 327 µs (efficiency 0.87, 0.82), on Rotor 67 upper
// 386 / 250 and 390 / 275 µs (0.77, 0.71); improve on HECC a 313 / 179 and 317 / 197 µs
// (0.87, 0.80), on Rotor 67 upper 177 / 106 and 176 / 121 µs (0.83, 0.73): the efficiencies
// decompose's cover stage shows. From run to run a two-thread median moved by up to a
// third (improve on HECC a, idle 0: 179 and 252 µs): compare builds alternated.
#include <benchmark/benchmark.h>

#include <chrono>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "bench/runs.h"
#include "io/read_mesh.h"
#include "kernels/mesh.h"
#include "kernels/parallel.h"
#include "solver/greedy_cover.h"

namespace flank {
namespace {

struct CoverCase {
  VecX area;
  std::vector<Patch> pool;
  Cover greedy;  // greedy_cover of the pool from nothing
};

const CoverCase& cover_case(const std::string& file) {
  static std::map<std::string, CoverCase> cases;  // its entries stay where they are
  if (const auto found = cases.find(file); found != cases.end()) return found->second;
  const Mesh mesh = io::read_mesh(FLANK_TEST_DATA_DIR "/" + file).mesh;
  CoverCase c;
  c.area = vertex_areas(mesh);
  const double diagonal = (mesh.V.colwise().maxCoeff() - mesh.V.colwise().minCoeff()).norm();
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const int V = mesh.vertex_count();
  for (int k = 0; k < 48; ++k) {
    const Vec3 center = mesh.V.row(static_cast<int>(rng() % static_cast<unsigned>(V))).transpose();
    const double u = unit(rng), radius = diagonal * (0.03 + 0.12 * u * u);
    Patch p;
    for (int v = 0; v < V; ++v)
      if ((mesh.V.row(v).transpose() - center).norm() <= radius) p.covered_vertices.push_back(v);
    p.error.max = 0.001 * static_cast<double>(k % 7);
    c.pool.push_back(std::move(p));
  }
  c.greedy = empty_cover(c.area);
  greedy_cover(c.pool, c.area, CoverOptions{}, &c.greedy);
  return cases.emplace(file, std::move(c)).first->second;
}

using Clock = std::chrono::steady_clock;

void BM_CoverExtend(benchmark::State& state, const std::string& file) {
  const CoverCase& c = cover_case(file);
  const std::chrono::microseconds idle(state.range(0));
  const ThreadLimit limit(static_cast<int>(state.range(1)));
  for (auto _ : state) {
    Cover cover = empty_cover(c.area);
    bench::spin_for(idle);
    const Clock::time_point start = Clock::now();
    extend_cover(c.pool, c.area, CoverOptions{}, 8, &cover);
    state.SetIterationTime(std::chrono::duration<double>(Clock::now() - start).count());
    benchmark::DoNotOptimize(cover.covered_area);
  }
  state.counters["patches"] = static_cast<double>(c.greedy.picks.size());
}

void BM_CoverImprove(benchmark::State& state, const std::string& file) {
  const CoverCase& c = cover_case(file);
  const std::chrono::microseconds idle(state.range(0));
  const ThreadLimit limit(static_cast<int>(state.range(1)));
  for (auto _ : state) {
    Cover cover = c.greedy;  // a round improves the cover it has
    bench::spin_for(idle);
    const Clock::time_point start = Clock::now();
    improve_cover(c.pool, c.area, 8, &cover);
    state.SetIterationTime(std::chrono::duration<double>(Clock::now() - start).count());
    benchmark::DoNotOptimize(cover.covered_area);
  }
}

void register_cover_benchmarks() {
  using Body = void (*)(benchmark::State&, const std::string&);
  for (const auto& [part, file] : {std::pair{"hecc_a", "hecc_splitter_blade_side_a.stl"},
                                   std::pair{"rotor_upper", "rotor67_blade_upper.stl"}})
    for (const auto& [call, body] : {std::pair<const char*, Body>{"extend", BM_CoverExtend},
                                     std::pair<const char*, Body>{"improve", BM_CoverImprove}})
      benchmark::RegisterBenchmark(("Cover/" + std::string(call) + "/" + part).c_str(), body,
                                   std::string(file))
          ->ArgNames({"idle_us", "threads"})
          ->ArgsProduct({{0, 1000}, {1, 2}})
          ->UseManualTime()
          ->Unit(benchmark::kMicrosecond);
}

const int registered = (register_cover_benchmarks(), 0);

}  // namespace
}  // namespace flank
