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
#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdint>

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

}  // namespace
}  // namespace flank
