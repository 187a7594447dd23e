#include "solver/grow_patch.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>

#include "kernels/mesh.h"

namespace flank {

std::string GrowOptions::validate() const {
  if (std::string e = fit.validate(); !e.empty()) return e;
  if (std::string e = thresholds.validate(); !e.empty()) return e;
  if (trim_rounds < 0) return "trim rounds must not be negative";
  if (refit_iterations < 0) return "refit iterations must not be negative";
  if (length_min < 0) return "the minimum length must not be negative";
  return {};
}

std::string reject_reason(const Patch& p, const GrowOptions& o) {
  if (p.covered_vertices.empty()) return "covers nothing";
  if (p.error.judged_gouge > o.thresholds.gouge) return "gouges";
  if (o.evaluate.holder && !p.collision.holder_clear) return "holder collides";
  if (!p.cutter.valid()) return "invalid cutter";
  if (p.cutter.length < o.length_min * (1.0 - 1e-9)) return "cutter shorter than allowed";
  constexpr double kSlack = 1e-9;
  const double lo = o.fit.radius_min, hi = o.fit.radius_max;
  for (int k = 0; k <= 100; ++k) {
    const double r = p.cutter.radius(k / 100.0);
    if ((lo > 0 && r < lo * (1 - kSlack)) || (hi > 0 && r > hi * (1 + kSlack))) return "radius out of range";
  }
  return {};
}

namespace {

// Trim the fitted motion to pieces that keep the cutter within the allowed lengths.
FitPatchOptions trim_options(const GrowOptions& o, double length) {
  FitPatchOptions fo;
  fo.fit = o.fit;
  fo.fit.length = length;
  fo.tolerance = o.thresholds.tolerance;
  fo.max_rounds = o.trim_rounds;
  fo.refit_below = o.refit_below;
  fo.refit_iterations = o.refit_iterations;
  fo.pieces = o.pieces;
  fo.untrusted_edges = o.given != nullptr;
  if (length > 0 && o.length_min > 0)
    fo.pieces.min_cols = std::max(fo.pieces.min_cols,
                                  static_cast<int>(std::ceil((o.fit.samples_s - 1) * o.length_min / length)) + 1);
  return fo;
}

Patch evaluate(const SurfaceIndex& index, const FitResult& fit, const GrowOptions& o) {
  EvaluateOptions eo = o.evaluate;
  eo.tolerance = o.thresholds.tolerance;
  eo.coverage = true;
  eo.untrusted_edges = o.given != nullptr;
  return evaluate_patch(index, fit.motion, fit.cutter, eo, o.given);
}

void trace_piece(const GrowOptions& o, const LineCandidate& c, int piece, const FitPatchResult& fit,
                 const Patch* p, const std::string& why) {
  if (!o.trace) return;
  char line[320];
  if (!p) {
    std::snprintf(line, sizeof line, "grow seed %d L %.2f piece %d: %s", c.seed, c.line.length(), piece,
                  fit.message.c_str());
  } else {
    std::snprintf(line, sizeof line,
                  "grow seed %d L %.2f est %.4g piece %d: %s L %.2f r %.3f..%.3f trims %d, covers %.2f%%, "
                  "max |e| %.2e, gouge %.2e: %s",
                  c.seed, c.line.length(), c.estimate, piece, std::string(to_string(p->cutter.kind)).c_str(),
                  p->cutter.length, p->cutter.radius(0), p->cutter.radius(1), fit.rounds,
                  100.0 * p->coverage_fraction, p->error.max, p->error.max_gouge, why.empty() ? "kept" : why.c_str());
  }
  o.trace(line);
}

}  // namespace

Grown grow_patch(const SurfaceIndex& index, const LineCandidate& c, const GrowOptions& o) {
  const auto start = std::chrono::steady_clock::now();
  Grown out;
  if (c.sweep.rulings.size() < 4) return out;
  const int K = o.fit.control_points > 0 ? o.fit.control_points : 16;
  const Motion init = Motion::fit(c.sweep.rulings, K);
  FitPatchOptions fo = trim_options(o, c.line.length());
  fo.fit.kind = c.kind;
  fo.keep_pieces = true;
  const FitPatchResult first = fit_and_trim(index, init, fo);
  std::vector<FitPatchResult> fits{first};
  fo.keep_pieces = false;
  for (const PieceStart& piece : first.other_pieces) {
    FitPatchOptions po = trim_options(o, piece.cutter.length);
    po.fit.kind = c.kind;
    if (o.refit_iterations > 0) po.fit.max_iterations = o.refit_iterations;
    fits.push_back(fit_and_trim(index, piece.motion, po, &piece.cutter));
  }

  for (std::size_t k = 0; k < fits.size(); ++k) {
    ++out.pieces;
    if (fits[k].status != FitPatchStatus::ok) {
      trace_piece(o, c, static_cast<int>(k), fits[k], nullptr, {});
      continue;
    }
    Patch p = evaluate(index, fits[k].fit, o);
    const std::string why = reject_reason(p, o);
    trace_piece(o, c, static_cast<int>(k), fits[k], &p, why);
    if (why.empty()) out.patches.push_back(std::move(p));
  }
  std::stable_sort(out.patches.begin(), out.patches.end(),
                   [](const Patch& a, const Patch& b) { return a.covered_area > b.covered_area; });
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

std::optional<Patch> finish_patch(const SurfaceIndex& index, const Patch& patch, const FinishOptions& o) {
  const GrowOptions& g = o.grow;
  Motion motion = patch.motion;
  Cutter cutter = patch.cutter;
  // A simpler kind whose least-squares radii stay within thresholds.simplify of the fitted ones
  // is refitted from the fitted motion (refit_iterations: it starts near an optimum), which
  // moves to absorb the difference: a barrel off in the radius ↔ offset valley of a cone's
  // envelope comes back as the cone. It is kept when it covers as much (99% of the area) of
  // the same surface (97% of the fitted kind's area: a refit moves Ω's edge, and on the exact
  // cone part the cone itself covers 98.7% of the spline's vertices). A cylinder that covered
  // 6% more of a blade face, but only 93% of the barrel's, left a patch of the cover adding
  // too little to keep: 1.3 points lost.
  std::vector<double> s(101), r(101);
  for (int k = 0; k <= 100; ++k) s[k] = k / 100.0, r[k] = cutter.radius(s[k]);
  VecX area;
  std::vector<char> covered;
  for (CutterKind kind : o.simpler) {
    if (coefficient_count(kind) >= coefficient_count(cutter.kind)) break;
    const Cutter simple = Cutter::fit(kind, cutter.length, s, r);
    double worst = 0.0;
    for (int k = 0; k <= 100; ++k) worst = std::max(worst, std::abs(simple.radius(s[k]) - r[k]));
    if (worst > g.thresholds.simplify) continue;
    auto trace = [&](const std::string& outcome) {
      if (!g.trace) return;
      char line[320];
      std::snprintf(line, sizeof line, "finish %s L %.2f r %.3f..%.3f as %s (least-squares radii off by %.3g): %s",
                    std::string(to_string(cutter.kind)).c_str(), cutter.length, cutter.radius(0), cutter.radius(1),
                    std::string(to_string(kind)).c_str(), worst, outcome.c_str());
      g.trace(line);
    };
    FitPatchOptions so = trim_options(g, cutter.length);
    so.fit.kind = kind;
    if (g.refit_iterations > 0) so.fit.max_iterations = g.refit_iterations;
    const FitPatchResult refit = fit_and_trim(index, motion, so, &simple);
    if (refit.status != FitPatchStatus::ok) {
      trace(refit.message);
      continue;
    }
    const Patch p = evaluate(index, refit.fit, g);
    if (covered.empty()) {
      const Mesh& phi = (g.given ? g.given : &index)->mesh();
      area = vertex_areas(phi);
      covered.assign(static_cast<std::size_t>(phi.V.rows()), 0);
      for (int v : patch.covered_vertices) covered[static_cast<std::size_t>(v)] = 1;
    }
    double same = 0.0;
    for (int v : p.covered_vertices) same += covered[static_cast<std::size_t>(v)] ? area(v) : 0.0;
    const std::string why = reject_reason(p, g);
    const bool keep = why.empty() && p.covered_area >= 0.99 * patch.covered_area && same >= 0.97 * patch.covered_area;
    if (g.trace) {
      char covers[160];
      std::snprintf(covers, sizeof covers, "r %.3f..%.3f covers %.1f%% as much, %.1f%% of the same",
                    refit.fit.cutter.radius(0), refit.fit.cutter.radius(1), 100.0 * p.covered_area / patch.covered_area,
                    100.0 * same / patch.covered_area);
      trace(std::string(covers) + (!why.empty() ? ": " + why : keep ? ": kept" : ""));
    }
    if (keep) {
      motion = refit.fit.motion;
      cutter = refit.fit.cutter;
      break;
    }
  }
  EvaluateOptions eo = o.evaluate;
  eo.tolerance = g.thresholds.tolerance;
  eo.coverage = true;
  eo.untrusted_edges = g.given != nullptr;
  // The fine grid sees what the fit's coarse one missed: a fold where the motion turns, or a
  // corner out of tolerance. Cut to its best rectangle (no refit: the fit is done) so that the
  // patch holds only what it cuts within tolerance.
  // A cut motion is a new spline, sampled anew: repeat until its grid holds nothing out of
  // tolerance (a few rounds at most; what still fails is no patch).
  constexpr int kFineTrims = 4;
  ErrorGrid grid;
  for (int round = 0;; ++round) {
    const auto [rows, cols] = evaluation_grid(motion, cutter, eo);
    grid = sample_errors(index, motion, cutter, rows, cols, eo.untrusted_edges);
    PieceOptions po = g.pieces;
    if (cutter.length > 0 && g.length_min > 0)
      po.min_cols = std::max(po.min_cols, static_cast<int>(std::ceil((cols - 1) * g.length_min / cutter.length)) + 1);
    const TrimRange range = find_trim(grid, g.thresholds.tolerance, po);
    if (range.empty) return std::nullopt;
    if (range.full(grid)) break;
    if (round == kFineTrims) return std::nullopt;
    const PieceStart cut = restrict_to(motion, cutter, range, grid, g.fit.radius_min, g.fit.radius_max);
    motion = cut.motion;
    cutter = cut.cutter;
  }
  Patch p = evaluate_patch(index, motion, cutter, eo, g.given, &grid);
  if (!reject_reason(p, g).empty()) return std::nullopt;
  return p;
}

}  // namespace flank
