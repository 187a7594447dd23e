#include "solver/decompose.h"

#include <algorithm>
#include <chrono>
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
  CutterKind kind = CutterKind::cone;
  double score = std::numeric_limits<double>::infinity();
  Movability movability;
  int seed = 0;
  bool good = false;
};

double line_score(const Movability& m, double L) {
  const double misfit = m.profile_rms / L;
  return m.value + misfit * misfit;
}

bool acceptable(const Movability& m, const Ranges& R, double L) {
  return m.ok() && m.max_slope < 0.9 * L && m.radius_min >= R.r0 && m.radius_max <= R.r1;
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
  for (CutterKind kind : o.kinds) {
    MovabilityOptions coarse;
    coarse.samples = o.coarse_samples;
    coarse.profile = kind;
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
            all.push_back(c);
          }
        }
    // Stable order: score, then generation order, so ties never depend on anything else.
    std::stable_sort(all.begin(), all.end(),
                     [](const LineCandidate& x, const LineCandidate& y) { return x.score < y.score; });
    if (static_cast<int>(all.size()) > o.fine_candidates) all.resize(static_cast<std::size_t>(o.fine_candidates));
    MovabilityOptions fine = coarse;
    fine.samples = o.fine_samples;
    for (LineCandidate& c : all) {
      c.movability = movability(index, c.line.a, c.line.b, fine);
      ++*scored;
      const double L = c.line.length();
      c.score = acceptable(c.movability, R, L) ? line_score(c.movability, L)
                                               : std::numeric_limits<double>::infinity();
    }
    std::stable_sort(all.begin(), all.end(),
                     [](const LineCandidate& x, const LineCandidate& y) { return x.score < y.score; });
    for (const LineCandidate& c : all) {
      if (!std::isfinite(c.score)) break;
      best.push_back(c);
    }
  }
  // A line that sweeps (F_l tiny) with a profile its cutter can follow is a patch in waiting.
  auto good = [&](const LineCandidate& c) {
    // The fit corrects a line a degree or two off, so "good" asks for the right shape of
    // profile, not already the tolerance: the fit and trim decide the final quality.
    return c.movability.ok() && c.movability.value <= o.good_movability &&
           c.movability.profile_rms <= 4.0 * o.tolerance;
  };
  // Distinct directions by score: a second line within 20° of a kept one grows the same patch.
  std::vector<LineCandidate> kept;
  for (const LineCandidate& c : best) {
    // Distinct: another direction, or another radius (the radius ↔ offset valley makes the
    // radius invisible locally; only growing tells which one sweeps the whole part).
    const Vec3 u = (c.line.b - c.line.a).normalized();
    bool distinct = true;
    for (const LineCandidate& k : kept) {
      const bool same_dir =
          std::abs(u.dot((k.line.b - k.line.a).normalized())) >= std::cos(20.0 * std::numbers::pi / 180.0);
      const double ra = c.movability.cutter.radius(0.5), rb = k.movability.cutter.radius(0.5);
      const bool same_radius = std::abs(ra - rb) <= 0.2 * std::max(ra, rb);
      distinct &= !(same_dir && same_radius);
    }
    if (distinct) kept.push_back(c);
    if (static_cast<int>(kept.size()) >= o.lines_per_seed) break;
  }
  // The paper's local search (Fig. 8) on each, at the allowed lengths from the longest down:
  // the grid of directions is coarse, and the longest line that still sweeps covers most.
  for (LineCandidate& c : kept) {
    const Vec3 u = (c.line.b - c.line.a).normalized(), mid = 0.5 * (c.line.a + c.line.b);
    RefineLineOptions ro;
    ro.kind = c.kind;
    ro.movability.samples = o.fine_samples;
    ro.candidates_per_end = 9;
    ro.rounds = 3;
    LineCandidate first;
    for (double L : lengths) {
      LineCandidate t = c;
      const RefinedLine r = refine_line(index, {mid - 0.5 * L * u, mid + 0.5 * L * u}, ro);
      *scored += r.evaluated;
      t.line = r.line;
      t.movability = r.movability;
      t.score = acceptable(r.movability, R, L) ? line_score(r.movability, L)
                                               : std::numeric_limits<double>::infinity();
      t.good = std::isfinite(t.score) && good(t);
      if (L == lengths.front()) first = t;
      if (t.good) {
        c = t;
        break;
      }
      if (L == lengths.back()) c = std::isfinite(first.score) ? first : t;
    }
  }
  kept.erase(std::remove_if(kept.begin(), kept.end(),
                            [](const LineCandidate& c) { return !std::isfinite(c.score); }),
             kept.end());
  return kept;
}

