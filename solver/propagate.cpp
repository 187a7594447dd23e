#include "solver/propagate.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>

#include "kernels/bspline.h"
#include "kernels/parallel.h"

namespace flank {

const char* to_string(PropagateStop stop) {
  switch (stop) {
    case PropagateStop::max_movability: return "movability above threshold";
    case PropagateStop::left_surface: return "left the surface";
    case PropagateStop::jump: return "footpoints jump";
    case PropagateStop::max_travel: return "travel cap";
    case PropagateStop::stalled: return "stalled (the corrector undoes the sweep)";
    case PropagateStop::degenerate: return "degenerate";
    case PropagateStop::profile_error: return "the cutter no longer fits";
  }
  return "unknown";
}

namespace {
// Point k of n in the unit disc, sunflower (Vogel) pattern: even cover, no RNG.
Vec2 sunflower(int k, int n) {
  if (k == 0) return Vec2::Zero();
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  const double r = std::sqrt((k + 0.5) / n);
  return Vec2(r * std::cos(k * golden), r * std::sin(k * golden));
}
}  // namespace

RefinedLine refine_line(const SurfaceIndex& index, const Line& start,
                        const RefineLineOptions& options) {
  MovabilityOptions mo = options.movability;
  if (options.kind) mo.profile = options.kind;
  const double L = start.length();
  auto score = [&](const Movability& m) {
    if (!m.ok()) return std::numeric_limits<double>::infinity();
    if (options.kind && ((options.radius_min > 0 && m.radius_min < options.radius_min) ||
                         (options.radius_max > 0 && m.radius_max > options.radius_max)))
      return std::numeric_limits<double>::infinity();
    const double misfit = options.kind ? m.profile_rms / L : 0.0;
    return m.value + options.profile_weight * misfit * misfit;
  };
  RefinedLine best;
  best.line = start;
  // The best line's footpoint faces: every line tried next lies within `radius` of it, so its
  // sample i starts from the best's sample i (hints never change an answer, only its cost).
  const auto n = static_cast<std::size_t>(mo.samples);
  std::vector<int> best_faces(n, -1);
  best.movability = movability(index, start.a, start.b, mo, best_faces);
  best.score = score(best.movability);
  best.evaluated = 1;
  double radius = options.radius > 0 ? options.radius : 0.05 * L;
  const int c = options.candidates_per_end;
  for (int round = 0; round < options.rounds; ++round) {
    const Vec3 u = (best.line.b - best.line.a).normalized();
    const Vec3 n1 = u.unitOrthogonal(), n2 = u.cross(n1);
    std::vector<Movability> scores(static_cast<std::size_t>(c * c));
    std::vector<Line> lines(scores.size());
    std::vector<int> faces(scores.size() * n);
    for (int i = 0; i < c; ++i)
      for (int j = 0; j < c; ++j) {
        const Vec2 pa = radius * sunflower(i, c), pb = radius * sunflower(j, c);
        Line l{best.line.a + pa.x() * n1 + pa.y() * n2, best.line.b + pb.x() * n1 + pb.y() * n2};
        // Keep the length: a rigid cutter.
        const Vec3 mid = 0.5 * (l.a + l.b), dir = (l.b - l.a).normalized();
        lines[static_cast<std::size_t>(i * c + j)] = {mid - 0.5 * L * dir, mid + 0.5 * L * dir};
      }
    parallel_for(0, lines.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t k = b; k < e; ++k) {
        const std::span<int> hints(faces.data() + k * n, n);
        std::copy(best_faces.begin(), best_faces.end(), hints.begin());
        scores[k] = movability(index, lines[k].a, lines[k].b, mo, hints);
      }
    }, 8);
    best.evaluated += static_cast<int>(lines.size());
    for (std::size_t k = 0; k < lines.size(); ++k) {  // serial: ties go to the lower index
      const double sk = score(scores[k]);
      if (sk < best.score) {
        best.score = sk;
        best.movability = scores[k];
        best.line = lines[k];
        std::copy_n(faces.begin() + static_cast<std::ptrdiff_t>(k * n), n, best_faces.begin());
      }
    }
    radius *= 0.5;
  }
  return best;
}

