#include "kernels/bspline.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cassert>

namespace flank {

std::vector<double> clamped_uniform_knots(int count, int degree) {
  assert(count >= degree + 1);
  std::vector<double> knots(static_cast<std::size_t>(count + degree + 1));
  const int spans = count - degree;
  for (int i = 0; i < static_cast<int>(knots.size()); ++i) {
    if (i <= degree)
      knots[i] = 0.0;
    else if (i >= count)
      knots[i] = 1.0;
    else
      knots[i] = static_cast<double>(i - degree) / spans;
  }
  return knots;
}

BasisRow cubic_basis(const std::vector<double>& knots, int count, double t) {
  constexpr int p = kSplineDegree;
  t = std::clamp(t, 0.0, 1.0);
  // Span index: knots[span] <= t < knots[span+1], with t == 1 in the last span.
  int span = p;
  if (t >= knots[count]) {
    span = count - 1;
  } else {
    span = static_cast<int>(std::upper_bound(knots.begin() + p, knots.begin() + count + 1, t) -
                            knots.begin()) - 1;
    span = std::clamp(span, p, count - 1);
  }
  // Cox–de Boor with derivatives (The NURBS Book, A2.3), up to order 2.
  double ndu[p + 1][p + 1];
  double left[p + 1], right[p + 1];
  ndu[0][0] = 1.0;
  for (int j = 1; j <= p; ++j) {
    left[j] = t - knots[span + 1 - j];
    right[j] = knots[span + j] - t;
    double saved = 0.0;
    for (int r = 0; r < j; ++r) {
      ndu[j][r] = right[r + 1] + left[j - r];
      const double temp = ndu[r][j - 1] / ndu[j][r];
      ndu[r][j] = saved + right[r + 1] * temp;
      saved = left[j - r] * temp;
    }
    ndu[j][j] = saved;
  }
  BasisRow row;
  row.first = span - p;
  double ders[3][p + 1] = {};
  for (int j = 0; j <= p; ++j) ders[0][j] = ndu[j][p];
  double a[2][p + 1];
  for (int r = 0; r <= p; ++r) {
    int s1 = 0, s2 = 1;
    a[0][0] = 1.0;
    for (int k = 1; k <= 2; ++k) {
      double d = 0.0;
      const int rk = r - k, pk = p - k;
      if (r >= k) {
        a[s2][0] = a[s1][0] / ndu[pk + 1][rk];
        d = a[s2][0] * ndu[rk][pk];
      }
      const int j1 = rk >= -1 ? 1 : -rk;
      const int j2 = (r - 1 <= pk) ? k - 1 : p - r;
      for (int j = j1; j <= j2; ++j) {
        a[s2][j] = (a[s1][j] - a[s1][j - 1]) / ndu[pk + 1][rk + j];
        d += a[s2][j] * ndu[rk + j][pk];
      }
      if (r <= pk) {
        a[s2][k] = -a[s1][k - 1] / ndu[pk + 1][r];
        d += a[s2][k] * ndu[r][pk];
      }
      ders[k][r] = d;
      std::swap(s1, s2);
    }
  }
  for (int j = 0; j <= p; ++j) {
    row.value[j] = ders[0][j];
    row.d1[j] = ders[1][j] * p;
    row.d2[j] = ders[2][j] * p * (p - 1);
  }
  return row;
}

namespace {
double pick(const BasisRow& row, int k, int order) {
  return order == 0 ? row.value[k] : order == 1 ? row.d1[k] : row.d2[k];
}
}  // namespace

Vec3 evaluate_spline(const std::vector<double>& knots, PointsRef control, double t, int order) {
  const BasisRow row = cubic_basis(knots, static_cast<int>(control.rows()), t);
  Vec3 out = Vec3::Zero();
  for (int k = 0; k <= kSplineDegree; ++k)
    out += pick(row, k, order) * control.row(row.first + k).transpose();
  return out;
}

double evaluate_scalar_spline(const std::vector<double>& knots, const VecX& coeffs, double t, int order) {
  const BasisRow row = cubic_basis(knots, static_cast<int>(coeffs.size()), t);
  double out = 0.0;
  for (int k = 0; k <= kSplineDegree; ++k) out += pick(row, k, order) * coeffs(row.first + k);
  return out;
}

Points fit_spline(PointsRef samples, const std::vector<double>& params, int count) {
  const std::vector<double> knots = clamped_uniform_knots(count);
  MatX N = MatX::Zero(samples.rows(), count);
  for (Eigen::Index i = 0; i < samples.rows(); ++i) {
    const BasisRow row = cubic_basis(knots, count, params[static_cast<std::size_t>(i)]);
    for (int k = 0; k <= kSplineDegree; ++k) N(i, row.first + k) = row.value[k];
  }
  MatX A = N.transpose() * N;
  // Second differences of the control polygon, weighted far below the data term.
  const double w = 1e-8 * std::max(1.0, A.diagonal().maxCoeff());
  for (int k = 1; k + 1 < count; ++k) {
    const int idx[3] = {k - 1, k, k + 1};
    const double c[3] = {1.0, -2.0, 1.0};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) A(idx[i], idx[j]) += w * c[i] * c[j];
  }
  const MatX rhs = N.transpose() * samples;
  Points out = A.ldlt().solve(rhs);
  return out;
}

}  // namespace flank