struct Grown {
  bool ok = false;
  Patch patch;
};

Grown grow(const SurfaceIndex& index, const LineCandidate& c, const DecomposeOptions& o,
           const Ranges& R) {
  Grown g;
  // A sweep drifts from Φ by about √F_l per unit of travel: to stay within tolerance over a
  // sweep of half the diagonal, F_l must stay below (tol / (diagonal/2))²; 20× that leaves the
  // fit room to correct.
  PropagateOptions po;
  const double rel = o.tolerance / (0.5 * index.diagonal());
  po.max_movability = std::min(po.max_movability, 400.0 * rel * rel);
  const Propagation prop = propagate(index, c.line, po);
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
  return g;
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
  for (int round = 0; round < o.max_rounds; ++round) {
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
    std::stable_sort(lines.begin(), lines.end(), [](const LineCandidate& x, const LineCandidate& y) {
      if (x.good != y.good) return x.good;
      if (x.good && std::abs(x.line.length() - y.line.length()) > 1e-9)
        return x.line.length() > y.line.length();
      return x.score < y.score;
    });
    if (static_cast<int>(lines.size()) > o.max_grown_per_round)
      lines.resize(static_cast<std::size_t>(o.max_grown_per_round));
    out.times.candidates += since(t0);
    say("round " + std::to_string(round + 1) + ": " + std::to_string(seeds.size()) + " seeds, " +
        std::to_string(out.lines_scored) + " lines scored, growing " + std::to_string(lines.size()));

    // 3. Grow and fit all candidates concurrently, one task each.
    t0 = Clock::now();
    std::vector<Grown> grown(lines.size());
    parallel_invoke_each(lines.size(), [&](std::size_t k) { grown[k] = grow(index, lines[k], o, R); });
    for (Grown& g : grown) {
      ++out.grown;
      if (!g.ok) continue;
      ++out.candidates_valid;
      pool.push_back(std::move(g.patch));
      used.push_back(0);
    }
    out.times.fit += since(t0);
    say("round " + std::to_string(round + 1) + ": " + std::to_string(out.candidates_valid) +
        " candidate patches within tolerance so far");

    // 4. Greedy cover: most newly covered area; ties lower error, then lower id.
    t0 = Clock::now();
    for (;;) {
      if (static_cast<int>(out.patches.size()) >= o.max_patches) break;
      if (out.covered_area >= o.coverage_target * out.total_area) break;
      int pick = -1;
      double best_gain = 0.0;
      for (std::size_t k = 0; k < pool.size(); ++k) {
        if (used[k]) continue;
        double gain = 0.0;
        for (int v : pool[k].covered_vertices)
          if (out.vertex_patch[v] < 0) gain += area(v);
        const bool better = pick < 0 || gain > best_gain ||
                            (gain == best_gain && pool[k].error.max < pool[pick].error.max);
        if (better) pick = static_cast<int>(k), best_gain = gain;
      }
      if (pick < 0 || best_gain < o.min_gain * out.total_area) break;
      used[pick] = 1;
      Patch p = pool[pick];
      p.id = static_cast<int>(out.patches.size());
      for (int v : p.covered_vertices)
        if (out.vertex_patch[v] < 0) out.vertex_patch[v] = p.id, out.covered_area += area(v);
      out.patches.push_back(std::move(p));
    }
    out.times.cover += since(t0);
    out.rounds = round + 1;
    out.coverage = out.total_area > 0 ? out.covered_area / out.total_area : 0.0;
    say("round " + std::to_string(round + 1) + ": " + std::to_string(out.patches.size()) +
        " patches cover " + std::to_string(100.0 * out.coverage) + "%");
    if (out.coverage >= o.coverage_target || static_cast<int>(out.patches.size()) >= o.max_patches) break;
  }
  out.uncovered = uncovered_regions(mesh, out.vertex_patch, area);
  return out;
}

}  // namespace flank
