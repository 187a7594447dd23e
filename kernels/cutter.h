// The cutter Ψ as the envelope of spheres on its axis: sphere radius d(s) at the axis point
// a + s (b − a), s ∈ [0, 1], parametrised linearly d(s) = P(s) c by kind (DESIGN §4.5).
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "kernels/types.h"

namespace flank {

enum class CutterKind { cylinder, cone, barrel, spline };

constexpr int kSplineProfileCoefficients = 10;

std::string_view to_string(CutterKind kind);
// Parses "cylinder", "cone", "barrel", "spline"; false if unknown.
bool parse_cutter_kind(std::string_view text, CutterKind* kind);
int coefficient_count(CutterKind kind);

// Where the profile d(s) of `kind` changes polynomial piece: sorted, inside (0, 1) (none but
// for a spline).
std::vector<double> profile_breaks(CutterKind kind);

// Basis row P(s) (coefficient_count entries) and its s-derivative.
void profile_basis(CutterKind kind, double s, double* value, double* derivative);

// The basis of `kind` tabulated at fixed parameters, for callers that fit and evaluate many
// profiles at the same s (every candidate line's samples): row i holds profile_basis(kind, s[i]).
// Evaluating through it gives the same numbers, bit for bit, as evaluating at s[i] directly.
struct ProfileTable {
  CutterKind kind = CutterKind::cylinder;
  std::vector<double> s;
  MatX value, derivative;  // #s by coefficient_count(kind)
};
ProfileTable profile_table(CutterKind kind, const std::vector<double>& s);

struct Cutter {
  CutterKind kind = CutterKind::cylinder;
  double length = 0.0;  // L = |b − a|
  VecX coeffs;          // c

  double radius(double s) const;  // sphere radius d(s)
  double slope(double s) const;   // d′(s) = dd/ds
  // Meridian point of sphere s: (z from a along the axis, r). Valid while |d′| < L.
  Vec2 meridian(double s) const;
  bool valid() const;  // |d′(s)| < L and d(s) > 0 over [0, 1]
  // Cutter radius r(z) at the axis ends for a cone (meridian line extended to z = 0, L).
  Vec2 cone_end_radii() const;

  static Cutter constant(CutterKind kind, double length, double radius);
  // Least-squares coefficients so that d(s) matches `radii` sampled at `s`.
  static Cutter fit(CutterKind kind, double length, const std::vector<double>& s,
                    const std::vector<double>& radii);
  // The same for s = table.s[rows[k]] (rows ascending or not, as fit() would take them).
  static Cutter fit(const ProfileTable& table, double length, const std::vector<int>& rows,
                    const std::vector<double>& radii);
  // radius(table.s[row]) and slope(table.s[row]), read from the table.
  double radius_at(const ProfileTable& table, int row) const;
  double slope_at(const ProfileTable& table, int row) const;
};

// Sphere radii of a cone whose meridian runs from radius r_tip at z = 0 to r_end at z = L.
Cutter cone_from_end_radii(double length, double r_tip, double r_end);

}  // namespace flank
