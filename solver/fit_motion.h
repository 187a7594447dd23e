// Joint fit of the axis motion and the cutter profile to Φ (paper §4.5, DESIGN "Motion and
// cutter fit"): Gauss–Newton with Levenberg–Marquardt damping on
//   F = μ1 F_plane + μ2 F_fair + μ3 F_point + μ4 F_rigid,
// footpoints recomputed every iteration, the sparse normal matrix factorised with CHOLMOD
// (symbolic analysis once per call).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "kernels/cutter.h"
#include "kernels/surface_index.h"
#include "solver/motion.h"

namespace flank {

struct FitOptions {
  CutterKind kind = CutterKind::cone;
  int samples_t = 100;      // m
  int samples_s = 30;       // n
  // K per boundary curve; 0 keeps the initial motion's. 40 because the motions of real
  // parts (e.g. an axis through two guide curves, normalised to a fixed length) are not
  // polynomial: with 12–16 the spline's own error biases the cutter radius by tenths of a mm.
  int control_points = 40;
  // Paper defaults (§4.5), for Φ normalised to a unit bbox diagonal; the fit normalises by
  // `scale` so they mean the same on parts of any size.
  double weight_plane = 1.0;
  double weight_fair = 0.1;
  double weight_point = 0.001;
  double weight_rigid = 0.1;
  int max_iterations = 60;
  // F_fair (eq. 11) is applied to each Gauss–Newton update — the second differences of the
  // step of a(t) and b(t) — rather than to the trajectory itself. On the trajectory it
  // penalises the true curvature of the motion and, unopposed along the surface, slowly
  // shrinks it: on exact envelopes that biased the cutter radius by 0.2–1.1 mm and cut the
  // coverage to 73–87%, far outside flank's 2e-5 × diagonal. On the update it keeps the
  // large early steps fair with the same μ2 and exerts no force at a converged motion; after
  // `fair_iterations` it is dropped, because it also damps the slow radius ↔ offset valley
  // that decides the cutter's radius to 0.01 mm.
  int fair_iterations = 4;
  // After an accepted step δ, one batch of closest points tries the minimum, along δ, of the
  // parabola through the cost before, its slope and the cost after, when that lies at least
  // 1.5 steps out; at most 2^max_extrapolations steps (0: never). The linear convergence along
  // the radius ↔ offset valley makes successive steps line up and fall short.
  int max_extrapolations = 4;
  double length = 0.0;  // rigid ruling length L; 0: the initial motion's mean length
  double scale = 0.0;   // normalising length; 0: bbox diagonal of Φ

  // A real tool (DESIGN "Real surfaces are not exact envelopes"): the fit keeps the sphere
  // radii within [radius_min, radius_max] (mm; 0: no bound on that side) and |d′(s)| ≤
  // max_slope_fraction · L, so that the meridian (sL − d d′/L, d √(1 − (d′/L)²)) stays valid
  // with a margin (0: no slope bound). They are linear inequalities on the profile
  // coefficients c, imposed inside every Levenberg–Marquardt step: the Bernstein and B-spline
  // bases are non-negative and sum to one, so bounding the c_k bounds d(s) for every s, and
  // bounding their scaled differences (the coefficients of d′) bounds |d′| for every s.
  // Without them a fit along a long twisted sweep can shrink the cutter to a few hundredths
  // of a millimetre: the axis then lies on Φ and the "cutter" is a line.
  double radius_min = 0.0;
  double radius_max = 0.0;
  double max_slope_fraction = 0.9;
  // Guard on the active-set iterations per step; the primal method ends after a few, since
  // each adds or drops one of at most 2 (2 nc − 1) constraints.
  int active_set_iterations = 50;

  // One line per Levenberg–Marquardt trial (damping, cost before and after, fairness of the
  // step, interior samples, largest motion step, active cutter constraints); empty: silent.
  std::function<void(const std::string&)> trace;

  // Empty when valid, else a one-line reason.
  std::string validate() const;
};

enum class FitStatus {
  converged,
  max_iterations,
  not_positive_definite,
  left_surface,    // too few samples have footpoints inside Φ
  // The optimum has |d′| ≥ L or d ≤ 0 somewhere. Cannot happen with radius_min > 0 and
  // max_slope_fraction > 0: the fit then never leaves the valid cutters.
  invalid_cutter,
};
const char* to_string(FitStatus status);

struct FitTiming {
  double query_s = 0.0;     // closest points
  double assembly_s = 0.0;  // residuals, JᵀJ and Jᵀr
  double factor_s = 0.0;    // CHOLMOD analyse, factorise, solve
  double total_s = 0.0;
  long long queries = 0;     // closest-point queries made
  int factorisations = 0;    // numeric factorisations a step was solved with
  int made_ahead = 0;        // of them, made on a second thread before they were needed
};

struct FitResult {
  FitStatus status = FitStatus::max_iterations;
  Motion motion;
  Cutter cutter;
  double length = 0.0;
  int iterations = 0;
  double initial_cost = 0.0;
  double final_cost = 0.0;
  double interior_fraction = 0.0;  // samples whose footpoint is inside Φ, at the end
  // Cutter constraints (FitOptions::radius_min, radius_max, max_slope_fraction) that hold a
  // profile coefficient on their bound (to rounding) at the end: the fit pressed against them.
  bool radius_at_min = false;
  bool radius_at_max = false;
  bool slope_at_limit = false;
  FitTiming timing;

  bool ok() const { return status == FitStatus::converged || status == FitStatus::max_iterations; }
  bool radius_at_bound() const { return radius_at_min || radius_at_max; }
  std::string brief_report() const;
};

// `init_cutter` (optional) seeds the profile; otherwise it is fitted to the initial footpoint
// distances. The cutter kind is options.kind.
FitResult fit_motion(const SurfaceIndex& index, const Motion& init, const FitOptions& options,
                     const Cutter* init_cutter = nullptr);

// The inequality-constrained step of fit_motion, exposed for its test: minimises
//   q(δ) = ½ δᵀ H δ + gᵀ δ   subject to   A δ ≤ b   (b ≥ 0, so δ = 0 is feasible)
// for a positive definite H known only through `solve` (x = H⁻¹ rhs; false on failure) and
// the unconstrained minimiser `free_step` = −H⁻¹ g. Primal active-set method (Nocedal &
// Wright, Algorithm 16.3) from δ = 0: step toward the minimiser on the working set's
// equalities, stop at the first constraint in the way and add it, drop the constraint of the
// most negative multiplier once the minimiser is feasible. Every iterate is feasible and
// none raises q, so the step is usable even when `max_iterations` cuts it short. H⁻¹aᵢ costs one
// solve per constraint that ever blocks. A is #constraints by #δ; the working set is kept
// linearly independent (a row in the span of its rows never enters). Violations up to
// `tolerance` (in the units of b; above the rounding of δ) count as feasible. Not ok when a
// solve fails or H turns out not numerically positive definite along the constraints.
struct ActiveSetStep {
  bool ok = false;          // false: a solve failed or H is not numerically positive definite
  bool optimal = false;     // KKT conditions met (else max_iterations cut it short)
  VecX step;                // δ
  std::vector<int> active;  // rows of A in the final working set, ascending
  VecX multipliers;         // when optimal: their Lagrange multipliers, all ≥ 0
  int iterations = 0;
};
ActiveSetStep active_set_step(const std::function<bool(const VecX& rhs, VecX* x)>& solve,
                              const VecX& free_step, const MatX& A, const VecX& b,
                              double tolerance, int max_iterations);

}  // namespace flank
