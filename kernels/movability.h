// Tangential movability of a finite line along Φ (paper §4.1, with the sliding fix of
// DESIGN "Tangential movability"): the best first-order rigid motion of the line that keeps
// every sample's distance to Φ, and its residual F_l (0 on an exact envelope).
#pragma once

#include <limits>
#include <optional>
#include <span>
#include <vector>

#include "kernels/cutter.h"

#include "kernels/surface_index.h"
#include "kernels/types.h"

namespace flank {

enum class MovabilityStatus {
  ok,
  left_surface,  // too many footpoints on Φ's boundary: the line has left the surface
  jump,          // consecutive footpoints jump (two branches, paper Remark 1)
  degenerate,    // zero-length line or too few usable samples
};

struct MovabilityOptions {
  int samples = 30;                    // n
  double max_boundary_fraction = 0.34; // more boundary footpoints than this: left_surface
  double jump_factor = 4.0;            // footpoint step > factor × sample step: jump
  // Also fit the footpoint distances with a cutter of this kind (the sphere radii the line
  // would need), reporting the misfit and the profile.
  std::optional<CutterKind> profile;
  // And the misfit of a second kind, from the same footpoints (Movability::second_profile_rms).
  std::optional<CutterKind> second_profile;
  // Eigen-directions of A_yy below this fraction of trace(A) are treated as free and set to
  // zero: 1e-9 keeps the exact answer on analytic data; propagation uses 1e-4 so that
  // sliding along a cylinder-like line (g·u is mesh noise there) is not amplified into motion.
  double null_cutoff = 1e-9;
  // Propagation: when both sweeps of S cost at most this, take the one tangent to Φ (closest
  // to u × mean g) rather than the cheaper one. On a cone-like line "approach Φ while sliding
  // along the axis" keeps every distance too, and noise can make it the cheaper one.
  double tangent_sweep_below = 0.0;
};

struct Movability {
  MovabilityStatus status = MovabilityStatus::degenerate;
  double value = std::numeric_limits<double>::infinity();  // F_l = λ_min(S)
  double value_other = std::numeric_limits<double>::infinity();  // λ_max(S): the other sweep
  // x = (μ1, μ2, α, λ1, λ2) in the frame (u, n1, n2), μ1² + μ2² = 1.
  double mu1 = 0, mu2 = 0, alpha = 0, lambda1 = 0, lambda2 = 0;
  Vec3 u = Vec3::Zero(), n1 = Vec3::Zero(), n2 = Vec3::Zero();
  int boundary_samples = 0;
  int samples = 0;
  // With options.profile: least-squares sphere radii d(s) = P(s) c over the footpoint
  // distances, their rms misfit, and the range of d and of |d′|.
  Cutter cutter;
  double profile_rms = 0.0;
  double second_profile_rms = std::numeric_limits<double>::infinity();
  double radius_min = 0.0, radius_max = 0.0, max_slope = 0.0;

  bool ok() const { return status == MovabilityStatus::ok; }
  // v(s) = v_m + (s − ½)(λ1 n1 + λ2 n2), v_m = α u + μ1 n1 + μ2 n2.
  Vec3 velocity(double s) const {
    return alpha * u + mu1 * n1 + mu2 * n2 + (s - 0.5) * (lambda1 * n1 + lambda2 * n2);
  }
};

// Sample parameters s_i = (i + ½)/n: the ends themselves are left out because their
// footpoints sit on Φ's boundary whenever the line spans the whole surface.
double movability_sample(int i, int n);

// Movability from given unit distance-gradient directions g_i at parameters s_i on line ab
// (#n by 3 `g`, n values `s`, optional 0/1 `weights`). Pure linear algebra, no mesh: this is
// what the analytic tests feed with exact footpoints.
// `tangent` (optional, ⟂ ab) and `tangent_below`: see MovabilityOptions::tangent_sweep_below.
Movability movability_from_directions(const Vec3& a, const Vec3& b, std::span<const double> s,
                                      PointsRef g, std::span<const double> weights = {},
                                      double null_cutoff = 1e-9, const Vec3* tangent = nullptr,
                                      double tangent_below = 0.0);

// Movability of line ab against Φ. `hints` (empty or options.samples faces) warm-starts the
// closest-point queries and receives the new footpoint faces. Runs on the calling thread.
Movability movability(const SurfaceIndex& index, const Vec3& a, const Vec3& b,
                      const MovabilityOptions& options = {}, std::span<int> hints = {});

// The same in two steps, for callers that judge one line several ways (several cutter kinds,
// say): the footpoints of its n samples at movability_sample(i, n), then the movability from
// them (options.samples is not read: n is footpoints.size()). movability() is exactly
// movability_from_footpoints(a, b, line_footpoints(index, a, b, options.samples, hints), options).
std::vector<ClosestPoint> line_footpoints(const SurfaceIndex& index, const Vec3& a, const Vec3& b, int n,
                                          std::span<int> hints = {});
Movability movability_from_footpoints(const Vec3& a, const Vec3& b, std::span<const ClosestPoint> footpoints,
                                      const MovabilityOptions& options);

}  // namespace flank