double interior_edge(const SurfaceIndex& index, const Line& line, bool low, double from,
                     double reach, int* hint) {
  constexpr double kStep = 1.0 / 64.0;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  auto interior_at = [&](double s) {
    const ClosestPoint cp = index.closest_point(line.point(s), *hint);
    if (cp.face >= 0) *hint = cp.face;
    return cp.face >= 0 && !cp.boundary;
  };
  const double inward = low ? 1.0 : -1.0;
  double in, out;
  if (interior_at(from)) {
    in = from;
    for (double s = from - inward * kStep;; s -= inward * kStep) {
      if (low ? s < -reach : s > 1.0 + reach) return nan;
      if (!interior_at(s)) {
        out = s;
        break;
      }
      in = s;
    }
  } else {
    out = from;
    for (double s = from + inward * kStep;; s += inward * kStep) {
      if (low ? s > 0.5 : s < 0.5) return nan;
      if (interior_at(s)) {
        in = s;
        break;
      }
      out = s;
    }
  }
  for (int k = 0; k < 6; ++k) {  // to 1/4096 of the length
    const double m = 0.5 * (in + out);
    (interior_at(m) ? in : out) = m;
  }
  return 0.5 * (in + out);
}

namespace {
struct Stepper {
  const SurfaceIndex& index;
  const PropagateOptions& options;
  std::vector<int> hints;
  double L;

  // Velocities of the ends for line l with the sweep sign aligned to `reference`.
  bool velocity(const Line& l, const Vec3& reference, Vec3* va, Vec3* vb, Movability* mv) {
    *mv = movability(index, l.a, l.b, options.movability, hints);
    if (!std::isfinite(mv->value)) return false;
    // The sweep is the part of v_m across the axis; sliding along it says nothing of the
    // direction of travel.
    const Vec3 sweep = mv->mu1 * mv->n1 + mv->mu2 * mv->n2;
    double sign = reference.squaredNorm() > 0 && sweep.dot(reference) < 0 ? -1.0 : 1.0;
    // The slide along the axis (α) is left to the corrector: on cone-like lines α trades
    // against the approach to Φ and the footpoints barely tell them apart (|g·u| ≪ 1), so
    // the integrated α is noise, while the corrector pins the axial position by the distance
    // profile and Φ's edges.
    const Vec3 slide = mv->alpha * mv->u;
    *va = sign * (mv->velocity(0.0) - slide);
    *vb = sign * (mv->velocity(1.0) - slide);
    return true;
  }

  Line rigid(const Line& l) const {
    const Vec3 mid = 0.5 * (l.a + l.b), dir = (l.b - l.a).normalized();
    return {mid - 0.5 * L * dir, mid + 0.5 * L * dir};
  }

  // Footpoint distances of the samples (NaN where the footpoint is beyond Φ's boundary).
  std::vector<double> distances(const Line& l, std::vector<ClosestPoint>* cp) {
    const int n = options.movability.samples;
    Points q(n, 3);
    for (int i = 0; i < n; ++i) q.row(i) = l.point(movability_sample(i, n)).transpose();
    cp->resize(static_cast<std::size_t>(n));
    index.closest_points_serial(q, hints, *cp);
    std::vector<double> d(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i)
      d[i] = (*cp)[i].boundary || (*cp)[i].face < 0 ? std::numeric_limits<double>::quiet_NaN()
                                                    : (*cp)[i].distance;
    return d;
  }

