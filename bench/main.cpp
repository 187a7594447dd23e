// flank_bench: Google Benchmark's own main, after registering the scaling ladder.
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <string_view>

#include "bench/ladder.h"
#include "kernels/memory.h"

int main(int argc, char** argv) {
  // As the flank command line runs (kernels/memory.h).
  flank::retain_freed_memory();
  if (const char* h = std::getenv("FLANK_HUGE_PAGES"); !h || std::string_view(h) != "0") flank::prefer_huge_pages();
  flank::register_ladder_benchmarks();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
