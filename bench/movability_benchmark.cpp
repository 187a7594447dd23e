// Movability scoring throughput (lines/s at n = 30) on the exact cone envelope of the
// Li–Mann–Bedi part, lines near the true axes: warm-started queries along each line, lines
// in parallel as candidate scoring issues them.
#include <benchmark/benchmark.h>

#include <random>
#include <vector>

#include "kernels/movability.h"
#include "kernels/parallel.h"
#include "solver/synth.h"

namespace flank {
namespace {

struct Fixture {
  Mesh mesh;
  std::vector<std::pair<Vec3, Vec3>> lines;
};

const Fixture& fixture() {
  static const Fixture f = [] {
    Fixture x;
    SynthOptions so;  // 241 × 61: 14,701 vertices, 28,800 triangles
    const AxisMotion motion = guide_motion(paper_guides(), kPaperToolLength);
    x.mesh = synth_envelope(motion, cone_profile(kPaperToolLength, 4, 7), so).mesh;
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> t(0.05, 0.95), jitter(-1.0, 1.0);
    for (int i = 0; i < 4096; ++i) {
      const double ti = t(rng);
      const Vec3 j(jitter(rng), jitter(rng), jitter(rng));
      x.lines.emplace_back(motion.a(ti, 0) + j, motion.b(ti, 0) + j);
    }
    return x;
  }();
  return f;
}

void BM_Movability(benchmark::State& state) {
  const Fixture& f = fixture();
  static const SurfaceIndex index(f.mesh);
  ThreadLimit limit(static_cast<int>(state.range(0)));
  MovabilityOptions mo;
  mo.samples = 30;
  std::vector<double> values(f.lines.size());
  for (auto _ : state) {
    parallel_for(0, f.lines.size(), [&](std::size_t b, std::size_t e) {
      std::vector<int> hints(30, -1);
      for (std::size_t k = b; k < e; ++k) {
        std::fill(hints.begin(), hints.end(), -1);
        values[k] = movability(index, f.lines[k].first, f.lines[k].second, mo, hints).value;
      }
    }, 16);
    benchmark::DoNotOptimize(values.data());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(f.lines.size()));
  state.counters["lines_per_s"] = benchmark::Counter(
      static_cast<double>(state.iterations() * f.lines.size()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_Movability)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace flank
