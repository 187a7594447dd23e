#include "solver/trim.h"

#include <cmath>
#include <vector>

namespace flank {

std::string FitPatchOptions::validate() const {
  if (std::string e = fit.validate(); !e.empty()) return e;
  if (!(tolerance > 0.0) || !std::isfinite(tolerance)) return "tolerance must be positive";
  if (max_rounds < 0) return "trim rounds must not be negative";
  return {};
}

namespace {
// Longest run of `ok` entries; ties keep the first. Returns false when there is none.
bool longest_run(const std::vector<char>& ok, int* begin, int* end) {
  int best = 0, run_start = 0;
  bool found = false;
  for (int i = 0; i <= static_cast<int>(ok.size()); ++i) {
    if (i < static_cast<int>(ok.size()) && ok[i]) continue;
    if (i - run_start > best) {
      best = i - run_start;
      *begin = run_start, *end = i - 1;
      found = true;
    }
    run_start = i + 1;
  }
  return found;
}
}  // namespace

TrimRange find_trim(const ErrorGrid& grid, double tolerance) {
  TrimRange range;
  std::vector<char> row_ok(static_cast<std::size_t>(grid.rows), 0);
  std::vector<char> row_out(static_cast<std::size_t>(grid.rows), 0);  // nothing inside Φ
  for (int i = 0; i < grid.rows; ++i) {
    int inside = 0;
    bool within = true;
    for (int j = 0; j < grid.cols; ++j) {
      if (!grid.inside(i, j)) continue;
      ++inside;
      if (std::abs(grid.at(i, j)) > tolerance) within = false;
    }
    // Samples beyond Φ's boundary are overhang, not error: a row goes only when it is out of
    // tolerance or has nothing inside Φ at all.
    row_ok[i] = within && inside > 0;
    row_out[i] = inside == 0;
  }
  if (!longest_run(row_ok, &range.row0, &range.row1)) return range;
  // Keep one sample of pure overhang past each end: the run's last sample inside Φ may lie up
  // to a sample spacing short of Φ's edge, and cutting there leaves a strip uncut.
  if (range.row0 > 0 && row_out[range.row0 - 1]) --range.row0;
  if (range.row1 < grid.rows - 1 && row_out[range.row1 + 1]) ++range.row1;
  std::vector<char> col_ok(static_cast<std::size_t>(grid.cols), 0);
  std::vector<char> col_out(static_cast<std::size_t>(grid.cols), 0);
  for (int j = 0; j < grid.cols; ++j) {
    int inside = 0;
    bool within = true;
    for (int i = range.row0; i <= range.row1; ++i) {
      if (!grid.inside(i, j)) continue;
      ++inside;
      if (std::abs(grid.at(i, j)) > tolerance) within = false;
    }
    col_ok[j] = within && inside > 0;
    col_out[j] = inside == 0;
  }
  if (!longest_run(col_ok, &range.col0, &range.col1)) return range;
  if (range.col0 > 0 && col_out[range.col0 - 1]) --range.col0;
  if (range.col1 < grid.cols - 1 && col_out[range.col1 + 1]) ++range.col1;
  range.empty = false;
  return range;
}

Cutter restrict_cutter(const Cutter& cutter, double s0, double s1) {
  const int samples = 41;
  std::vector<double> s(samples), r(samples);
  for (int k = 0; k < samples; ++k) {
    s[k] = static_cast<double>(k) / (samples - 1);
    r[k] = cutter.radius(s0 + s[k] * (s1 - s0));
  }
  return Cutter::fit(cutter.kind, cutter.length * (s1 - s0), s, r);
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
                                         fo.samples_s);
    const TrimRange range = find_trim(grid, options.tolerance);
    if (range.empty || range.row1 - range.row0 + 1 < options.min_rows) {
      out.status = FitPatchStatus::nothing_within_tolerance;
      out.message = "no part of the motion is within tolerance";
      return out;
    }
    if (range.full(grid) || out.rounds >= options.max_rounds) {
      out.status = FitPatchStatus::ok;
      // The last round may still hold rows out of tolerance: cut them without a refit.
      if (!range.full(grid)) {
        const double t0 = static_cast<double>(range.row0) / (grid.rows - 1);
        const double t1 = static_cast<double>(range.row1) / (grid.rows - 1);
        const double s0 = static_cast<double>(range.col0) / (grid.cols - 1);
        const double s1 = static_cast<double>(range.col1) / (grid.cols - 1);
        out.fit.motion = out.fit.motion.restricted(t0, t1, s0, s1, out.fit.motion.count());
        out.fit.cutter = restrict_cutter(out.fit.cutter, s0, s1);
        out.fit.length = out.fit.cutter.length;
      }
      return out;
    }
    const double t0 = static_cast<double>(range.row0) / (grid.rows - 1);
    const double t1 = static_cast<double>(range.row1) / (grid.rows - 1);
    const double s0 = static_cast<double>(range.col0) / (grid.cols - 1);
    const double s1 = static_cast<double>(range.col1) / (grid.cols - 1);
    const Motion next = out.fit.motion.restricted(t0, t1, s0, s1, out.fit.motion.count());
    const Cutter cutter = restrict_cutter(out.fit.cutter, s0, s1);
    fo.length = cutter.length;
    ++out.rounds;
    out.fit = fit_motion(index, next, fo, &cutter);
  }
}

}  // namespace flank
