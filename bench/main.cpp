// flank_bench: Google Benchmark's own main, after registering the scaling ladder.
#include <benchmark/benchmark.h>

#include "bench/ladder.h"

int main(int argc, char** argv) {
  flank::register_ladder_benchmarks();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
