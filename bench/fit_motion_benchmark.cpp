// One fit_motion (30 × 100 samples, K = 40, cone) on the exact cone envelope of the
// Li–Mann–Bedi part (361 × 91 grid, 65k triangles), from seven surface-driven lines 1 mm off
// and turned 2°; 1 and 2 threads. Counters split the time into queries, assembly, CHOLMOD.
#include <benchmark/benchmark.h>

#include <numbers>
#include <vector>

#include "bench/runs.h"
#include "kernels/parallel.h"
#include "solver/fit_motion.h"
#include "solver/propagate.h"
#include "solver/synth.h"

namespace flank {
namespace {

std::vector<Line> perturbed_axes(const AxisMotion& motion) {
  std::vector<Line> lines;
  for (int i = 0; i < 7; ++i) {
    const double t = i / 6.0;
    const Vec3 a = motion.a(t, 0), b = motion.b(t, 0), u = (b - a).normalized();
    const Vec3 n = (i % 2 ? 1.0 : -1.0) * u.cross(motion.a(t, 1)).normalized();
    const Vec3 mid = 0.5 * (a + b) + n;
    const Vec3 u2 = Eigen::AngleAxisd(2.0 * std::numbers::pi / 180.0, u.cross(n)) * u;
    lines.push_back({mid - 25.0 * u2, mid + 25.0 * u2});
  }
  return lines;
}

void BM_FitMotion(benchmark::State& state) {
  const AxisMotion motion = guide_motion(paper_guides(), kPaperToolLength);
  SynthOptions so;
  so.rows = 361;
  so.cols = 91;
  static const SurfaceIndex index(
      synth_envelope(motion, cone_profile(kPaperToolLength, 4, 7), so).mesh);
  const Motion init = motion_from_lines(perturbed_axes(motion), 40);
  ThreadLimit limit(static_cast<int>(state.range(0)));
  FitOptions fo;
  fo.kind = CutterKind::cone;
  bench::run_fit(state, index, init, fo);
}
BENCHMARK(BM_FitMotion)->Arg(1)->Arg(2)->UseRealTime()->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace flank