  // Corrector of the predictor–corrector continuation: one Gauss–Newton step on the line's
  // five degrees of freedom back to the start line's distance profile (the same cutter).
  // Without it the weakly determined sliding of cone-like lines integrates into drift.
  // `sweep`: the direction of travel (⟂ the axis), held still with hold_sweep. `residual`
  // receives the largest predicted distance misfit after the step.
  // `faces` receives the faces of l's footpoints inside Φ (−1 for the others).
  Line correct(const Line& l, const Vec3& sweep, double* residual, std::vector<int>* faces) {
    std::vector<ClosestPoint> cp;
    const std::vector<double> d = distances(l, &cp);
    const int n = options.movability.samples;
    faces->resize(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) (*faces)[i] = std::isfinite(d[i]) ? cp[i].face : -1;
    const Vec3 u = (l.b - l.a).normalized(), n1 = u.unitOrthogonal(), n2 = u.cross(n1);
    Eigen::Matrix<double, 5, 5> H = Eigen::Matrix<double, 5, 5>::Zero();
    Eigen::Matrix<double, 5, 1> g = Eigen::Matrix<double, 5, 1>::Zero();
    for (int i = 0; i < n; ++i) {
      if (!std::isfinite(d[i]) || !std::isfinite(profile[i])) continue;
      const double s = movability_sample(i, n);
      const Vec3& gi = cp[i].direction;
      Eigen::Matrix<double, 5, 1> k;
      k << (1 - s) * gi.dot(n1), (1 - s) * gi.dot(n2), s * gi.dot(n1), s * gi.dot(n2), gi.dot(u);
      H.noalias() += k * k.transpose();
      g += k * (d[i] - profile[i]);
    }
    if (!(H.trace() > 0)) return l;
    const double trace = H.trace();
    H.diagonal().array() += 1e-6 * trace;  // the sweep itself is free: keep it still
    if (options.hold_sweep > 0 && sweep.squaredNorm() > 0) {
      // A spring on each end against moving along the sweep (see PropagateOptions::hold_sweep).
      const Vec3 w = (sweep - sweep.dot(u) * u).normalized();
      Eigen::Matrix<double, 5, 1> ka, kb;
      ka << w.dot(n1), w.dot(n2), 0, 0, 0;
      kb << 0, 0, w.dot(n1), w.dot(n2), 0;
      H.noalias() += options.hold_sweep * trace * (ka * ka.transpose() + kb * kb.transpose());
    }
    // Axial position: where the part's edge crosses the line, it must cross it where it did at
    // the start. A cylinder may slide along its axis at no cost in distance, and the true
    // motion does slide (a′·u ≠ 0), so without this the line walks off the part's width.
    double shift = 0.0;
    int ends = 0;
    for (int e = 0; e < 2; ++e) {
      if (!std::isfinite(edge_start[e])) continue;
      const double now = edge(l, e == 0, edge_now[e], &edge_hint[e]);
      // An edge that jumps is another edge (the end of Φ across the motion): not this one.
      if (!std::isfinite(now) || std::abs(now - edge_now[e]) * L > 4.0 * step) continue;
      edge_now[e] = now;
      shift += (now - edge_start[e]) * L;
      ++ends;
    }
    if (options.trace) {
      char line[160];
      std::snprintf(line, sizeof line, "  edges start %.4f %.4f now %.4f %.4f shift %.4f", edge_start[0],
                    edge_start[1], edge_now[0], edge_now[1], ends ? shift / ends : 0.0);
      options.trace(line);
    }
    if (ends > 0) {
      const double w = 0.5 * n;
      H(4, 4) += w;
      g(4) -= w * shift / ends;
    }
    const Eigen::Matrix<double, 5, 1> x = -H.ldlt().solve(g);
    if (residual) {
      *residual = 0.0;
      for (int i = 0; i < n; ++i) {
        if (!std::isfinite(d[i]) || !std::isfinite(profile[i])) continue;
        const double s = movability_sample(i, n);
        const Vec3& gi = cp[i].direction;
        Eigen::Matrix<double, 5, 1> k;
        k << (1 - s) * gi.dot(n1), (1 - s) * gi.dot(n2), s * gi.dot(n1), s * gi.dot(n2), gi.dot(u);
        *residual = std::max(*residual, std::abs(d[i] - profile[i] + k.dot(x)));
      }
    }
    return rigid({l.a + x(0) * n1 + x(1) * n2 + x(4) * u, l.b + x(2) * n1 + x(3) * n2 + x(4) * u});
  }

  std::vector<double> profile;  // the start line's footpoint distances

  double edge(const Line& l, bool low, double from, int* hint) const {
    return interior_edge(index, l, low, from, 0.25, hint);
  }

