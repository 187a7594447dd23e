#include "kernels/cutter.h"

#include <Eigen/Cholesky>
#include <cassert>
#include <cmath>

#include "kernels/bspline.h"

namespace flank {

std::string_view to_string(CutterKind kind) {
  switch (kind) {
    case CutterKind::cylinder: return "cylinder";
    case CutterKind::cone: return "cone";
    case CutterKind::barrel: return "barrel";
    case CutterKind::spline: return "spline";
  }
  return "cylinder";
}

bool parse_cutter_kind(std::string_view text, CutterKind* kind) {
  for (CutterKind k : {CutterKind::cylinder, CutterKind::cone, CutterKind::barrel, CutterKind::spline})
    if (text == to_string(k)) {
      *kind = k;
      return true;
    }
  return false;
}

int coefficient_count(CutterKind kind) {
  switch (kind) {
    case CutterKind::cylinder: return 1;
    case CutterKind::cone: return 2;
    case CutterKind::barrel: return 3;
    case CutterKind::spline: return kSplineProfileCoefficients;
  }
  return 1;
}

namespace {
const std::vector<double>& spline_profile_knots() {
  static const std::vector<double> knots = clamped_uniform_knots(kSplineProfileCoefficients);
  return knots;
}
}  // namespace

std::vector<double> profile_breaks(CutterKind kind) {
  if (kind != CutterKind::spline) return {};
  const std::vector<double>& k = spline_profile_knots();
  return {k.begin() + kSplineDegree + 1, k.end() - kSplineDegree - 1};
}

void profile_basis(CutterKind kind, double s, double* value, double* derivative) {
  switch (kind) {
    case CutterKind::cylinder:
      value[0] = 1.0;
      derivative[0] = 0.0;
      return;
    case CutterKind::cone:  // linear Bernstein: coefficients are the end radii
      value[0] = 1.0 - s, value[1] = s;
      derivative[0] = -1.0, derivative[1] = 1.0;
      return;
    case CutterKind::barrel:  // quadratic Bernstein
      value[0] = (1 - s) * (1 - s), value[1] = 2 * s * (1 - s), value[2] = s * s;
      derivative[0] = -2 * (1 - s), derivative[1] = 2 - 4 * s, derivative[2] = 2 * s;
      return;
    case CutterKind::spline: {
      const BasisRow row = cubic_basis(spline_profile_knots(), kSplineProfileCoefficients, s);
      for (int k = 0; k < kSplineProfileCoefficients; ++k) value[k] = derivative[k] = 0.0;
      for (int k = 0; k <= kSplineDegree; ++k) {
        value[row.first + k] = row.value[k];
        derivative[row.first + k] = row.d1[k];
      }
      return;
    }
  }
}

ProfileTable profile_table(CutterKind kind, const std::vector<double>& s) {
  ProfileTable t;
  t.kind = kind;
  t.s = s;
  const int n = coefficient_count(kind);
  t.value.resize(static_cast<Eigen::Index>(s.size()), n);
  t.derivative.resize(static_cast<Eigen::Index>(s.size()), n);
  double v[kSplineProfileCoefficients], d[kSplineProfileCoefficients];
  for (std::size_t i = 0; i < s.size(); ++i) {
    profile_basis(kind, s[i], v, d);
    for (int k = 0; k < n; ++k) {
      t.value(static_cast<Eigen::Index>(i), k) = v[k];
      t.derivative(static_cast<Eigen::Index>(i), k) = d[k];
    }
  }
  return t;
}

double Cutter::radius_at(const ProfileTable& table, int row) const {
  assert(table.kind == kind);
  double r = 0.0;
  for (int k = 0; k < coeffs.size(); ++k) r += table.value(row, k) * coeffs(k);
  return r;
}

double Cutter::slope_at(const ProfileTable& table, int row) const {
  assert(table.kind == kind);
  double r = 0.0;
  for (int k = 0; k < coeffs.size(); ++k) r += table.derivative(row, k) * coeffs(k);
  return r;
}

double Cutter::radius(double s) const {
  double v[kSplineProfileCoefficients], d[kSplineProfileCoefficients];
  profile_basis(kind, s, v, d);
  double r = 0.0;
  for (int k = 0; k < coeffs.size(); ++k) r += v[k] * coeffs(k);
  return r;
}

double Cutter::slope(double s) const {
  double v[kSplineProfileCoefficients], d[kSplineProfileCoefficients];
  profile_basis(kind, s, v, d);
  double r = 0.0;
  for (int k = 0; k < coeffs.size(); ++k) r += d[k] * coeffs(k);
  return r;
}

Vec2 Cutter::meridian(double s) const {
  const double d = radius(s), dd = slope(s);
  const double q = dd / length;
  return Vec2(s * length - d * q, d * std::sqrt(std::max(0.0, 1.0 - q * q)));
}

bool Cutter::valid() const {
  if (!(length > 0.0) || coeffs.size() != coefficient_count(kind)) return false;
  for (int i = 0; i <= 100; ++i) {
    const double s = i / 100.0;
    const double d = radius(s), dd = slope(s);
    if (!std::isfinite(d) || d <= 0.0 || std::abs(dd) >= length) return false;
  }
  return true;
}

Vec2 Cutter::cone_end_radii() const {
  // d(s) = (r0 + k s L)/√(1 + k²): the sphere inscribed in the cone at axis point sL.
  const double q = slope(0.5) / length;  // = k/√(1+k²)
  const double k = q / std::sqrt(std::max(1e-300, 1.0 - q * q));
  const double r0 = radius(0.0) * std::sqrt(1.0 + k * k);
  return Vec2(r0, r0 + k * length);
}

Cutter Cutter::constant(CutterKind kind, double length, double radius) {
  std::vector<double> s(21), r(21, radius);
  for (int i = 0; i <= 20; ++i) s[i] = i / 20.0;
  return fit(kind, length, s, r);
}

namespace {
// Least squares over basis rows given by `row(i, v)` (fills v with the basis at sample i).
// Only the lower triangle of the normal matrix is formed (all that LDLT reads), and only from
// a row's nonzero entries (a spline row has four of ten): basis values are finite, so a product
// with a zero is ±0, which leaves a sum as it was (no sum here is ever −0: it starts at +0, and
// round-to-nearest gives −0 only from −0 + −0). A is the full loop's, bit for bit.
template <class Row>
Cutter fit_rows(CutterKind kind, double length, std::size_t count, const std::vector<double>& radii, Row&& row) {
  // On the stack: at most 10 × 10.
  using Normal = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kSplineProfileCoefficients,
                               kSplineProfileCoefficients>;
  using Rhs = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kSplineProfileCoefficients, 1>;
  const int n = coefficient_count(kind);
  Normal A = Normal::Zero(n, n);
  Rhs rhs = Rhs::Zero(n);
  double v[kSplineProfileCoefficients];
  int nonzero[kSplineProfileCoefficients];
  for (std::size_t i = 0; i < count; ++i) {
    row(i, v);
    int m = 0;
    for (int p = 0; p < n; ++p) {
      rhs(p) += v[p] * radii[i];  // every entry: a radius may be non-finite
      if (v[p] != 0.0) nonzero[m++] = p;
    }
    for (int a = 0; a < m; ++a) {
      const int p = nonzero[a];
      for (int b = 0; b <= a; ++b) A(p, nonzero[b]) += v[p] * v[nonzero[b]];
    }
  }
  A.diagonal().array() += 1e-12 * (1.0 + A.diagonal().maxCoeff());
  Cutter c;
  c.kind = kind;
  c.length = length;
  c.coeffs = Eigen::LDLT<Normal>(A).solve(rhs);
  return c;
}
}  // namespace

Cutter Cutter::fit(CutterKind kind, double length, const std::vector<double>& s,
                   const std::vector<double>& radii) {
  assert(s.size() == radii.size() && !s.empty());
  return fit_rows(kind, length, s.size(), radii, [&](std::size_t i, double* v) {
    double d[kSplineProfileCoefficients];
    profile_basis(kind, s[i], v, d);
  });
}

Cutter Cutter::fit(const ProfileTable& table, double length, const std::vector<int>& rows,
                   const std::vector<double>& radii) {
  assert(rows.size() == radii.size() && !rows.empty());
  const int n = coefficient_count(table.kind);
  return fit_rows(table.kind, length, rows.size(), radii, [&](std::size_t i, double* v) {
    for (int k = 0; k < n; ++k) v[k] = table.value(rows[i], k);
  });
}

Cutter cone_from_end_radii(double length, double r_tip, double r_end) {
  const double k = (r_end - r_tip) / length;
  const double scale = 1.0 / std::sqrt(1.0 + k * k);
  Cutter c;
  c.kind = CutterKind::cone;
  c.length = length;
  c.coeffs.resize(2);
  c.coeffs << r_tip * scale, r_end * scale;
  return c;
}

}  // namespace flank
