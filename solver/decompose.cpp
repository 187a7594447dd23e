#include "solver/decompose.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <numbers>
#include <numeric>

#include "kernels/movability.h"
#include "kernels/parallel.h"
#include "solver/evaluate_patch.h"
#include "solver/propagate.h"
#include "solver/seed_tiles.h"
#include "solver/trim.h"

namespace flank {

std::string DecomposeOptions::validate() const {
  if (!(tolerance > 0.0) || !std::isfinite(tolerance)) return "tolerance must be positive";
  if (kinds.empty()) return "at least one cutter kind is needed";
  if (radius_min < 0 || radius_max < 0 || (radius_max > 0 && radius_min > radius_max))
    return "--radius MIN,MAX needs 0 < MIN <= MAX";
  if (length_min < 0 || length_max < 0 || (length_max > 0 && length_min > length_max))
    return "--length MIN,MAX needs 0 < MIN <= MAX";
  if (holder && !(holder_length > 0 && holder_radius > 0)) return "holder length and radius must be positive";
  if (!(coverage_target > 0 && coverage_target <= 1)) return "coverage target must be in (0, 1]";
  if (max_patches < 1) return "the patch cap must be at least 1";
  if (max_rounds < 1) return "at least one seeding round is needed";
  if (directions < 1 || tilts < 1 || radii < 1 || lengths < 1) return "candidate counts must be positive";
  if (coarse_samples < 4 || fine_samples < 4) return "movability needs at least 4 samples per line";
  if (control_points < 4 || fit_iterations < 1) return "fit settings out of range";
  return {};
}

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

struct Ranges {
  double r0, r1, l0, l1;
};

Ranges resolve_ranges(const DecomposeOptions& o, double diagonal) {
  Ranges r;
  r.r0 = o.radius_min > 0 ? o.radius_min : 0.01 * diagonal;
  r.r1 = o.radius_max > 0 ? o.radius_max : 0.10 * diagonal;
  r.l0 = o.length_min > 0 ? o.length_min : 0.10 * diagonal;
  r.l1 = o.length_max > 0 ? o.length_max : 0.45 * diagonal;
  return r;
}

// Values spread over [lo, hi]: geometric for radii (tools come in ratios), the top first.
std::vector<double> spread(double lo, double hi, int count, bool geometric) {
  std::vector<double> v;
  for (int k = 0; k < count; ++k) {
    const double f = count == 1 ? 1.0 : 1.0 - static_cast<double>(k) / (count - 1);
    v.push_back(geometric ? lo * std::pow(hi / lo, f) : lo + f * (hi - lo));
  }
  return v;
}

struct LineCandidate {
  Line line;
  double inside = 0.0;  // length of the line whose footpoints are inside Φ
  double swept = 0.0;   // how far it sweeps in the probe (sweep_probe)
  CutterKind kind = CutterKind::cone;
  double score = std::numeric_limits<double>::infinity();
  Movability movability;
  int seed = 0;
  bool good = false;
};

// F_l alone is a narrow hole: on an exact envelope it is ~1e-9 on the ruling and ~5e-6
// already 0.2 mm off it, flat beyond. The misfit of the cutter profile grows linearly with
// the offset instead (about 0.014 mm per mm on the paper's part), so weighted in it leads a
// local search into the hole from millimetres away.
constexpr double kProfileWeight = 1e3;

double line_score(const Movability& m, double L) {
  const double misfit = m.profile_rms / L;
  return m.value + kProfileWeight * misfit * misfit;
}

double inside_length(const Movability& m, double L) {
  return m.samples > 0 ? L * (m.samples - m.boundary_samples) / m.samples : 0.0;
}

bool acceptable(const Movability& m, const Ranges& R, double L) {
  return m.ok() && m.max_slope < 0.9 * L && m.radius_min >= R.r0 && m.radius_max <= R.r1;
}

PropagateOptions propagate_options(const SurfaceIndex& index, const DecomposeOptions& o) {
  // A sweep drifts from Φ by about √F_l per unit of travel: to stay within tolerance over a
  // sweep of half the diagonal, F_l must stay below (tol / (diagonal/2))²; 20× that leaves the
  // fit room to correct.
  PropagateOptions po;
  const double rel = o.tolerance / (0.5 * index.diagonal());
  po.max_movability = std::min(po.max_movability, 400.0 * rel * rel);
  return po;
}

// How far the line sweeps (both ways together, each way at most kProbe of the diagonal)
// before it stalls, leaves Φ or stops moving like a ruling.
constexpr double kProbe = 0.15;
double sweep_probe(const SurfaceIndex& index, const Line& line, const DecomposeOptions& o) {
  PropagateOptions po = propagate_options(index, o);
  po.max_travel = kProbe * index.diagonal();
  po.step = 1e-3 * index.diagonal();  // propagate's default, set here so the count converts
  const Propagation p = propagate(index, line, po);
  return static_cast<double>(p.rulings.size() - 1) * po.step;
}

// The line on the same axis that spans Φ's width: centred on the run of footpoints inside Φ
// through its middle, as long as that run plus 2% overhang at each end, within the allowed
// lengths. Where Φ goes on past the longest allowed cutter on one side, the line starts at
// the edge on the other; where on both sides, it keeps its middle.
Line span_width(const SurfaceIndex& index, const Line& line, const Ranges& R) {
  const double L = line.length();
  const Vec3 u = (line.b - line.a) / L;
  // Start from the middle of the longest run of samples inside Φ: a grid line through a seed
  // near Φ's edge may have its middle off Φ.
  constexpr int kSamples = 32;
  int hint = -1, run = 0, best = 0, best_end = -1;
  for (int k = 0; k < kSamples; ++k) {
    const ClosestPoint cp = index.closest_point(line.point((k + 0.5) / kSamples), hint);
    if (cp.face >= 0) hint = cp.face;
    run = cp.face >= 0 && !cp.boundary ? run + 1 : 0;
    if (run > best) best = run, best_end = k;
  }
  if (best == 0) return line;
  const double from = (best_end + 1.0 - 0.5 * best) / kSamples;
  const double reach = std::max(0.0, R.l1 / L - 0.5);
  const double lo = interior_edge(index, line, true, from, reach, &hint);
  const double hi = interior_edge(index, line, false, from, reach, &hint);
  constexpr double kOverhang = 0.02;
  if (std::isfinite(lo) && std::isfinite(hi)) {
    const double len = std::clamp((hi - lo) * L * (1.0 + 2.0 * kOverhang), R.l0, R.l1);
    const Vec3 mid = line.point(0.5 * (lo + hi));
    return {mid - 0.5 * len * u, mid + 0.5 * len * u};
  }
  if (std::isfinite(lo)) {
    const Vec3 a = line.point(lo) - kOverhang * R.l1 * u;
    return {a, a + R.l1 * u};
  }
  if (std::isfinite(hi)) {
    const Vec3 b = line.point(hi) + kOverhang * R.l1 * u;
    return {b - R.l1 * u, b};
  }
  const Vec3 mid = 0.5 * (line.a + line.b);
  return {mid - 0.5 * R.l1 * u, mid + 0.5 * R.l1 * u};
}

// Candidate lines at one seed (DESIGN): midpoint p + r N, direction in the tangent plane at
// `directions` angles, tilted toward N, over the allowed lengths; coarse score, then the best
// rescored fine; returns up to lines_per_seed with distinct directions.
std::vector<LineCandidate> seed_candidates(const SurfaceIndex& index, const Seed& seed, int seed_id,
                                           const DecomposeOptions& o, const Ranges& R,
                                           long long* scored) {
  const std::vector<double> radii = spread(R.r0, R.r1, o.radii, true);
  const std::vector<double> lengths = spread(R.l0, R.l1, o.lengths, false);
  std::vector<LineCandidate> best;
  // A line that sweeps (F_l tiny) with a profile its cutter can follow is a patch in waiting.
  auto good = [&](const LineCandidate& c) {
    // The fit corrects a line a degree or two off, so "good" asks for the right shape of
    // profile, not already the tolerance: the fit and trim decide the final quality.
    return c.movability.ok() && c.movability.value <= o.good_movability &&
           c.movability.profile_rms <= 4.0 * o.tolerance;
  };
  // Good lines first, the longest inside Φ first among them (the ruling across the whole
  // width beats a short chord that sweeps only locally); then by score.
  auto better = [](const LineCandidate& x, const LineCandidate& y) {
    if (x.good != y.good) return x.good;
    if (x.good && std::abs(x.inside - y.inside) > 1e-9) return x.inside > y.inside;
    return x.score < y.score;
  };
  for (CutterKind kind : o.kinds) {
    MovabilityOptions coarse;
    coarse.samples = o.coarse_samples;
    coarse.profile = kind;
    // A line may overhang Φ by up to half its length here: span_width fits it to Φ's width
    // later, and a true ruling through a seed off the middle of the width overhangs one side.
    coarse.max_boundary_fraction = 0.5;
    std::vector<LineCandidate> all;
    std::vector<int> hints(static_cast<std::size_t>(o.coarse_samples), -1);
    for (double L : lengths)
      for (double r : radii)
        for (int t = 0; t < o.tilts; ++t) {
          const double tilt = o.tilts == 1 ? 0.0
                                           : (-1.0 + 2.0 * t / (o.tilts - 1)) * o.max_tilt_deg *
                                                 std::numbers::pi / 180.0;
          std::fill(hints.begin(), hints.end(), -1);
          for (int d = 0; d < o.directions; ++d) {
            const double th = std::numbers::pi * d / o.directions;
            const Vec3 tangent = std::cos(th) * seed.dir_min + std::sin(th) * seed.dir_max;
            const Vec3 u = std::cos(tilt) * tangent + std::sin(tilt) * seed.normal;
            const Vec3 mid = seed.point + r * seed.normal;
            LineCandidate c;
            c.line = {mid - 0.5 * L * u, mid + 0.5 * L * u};
            c.kind = kind;
            c.seed = seed_id;
            // Warm start from the previous direction's footpoints: neighbours share faces.
            c.movability = movability(index, c.line.a, c.line.b, coarse, hints);
            ++*scored;
            if (!acceptable(c.movability, R, L)) continue;
            c.score = line_score(c.movability, L);
            c.inside = inside_length(c.movability, L);
            c.good = good(c);
            all.push_back(c);
          }
        }
    // Stable order, so ties never depend on anything but generation order.
    std::stable_sort(all.begin(), all.end(), better);
    if (static_cast<int>(all.size()) > o.fine_candidates) all.resize(static_cast<std::size_t>(o.fine_candidates));
    MovabilityOptions fine = coarse;
    fine.samples = o.fine_samples;
    for (LineCandidate& c : all) {
      c.movability = movability(index, c.line.a, c.line.b, fine);
      ++*scored;
      const double L = c.line.length();
      c.score = acceptable(c.movability, R, L) ? line_score(c.movability, L)
                                               : std::numeric_limits<double>::infinity();
      c.inside = inside_length(c.movability, L);
      c.good = std::isfinite(c.score) && good(c);
    }
    std::stable_sort(all.begin(), all.end(), better);
    for (const LineCandidate& c : all)
      if (std::isfinite(c.score)) best.push_back(c);
  }
  std::stable_sort(best.begin(), best.end(), better);
  // The paper's local search (Fig. 8): first spanning Φ's width along the line, then at the
  // shorter allowed lengths: the grid of directions is coarse, and the longest line that
  // still sweeps covers most.
  auto polish = [&](LineCandidate c) {
    const Line spanning = span_width(index, c.line, R);
    const Vec3 u = (spanning.b - spanning.a).normalized(), mid = 0.5 * (spanning.a + spanning.b);
    std::vector<double> ladder{spanning.length()};
    for (double L : lengths)
      if (L < 0.95 * ladder.front()) ladder.push_back(L);
    RefineLineOptions ro;
    ro.kind = c.kind;
    ro.movability.samples = o.fine_samples;
    ro.candidates_per_end = 9;
    ro.rounds = 5;  // down to 1/16 of the first radius: the hole is ~0.2 mm wide
    ro.profile_weight = kProfileWeight;
    LineCandidate first;
    for (double L : ladder) {
      LineCandidate t = c;
      const RefinedLine r = refine_line(index, {mid - 0.5 * L * u, mid + 0.5 * L * u}, ro);
      *scored += r.evaluated;
      t.line = r.line;
      t.movability = r.movability;
      t.score = acceptable(r.movability, R, L) ? line_score(r.movability, L)
                                               : std::numeric_limits<double>::infinity();
      t.good = std::isfinite(t.score) && good(t);
      if (L == ladder.front()) first = t;
      if (t.good) return t;
      if (L == ladder.back()) return std::isfinite(first.score) ? first : t;
    }
    return c;
  };
  // Kept: distinct lines by rank, polished, that sweep. A second line within 20° of a kept one
  // and of about its radius grows the same patch; another radius may not (the radius ↔ offset
  // valley hides the radius locally; only growing tells which one sweeps the whole part).
  std::vector<LineCandidate> kept;
  int attempts = 0;
  for (const LineCandidate& c : best) {
    if (static_cast<int>(kept.size()) >= o.lines_per_seed || attempts >= 3 * o.lines_per_seed) break;
    const Vec3 u = (c.line.b - c.line.a).normalized();
    bool distinct = true;
    for (const LineCandidate& k : kept) {
      const bool same_dir =
          std::abs(u.dot((k.line.b - k.line.a).normalized())) >= std::cos(20.0 * std::numbers::pi / 180.0);
      const double ra = c.movability.cutter.radius(0.5), rb = k.movability.cutter.radius(0.5);
      const bool same_radius = std::abs(ra - rb) <= 0.2 * std::max(ra, rb);
      distinct &= !(same_dir && same_radius);
    }
    if (!distinct) continue;
    // Lines that do not sweep yet (ranked after those that do) get fewer tries: the local
    // search rarely turns them into rulings, and with a tolerance nothing meets they are all.
    if (!c.good && attempts >= o.lines_per_seed) break;
    ++attempts;
    LineCandidate p = polish(c);
    // A line that cannot sweep a few millimetres is no ruling: a barrel-like profile also
    // fits the curved distances of a chord along the part's long direction, and only moving
    // the line tells them apart.
    if (!std::isfinite(p.score)) continue;
    p.swept = sweep_probe(index, p.line, o);
    if (std::getenv("FLANK_TRACE_DECOMPOSE"))
      std::fprintf(stderr, "seed %d line: kind %s, L %.2f, F_l %.2e, profile rms %.2e, swept %.2f\n", seed_id,
                   std::string(to_string(p.kind)).c_str(), p.line.length(), p.movability.value, p.movability.profile_rms, p.swept);
    if (p.swept >= 0.9 * kProbe * index.diagonal()) kept.push_back(p);
  }
  std::stable_sort(kept.begin(), kept.end(),
                   [](const LineCandidate& x, const LineCandidate& y) { return x.swept > y.swept; });
  return kept;
}

struct Grown {
  bool ok = false;
  Patch patch;
};

Grown grow(const SurfaceIndex& index, const LineCandidate& c, const DecomposeOptions& o,
           const Ranges& R) {
  Grown g;
  const Propagation prop = propagate(index, c.line, propagate_options(index, o));
  if (prop.rulings.size() < 8) return g;
  const Motion init = Motion::fit(prop.rulings, o.control_points);
  FitPatchOptions fo;
  fo.fit.kind = c.kind;
  fo.fit.control_points = o.control_points;
  fo.fit.max_iterations = o.fit_iterations;
  fo.tolerance = o.tolerance;
  const FitPatchResult fit = fit_and_trim(index, init, fo);
  if (fit.status != FitPatchStatus::ok) return g;
  EvaluateOptions eo;
  eo.tolerance = o.tolerance;
  eo.holder = o.holder;
  eo.holder_length = o.holder_length;
  eo.holder_radius = o.holder_radius;
  g.patch = evaluate_patch(index, fit.fit.motion, fit.fit.cutter, eo);
  // A patch that gouges anywhere along the whole cutter, or whose holder hits Φ, is no patch.
  double rmin = std::numeric_limits<double>::infinity(), rmax = 0.0;
  for (int k = 0; k <= 20; ++k) {
    rmin = std::min(rmin, g.patch.cutter.radius(k / 20.0));
    rmax = std::max(rmax, g.patch.cutter.radius(k / 20.0));
  }
  g.ok = g.patch.error.max_gouge <= o.tolerance && (!o.holder || g.patch.collision.holder_clear) &&
         !g.patch.covered_vertices.empty() && rmin >= R.r0 && rmax <= R.r1 &&
         g.patch.cutter.length >= 0.5 * R.l0;
  if (std::getenv("FLANK_TRACE_DECOMPOSE"))
    std::fprintf(stderr,
                 "grow seed %d L %.2f r %.3f..%.3f F %.2e | rulings %zu stops %s / %s | cutter L %.2f r %.3f..%.3f "
                 "cov %.3f max %.2e gouge %.2e ok %d\n",
                 c.seed, c.line.length(), c.movability.radius_min, c.movability.radius_max, c.movability.value,
                 prop.rulings.size(), to_string(prop.stop_backward), to_string(prop.stop_forward),
                 g.patch.cutter.length, rmin, rmax, g.patch.coverage_fraction, g.patch.error.max,
                 g.patch.error.max_gouge, g.ok);
  return g;
}

struct Cover {
  std::vector<int> vertex_patch;
  std::vector<char> used;
  double covered_area = 0.0;
  std::vector<int> picks;  // pool indices, in the order chosen
};

// Greedy cover: most newly covered area; ties lower error, then lower pool index. Picks get
// ids from `first_id` on.
void greedy_cover(const std::vector<Patch>& pool, const VecX& area, const DecomposeOptions& o,
                  double total_area, int first_id, Cover* c) {
  for (;;) {
    const int id = first_id + static_cast<int>(c->picks.size());
    if (id >= o.max_patches) break;
    if (c->covered_area >= o.coverage_target * total_area) break;
    int pick = -1;
    double best_gain = 0.0;
    for (std::size_t k = 0; k < pool.size(); ++k) {
      if (c->used[k]) continue;
      double gain = 0.0;
      for (int v : pool[k].covered_vertices)
        if (c->vertex_patch[v] < 0) gain += area(v);
      const bool better = pick < 0 || gain > best_gain ||
                          (gain == best_gain && pool[k].error.max < pool[static_cast<std::size_t>(pick)].error.max);
      if (better) pick = static_cast<int>(k), best_gain = gain;
    }
    if (pick < 0 || best_gain < o.min_gain * total_area) break;
    c->used[static_cast<std::size_t>(pick)] = 1;
    for (int v : pool[static_cast<std::size_t>(pick)].covered_vertices)
      if (c->vertex_patch[v] < 0) c->vertex_patch[v] = id, c->covered_area += area(v);
    c->picks.push_back(pick);
  }
}

std::vector<UncoveredRegion> uncovered_regions(const Mesh& mesh, const std::vector<int>& vertex_patch,
                                               const VecX& area) {
  const int V = mesh.vertex_count();
  std::vector<int> parent(static_cast<std::size_t>(V));
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (int f = 0; f < mesh.face_count(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.F(f, k), b = mesh.F(f, (k + 1) % 3);
      if (vertex_patch[a] < 0 && vertex_patch[b] < 0) parent[find(a)] = find(b);
    }
  std::vector<UncoveredRegion> regions;
  std::vector<int> slot(static_cast<std::size_t>(V), -1);
  for (int v = 0; v < V; ++v) {
    if (vertex_patch[v] >= 0) continue;
    const int r = find(v);
    if (slot[r] < 0) {
      slot[r] = static_cast<int>(regions.size());
      regions.emplace_back();
    }
    UncoveredRegion& u = regions[static_cast<std::size_t>(slot[r])];
    u.area += area(v);
    u.centroid += area(v) * mesh.V.row(v).transpose();
    ++u.vertices;
  }
  for (UncoveredRegion& u : regions)
    if (u.area > 0) u.centroid /= u.area;
  std::stable_sort(regions.begin(), regions.end(),
                   [](const UncoveredRegion& a, const UncoveredRegion& b) { return a.area > b.area; });
  return regions;
}

}  // namespace

DecomposeResult decompose(const SurfaceIndex& index, const DecomposeOptions& o,
                          const ProgressFn& progress) {
  auto say = [&](const std::string& s) {
    if (progress) progress(s);
  };
  DecomposeResult out;
  const Mesh& mesh = index.mesh();
  const double diagonal = index.diagonal();
  const Ranges R = resolve_ranges(o, diagonal);
  const VecX area = vertex_areas(mesh);
  out.total_area = area.sum();
  out.vertex_patch.assign(static_cast<std::size_t>(mesh.vertex_count()), -1);

  std::vector<Patch> pool;  // every valid candidate patch so far, in a deterministic order
  std::vector<char> used;
  std::vector<Line> grown_lines;  // every line grown so far
  for (int round = 0; round < o.max_rounds; ++round) {
    const std::size_t patches_before = out.patches.size();
    // 1. Seeds: over all of Φ first, then over what is still uncovered.
    auto t0 = Clock::now();
    SeedOptions so;
    so.spacing = 0.5 * R.l1;
    if (round > 0) {
      so.allowed.assign(static_cast<std::size_t>(mesh.vertex_count()), 0);
      for (int v = 0; v < mesh.vertex_count(); ++v) so.allowed[v] = out.vertex_patch[v] < 0;
    }
    const std::vector<Seed> seeds = seed_tiles(mesh, so);
    out.times.seeds += since(t0);
    out.seeds += static_cast<int>(seeds.size());
    if (seeds.empty()) break;

    // 2. Candidate lines, one task per seed; per-seed results keep the order deterministic.
    t0 = Clock::now();
    std::vector<std::vector<LineCandidate>> per_seed(seeds.size());
    std::vector<long long> scored(seeds.size(), 0);
    parallel_invoke_each(seeds.size(), [&](std::size_t s) {
      per_seed[s] = seed_candidates(index, seeds[s], static_cast<int>(s), o, R, &scored[s]);
    });
    std::vector<LineCandidate> lines;
    for (std::size_t s = 0; s < seeds.size(); ++s) {
      out.lines_scored += scored[s];
      lines.insert(lines.end(), per_seed[s].begin(), per_seed[s].end());
    }
    std::stable_sort(lines.begin(), lines.end(), [&](const LineCandidate& x, const LineCandidate& y) {
      if (x.good != y.good) return x.good;
      // Farther in the probe first, to 1% of it: a ruling of the part sweeps on, others stall.
      const double q = 0.01 * kProbe * diagonal;
      if (std::floor(x.swept / q) != std::floor(y.swept / q)) return x.swept > y.swept;
      if (x.good && std::abs(x.line.length() - y.line.length()) > 1e-9)
        return x.line.length() > y.line.length();
      return x.score < y.score;
    });
    // A line grown in an earlier round grows the same patch again: skip it.
    std::erase_if(lines, [&](const LineCandidate& c) {
      return std::any_of(grown_lines.begin(), grown_lines.end(), [&](const Line& l) {
        return (l.a - c.line.a).norm() + (l.b - c.line.b).norm() <= 1e-9 * diagonal;
      });
    });
    if (static_cast<int>(lines.size()) > o.max_grown_per_round)
      lines.resize(static_cast<std::size_t>(o.max_grown_per_round));
    for (const LineCandidate& c : lines) grown_lines.push_back(c.line);
    out.times.candidates += since(t0);
    say("round " + std::to_string(round + 1) + ": " + std::to_string(seeds.size()) + " seeds, " +
        std::to_string(out.lines_scored) + " lines scored, growing " + std::to_string(lines.size()));

    // 3–4. Grow and fit the lines concurrently, in batches of kBatch in rank order (one task
    // each), and cover greedily. When the candidates so far already reach the coverage
    // target, the rest are not grown: on a single envelope the first batch holds the patch.
    // The batch size is fixed, so the result does not depend on the thread count.
    constexpr std::size_t kBatch = 4;
    for (std::size_t begin = 0;; begin += kBatch) {  // once at least, to cover from the pool
      t0 = Clock::now();
      const std::size_t end = std::min(lines.size(), begin + kBatch);
      std::vector<Grown> grown(end - begin);
      parallel_invoke_each(grown.size(), [&](std::size_t k) { grown[k] = grow(index, lines[begin + k], o, R); });
      for (Grown& g : grown) {
        ++out.grown;
        if (!g.ok) continue;
        ++out.candidates_valid;
        pool.push_back(std::move(g.patch));
        used.push_back(0);
      }
      out.times.fit += since(t0);
      say("round " + std::to_string(round + 1) + ": grown " + std::to_string(end) + " of " +
          std::to_string(lines.size()) + ", " + std::to_string(out.candidates_valid) +
          " candidate patches within tolerance so far");
      t0 = Clock::now();
      Cover trial{out.vertex_patch, used, out.covered_area, {}};
      greedy_cover(pool, area, o, out.total_area, static_cast<int>(out.patches.size()), &trial);
      const bool last = end == lines.size();
      if (last || trial.covered_area >= o.coverage_target * out.total_area) {
        out.vertex_patch = std::move(trial.vertex_patch);
        used = std::move(trial.used);
        out.covered_area = trial.covered_area;
        for (int k : trial.picks) {
          Patch p = pool[static_cast<std::size_t>(k)];
          p.id = static_cast<int>(out.patches.size());
          out.patches.push_back(std::move(p));
        }
        out.times.cover += since(t0);
        break;
      }
      out.times.cover += since(t0);
    }
    out.rounds = round + 1;
    out.coverage = out.total_area > 0 ? out.covered_area / out.total_area : 0.0;
    say("round " + std::to_string(round + 1) + ": " + std::to_string(out.patches.size()) +
        " patches cover " + std::to_string(100.0 * out.coverage) + "%");
    if (out.coverage >= o.coverage_target || static_cast<int>(out.patches.size()) >= o.max_patches) break;
    // Nothing new covered: the next round would seed the same uncovered area the same way.
    if (out.patches.size() == patches_before) break;
  }
  out.uncovered = uncovered_regions(mesh, out.vertex_patch, area);
  return out;
}

}  // namespace flank
