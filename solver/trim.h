// Trimming (DESIGN §4.5 "Afterwards trim"): keep the part of a fitted sweep that is within
// tolerance, along the sweep (t) and along the cutter (s); refit; repeat until stable. A sweep
// that leaves tolerance in its middle gives several pieces, each its own candidate.
#pragma once

#include <string>
#include <vector>

#include "solver/evaluate_patch.h"
#include "solver/fit_motion.h"

namespace flank {

// A rectangle of the (t, s) sample grid, inclusive bounds.
struct TrimRange {
  int row0 = 0, row1 = 0;  // rows (t)
  int col0 = 0, col1 = 0;  // columns (s)
  int within = 0;          // samples within tolerance inside it (its worth)
  bool empty = true;
  bool full(const ErrorGrid& g) const {
    return !empty && row0 == 0 && row1 == g.rows - 1 && col0 == 0 && col1 == g.cols - 1;
  }
  int rows() const { return row1 - row0 + 1; }
  int cols() const { return col1 - col0 + 1; }
};

struct PieceOptions {
  int min_rows = 4;   // along the sweep: fewer is no patch
  int min_cols = 3;   // along the cutter
  // A piece beside the best one is kept when it holds at least this fraction of the best
  // piece's samples within tolerance.
  double min_fraction = 0.15;
  int max_pieces = 3;
};

// The rectangle holding the most samples within tolerance and none out of it (samples beyond
// Φ's edge are allowed and count nothing: the cutter may overhang the part). Ties keep the
// first found: the lowest first column, then the lowest last column, then the lowest first
// row. It then grows by the rows and columns beside it that hold nothing out of tolerance and
// shrinks to those holding samples within tolerance plus one of pure overhang past each end,
// never below min_rows × min_cols. Empty when no rectangle of that size holds a sample within
// tolerance.
TrimRange find_trim(const ErrorGrid& grid, double tolerance, const PieceOptions& options = {});

// The best rectangle, then recursively the best ones in the rows before and after it: the
// pieces of a sweep that leaves tolerance in its middle, best first.
std::vector<TrimRange> find_pieces(const ErrorGrid& grid, double tolerance,
                                   const PieceOptions& options = {});

struct FitPatchOptions {
  FitOptions fit;
  double tolerance = 0.0;  // absolute
  int max_rounds = 3;      // refits after trimming
  // A trim that keeps at least this fraction of the grid is cut without a refit (1: always
  // refit): a refit of nearly the same range changes nearly nothing and costs a whole fit.
  double refit_below = 1.0;
  // Iterations of a refit after a trim (0: fit.max_iterations). It starts from the fitted
  // motion cut to the kept range, near its optimum already.
  int refit_iterations = 0;
  PieceOptions pieces;
  // Also return the other pieces of the first trim (as restricted, not yet refitted starts).
  bool keep_pieces = false;
  bool untrusted_edges = false;  // the index is a smoothed scan (see sample_errors)

  std::string validate() const;
};

enum class FitPatchStatus { ok, fit_failed, nothing_within_tolerance };

// A sweep restricted to a piece of its grid: a start for another fit.
struct PieceStart {
  Motion motion;
  Cutter cutter;
};

struct FitPatchResult {
  FitPatchStatus status = FitPatchStatus::fit_failed;
  FitResult fit;     // the last fit
  int rounds = 0;    // trims applied
  std::string message;
  std::vector<PieceStart> other_pieces;  // with keep_pieces: the first trim's other pieces
};

// fit_motion, then trim to the best piece and refit until the kept range is the whole motion.
FitPatchResult fit_and_trim(const SurfaceIndex& index, const Motion& init,
                            const FitPatchOptions& options, const Cutter* init_cutter = nullptr);

// The cutter restricted to s ∈ [s0, s1] and re-parametrised over [0, 1]. A spline profile is
// refitted by least squares there, which may overshoot a little: its coefficients are kept
// within [radius_min, radius_max] when those are given (> 0), so it stays the real tool it was.
Cutter restrict_cutter(const Cutter& cutter, double s0, double s1, double radius_min = 0.0,
                       double radius_max = 0.0);

// The motion and cutter of `range` of a grid over them (radius bounds as restrict_cutter).
PieceStart restrict_to(const Motion& motion, const Cutter& cutter, const TrimRange& range,
                       const ErrorGrid& grid, double radius_min = 0.0, double radius_max = 0.0);

}  // namespace flank
