#include "kernels/bspline.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace flank
