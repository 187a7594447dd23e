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
// BM_StepChain, last: how far a chain of a read's kind of steps scales here, whatever the code.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <numeric>
#include <vector>

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

// BM_StepChain: a chain of steps of a mesh read's kind, with nothing of the read in it. 24
// steps, each a parallel loop (parallel_invoke_each) over pieces of 6144 items (a read's
// pieces of 2048 faces) of an array of `items` doubles, that reads the array the step before
// wrote and writes the other. `gather` 0: item i reads item i (a parse, a copy: each piece
// reads what the same piece wrote, on whichever thread ran it); 1: item i reads item
// (i · k) mod n, k coprime with n (a weld's or an edge's lookups: every piece reads what
// every other wrote). No shared counter, no serial work between the steps, pieces of equal
// work: what two threads take beyond half of one's time is the machine's, not a code's. The
// scaling report prints its efficiency beside the stages' as a yardstick.
//
// On 2026-12-01, six runs whose two-thread runs saw a round trip of 80-116 ns, efficiency
// (1 / 2 threads): 73,728 items (a 24k-face read's points) streaming 0.85-0.92 (234-257 /
// 137-146 µs), gathering 0.77-0.79 (934-999 / 607-633 µs); 294,912 items streaming 0.91-1.01,
// gathering 0.88-0.95. Pieces of 1536 items instead: the 73,728 items' gathering 0.80-0.81,
// slower at both thread counts. Two pinned threads, a spin barrier between the steps (a
// throwaway program), each gathering from its own half of the array or, with the same
// pattern, from the other thread's half: 0.83-0.93 (median 0.875) and 0.79-0.86 (0.82), six
// quiet runs; two-thread times 566-633 and 590-656 µs. Keeping each thread's random reads in
// its own data gains some 4% here, and they still run short of twice one thread's speed.
void BM_StepChain(benchmark::State& state) {
  const auto items = static_cast<std::size_t>(state.range(0));
  const bool gather = state.range(1) != 0;
  const int threads = static_cast<int>(state.range(2));
  const double round_trip = threads == 2 ? bench::line_round_trip_ns() : 0.0;
  const ThreadLimit limit(threads);
  constexpr int kSteps = 24;
  constexpr std::size_t kPieceItems = 6144;
  const std::size_t pieces = std::max<std::size_t>(1, items / kPieceItems);
  std::vector<double> a(items, 1.0), b(items, 0.0);
  std::size_t k = 40503 % items;  // a stride of some 40k items (320 KB), coprime with n
  while (std::gcd(k, items) != 1) ++k;
  std::vector<std::uint32_t> source(items);  // item i reads item (i · k) mod n
  for (std::size_t i = 0; i < items; ++i) source[i] = static_cast<std::uint32_t>(i * k % items);
  for (auto _ : state) {
    for (int step = 0; step < kSteps; ++step) {
      const double* from = step % 2 ? b.data() : a.data();
      double* to = step % 2 ? a.data() : b.data();
      parallel_invoke_each(pieces, [&](std::size_t c) {
        const std::size_t begin = items * c / pieces, end = items * (c + 1) / pieces;
        if (gather)
          for (std::size_t i = begin; i < end; ++i) to[i] = from[source[i]] * 0.5 + 1.0;
        else
          for (std::size_t i = begin; i < end; ++i) to[i] = from[i] * 0.5 + 1.0;
      });
    }
    benchmark::DoNotOptimize(a.data());
  }
  state.counters["steps"] = kSteps;
  if (threads == 2) state.counters["line_rt_ns"] = round_trip;
}
BENCHMARK(BM_StepChain)
    ->ArgNames({"items", "gather", "threads"})
    ->ArgsProduct({{73728, 294912}, {0, 1}, {1, 2}})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace flank
