// The one tolerance turned into every threshold: each a fixed positive multiple of it (the
// multiples of solver/thresholds.cpp; the header documents sweep_misfit = 2τ and the others'
// roles), and validate() refusing a tolerance that is not a positive finite number.
#include "solver/thresholds.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace flank {
namespace {

TEST(Thresholds, EveryThresholdIsItsMultipleOfTheTolerance) {
  for (double tol : {1e-6, 1e-4, 3e-4, 0.01, 2.5, 1e3}) {
    SCOPED_TRACE(tol);
    const Thresholds t = thresholds_for(tol);
    EXPECT_EQ(t.tolerance, tol);
    EXPECT_DOUBLE_EQ(t.sweep_misfit, 2.0 * tol);  // "beyond 2τ no refit ... brings it back"
    EXPECT_DOUBLE_EQ(t.line_misfit, 1.0 * tol);
    EXPECT_DOUBLE_EQ(t.kind_misfit, 0.25 * tol);
    EXPECT_DOUBLE_EQ(t.simplify, 16.0 * tol);
    EXPECT_DOUBLE_EQ(t.gouge, 1.0 * tol);
    for (double v : {t.tolerance, t.sweep_misfit, t.line_misfit, t.kind_misfit, t.simplify, t.gouge})
      EXPECT_GT(v, 0.0);
    // Their order, which the stages rely on: a candidate's kind must fit tighter than the line
    // itself, which must fit tighter than a sweep may drift. (simplify only bounds which refits
    // are tried: a refit moves the motion to absorb it.)
    EXPECT_LT(t.kind_misfit, t.line_misfit);
    EXPECT_LT(t.line_misfit, t.sweep_misfit);
    EXPECT_EQ(t.validate(), "");
  }
}

// Scaling the tolerance scales every threshold: none hides an absolute constant.
TEST(Thresholds, ScaleWithTheTolerance) {
  const Thresholds a = thresholds_for(1e-4), b = thresholds_for(1e-4 * 8.0);
  EXPECT_DOUBLE_EQ(b.sweep_misfit, 8.0 * a.sweep_misfit);
  EXPECT_DOUBLE_EQ(b.line_misfit, 8.0 * a.line_misfit);
  EXPECT_DOUBLE_EQ(b.kind_misfit, 8.0 * a.kind_misfit);
  EXPECT_DOUBLE_EQ(b.simplify, 8.0 * a.simplify);
  EXPECT_DOUBLE_EQ(b.gouge, 8.0 * a.gouge);
}

TEST(Thresholds, ValidateNamesABadTolerance) {
  const double inf = std::numeric_limits<double>::infinity();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (double tol : {0.0, -0.0, -1e-4, -inf, inf, nan}) {
    SCOPED_TRACE(tol);
    const std::string e = thresholds_for(tol).validate();
    EXPECT_NE(e.find("tolerance"), std::string::npos) << e;
  }
  // A default (all zero) set is refused; so is one threshold spoiled by hand.
  EXPECT_FALSE(Thresholds{}.validate().empty());
  Thresholds t = thresholds_for(1e-3);
  t.simplify = 0.0;
  EXPECT_FALSE(t.validate().empty());
  t = thresholds_for(1e-3);
  t.gouge = nan;
  EXPECT_FALSE(t.validate().empty());
  // The smallest positive tolerances are still accepted when every multiple stays positive.
  EXPECT_EQ(thresholds_for(1e-300).validate(), "");
}

}  // namespace
}  // namespace flank
