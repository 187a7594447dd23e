// The motion of the cutter axis: a ruled surface R(t, s) = (1 − s) a(t) + s b(t) whose
// boundary curves a, b are clamped cubic B-splines over t ∈ [0, 1] (paper eq. 7).
#pragma once

#include <vector>

#include "kernels/types.h"

namespace flank {

struct Line {
  Vec3 a = Vec3::Zero();
  Vec3 b = Vec3::Zero();
  double length() const { return (b - a).norm(); }
  Vec3 point(double s) const { return (1.0 - s) * a + s * b; }
};

struct Motion {
  std::vector<double> knots;  // clamped cubic knots over [0, 1]
  Points a;                   // #K by 3 control points of a(t) (the tip end)
  Points b;                   // #K by 3 control points of b(t)

  int count() const { return static_cast<int>(a.rows()); }
  Vec3 a_at(double t, int order = 0) const;
  Vec3 b_at(double t, int order = 0) const;
  Line ruling(double t) const { return {a_at(t), b_at(t)}; }
  Vec3 point(double t, double s) const { return (1.0 - s) * a_at(t) + s * b_at(t); }
  // ∂R/∂t at (t, s).
  Vec3 velocity(double t, double s) const { return (1.0 - s) * a_at(t, 1) + s * b_at(t, 1); }
  // Mean ruling length over the motion.
  double mean_length(int samples = 64) const;

  // The motion with these control points (#K by 3 each, K ≥ 4) on uniform clamped knots.
  static Motion from_control_points(Points a, Points b);
  // Least-squares motion with `count` control points through rulings at parameters
  // `params` (increasing, in [0, 1]); chord-length parameters when `params` is empty.
  static Motion fit(const std::vector<Line>& rulings, int count, std::vector<double> params = {});
  // The same motion restricted to t ∈ [t0, t1] and s ∈ [s0, s1], re-parametrised over
  // [0, 1]² (used by trimming).
  Motion restricted(double t0, double t1, double s0, double s1, int count) const;
};

}  // namespace flank
