#include "solver/candidate_lines.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <numeric>
#include <optional>

#include "kernels/parallel.h"

namespace flank {

std::string CandidateLineOptions::validate() const {
  if (kinds.empty()) return "at least one cutter kind is needed";
  if (!(radius_min > 0) || !(radius_max >= radius_min) || !std::isfinite(radius_max))
    return "the radius range needs 0 < MIN <= MAX";
  if (!(length_min > 0) || !(length_max >= length_min) || !std::isfinite(length_max))
    return "the length range needs 0 < MIN <= MAX";
  if (directions < 1 || tilts < 1 || radii < 1 || lengths < 1 || directions_kept < 1)
    return "candidate counts must be positive";
  if (coarse_samples < 4 || fine_samples < 4) return "movability needs at least 4 samples per line";
  if (fine_candidates < 1) return "at least one line per seed must be rescored";
  if (!(overhang >= 0 && overhang < 0.5)) return "overhang must be in [0, 0.5)";
  if (refine_rounds < 0 || refine_candidates < 1) return "local search settings out of range";
  if (!(step > 0) || !(max_travel > 0)) return "the probe sweep needs a positive step and travel";
  return {};
}

namespace {

// F_l alone is a narrow hole: on an exact envelope it is ~1e-9 on the ruling and ~5e-6
// already 0.2 mm off it, flat beyond. The misfit of the cutter profile grows linearly with
// the offset instead (about 0.014 mm per mm on the paper's part), so weighted in it leads a
// local search into the hole from millimetres away.
constexpr double kProfileWeight = 1e3;

double line_score(const Movability& m, double L) {
  const double misfit = m.profile_rms / L;
  return m.value + kProfileWeight * misfit * misfit;
}

// Values spread geometrically over [lo, hi], the top first.
std::vector<double> geometric(double lo, double hi, int count) {
  std::vector<double> v;
  for (int k = 0; k < count; ++k) {
    const double f = count == 1 ? 1.0 : 1.0 - static_cast<double>(k) / (count - 1);
    v.push_back(lo * std::pow(hi / lo, f));
  }
  return v;
}

// A line's cutter is a real tool: its sphere radii fit the allowed range and its meridian is
// valid, with some slack where the fit will correct the line.
bool acceptable(const Movability& m, const CandidateLineOptions& o, double L) {
  return m.ok() && m.max_slope < 0.9 * L && m.radius_min >= 0.9 * o.radius_min &&
         m.radius_max <= 1.1 * o.radius_max;
}

// The length of a line laid across a free run: the run with the overhang past both ends,
// within the allowed lengths.
double laid_length(const FreeRun& run, const CandidateLineOptions& o) {
  return std::clamp((run.low + run.high) * (1.0 + 2.0 * o.overhang), o.length_min, o.length_max);
}

struct Scored {
  Line line;
  Movability movability;
  double score = std::numeric_limits<double>::infinity();         // with the first steering profile
  double second_score = std::numeric_limits<double>::infinity();  // with the second
};

}  // namespace

void rank_candidates(std::vector<LineCandidate>& lines, const CoveredFaces& covered) {
  for (LineCandidate& lc : lines) {
    lc.sweep.fresh = fresh_fractions(lc.sweep, &covered);
    // The area still to cut that the sweep passes over: per step, the length over uncovered Φ
    // times the travel across the line (a line that turns as it sweeps travels farther than
    // it sweeps).
    lc.swept = lc.estimate = 0.0;
    for (std::size_t r = 1; r < lc.sweep.rulings.size(); ++r) {
      const Line& p = lc.sweep.rulings[r - 1];
      const Line& q = lc.sweep.rulings[r];
      const Vec3 step = 0.5 * (q.a + q.b) - 0.5 * (p.a + p.b);
      const Vec3 along = (q.b - q.a).normalized();
      const double across = (step - step.dot(along) * along).norm();
      lc.swept += across;
      lc.estimate += across * q.length() * 0.5 * (lc.sweep.fresh[r - 1] + lc.sweep.fresh[r]);
    }
  }
  std::sort(lines.begin(), lines.end(), [](const LineCandidate& x, const LineCandidate& y) { return x.order < y.order; });
  std::stable_sort(lines.begin(), lines.end(),
                   [](const LineCandidate& x, const LineCandidate& y) { return x.estimate > y.estimate; });
}

FreeRun free_run(const SurfaceIndex& index, const Vec3& mid, const Vec3& u, double reach,
                 const CoveredFaces& covered) {
  FreeRun run;
  int hint = -1;
  auto free_at = [&](double x) {
    const ClosestPoint cp = index.closest_point(mid + x * u, hint);
    if (cp.face >= 0) hint = cp.face;
    return cp.face >= 0 && !cp.boundary && (covered.empty() || !covered[static_cast<std::size_t>(cp.face)]);
  };
  const double step = reach / 64.0;
  for (int side = 0; side < 2; ++side) {
    const double sign = side == 0 ? -1.0 : 1.0;
    hint = -1;
    double in = 0.0, out = std::numeric_limits<double>::quiet_NaN();
    for (double x = step; x <= reach + 1e-12 * reach; x += step) {
      if (!free_at(sign * x)) {
        out = x;
        break;
      }
      in = x;
    }
    double end = reach;
    if (std::isfinite(out)) {
      for (int k = 0; k < 6; ++k) {
        const double m = 0.5 * (in + out);
        (free_at(sign * m) ? in : out) = m;
      }
      end = 0.5 * (in + out);
    }
    (side == 0 ? run.low : run.high) = end;
    (side == 0 ? run.low_open : run.high_open) = !std::isfinite(out);
  }
  return run;
}

bool free_runs_hold(const SurfaceIndex& index, const std::vector<FreeRunRecord>& runs, const CoveredFaces& covered) {
  for (const FreeRunRecord& r : runs)
    if (!(free_run(index, r.mid, r.u, r.reach, covered) == r.run)) return false;
  return true;
}

Line lay_line(const Vec3& mid, const Vec3& u, double L, const FreeRun& run, double overhang) {
  const double length = run.low + run.high;
  double from;  // where the line starts, as a signed distance from mid along u
  if (length <= L) {
    from = 0.5 * (run.high - run.low) - 0.5 * L;
  } else {
    const bool near_low = !run.low_open && run.low < 0.75 * L;
    const bool near_high = !run.high_open && run.high < 0.75 * L;
    if (near_low && (!near_high || run.low <= run.high))
      from = -run.low - overhang * L;
    else if (near_high)
      from = run.high + overhang * L - L;
    else
      from = -0.5 * L;
  }
  return {mid + from * u, mid + (from + L) * u};
}

std::vector<LineCandidate> seed_candidates(const SurfaceIndex& index, const Seed& seed, int seed_id,
                                           const CoveredFaces& covered,
                                           const CandidateLineOptions& o,
                                           const Thresholds& thresholds, long long* scored,
                                           std::vector<FreeRunRecord>* runs, SearchStop* stop) {
  // Read at the start of each task, and after each stage (where `stopped` is set, on this
  // thread). The flag only ever goes from unset to set, so a task that skipped its work is
  // seen by the check after its stage.
  const auto halted = [&] { return stop && stop->flag && stop->flag->load(std::memory_order_relaxed); };
  const auto stopped = [&] {
    if (!halted()) return false;
    stop->stopped = true;
    return true;
  };
  // Each stage's lines are independent of one another and run concurrently; what each finds
  // (lines, free runs, counts) is kept per task and joined in task order, which is the order
  // of a serial loop: the result is the same at every thread count.
  // Free runs through the cover, recorded (per task) where asked.
  auto free_run_through = [&](const Vec3& mid, const Vec3& u, std::vector<FreeRunRecord>& records) {
    const FreeRun run = free_run(index, mid, u, o.length_max, covered);
    if (runs) records.push_back({mid, u, o.length_max, run});
    return run;
  };
  const auto join_records = [&](std::vector<FreeRunRecord>& records) {
    if (runs) runs->insert(runs->end(), records.begin(), records.end());
  };
  const double L_ref = std::sqrt(o.length_min * o.length_max);
  const CutterKind general = o.kinds.back();
  // The profiles that steer the search: the barrel where allowed, and the most general kind.
  std::vector<CutterKind> steer;
  for (CutterKind k : o.kinds)
    if (k == CutterKind::barrel) steer.push_back(k);
  if (steer.empty() || steer.front() != general) steer.push_back(general);
  // Directions are scored with both steering profiles, and the best of each go on: a free-form
  // profile fits the distances of almost any short line, so its score is the movability alone,
  // and on an exact cone envelope lines 15–25° off the axis scored as well as the axis; the
  // barrel alone ranks the axis of a free-form cutter's envelope low.
  MovabilityOptions coarse;
  coarse.samples = o.coarse_samples;
  coarse.profile = steer.front();
  if (steer.size() > 1) coarse.second_profile = steer.back();
  // A line through a seed near Φ's edge overhangs it: lay_line fits it to Φ later.
  coarse.max_boundary_fraction = 0.5;
  const std::vector<double> radii = geometric(o.radius_min, o.radius_max, o.radii);
  // One task per offset and tilt, over the directions.
  const std::size_t groups = radii.size() * static_cast<std::size_t>(o.tilts);
  std::vector<std::vector<Scored>> scored_by_group(groups);
  parallel_invoke_each(groups, [&](std::size_t g) {
    if (halted()) return;
    const double r = radii[g / static_cast<std::size_t>(o.tilts)];
    const int t = static_cast<int>(g % static_cast<std::size_t>(o.tilts));
    const double tilt = o.tilts == 1 ? 0.0
                                     : (-1.0 + 2.0 * t / (o.tilts - 1)) * o.max_tilt_deg *
                                           std::numbers::pi / 180.0;
    std::vector<int> hints(static_cast<std::size_t>(o.coarse_samples), -1);
    for (int d = 0; d < o.directions; ++d) {
      const double th = std::numbers::pi * d / o.directions;
      const Vec3 tangent = std::cos(th) * seed.dir_min + std::sin(th) * seed.dir_max;
      const Vec3 u = std::cos(tilt) * tangent + std::sin(tilt) * seed.normal;
      const Vec3 mid = seed.point + r * seed.normal;
      Scored c;
      c.line = {mid - 0.5 * L_ref * u, mid + 0.5 * L_ref * u};
      // Warm start from the previous direction's footpoints: neighbours share faces.
      c.movability = movability(index, c.line.a, c.line.b, coarse, hints);
      if (!acceptable(c.movability, o, L_ref)) continue;
      c.score = line_score(c.movability, L_ref);
      c.second_score = c.score;
      if (coarse.second_profile) {
        const double misfit = c.movability.second_profile_rms / L_ref;
        c.second_score = c.movability.value + kProfileWeight * misfit * misfit;
      }
      scored_by_group[g].push_back(c);
    }
  });
  if (stopped()) return {};
  *scored += static_cast<long long>(groups) * o.directions;
  std::vector<Scored> all;
  for (const std::vector<Scored>& group : scored_by_group) all.insert(all.end(), group.begin(), group.end());
  // The best by each steering profile's score, half each (stable: ties never depend on
  // anything but generation order); a line among both counts once.
  {
    std::vector<std::size_t> order(all.size());
    std::vector<Scored> best;
    std::vector<char> taken(all.size(), 0);
    const int per = coarse.second_profile ? (o.fine_candidates + 1) / 2 : o.fine_candidates;
    for (int pass = 0; pass < (coarse.second_profile ? 2 : 1); ++pass) {
      std::iota(order.begin(), order.end(), 0);
      std::stable_sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) {
        return pass == 0 ? all[x].score < all[y].score : all[x].second_score < all[y].second_score;
      });
      int added = 0;
      for (std::size_t i : order) {
        if (added == per || static_cast<int>(best.size()) == o.fine_candidates) break;
        if (taken[i]) continue;
        taken[i] = 1;
        best.push_back(all[i]);
        ++added;
      }
    }
    all = std::move(best);
  }
  MovabilityOptions fine = coarse;
  fine.samples = o.fine_samples;

  // Aim: each of the best is laid over the free part of Φ at the longest length that fits
  // there (L0) and aimed anew at that length, over the offsets and a few small turns, with each
  // steering profile. A short line cannot tell directions apart that a long one can: at the
  // reference length a line 15° off a ruling may score as well as the ruling. One task each.
  const double turn = o.aim_turn_deg * std::numbers::pi / 180.0;
  struct Aimed {
    Vec3 u = Vec3::Zero();
    double L0 = 0.0;
    std::vector<Line> start;      // per steering kind
    std::vector<double> score;    // per steering kind
    double best = std::numeric_limits<double>::infinity();
    std::vector<FreeRunRecord> records;
    long long lines = 0;
  };
  std::vector<Aimed> aimed(all.size());
  parallel_invoke_each(all.size(), [&](std::size_t i) {
    if (halted()) return;
    const Scored& c = all[i];
    Aimed& a = aimed[i];
    a.u = (c.line.b - c.line.a).normalized();
    const Vec3 mid0 = 0.5 * (c.line.a + c.line.b);
    const FreeRun run0 = free_run_through(mid0, a.u, a.records);
    a.L0 = laid_length(run0, o);
    const Line laid = lay_line(mid0, a.u, a.L0, run0, o.overhang);
    const Vec3 centre = 0.5 * (laid.a + laid.b);
    const Vec3 w1 = seed.normal.cross(a.u).normalized(), w2 = a.u.cross(w1);
    std::vector<Vec3> dirs{a.u};
    for (const Vec3& w : {w1, w2})
      for (double sgn : {-1.0, 1.0}) dirs.push_back((std::cos(turn) * a.u + sgn * std::sin(turn) * w).normalized());
    // Each line's footpoints once, judged with every steering profile.
    a.start.assign(steer.size(), laid);
    a.score.assign(steer.size(), std::numeric_limits<double>::infinity());
    // Each line's sample i starts from the previous line's (a neighbour: the next offset or
    // turn).
    std::vector<int> aim_hints(static_cast<std::size_t>(fine.samples), -1);
    for (const Vec3& d : dirs)
      for (double r : radii) {
        // The laid line's middle moved to offset r along the seed's normal.
        const Vec3 m = centre + (seed.point + r * seed.normal - mid0);
        const Line l{m - 0.5 * a.L0 * d, m + 0.5 * a.L0 * d};
        const std::vector<ClosestPoint> feet = line_footpoints(index, l.a, l.b, fine.samples, aim_hints);
        ++a.lines;
        for (std::size_t si = 0; si < steer.size(); ++si) {
          MovabilityOptions mo = fine;
          mo.profile = steer[si];
          const Movability mv = movability_from_footpoints(l.a, l.b, feet, mo);
          if (!acceptable(mv, o, a.L0)) continue;
          const double sc = line_score(mv, a.L0);
          if (sc < a.score[si]) a.score[si] = sc, a.start[si] = l;
        }
      }
    for (double sc : a.score) a.best = std::min(a.best, sc);
  });
  if (stopped()) return {};
  for (Aimed& a : aimed) {
    *scored += a.lines;
    join_records(a.records);
  }
  std::stable_sort(aimed.begin(), aimed.end(), [](const Aimed& x, const Aimed& y) { return x.best < y.best; });

  // The best distinct directions, each refined with each steering profile (one task each) and
  // laid across the free part of Φ at a few lengths.
  std::vector<Vec3> kept_dirs;
  struct Refined {
    const Aimed* aimed = nullptr;
    std::size_t steering = 0;
    Vec3 axis = Vec3::Zero(), mid = Vec3::Zero();
    std::vector<std::pair<double, FreeRun>> laid;  // lengths and the runs they are laid over
    std::vector<FreeRunRecord> records;
    long long lines = 0;
  };
  std::vector<Refined> refined_lines;
  const double cos_distinct = std::cos(o.distinct_deg * std::numbers::pi / 180.0);
  for (const Aimed& a : aimed) {
    if (!std::isfinite(a.best) || static_cast<int>(kept_dirs.size()) >= o.directions_kept) break;
    bool distinct = true;
    for (const Vec3& k : kept_dirs) distinct &= std::abs(a.u.dot(k)) < cos_distinct;
    if (!distinct) continue;
    kept_dirs.push_back(a.u);
    for (std::size_t si = 0; si < steer.size(); ++si)
      if (std::isfinite(a.score[si])) {
        Refined rl;
        rl.aimed = &a;
        rl.steering = si;
        refined_lines.push_back(std::move(rl));
      }
  }
  parallel_invoke_each(refined_lines.size(), [&](std::size_t i) {
    if (halted()) return;
    Refined& rl = refined_lines[i];
    const Aimed& a = *rl.aimed;
    const CutterKind steering = steer[rl.steering];
    // The local search (Fig. 8) refines the axis once, laid at the longest length; the
    // shorter lengths are laid along the refined axis.
    RefineLineOptions ro;
    ro.kind = steering;
    ro.movability = fine;
    ro.movability.samples = o.refine_samples;
    ro.movability.profile = steering;
    ro.candidates_per_end = o.refine_candidates;
    ro.rounds = o.refine_rounds;
    ro.profile_weight = kProfileWeight;
    ro.radius_min = o.radius_min;
    ro.radius_max = o.radius_max;
    const RefinedLine refined = refine_line(index, a.start[rl.steering], ro);
    rl.lines += refined.evaluated;
    if (o.trace) {
      char line[400];
      std::snprintf(line, sizeof line,
                    "seed %d direction %.3f,%.3f,%.3f L0 %.2f aimed score %.2e; refined with %s: F_l %.2e, misfit "
                    "%.2e, radii %.2f..%.2f",
                    seed_id, a.u.x(), a.u.y(), a.u.z(), a.L0, a.score[rl.steering],
                    std::string(to_string(steering)).c_str(), refined.movability.value,
                    refined.movability.profile_rms, refined.movability.radius_min, refined.movability.radius_max);
      o.trace(line);
    }
    if (!refined.movability.ok()) return;
    rl.axis = (refined.line.b - refined.line.a).normalized();
    rl.mid = 0.5 * (refined.line.a + refined.line.b);
    // The lengths: across the free part of Φ, then halved; and, once part of Φ is covered,
    // also across Φ regardless of it: a long sweep over covered area may replace several
    // short ones in the cover (greedy_cover's swaps), where gap-fillers alone cannot.
    const FreeRun run = free_run_through(rl.mid, rl.axis, rl.records);
    if (!covered.empty()) {
      const FreeRun whole = free_run(index, rl.mid, rl.axis, o.length_max, {});
      if (whole.low + whole.high > 1.1 * (run.low + run.high)) rl.laid.emplace_back(laid_length(whole, o), whole);
    }
    double len = laid_length(run, o);
    for (int k = 0; k < o.lengths; ++k, len *= 0.5) {
      if (len < o.length_min * (1.0 - 1e-9)) break;
      rl.laid.emplace_back(len, run);
    }
  });
  // Each laid line judged and swept: one task each.
  struct Laid {
    const Refined* from = nullptr;
    double L = 0.0;
    const FreeRun* on = nullptr;
    std::optional<LineCandidate> candidate;
  };
  std::vector<Laid> laid;
  if (stopped()) return {};
  for (Refined& rl : refined_lines) {
    *scored += rl.lines;
    join_records(rl.records);
    for (const auto& [L, on] : rl.laid) {
      Laid l;
      l.from = &rl;
      l.L = L;
      l.on = &on;
      laid.push_back(std::move(l));
    }
  }
  parallel_invoke_each(laid.size(), [&](std::size_t i) {
    if (halted()) return;
    const Refined& rl = *laid[i].from;
    const double L = laid[i].L;
    LineCandidate lc;
    lc.line = lay_line(rl.mid, rl.axis, L, *laid[i].on, o.overhang);
    // The simplest allowed kind that follows the line's distances; the most general one
    // must at least fit them within line_misfit.
    bool found = false;
    const std::vector<ClosestPoint> feet = line_footpoints(index, lc.line.a, lc.line.b, fine.samples);
    for (CutterKind kind : o.kinds) {
      MovabilityOptions mk = fine;
      mk.profile = kind;
      const Movability m = movability_from_footpoints(lc.line.a, lc.line.b, feet, mk);
      const double limit = kind == general ? thresholds.line_misfit : thresholds.kind_misfit;
      if (acceptable(m, o, L) && m.profile_rms <= limit) {
        lc.kind = kind;
        lc.movability = m;
        found = true;
        break;
      }
    }
    if (!found) return;
    lc.seed = seed_id;
    lc.score = line_score(lc.movability, L);
    lc.inside = L * (lc.movability.samples - lc.movability.boundary_samples) /
                std::max(1, lc.movability.samples);
    PropagateOptions po;
    po.movability.samples = o.probe_samples;
    po.movability.max_boundary_fraction = 0.5;
    po.step = o.step;
    po.max_travel = o.max_travel;
    // The sweep ends where its cutter stops fitting (max_profile_error), not on a rate: F_l
    // here only guards against a line thrown off Φ (0.1 mm of approach per mm of travel).
    po.max_movability = 1e-2;
    po.max_profile_error = thresholds.sweep_misfit;
    // The sweep's rulings do not depend on the cover; what it passes over that is still
    // to cut does (rank_candidates).
    lc.sweep = propagate(index, lc.line, po);
    if (lc.sweep.rulings.size() >= 4) laid[i].candidate = std::move(lc);
  });
  if (stopped()) return {};
  *scored += static_cast<long long>(laid.size());
  std::vector<LineCandidate> out;
  for (Laid& l : laid)
    if (l.candidate) {
      l.candidate->order = static_cast<int>(out.size());
      out.push_back(std::move(*l.candidate));
    }
  rank_candidates(out, covered);
  return out;
}

}  // namespace flank
