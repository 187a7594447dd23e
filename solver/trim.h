// Trimming (DESIGN §4.5 "Afterwards trim"): keep the longest t-interval, and within it the
// s-range of the cutter, where the error is within tolerance; refit; repeat until stable.
#pragma once

#include <string>

#include "solver/evaluate_patch.h"
#include "solver/fit_motion.h"

namespace flank {

struct TrimRange {
  int row0 = 0, row1 = 0;  // inclusive grid rows (t)
  int col0 = 0, col1 = 0;  // inclusive grid columns (s)
  bool empty = true;
  bool full(const ErrorGrid& g) const {
    return !empty && row0 == 0 && row1 == g.rows - 1 && col0 == 0 && col1 == g.cols - 1;
  }
};

// Longest run of rows whose samples inside Φ are all within tolerance (and that have some),
// then the longest run of such columns within it.
TrimRange find_trim(const ErrorGrid& grid, double tolerance);

struct FitPatchOptions {
  FitOptions fit;
  double tolerance = 0.0;  // absolute
  int max_rounds = 3;      // refits after trimming
  int min_rows = 4;        // a trimmed range shorter than this is no patch

  std::string validate() const;
};

enum class FitPatchStatus { ok, fit_failed, nothing_within_tolerance };

struct FitPatchResult {
  FitPatchStatus status = FitPatchStatus::fit_failed;
  FitResult fit;     // the last fit
  int rounds = 0;    // trims applied
  std::string message;
};

// fit_motion, then trim and refit until the kept range is the whole motion.
FitPatchResult fit_and_trim(const SurfaceIndex& index, const Motion& init,
                            const FitPatchOptions& options, const Cutter* init_cutter = nullptr);

// The cutter restricted to s ∈ [s0, s1] and re-parametrised over [0, 1].
Cutter restrict_cutter(const Cutter& cutter, double s0, double s1);

}  // namespace flank
