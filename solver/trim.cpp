#include "solver/trim.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace flank {

std::string FitPatchOptions::validate() const {
  if (std::string e = fit.validate(); !e.empty()) return e;
  if (!(tolerance > 0.0) || !std::isfinite(tolerance)) return "tolerance must be positive";
  if (max_rounds < 0) return "trim rounds must not be negative";
  if (refit_iterations < 0) return "refit iterations must not be negative";
  if (pieces.min_rows < 2 || pieces.min_cols < 2) return "a piece needs at least 2 by 2 samples";
  return {};
}

namespace {

// The best rectangle within rows [r_begin, r_end) (see find_trim).
TrimRange best_rectangle(const std::vector<SampleClass>& cls, int rows, int cols, int r_begin,
                         int r_end, const PieceOptions& o) {
  TrimRange best;
  if (r_end - r_begin < o.min_rows) return best;
  auto at = [&](int i, int j) { return cls[static_cast<std::size_t>(i) * cols + j]; };
  std::vector<char> bad(static_cast<std::size_t>(rows));
  std::vector<int> within(static_cast<std::size_t>(rows));
  // The samples within tolerance in columns c and beyond (all rows of the range): no
  // rectangle from column c on holds more.
  std::vector<int> beyond(static_cast<std::size_t>(cols) + 1, 0);
  for (int j = cols - 1; j >= 0; --j) {
    int n = 0;
    for (int i = r_begin; i < r_end; ++i) n += at(i, j) == SampleClass::within;
    beyond[static_cast<std::size_t>(j)] = beyond[static_cast<std::size_t>(j) + 1] + n;
  }
  // Every column range [c0, c1], and within it the best run of rows with no sample out of
  // tolerance: O(cols² · rows) at most. A rectangle is taken only if it holds more than the
  // best so far, so the ranges that provably cannot are skipped: the same rectangle, and on
  // a grid mostly within tolerance (a finished patch's) a few passes over it instead of cols.
  for (int c0 = 0; c0 < cols; ++c0) {
    if (beyond[static_cast<std::size_t>(c0)] <= best.within) break;
    std::fill(bad.begin(), bad.end(), 0);
    std::fill(within.begin(), within.end(), 0);
    for (int c1 = c0; c1 < cols; ++c1) {
      int open = 0;  // within tolerance in [c0, c1], over the rows still clean there
      for (int i = r_begin; i < r_end; ++i) {
        bad[i] |= at(i, c1) == SampleClass::outside;
        within[i] += at(i, c1) == SampleClass::within;
        if (!bad[i]) open += within[i];
      }
      if (c1 - c0 + 1 >= o.min_cols) {
        int run_start = r_begin, sum = 0;
        for (int i = r_begin; i <= r_end; ++i) {
          if (i < r_end && !bad[i]) {
            sum += within[i];
            continue;
          }
          if (i - run_start >= o.min_rows && sum > best.within) {
            best.row0 = run_start, best.row1 = i - 1, best.col0 = c0, best.col1 = c1;
            best.within = sum;
            best.empty = false;
          }
          run_start = i + 1;
          sum = 0;
        }
      }
      // Any range [c0, c1' > c1] keeps only rows clean here and adds at most what lies
      // beyond c1: once that cannot beat the best, no wider range from c0 can.
      if (open + beyond[static_cast<std::size_t>(c1) + 1] <= best.within) break;
    }
  }
  if (best.empty) return best;
  // Grow by the rows and columns beside it that hold nothing out of tolerance (ties of the
  // search above keep the smaller rectangle: a column of pure overhang adds no sample).
  auto clean_row = [&](int i, int c0, int c1) {
    for (int j = c0; j <= c1; ++j)
      if (at(i, j) == SampleClass::outside) return false;
    return true;
  };
  auto clean_col = [&](int j, int r0, int r1) {
    for (int i = r0; i <= r1; ++i)
      if (at(i, j) == SampleClass::outside) return false;
    return true;
  };
  for (bool grew = true; grew;) {
    grew = false;
    if (best.row0 > r_begin && clean_row(best.row0 - 1, best.col0, best.col1)) --best.row0, grew = true;
    if (best.row1 + 1 < r_end && clean_row(best.row1 + 1, best.col0, best.col1)) ++best.row1, grew = true;
    if (best.col0 > 0 && clean_col(best.col0 - 1, best.row0, best.row1)) --best.col0, grew = true;
    if (best.col1 + 1 < cols && clean_col(best.col1 + 1, best.row0, best.row1)) ++best.col1, grew = true;
  }
  // Shrink to the rows and columns that hold samples within tolerance, plus one of pure
  // overhang past each end: the last sample inside Φ may lie up to a sample spacing short of
  // Φ's edge, and cutting there would leave a strip uncut.
  int rw0 = best.row1, rw1 = best.row0, cw0 = best.col1, cw1 = best.col0;
  for (int i = best.row0; i <= best.row1; ++i)
    for (int j = best.col0; j <= best.col1; ++j)
      if (at(i, j) == SampleClass::within) {
        rw0 = std::min(rw0, i), rw1 = std::max(rw1, i);
        cw0 = std::min(cw0, j), cw1 = std::max(cw1, j);
      }
  const TrimRange grown = best;
  best.row0 = std::max(best.row0, rw0 - 1), best.row1 = std::min(best.row1, rw1 + 1);
  best.col0 = std::max(best.col0, cw0 - 1), best.col1 = std::min(best.col1, cw1 + 1);
  // Never below the minimum size: give back overhang on the side that has it.
  while (best.rows() < o.min_rows)
    (best.row1 < grown.row1 ? ++best.row1 : --best.row0);
  while (best.cols() < o.min_cols)
    (best.col1 < grown.col1 ? ++best.col1 : --best.col0);
  return best;
}

void collect_pieces(const std::vector<SampleClass>& cls, int rows, int cols, int r_begin, int r_end,
                    const PieceOptions& o, int floor, std::vector<TrimRange>* out) {
  const TrimRange r = best_rectangle(cls, rows, cols, r_begin, r_end, o);
  if (r.empty || r.within < floor) return;
  out->push_back(r);
  collect_pieces(cls, rows, cols, r_begin, r.row0, o, floor, out);
  collect_pieces(cls, rows, cols, r.row1 + 1, r_end, o, floor, out);
}

}  // namespace