  double step = 0.0;                  // the integration step h
  double edge_start[2] = {0.0, 0.0};  // low and high edge at the start line (NaN: none)
  double edge_now[2] = {0.0, 0.0};
  int edge_hint[2] = {-1, -1};
  void reset_edges() {
    for (int e = 0; e < 2; ++e) edge_now[e] = std::isfinite(edge_start[e]) ? edge_start[e] : 0.0, edge_hint[e] = -1;
  }
};

PropagateStop run(Stepper& st, const Line& start, const Vec3& initial_dir, double h,
                  double max_travel, std::vector<Line>* out, std::vector<int>* faces, double* worst) {
  Line cur = start;
  Vec3 ref = initial_dir;
  double travel = 0.0;
  for (;;) {
    if (travel >= max_travel) return PropagateStop::max_travel;
    Vec3 va, vb;
    Movability mv;
    // A line wholly past Φ's edge has no movability at all: it left the surface.
    const bool moves = st.velocity(cur, ref, &va, &vb, &mv);
    if (mv.status == MovabilityStatus::left_surface) return PropagateStop::left_surface;
    if (mv.status == MovabilityStatus::jump) return PropagateStop::jump;
    if (!moves) return PropagateStop::degenerate;
    if (mv.value > st.options.max_movability) return PropagateStop::max_movability;
    *worst = std::max(*worst, mv.value);
    if (st.options.trace) {
      char line[160];
      std::snprintf(line, sizeof line, "step %zu F %.3g other %.3g alpha %.3f a %.2f %.2f %.2f", out->size(),
                    mv.value, mv.value_other, mv.alpha, cur.a.x(), cur.a.y(), cur.a.z());
      st.options.trace(line);
    }
    // RK2 (midpoint rule); the speed of the midpoint across the axis is 1, so h is a length.
    const Vec3 u = (cur.b - cur.a).normalized();
    const Vec3 vm1 = 0.5 * (va + vb) - u.dot(0.5 * (va + vb)) * u;
    const Line half = st.rigid({cur.a + 0.5 * h * va, cur.b + 0.5 * h * vb});
    Vec3 va2, vb2;
    Movability mv2;
    if (!st.velocity(half, vm1, &va2, &vb2, &mv2) || !mv2.ok()) return PropagateStop::left_surface;
    const Line pred = st.rigid({cur.a + h * va2, cur.b + h * vb2});
    double residual = 0.0;
    std::vector<int> next_faces;
    const Line next = st.correct(pred, vm1, &residual, &next_faces);
    if (st.options.max_profile_error > 0 && residual > st.options.max_profile_error)
      return PropagateStop::profile_error;
    ref = 0.5 * (va2 + vb2);
    ref -= u.dot(ref) * u;
    const double progress = (0.5 * (next.a + next.b) - 0.5 * (cur.a + cur.b)).norm();
    // Where keeping the cutter's profile forbids the sweep, the corrector pulls the line back
    // onto itself: no progress is a stop, not a loop.
    if (progress < 0.25 * h) return PropagateStop::stalled;
    travel += progress;
    out->push_back(next);
    faces->insert(faces->end(), next_faces.begin(), next_faces.end());
    cur = next;
  }
}
}  // namespace

Propagation propagate(const SurfaceIndex& index, const Line& start,
                      const PropagateOptions& options) {
  Propagation p;
  const double h = options.step > 0 ? options.step : 1e-3 * index.diagonal();
  const double cap = options.max_travel > 0 ? options.max_travel : 4.0 * index.diagonal();
  PropagateOptions po = options;
  po.movability.null_cutoff = std::max(po.movability.null_cutoff, 1e-4);
  po.movability.tangent_sweep_below = std::max(po.movability.tangent_sweep_below, options.max_movability);
  Stepper st{index, po, std::vector<int>(static_cast<std::size_t>(options.movability.samples), -1),
             start.length(), {}};
  st.step = h;
  const int n = options.movability.samples;
  p.samples = n;
  std::vector<int> faces0(static_cast<std::size_t>(n), -1);
  {
    std::vector<ClosestPoint> cp;
    st.profile = st.distances(start, &cp);
    for (int i = 0; i < n; ++i) faces0[i] = std::isfinite(st.profile[i]) ? cp[i].face : -1;
    for (int e = 0; e < 2; ++e) st.edge_start[e] = st.edge(start, e == 0, e == 0 ? 0.0 : 1.0, &st.edge_hint[e]);
    st.reset_edges();
  }
  Movability m0 = movability(index, start.a, start.b, po.movability, st.hints);
  p.max_movability = m0.value;
  std::vector<Line> forward, backward;
  std::vector<int> faces_forward, faces_backward;
  if (m0.ok()) {
    const Vec3 dir = m0.mu1 * m0.n1 + m0.mu2 * m0.n2;
    p.stop_forward = run(st, start, dir, h, cap, &forward, &faces_forward, &p.max_movability);
    std::fill(st.hints.begin(), st.hints.end(), -1);
    st.reset_edges();
    p.stop_backward = run(st, start, -dir, h, cap, &backward, &faces_backward, &p.max_movability);
  }
  p.rulings.assign(backward.rbegin(), backward.rend());
  for (std::size_t r = backward.size(); r-- > 0;)
    p.faces.insert(p.faces.end(), faces_backward.begin() + static_cast<std::ptrdiff_t>(r * n),
                   faces_backward.begin() + static_cast<std::ptrdiff_t>((r + 1) * n));
  p.start_index = static_cast<int>(p.rulings.size());
  p.rulings.push_back(start);
  p.faces.insert(p.faces.end(), faces0.begin(), faces0.end());
  p.rulings.insert(p.rulings.end(), forward.begin(), forward.end());
  p.faces.insert(p.faces.end(), faces_forward.begin(), faces_forward.end());
  p.fresh = fresh_fractions(p, options.covered_faces);
  return p;
}

