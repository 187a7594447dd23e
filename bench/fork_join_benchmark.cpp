// What one fork and join of two threads costs on this machine, after the other thread has
// been idle: the floor under the parallel efficiency of a short stage. Each iteration waits
// `idle` µs on the calling thread (untimed: the worker finds nothing to do and sleeps, as it
// does between a command's serial steps and its next parallel stage), then times
// parallel_invoke_each (kernels/parallel.h) over two tasks of `work` µs each, spun on the
// clock. One thread runs the two back to back (2 × work); two threads ideally take `work`.
// The scaling report turns the two-thread time's excess over `work` into the ceiling a stage
// of a given length can reach (scripts/scaling_report.py, "Parallel efficiency").
//
// On the 2-core virtual machines here (2026-11-28) the excess was 83-94 µs whatever the work;
// in a throwaway oneTBB program the other thread started 79-83 µs after a task_group's fork
// (the idle vCPU's wake-up). A stage that forks once then needs about 1.6 ms of one thread's
// work to reach an efficiency of 0.9.
//
// BM_CrewSteps, below: what a crew's short steps cost, its helper woken once for 20 of them.
#include <benchmark/benchmark.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>

#include "bench/runs.h"
#include "kernels/parallel.h"

namespace flank {
namespace {

using Clock = std::chrono::steady_clock;

void BM_ForkJoin(benchmark::State& state) {
  const std::chrono::microseconds work(state.range(0)), idle(state.range(1));
  const ThreadLimit limit(static_cast<int>(state.range(2)));
  for (auto _ : state) {
    bench::spin_for(idle);
    const Clock::time_point start = Clock::now();
    parallel_invoke_each(2, [&](std::size_t) { bench::spin_for(work); });
    state.SetIterationTime(std::chrono::duration<double>(Clock::now() - start).count());
  }
  state.counters["work_s"] = std::chrono::duration<double>(work).count();
}
BENCHMARK(BM_ForkJoin)
    ->ArgNames({"work_us", "idle_us", "threads"})
    ->ArgsProduct({{100, 250, 500, 1000, 2000}, {1000}, {1, 2}})
    ->UseManualTime()
    ->Unit(benchmark::kMicrosecond);

// A crew's steps (kernels/parallel.h, with_crew), as the cover's greedy picks and swaps make
// them: a crew of 20 steps of `chunks` chunks, each `iterations` dependent multiply-adds (some
// 1.35 ns each here) that write a cache line of their own. One thread runs every chunk; two
// ideally take half the time. What two take beyond half is the crew's own cost: the step's
// hand-over and, per chunk, the shared counters (chunks taken, chunks run), whose cache line
// passes from one thread to the other.
//
// On 2026-11-30 (medians of four runs alternated with a build that changed the crew; µs per
// crew of 20 steps, 1 / 2 threads): 40 chunks of 100 multiply-adds 76 / 83, of 300: 301 /
// 189, of 1000: 1090 / 580; 200 chunks of 200: 941 / 645 (in a run a quarter hour earlier,
// 948 at two threads: compare builds alternated). A step of chunks under half a microsecond
// gains little from the second thread. Taking several chunks at a claim, an eighth of those
// left (with the two counters on cache lines of their own and each thread's chunks counted
// once), gave 64, 171, 568 and 503 µs at two threads, but the cover's calls (Cover/) and
// decompose's cover stage ran no faster: their chunks are longer, and longest first, where a
// claim of several would take the longest together (issue 13, forty-seventh part).
constexpr std::size_t kMostChunks = 200;

struct ChunkResults {
  alignas(64) std::array<double, 8> scale{};  // 0, read by every chunk: its work depends on it
  alignas(64) std::array<double, 8 * kMostChunks> of{};  // chunk c's at 8 c: a cache line each
};

void BM_CrewSteps(benchmark::State& state) {
  const auto chunks = static_cast<std::size_t>(state.range(0));
  const auto iterations = static_cast<int>(state.range(1));
  const ThreadLimit limit(static_cast<int>(state.range(2)));
  constexpr int kSteps = 20;
  if (chunks > kMostChunks) {
    state.SkipWithError("more chunks than ChunkResults holds");
    return;
  }
  static ChunkResults results;
  const std::function<void(std::size_t, std::size_t)> chunk = [&](std::size_t b, std::size_t e) {
    for (std::size_t c = b; c < e; ++c) {
      double x = 1.0 + static_cast<double>(c) * results.scale[0];
      for (int i = 0; i < iterations; ++i) x = x * 1.0000001 + 1e-9;
      results.of[8 * c] = x;
    }
  };
  for (auto _ : state)
    with_crew([&](Crew& crew) {
      for (int step = 0; step < kSteps; ++step) crew.parallel_for(0, chunks, chunk, 1);
    });
  state.counters["steps"] = kSteps;
}
BENCHMARK(BM_CrewSteps)
    ->ArgNames({"chunks", "iterations", "threads"})
    ->ArgsProduct({{40}, {100, 300, 1000}, {1, 2}})
    ->ArgsProduct({{200}, {200}, {1, 2}})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace flank
