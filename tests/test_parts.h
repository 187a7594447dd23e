// Shared ground truth for the solver tests: the Li–Mann–Bedi part (Table 1 guiding curves)
// machined by a known cutter, synthesised exactly by our forward model.
#pragma once

#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "solver/motion.h"
#include "solver/synth.h"

namespace flank::testing {

enum class PaperTool { cylinder, cone, barrel };

inline ToolProfile paper_profile(PaperTool tool) {
  switch (tool) {
    case PaperTool::cylinder: return cylinder_profile(kPaperToolLength, 5.0);
    case PaperTool::cone: return cone_profile(kPaperToolLength, 4.0, 7.0);
    case PaperTool::barrel:
      return barrel_profile(kPaperToolLength, kPaperBarrelR0, kPaperBarrelEndRadius);
  }
  return cylinder_profile(kPaperToolLength, 5.0);
}

inline CutterKind paper_kind(PaperTool tool) {
  return tool == PaperTool::cylinder ? CutterKind::cylinder
         : tool == PaperTool::cone   ? CutterKind::cone
                                     : CutterKind::barrel;
}

inline const char* paper_name(PaperTool tool) {
  return tool == PaperTool::cylinder ? "cylinder" : tool == PaperTool::cone ? "cone" : "barrel";
}

// The recovery tests' resolution: 361 × 91 (t × s) keeps the chord error under
// 5e-6 × bbox diagonal for all three cutters (checked in fit_motion_test).
constexpr int kRecoveryRows = 481;
constexpr int kRecoveryCols = 121;

inline SynthResult paper_part(PaperTool tool, int rows = kRecoveryRows, int cols = kRecoveryCols) {
  SynthOptions so;
  so.rows = rows;
  so.cols = cols;
  return synth_envelope(guide_motion(paper_guides(), kPaperToolLength), paper_profile(tool), so);
}

// True axes at `count` parameters, each moved `offset` mm off the axis and turned `degrees`
// about its midpoint: the surface-driven start of the recovery tests.
inline std::vector<Line> perturbed_axes(int count, double offset, double degrees) {
  const AxisMotion motion = guide_motion(paper_guides(), kPaperToolLength);
  std::vector<Line> lines;
  for (int i = 0; i < count; ++i) {
    const double t = static_cast<double>(i) / (count - 1);
    const Vec3 a = motion.a(t, 0), b = motion.b(t, 0);
    const Vec3 u = (b - a).normalized();
    // Alternate the offset direction so that no single rigid shift explains the error.
    const Vec3 n = (i % 2 ? 1.0 : -1.0) * u.cross(motion.a(t, 1)).normalized();
    const Vec3 mid = 0.5 * (a + b) + offset * n;
    const Eigen::AngleAxisd turn(degrees * std::numbers::pi / 180.0, u.cross(n).normalized());
    const Vec3 u2 = turn * u;
    const double half = 0.5 * (b - a).norm();
    lines.push_back({mid - half * u2, mid + half * u2});
  }
  return lines;
}

// The true motion of the paper part as a motion of flank's own: clamped cubic B-splines with
// `count` control points through 201 true rulings at their own parameters.
inline Motion true_motion(int count) {
  const AxisMotion truth = guide_motion(paper_guides(), kPaperToolLength);
  std::vector<Line> rulings;
  std::vector<double> params;
  for (int i = 0; i <= 200; ++i) {
    const double t = i / 200.0;
    rulings.push_back({truth.a(t, 0), truth.b(t, 0)});
    params.push_back(t);
  }
  return Motion::fit(rulings, count, params);
}

}  // namespace flank::testing