std::vector<double> fresh_fractions(const Propagation& p, const std::vector<char>* covered) {
  std::vector<double> fresh(p.rulings.size(), 0.0);
  if (p.samples <= 0) return fresh;
  for (std::size_t r = 0; r < fresh.size(); ++r) {
    int count = 0;
    for (int i = 0; i < p.samples; ++i) {
      const int f = p.faces[r * static_cast<std::size_t>(p.samples) + static_cast<std::size_t>(i)];
      count += f >= 0 && !(covered && !covered->empty() && (*covered)[static_cast<std::size_t>(f)]);
    }
    fresh[r] = static_cast<double>(count) / p.samples;
  }
  return fresh;
}

LineStart line_driven_start(const SurfaceIndex& index, const Line& line,
                            std::optional<CutterKind> kind, int control_points,
                            const PropagateOptions& propagate_options) {
  LineStart out;
  RefineLineOptions ro;
  ro.kind = kind;
  ro.movability = propagate_options.movability;
  out.refined = refine_line(index, line, ro);
  if (!out.refined.movability.ok()) {
    out.message = "the line has no usable footpoints on the surface (it is off the part)";
    return out;
  }
  out.propagation = propagate(index, out.refined.line, propagate_options);
  if (out.propagation.rulings.size() < kSplineDegree + 1) {
    out.message = "the line cannot move along the surface";
    return out;
  }
  out.motion = Motion::fit(out.propagation.rulings, control_points);
  out.ok = true;
  return out;
}

Motion motion_from_lines(const std::vector<Line>& lines, int control_points) {
  // The endpoints are the control polygons (§4.4) of cubic B-splines with as many control
  // points as lines; two or three lines are first spread evenly along their polyline.
  std::vector<Line> poly = lines;
  if (poly.size() < kSplineDegree + 1) {
    std::vector<Line> spread(kSplineDegree + 1);
    for (int i = 0; i <= kSplineDegree; ++i) {
      const double x = static_cast<double>(i) / kSplineDegree * (lines.size() - 1);
      const std::size_t k = std::min(static_cast<std::size_t>(x), lines.size() - 2);
      const double f = x - static_cast<double>(k);
      spread[i] = {(1 - f) * lines[k].a + f * lines[k + 1].a, (1 - f) * lines[k].b + f * lines[k + 1].b};
    }
    poly = spread;
  }
  Motion m;
  m.knots = clamped_uniform_knots(static_cast<int>(poly.size()));
  m.a.resize(static_cast<Eigen::Index>(poly.size()), 3);
  m.b.resize(m.a.rows(), 3);
  for (std::size_t i = 0; i < poly.size(); ++i) {
    m.a.row(static_cast<Eigen::Index>(i)) = poly[i].a.transpose();
    m.b.row(static_cast<Eigen::Index>(i)) = poly[i].b.transpose();
  }
  if (control_points <= 0 || control_points == m.count()) return m;
  return m.restricted(0, 1, 0, 1, control_points);
}

}  // namespace flank
