// What fresh memory costs on this machine: the first touch of each page of a new anonymous
// mapping, which every index or buffer pays where it grows the process past its peak.
// items_per_second is pages per second. On the 2-core virtual machines flank is measured on
// (2026-11-27) a 4 KiB page's first touch took 12-15 µs, some 50 times what the same memory
// costs once touched: a structure with a few MB of scratch pays more for the page faults
// than for its work (kernels/cell_grid.cpp). Args: {huge}: 1 asks for transparent huge pages
// (madvise), which flank does not use; 0.23 µs per 4 KiB here, warm.
#include <benchmark/benchmark.h>

#include <sys/mman.h>

#include <cstddef>
#include <cstdint>

namespace {

void BM_FirstTouch(benchmark::State& state) {
  const bool huge = state.range(0) != 0;
  constexpr std::size_t kBytes = std::size_t{32} << 20, kAlign = std::size_t{2} << 20, kPage = 4096;
  for (auto _ : state) {
    void* raw = mmap(nullptr, kBytes + kAlign, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (raw == MAP_FAILED) {
      state.SkipWithError("mmap failed");
      break;
    }
    const auto at = (reinterpret_cast<std::uintptr_t>(raw) + kAlign - 1) & ~(kAlign - 1);
    auto* p = reinterpret_cast<volatile char*>(at);
    if (huge) madvise(reinterpret_cast<void*>(at), kBytes, MADV_HUGEPAGE);
    for (std::size_t i = 0; i < kBytes; i += kPage) p[i] = 1;
    munmap(raw, kBytes + kAlign);
  }
  // Pages per iteration; with real time per iteration, µs per page is its 1e6 / rate.
  state.counters["pages"] = static_cast<double>(kBytes / kPage);
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(kBytes / kPage));
}
BENCHMARK(BM_FirstTouch)->ArgNames({"huge"})->Arg(0)->Arg(1)->UseRealTime()->Unit(benchmark::kMillisecond);

}  // namespace