TrimRange find_trim(const ErrorGrid& grid, double tolerance, const PieceOptions& options) {
  return best_rectangle(classify_samples(grid, tolerance), grid.rows, grid.cols, 0, grid.rows, options);
}

std::vector<TrimRange> find_pieces(const ErrorGrid& grid, double tolerance, const PieceOptions& options) {
  const std::vector<SampleClass> cls = classify_samples(grid, tolerance);
  std::vector<TrimRange> out;
  const TrimRange best = best_rectangle(cls, grid.rows, grid.cols, 0, grid.rows, options);
  if (best.empty) return out;
  out.push_back(best);
  const int floor = std::max(1, static_cast<int>(std::ceil(options.min_fraction * best.within)));
  collect_pieces(cls, grid.rows, grid.cols, 0, best.row0, options, floor, &out);
  collect_pieces(cls, grid.rows, grid.cols, best.row1 + 1, grid.rows, options, floor, &out);
  // Best first; ties in their order along t.
  std::stable_sort(out.begin() + 1, out.end(),
                   [](const TrimRange& a, const TrimRange& b) { return a.within > b.within; });
  if (static_cast<int>(out.size()) > options.max_pieces) out.resize(static_cast<std::size_t>(options.max_pieces));
  return out;
}

Cutter restrict_cutter(const Cutter& cutter, double s0, double s1, double radius_min, double radius_max) {
  const int samples = 41;
  std::vector<double> s(samples), r(samples);
  for (int k = 0; k < samples; ++k) {
    s[k] = static_cast<double>(k) / (samples - 1);
    r[k] = cutter.radius(s0 + s[k] * (s1 - s0));
  }
  Cutter out = Cutter::fit(cutter.kind, cutter.length * (s1 - s0), s, r);
  // The bases are non-negative and sum to one: coefficients in range keep d(s) in range.
  for (Eigen::Index k = 0; k < out.coeffs.size(); ++k) {
    if (radius_min > 0) out.coeffs(k) = std::max(out.coeffs(k), radius_min);
    if (radius_max > 0) out.coeffs(k) = std::min(out.coeffs(k), radius_max);
  }
  return out;
}

