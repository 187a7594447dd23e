// Joint fit of the axis motion and the cutter profile to Φ (paper §4.5, DESIGN "Motion and
// cutter fit"): Gauss–Newton with Levenberg–Marquardt damping on
//   F = μ1 F_plane + μ2 F_fair + μ3 F_point + μ4 F_rigid,
// footpoints recomputed every iteration, the sparse normal matrix factorised with CHOLMOD
// (symbolic analysis once per call).
#pragma once

#include <string>

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
  // After an accepted step, try it again at 1×, 2×, 4× … while the cost falls.
  int max_extrapolations = 4;
  double length = 0.0;  // rigid ruling length L; 0: the initial motion's mean length
  double scale = 0.0;   // normalising length; 0: bbox diagonal of Φ

  // Empty when valid, else a one-line reason.
  std::string validate() const;
};

enum class FitStatus {
  converged,
  max_iterations,
  not_positive_definite,
  left_surface,    // too few samples have footpoints inside Φ
  invalid_cutter,  // the optimum has |d′| ≥ L or d ≤ 0 somewhere
};
const char* to_string(FitStatus status);

struct FitTiming {
  double query_s = 0.0;     // closest points
  double assembly_s = 0.0;  // residuals, JᵀJ and Jᵀr
  double factor_s = 0.0;    // CHOLMOD analyse, factorise, solve
  double total_s = 0.0;
  long long queries = 0;     // closest-point queries made
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
  FitTiming timing;

  bool ok() const { return status == FitStatus::converged || status == FitStatus::max_iterations; }
  std::string brief_report() const;
};

// `init_cutter` (optional) seeds the profile; otherwise it is fitted to the initial footpoint
// distances. The cutter kind is options.kind.
FitResult fit_motion(const SurfaceIndex& index, const Motion& init, const FitOptions& options,
                     const Cutter* init_cutter = nullptr);

}  // namespace flank
