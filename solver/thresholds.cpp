#include "solver/thresholds.h"

#include <cmath>

namespace flank {

std::string Thresholds::validate() const {
  for (double v : {tolerance, sweep_misfit, line_misfit, kind_misfit, simplify, gouge})
    if (!std::isfinite(v) || !(v > 0.0)) return "tolerance must be positive";
  return {};
}

Thresholds thresholds_for(double tolerance) {
  Thresholds t;
  t.tolerance = tolerance;
  t.sweep_misfit = 2.0 * tolerance;
  t.line_misfit = tolerance;
  t.kind_misfit = 0.25 * tolerance;
  t.simplify = 16.0 * tolerance;
  t.gouge = tolerance;
  return t;
}

}  // namespace flank