PieceStart restrict_to(const Motion& motion, const Cutter& cutter, const TrimRange& range,
                       const ErrorGrid& grid, double radius_min, double radius_max) {
  const double t0 = static_cast<double>(range.row0) / (grid.rows - 1);
  const double t1 = static_cast<double>(range.row1) / (grid.rows - 1);
  const double s0 = static_cast<double>(range.col0) / (grid.cols - 1);
  const double s1 = static_cast<double>(range.col1) / (grid.cols - 1);
  return {motion.restricted(t0, t1, s0, s1, motion.count()),
          restrict_cutter(cutter, s0, s1, radius_min, radius_max)};
}

FitPatchResult fit_and_trim(const SurfaceIndex& index, const Motion& init,
                            const FitPatchOptions& options, const Cutter* init_cutter) {
  FitPatchResult out;
  FitOptions fo = options.fit;
  out.fit = fit_motion(index, init, fo, init_cutter);
  for (;;) {
    if (!out.fit.ok()) {
      out.status = FitPatchStatus::fit_failed;
      out.message = std::string("fit ") + to_string(out.fit.status);
      return out;
    }
    const ErrorGrid grid = sample_errors(index, out.fit.motion, out.fit.cutter, fo.samples_t,
                                         fo.samples_s, options.untrusted_edges);
    std::vector<TrimRange> pieces;
    if (out.rounds == 0 && options.keep_pieces)
      pieces = find_pieces(grid, options.tolerance, options.pieces);
    else if (TrimRange r = find_trim(grid, options.tolerance, options.pieces); !r.empty)
      pieces.push_back(r);
    if (pieces.empty()) {
      out.status = FitPatchStatus::nothing_within_tolerance;
      out.message = "no part of the motion is within tolerance";
      return out;
    }
    for (std::size_t k = 1; k < pieces.size(); ++k)
      out.other_pieces.push_back(restrict_to(out.fit.motion, out.fit.cutter, pieces[k], grid,
                                             fo.radius_min, fo.radius_max));
    const TrimRange& range = pieces.front();
    if (range.full(grid)) {
      out.status = FitPatchStatus::ok;
      return out;
    }
    const PieceStart next = restrict_to(out.fit.motion, out.fit.cutter, range, grid, fo.radius_min, fo.radius_max);
    // A cut that keeps most of the sweep and of the cutter changes the fit little: cut without
    // refitting. The last round may still hold samples out of tolerance: cut them likewise.
    const double kept = static_cast<double>(range.rows()) * range.cols() / (static_cast<double>(grid.rows) * grid.cols);
    if (out.rounds >= options.max_rounds || kept >= options.refit_below) {
      out.status = FitPatchStatus::ok;
      out.fit.motion = next.motion;
      out.fit.cutter = next.cutter;
      out.fit.length = next.cutter.length;
      return out;
    }
    fo.length = next.cutter.length;
    if (options.refit_iterations > 0) fo.max_iterations = options.refit_iterations;
    ++out.rounds;
    out.fit = fit_motion(index, next.motion, fo, &next.cutter);
  }
}

}  // namespace flank
