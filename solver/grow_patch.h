// Growth of a candidate line into candidate patches (DESIGN "Automatic decomposition"): the
// line's probe sweep starts a motion, fit_motion fits it with its cutter, the fit is trimmed
// along the sweep and along the cutter to what is within tolerance and refitted; a sweep that
// leaves tolerance in its middle gives its other pieces as candidates too. Each piece is
// evaluated (Ω's error, coverage, gouge, holder) and kept only as a real, gouge-free tool.
// finish_patch gives a chosen patch the simplest cutter kind that cuts the same surface and
// evaluates it finely.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "kernels/surface_index.h"
#include "solver/candidate_lines.h"
#include "solver/evaluate_patch.h"
#include "solver/patch.h"
#include "solver/thresholds.h"
#include "solver/trim.h"

namespace flank {

struct GrowOptions {
  FitOptions fit;               // kind, control points, samples, iterations, radius range
  int trim_rounds = 1;          // trim + refit rounds
  double refit_below = 0.8;     // a trim keeping more of the grid is cut without refit
  // Iterations of a fit that starts from a fitted motion: after a trim, and of the first
  // trim's other pieces (0: fit.max_iterations).
  int refit_iterations = 0;
  PieceOptions pieces;
  double length_min = 0.0;      // a piece whose cutter is shorter is no real tool (absolute)
  EvaluateOptions evaluate;     // grid, holder; coverage is always measured
  Thresholds thresholds;
  // Φ as given when the index grown on is a smoothed copy of it (see evaluate_patch); not owned.
  const SurfaceIndex* given = nullptr;
  std::function<void(const std::string&)> trace;  // one line per grown candidate

  std::string validate() const;
};

struct Grown {
  std::vector<Patch> patches;  // valid pieces, best first
  int pieces = 0;              // pieces fitted, valid or not
  double seconds = 0.0;        // wall time of the growth, on its thread
};

// On the calling thread's share of the pool (fits and evaluations use the parallel facade).
Grown grow_patch(const SurfaceIndex& index, const LineCandidate& candidate, const GrowOptions& options);

// Whether a patch is a real, gouge-free, collision-free tool covering something: why not, or
// empty when it is.
std::string reject_reason(const Patch& patch, const GrowOptions& options);

struct FinishOptions {
  GrowOptions grow;                 // as the patch was grown: refits of a simpler kind use it
  std::vector<CutterKind> simpler;  // kinds to try in place of the fitted one, simplest first
  EvaluateOptions evaluate;         // the final evaluation, with Ω kept as a mesh
};

// The patch with the simplest allowed cutter kind whose least-squares radii stay within
// thresholds.simplify of the fitted ones everywhere and that, refitted from the patch's motion
// (grow.refit_iterations Gauss–Newton iterations where set), covers at least 99% as much area
// and 97% of the same (the fitted kind's covered vertices);
// evaluated on the final grid. Empty when it is no valid patch there.
std::optional<Patch> finish_patch(const SurfaceIndex& index, const Patch& patch,
                                  const FinishOptions& options);

}  // namespace flank
