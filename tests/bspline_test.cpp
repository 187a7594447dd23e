#include "kernels/bspline.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "kernels/cutter.h"

namespace flank {
namespace {

TEST(BSpline, PartitionOfUnityAndDerivatives) {
  for (int count : {4, 7, 40}) {
    const auto knots = clamped_uniform_knots(count);
    for (double t = 0.0; t <= 1.0; t += 0.01) {
      const BasisRow r = cubic_basis(knots, count, t);
      double sum = 0, d1 = 0, d2 = 0;
      for (int k = 0; k < 4; ++k) sum += r.value[k], d1 += r.d1[k], d2 += r.d2[k];
      EXPECT_NEAR(sum, 1.0, 1e-12);
      EXPECT_NEAR(d1, 0.0, 1e-9);
      EXPECT_NEAR(d2, 0.0, 1e-7);
      EXPECT_GE(r.first, 0);
      EXPECT_LE(r.first + 3, count - 1);
    }
  }
}

TEST(BSpline, DerivativesMatchFiniteDifferences) {
  const int count = 9;
  const auto knots = clamped_uniform_knots(count);
  Points P(count, 3);
  for (int k = 0; k < count; ++k) P.row(k) << std::sin(k), std::cos(2.0 * k), 0.1 * k * k;
  const double h = 1e-6;
  for (double t : {0.05, 0.33, 0.5, 0.71, 0.95}) {
    const Vec3 fd1 = (evaluate_spline(knots, P, t + h) - evaluate_spline(knots, P, t - h)) / (2 * h);
    const Vec3 fd2 = (evaluate_spline(knots, P, t + h, 1) - evaluate_spline(knots, P, t - h, 1)) / (2 * h);
    EXPECT_LT((fd1 - evaluate_spline(knots, P, t, 1)).norm(), 1e-6);
    EXPECT_LT((fd2 - evaluate_spline(knots, P, t, 2)).norm(), 1e-4);
  }
}

TEST(BSpline, FitReproducesACubic) {
  // A cubic polynomial curve lies in every cubic spline space: the fit is exact.
  std::vector<double> params;
  Points samples(200, 3);
  for (int i = 0; i < 200; ++i) {
    const double t = i / 199.0;
    params.push_back(t);
    samples.row(i) << t * t * t - t, 2 * t * t, 3 - t;
  }
  const Points C = fit_spline(samples, params, 8);
  const auto knots = clamped_uniform_knots(8);
  for (int i = 0; i < 200; ++i)
    EXPECT_LT((evaluate_spline(knots, C, params[i]) - samples.row(i).transpose()).norm(), 1e-6);
}

TEST(Cutter, ConeEndRadiiAndMeridian) {
  const Cutter c = cone_from_end_radii(50.0, 4.0, 7.0);
  EXPECT_TRUE(c.valid());
  const Vec2 ends = c.cone_end_radii();
  EXPECT_NEAR(ends(0), 4.0, 1e-12);
  EXPECT_NEAR(ends(1), 7.0, 1e-12);
  // Every meridian point lies on the cone's line r = 4 + 3 z / 50.
  for (double s = 0; s <= 1.0; s += 0.1) {
    const Vec2 zr = c.meridian(s);
    EXPECT_NEAR(zr(1), 4.0 + 3.0 * zr(0) / 50.0, 1e-12);
  }
}

TEST(Cutter, FitIsExactForItsOwnKind) {
  std::vector<double> s, d;
  for (int i = 0; i <= 10; ++i) s.push_back(i / 10.0), d.push_back(5 + 2 * s.back() * (1 - s.back()));
  const Cutter barrel = Cutter::fit(CutterKind::barrel, 50, s, d);
  for (std::size_t i = 0; i < s.size(); ++i) EXPECT_NEAR(barrel.radius(s[i]), d[i], 1e-9);
  CutterKind k;
  EXPECT_TRUE(parse_cutter_kind("spline", &k));
  EXPECT_EQ(k, CutterKind::spline);
  EXPECT_FALSE(parse_cutter_kind("ballnose", &k));
  // |d'| >= L is no cutter.
  Cutter steep = cone_from_end_radii(1.0, 1.0, 10.0);
  steep.coeffs << 1.0, 3.0;
  EXPECT_FALSE(steep.valid());
}

// The fit forms only the lower triangle of its normal matrix, from each row's nonzero basis
// entries; its coefficients must be those of the plain dense assembly, bit for bit (the
// candidate search's choices hang on them), for every kind, from the table and from s.
TEST(Cutter, FitEqualsTheDenseNormalEquationsBitForBit) {
  std::vector<double> s;
  for (int i = 0; i < 30; ++i) s.push_back((i + 0.5) / 30);
  std::vector<int> rows;
  for (int i = 29; i >= 0; i -= 2) rows.push_back(i);  // a subset, not in order
  for (CutterKind kind : {CutterKind::cylinder, CutterKind::cone, CutterKind::barrel, CutterKind::spline}) {
    const ProfileTable table = profile_table(kind, s);
    const int n = coefficient_count(kind);
    for (int trial = 0; trial < 20; ++trial) {
      std::vector<double> radii, at;
      for (int r : rows) {
        radii.push_back(3.0 + std::sin(0.7 * r + trial) + 1e-3 * trial * r);
        at.push_back(s[static_cast<std::size_t>(r)]);
      }
      MatX A = MatX::Zero(n, n);
      VecX rhs = VecX::Zero(n);
      for (std::size_t i = 0; i < rows.size(); ++i) {
        for (int p = 0; p < n; ++p) {
          rhs(p) += table.value(rows[i], p) * radii[i];
          for (int q = 0; q < n; ++q) A(p, q) += table.value(rows[i], p) * table.value(rows[i], q);
        }
      }
      A.diagonal().array() += 1e-12 * (1.0 + A.diagonal().maxCoeff());
      const VecX dense = A.ldlt().solve(rhs);
      const Cutter from_table = Cutter::fit(table, 40.0, rows, radii);
      const Cutter from_s = Cutter::fit(kind, 40.0, at, radii);
      ASSERT_EQ(from_table.coeffs.size(), n);
      for (int k = 0; k < n; ++k) {
        EXPECT_EQ(from_table.coeffs(k), dense(k)) << to_string(kind) << " trial " << trial << " k " << k;
        EXPECT_EQ(from_s.coeffs(k), dense(k)) << to_string(kind) << " trial " << trial << " k " << k;
      }
    }
  }
}

}  // namespace
}  // namespace flank
