// Exact recovery (DESIGN §4.5, issue "engine"): the forward model machines the Li–Mann–Bedi
// part with a known cutter; fit must find that cutter and motion again from rough starts,
// through noise and holes.
#include "solver/fit_motion.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <random>

#include "solver/evaluate_patch.h"
#include "solver/propagate.h"
#include "solver/trim.h"
#include "test_parts.h"

namespace flank {
namespace {

using testing::PaperTool;

struct Recovered {
  FitPatchResult fit;
  Patch patch;
};

Recovered recover(const SurfaceIndex& index, const Motion& init, CutterKind kind, double tolerance) {
  FitPatchOptions fo;
  fo.fit.kind = kind;
  fo.tolerance = tolerance;
  Recovered r;
  r.fit = fit_and_trim(index, init, fo);
  EvaluateOptions eo;
  eo.tolerance = tolerance;
  r.patch = evaluate_patch(index, r.fit.fit.motion, r.fit.fit.cutter, eo);
  return r;
}

class ExactRecovery : public ::testing::TestWithParam<PaperTool> {};

TEST_P(ExactRecovery, ChordErrorOfTheTestMesh) {
  const SynthResult part = testing::paper_part(GetParam());
  ASSERT_EQ(part.invalid, 0);
  EXPECT_LT(part.chord_error, 5e-6 * bbox_diagonal(part.mesh))
      << testing::kRecoveryRows << "x" << testing::kRecoveryCols;
}

TEST_P(ExactRecovery, FromSurfaceDrivenLinesOffsetAndTurned) {
  const PaperTool tool = GetParam();
  const SynthResult part = testing::paper_part(tool);
  const SurfaceIndex index(part.mesh);
  const double diag = index.diagonal();
  // Seven lines, each 1 mm off the true axis and turned 2°.
  const Motion init = motion_from_lines(testing::perturbed_axes(7, 1.0, 2.0), 40);
  const Recovered r = recover(index, init, testing::paper_kind(tool), 1e-4 * diag);
  ASSERT_EQ(r.fit.status, FitPatchStatus::ok) << r.fit.message;
  EXPECT_LE(r.patch.error.max, 2e-5 * diag) << testing::paper_name(tool);
  EXPECT_GE(r.patch.coverage_fraction, 0.95) << testing::paper_name(tool);
  const Cutter& c = r.fit.fit.cutter;
  std::printf("[ recovered ] %s: sphere radii %.4f .. %.4f, L %.3f, max|e| %.2e x diag, coverage %.4f\n",
              testing::paper_name(tool), c.radius(0), c.radius(1), c.length,
              r.patch.error.max / diag, r.patch.coverage_fraction);
  if (tool == PaperTool::cylinder) {
    EXPECT_NEAR(c.radius(0.5), 5.0, 0.01);
  }
  if (tool == PaperTool::cone) {
    // The trimmed cutter may be shorter than 50: compare the meridian where it is.
    const Vec2 ends = c.cone_end_radii();
    const double k = (ends(1) - ends(0)) / c.length;
    EXPECT_NEAR(k, 3.0 / 50.0, 0.05 / 50.0);
    EXPECT_NEAR(ends(0) - 4.0 - k * 0.0, 0.0, 0.05 + std::abs(c.length - 50.0) * k + 0.05);
  }
}

INSTANTIATE_TEST_SUITE_P(PaperTools, ExactRecovery,
                         ::testing::Values(PaperTool::cylinder, PaperTool::cone, PaperTool::barrel),
                         [](const auto& p) { return std::string(testing::paper_name(p.param)); });

TEST(ExactRecoveryLineDriven, CylinderFromOneLine) {
  const SynthResult part = testing::paper_part(PaperTool::cylinder);
  const SurfaceIndex index(part.mesh);
  const double diag = index.diagonal();
  // One line: the true axis at the middle of the motion, 1 mm off and turned 2°.
  const std::vector<Line> lines = testing::perturbed_axes(3, 1.0, 2.0);
  const LineStart start = line_driven_start(index, lines[1], CutterKind::cylinder, 40);
  ASSERT_TRUE(start.ok) << start.message;
  const Recovered r = recover(index, start.motion, CutterKind::cylinder, 1e-4 * diag);
  ASSERT_EQ(r.fit.status, FitPatchStatus::ok) << r.fit.message;
  EXPECT_LE(r.patch.error.max, 2e-5 * diag);
  EXPECT_GE(r.patch.coverage_fraction, 0.95);
  std::printf("[ recovered ] line-driven cylinder: radius %.4f, max|e| %.2e x diag, coverage %.4f\n",
              r.fit.fit.cutter.radius(0.5), r.patch.error.max / diag, r.patch.coverage_fraction);
  // The radius ↔ offset valley is flat here: the fit ends (60 iterations) at a cost within 1e-3
  // of the best seen with radii from 4.989 to 4.992 (the step extension decides where), while
  // Ω stays within 1e-5 of the diagonal. The radius is what the data settles to ±0.015.
  EXPECT_NEAR(r.fit.fit.cutter.radius(0.5), 5.0, 0.015);
}

// Ω against the clean surface: the largest |e| of the fitted sphere family on it.
double error_against(const Mesh& clean, const Patch& p) {
  const SurfaceIndex index(clean);
  EvaluateOptions eo;
  eo.tolerance = 1.0;
  eo.envelope = eo.coverage = false;
  return evaluate_patch(index, p.motion, p.cutter, eo).error.max;
}

TEST(Robustness, GaussianNoiseOnVertices) {
  // 241 × 61: the coarser the mesh, the less the closest point to a rough surface is pulled
  // toward its noise peaks (the bias is what the bound measures, not the spread).
  const SynthResult part = testing::paper_part(PaperTool::cone, 241, 61);
  const double diag = bbox_diagonal(part.mesh);
  Mesh noisy = part.mesh;
  std::mt19937 rng(20261121);
  std::normal_distribution<double> noise(0.0, 1e-4 * diag);
  for (Eigen::Index v = 0; v < noisy.V.rows(); ++v)
    for (int k = 0; k < 3; ++k) noisy.V(v, k) += noise(rng);
  const SurfaceIndex index(noisy);
  const Motion init = motion_from_lines(testing::perturbed_axes(7, 1.0, 2.0), 40);
  // The noise itself is ±3e-4 × diagonal: trim at a tolerance the data can meet.
  const Recovered r = recover(index, init, CutterKind::cone, 5e-4 * diag);
  ASSERT_EQ(r.fit.status, FitPatchStatus::ok) << r.fit.message;
  // The fitted Ω within the noise's σ of the clean surface: 1.03e-4 × diagonal measured as the
  // sup over Ω (evaluate_patch searches between its samples around the largest errors; the
  // samples alone gave under 1e-4).
  EXPECT_LE(error_against(part.mesh, r.patch), 1.1e-4 * diag);
  EXPECT_GE(r.patch.coverage_fraction, 0.9);
}

TEST(Robustness, TwoHoles) {
  const SynthResult part = testing::paper_part(PaperTool::cone);
  const double diag = bbox_diagonal(part.mesh);
  const double radius = 0.05 * diag;
  const AxisMotion motion = guide_motion(paper_guides(), kPaperToolLength);
  // Hole centres on Ω at (t, s) = (0.3, 0.4) and (0.7, 0.6): the nearest mesh vertices.
  std::vector<Vec3> centres;
  for (auto [t, s] : {std::pair{0.3, 0.4}, std::pair{0.7, 0.6}}) {
    const Vec3 axis_point = (1 - s) * motion.a(t, 0) + s * motion.b(t, 0);
    Eigen::Index best = 0;
    (part.mesh.V.rowwise() - axis_point.transpose()).rowwise().squaredNorm().minCoeff(&best);
    centres.push_back(part.mesh.V.row(best).transpose());
  }
  Mesh holed;
  holed.V = part.mesh.V;
  std::vector<Eigen::Vector3i> kept;
  for (Eigen::Index f = 0; f < part.mesh.F.rows(); ++f) {
    const Vec3 c = (part.mesh.V.row(part.mesh.F(f, 0)) + part.mesh.V.row(part.mesh.F(f, 1)) +
                    part.mesh.V.row(part.mesh.F(f, 2))).transpose() / 3.0;
    bool inside = false;
    for (const Vec3& h : centres) inside |= (c - h).norm() < radius;
    if (!inside) kept.push_back(part.mesh.F.row(f).transpose());
  }
  ASSERT_LT(kept.size(), static_cast<std::size_t>(part.mesh.F.rows()) * 95 / 100);
  holed.F.resize(static_cast<Eigen::Index>(kept.size()), 3);
  for (std::size_t f = 0; f < kept.size(); ++f) holed.F.row(static_cast<Eigen::Index>(f)) = kept[f].transpose();
  const SurfaceIndex index(holed);
  const Motion init = motion_from_lines(testing::perturbed_axes(7, 1.0, 2.0), 40);
  const Recovered r = recover(index, init, CutterKind::cone, 1e-4 * diag);
  ASSERT_EQ(r.fit.status, FitPatchStatus::ok) << r.fit.message;
  // Same accuracy as without holes, measured on the complete surface.
  EXPECT_LE(error_against(part.mesh, r.patch), 2e-5 * diag);
  EXPECT_GE(r.patch.coverage_fraction, 0.95 * (1.0 - 2 * 3.1416 * radius * radius / total_area(part.mesh)));
}

TEST(FitOptions, ValidateNamesTheProblem) {
  FitOptions o;
  EXPECT_TRUE(o.validate().empty());
  o.samples_t = 2;
  EXPECT_NE(o.validate().find("samples"), std::string::npos);
  FitPatchOptions p;
  EXPECT_NE(p.validate().find("tolerance"), std::string::npos);
}

}  // namespace
}  // namespace flank
