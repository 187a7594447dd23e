// Clamped cubic B-splines over [0, 1] with uniform interior knots: the motion curves a(t),
// b(t) and the "spline" cutter profile. Local support is what keeps JᵀJ sparse.
#pragma once

#include <array>
#include <vector>

#include "kernels/types.h"

namespace flank {

constexpr int kSplineDegree = 3;

// count + degree + 1 knots, clamped at 0 and 1, uniform inside. count ≥ degree + 1.
std::vector<double> clamped_uniform_knots(int count, int degree = kSplineDegree);

// The degree+1 basis functions that do not vanish at t, with first and second derivatives.
// Function `first + k` has value value[k].
struct BasisRow {
  int first = 0;
  std::array<double, kSplineDegree + 1> value{};
  std::array<double, kSplineDegree + 1> d1{};
  std::array<double, kSplineDegree + 1> d2{};
};

// Cubic basis for `count` control points on `knots` (clamped), t clamped into [0, 1].
BasisRow cubic_basis(const std::vector<double>& knots, int count, double t);

// Point (derivative order 0, 1 or 2) of a cubic spline with #K by 3 control points.
Vec3 evaluate_spline(const std::vector<double>& knots, PointsRef control, double t, int order = 0);
// Scalar spline with #K coefficients.
double evaluate_scalar_spline(const std::vector<double>& knots, const VecX& coeffs, double t,
                       int order = 0);

// Least-squares cubic spline with `count` control points through #S samples at parameters
// `params` (in [0, 1]), with a tiny second-difference regulariser so that sparse data stay
// well posed. Returns #count by 3 control points.
Points fit_spline(PointsRef samples, const std::vector<double>& params, int count);

}  // namespace flank
