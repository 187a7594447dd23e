#include "solver/motion.h"

#include <cassert>

#include "kernels/bspline.h"

namespace flank {

Vec3 Motion::a_at(double t, int order) const { return evaluate_spline(knots, a, t, order); }
Vec3 Motion::b_at(double t, int order) const { return evaluate_spline(knots, b, t, order); }

double Motion::mean_length(int samples) const {
  double sum = 0.0;
  for (int i = 0; i < samples; ++i) sum += ruling((i + 0.5) / samples).length();
  return sum / samples;
}

Motion Motion::from_control_points(Points a, Points b) {
  assert(a.rows() >= 4 && a.rows() == b.rows());
  Motion m;
  m.knots = clamped_uniform_knots(static_cast<int>(a.rows()));
  m.a = std::move(a);
  m.b = std::move(b);
  return m;
}

Motion Motion::fit(const std::vector<Line>& rulings, int count, std::vector<double> params) {
  assert(rulings.size() >= 2);
  const std::size_t n = rulings.size();
  if (params.empty()) {
    params.assign(n, 0.0);
    for (std::size_t i = 1; i < n; ++i)
      params[i] = params[i - 1] + 0.5 * ((rulings[i].a - rulings[i - 1].a).norm() +
                                         (rulings[i].b - rulings[i - 1].b).norm());
    const double total = params.back();
    for (std::size_t i = 0; i < n; ++i)
      params[i] = total > 0 ? params[i] / total : static_cast<double>(i) / (n - 1);
  }
  Points A(n, 3), B(n, 3);
  for (std::size_t i = 0; i < n; ++i) {
    A.row(i) = rulings[i].a.transpose();
    B.row(i) = rulings[i].b.transpose();
  }
  Motion m;
  m.knots = clamped_uniform_knots(count);
  m.a = fit_spline(A, params, count);
  m.b = fit_spline(B, params, count);
  return m;
}

Motion Motion::restricted(double t0, double t1, double s0, double s1, int count) const {
  const int samples = std::max(8 * count, 64);
  std::vector<Line> rulings(samples);
  std::vector<double> params(samples);
  for (int i = 0; i < samples; ++i) {
    const double u = static_cast<double>(i) / (samples - 1);
    const double t = t0 + u * (t1 - t0);
    rulings[i] = {point(t, s0), point(t, s1)};
    params[i] = u;
  }
  return fit(rulings, count, params);
}

}  // namespace flank
