// Growth of a candidate line into patches (solver/grow_patch.h) against ground truth: the true
// axis of an exact envelope, swept as candidate_lines sweeps its probes, grows into a valid
// patch over nearly all of the part; reject_reason names why a patch is no real tool; and
// finish_patch gives a patch the simplest cutter kind that cuts the same surface.
#include "solver/grow_patch.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <limits>
#include <optional>

#include "solver/decompose.h"
#include "solver/propagate.h"
#include "test_parts.h"

namespace flank {
namespace {

using testing::PaperTool;

// The exact part at 121 × 31 (t × s).
constexpr int kRows = 121, kCols = 31;

// The options solver/decompose.cpp gives grow_patch (`go`), from DecomposeOptions' defaults
// and the part's diagonal.
GrowOptions decompose_like(double diag, CutterKind general) {
  const DecomposeOptions d;
  GrowOptions go;
  go.fit.kind = general;
  go.fit.control_points = d.control_points;
  go.fit.samples_t = d.samples_t;
  go.fit.samples_s = d.samples_s;
  go.fit.max_iterations = d.iterations;
  go.refit_iterations = d.refit_iterations;
  go.fit.max_extrapolations = d.extrapolations;
  go.fit.radius_min = DecomposeOptions::kDefaultRadiusMin * diag;
  go.fit.radius_max = DecomposeOptions::kDefaultRadiusMax * diag;
  go.length_min = DecomposeOptions::kDefaultLengthMin * diag;
  go.evaluate.rows = 2 * d.samples_t;
  go.evaluate.cols = 2 * d.samples_s;
  go.evaluate.spacing = 2.0 * d.final_spacing * diag;
  go.evaluate.envelope = false;
  go.thresholds = thresholds_for(1e-4 * diag);
  return go;
}

// The candidate by hand: the true axis at mid-motion, reaching 3% of its length past both
// edges of the part (as lay_line lays it), swept with the options of candidate_lines' probe.
LineCandidate true_axis_candidate(const SurfaceIndex& index, CutterKind kind, const Thresholds& th) {
  const AxisMotion truth = guide_motion(paper_guides(), kPaperToolLength);
  const Vec3 a = truth.a(0.5, 0), b = truth.b(0.5, 0);
  const double L = (b - a).norm();
  const Vec3 u = (b - a) / L;
  LineCandidate c;
  c.line = {a - 0.03 * L * u, b + 0.03 * L * u};
  c.kind = kind;
  c.seed = 0;
  const double diag = index.diagonal();
  PropagateOptions po;
  po.movability.samples = 16;
  po.movability.max_boundary_fraction = 0.5;
  po.step = 0.015 * diag;
  po.max_travel = 2.0 * diag;
  po.max_movability = 1e-2;
  po.max_profile_error = th.sweep_misfit;
  c.sweep = propagate(index, c.line, po);
  return c;
}

double min_radius(const Cutter& c) {
  double r = std::numeric_limits<double>::infinity();
  for (int k = 0; k <= 100; ++k) r = std::min(r, c.radius(k / 100.0));
  return r;
}
double max_radius(const Cutter& c) {
  double r = 0.0;
  for (int k = 0; k <= 100; ++k) r = std::max(r, c.radius(k / 100.0));
  return r;
}

void print(const char* what, const Patch& p, double diag) {
  std::printf("[ grow ] %s: %s L %.3f, radii %.4f..%.4f, coverage %.4f, max |e| %.2e x diag, gouge %.2e x diag\n",
              what, std::string(to_string(p.cutter.kind)).c_str(), p.cutter.length, p.cutter.radius(0),
              p.cutter.radius(1), p.coverage_fraction, p.error.max / diag, p.error.max_gouge / diag);
}

// ---------------------------------------------------------------------------------------------
// grow_patch

TEST(GrowPatch, TrueAxisOfTheConePartGrowsIntoOnePatchOverIt) {
  const SynthResult part = testing::paper_part(PaperTool::cone, kRows, kCols);
  const SurfaceIndex index(part.mesh);
  const double diag = index.diagonal();
  const GrowOptions go = decompose_like(diag, CutterKind::spline);
  ASSERT_TRUE(go.validate().empty()) << go.validate();
  const LineCandidate c = true_axis_candidate(index, CutterKind::cone, go.thresholds);
  std::printf("[ grow ] probe sweep: %zu rulings, stops %s / %s\n", c.sweep.rulings.size(),
              to_string(c.sweep.stop_backward), to_string(c.sweep.stop_forward));
  ASSERT_GE(c.sweep.rulings.size(), 4u);
  const Grown g = grow_patch(index, c, go);
  ASSERT_FALSE(g.patches.empty());
  EXPECT_GE(g.pieces, static_cast<int>(g.patches.size()));
  for (std::size_t k = 0; k < g.patches.size(); ++k) {
    print("piece", g.patches[k], diag);
    // Every kept piece is valid, best (largest covered area) first.
    EXPECT_EQ(reject_reason(g.patches[k], go), "") << k;
    if (k > 0) {
      EXPECT_GE(g.patches[k - 1].covered_area, g.patches[k].covered_area);
    }
  }
  const Patch& p = g.patches.front();
  EXPECT_EQ(p.cutter.kind, CutterKind::cone);  // the candidate's kind, not go.fit.kind
  EXPECT_GE(p.coverage_fraction, 0.95);
  EXPECT_GE(min_radius(p.cutter), go.fit.radius_min);
  EXPECT_LE(max_radius(p.cutter), go.fit.radius_max);
  EXPECT_LE(p.error.judged_gouge, go.thresholds.gouge);
  EXPECT_GE(p.cutter.length, go.length_min);
  // The true cone, 4 → 7 mm over 50 mm.
  const Vec2 ends = p.cutter.cone_end_radii();
  std::printf("[ grow ] cone end radii %.4f %.4f over %.3f\n", ends(0), ends(1), p.cutter.length);
  EXPECT_NEAR((ends(1) - ends(0)) / p.cutter.length, 3.0 / 50.0, 0.002);
}

TEST(GrowPatch, TooShortASweepGrowsNothing) {
  const SynthResult part = testing::paper_part(PaperTool::cone, 61, 21);
  const SurfaceIndex index(part.mesh);
  const GrowOptions go = decompose_like(index.diagonal(), CutterKind::cone);
  LineCandidate c = true_axis_candidate(index, CutterKind::cone, go.thresholds);
  c.sweep.rulings.resize(3);
  c.sweep.fresh.resize(3);
  const Grown g = grow_patch(index, c, go);
  EXPECT_TRUE(g.patches.empty());
  EXPECT_EQ(g.pieces, 0);
}

// A cylinder cannot follow the cone part (4 → 7 mm): the fit is out of tolerance toward the
// cutter's ends, cut to its middle and refitted from there, within refit_iterations.
TEST(FitAndTrim, ARefitAfterATrimRunsAtMostRefitIterations) {
  const SynthResult part = testing::paper_part(PaperTool::cone, 61, 21);
  const SurfaceIndex index(part.mesh);
  const double diag = index.diagonal();
  const GrowOptions go = decompose_like(diag, CutterKind::cylinder);
  const LineCandidate c = true_axis_candidate(index, CutterKind::cylinder, go.thresholds);
  const Motion init = Motion::fit(c.sweep.rulings, go.fit.control_points);
  FitPatchOptions fo;
  fo.fit = go.fit;
  fo.fit.kind = CutterKind::cylinder;
  fo.tolerance = go.thresholds.tolerance;
  fo.max_rounds = 2;
  for (const int refit : {0, 3}) {
    fo.refit_iterations = refit;
    ASSERT_TRUE(fo.validate().empty()) << fo.validate();
    const FitPatchResult r = fit_and_trim(index, init, fo);
    ASSERT_EQ(r.status, FitPatchStatus::ok) << r.message;
    ASSERT_GE(r.rounds, 1) << "the cylinder was never trimmed";
    std::printf("[ refit ] refit_iterations %d: %d trims, the last fit %d iterations, %s\n", refit, r.rounds,
                r.fit.iterations, to_string(r.fit.status));
    EXPECT_LE(r.fit.iterations, refit > 0 ? refit : fo.fit.max_iterations);
    EXPECT_TRUE(r.fit.ok());
  }
  fo.refit_iterations = -1;
  EXPECT_EQ(fo.validate(), "refit iterations must not be negative");
  GrowOptions bad = go;
  bad.refit_iterations = -1;
  EXPECT_EQ(bad.validate(), "refit iterations must not be negative");
}

// ---------------------------------------------------------------------------------------------
// reject_reason

// A patch that is a real tool by every rule: a cone 4 → 7 mm, 50 mm long, covering a vertex,
// not gouging, with the holder (when checked) clear.
Patch good_patch() {
  Patch p;
  p.cutter = cone_from_end_radii(50.0, 4.0, 7.0);
  p.covered_vertices = {0, 1, 2};
  p.covered_area = 1.0;
  return p;
}

GrowOptions reject_options() {
  GrowOptions o;
  o.thresholds = thresholds_for(0.01);  // gouge threshold 0.01
  o.fit.radius_min = 2.0;
  o.fit.radius_max = 10.0;
  o.length_min = 20.0;
  return o;
}

TEST(RejectReason, AGoodPatchHasNone) {
  EXPECT_EQ(reject_reason(good_patch(), reject_options()), "");
  // On the bounds (to the 1e-9 slack): still good.
  GrowOptions o = reject_options();
  o.length_min = 50.0;
  o.fit.radius_min = good_patch().cutter.radius(0.0);
  o.fit.radius_max = good_patch().cutter.radius(1.0);
  EXPECT_EQ(reject_reason(good_patch(), o), "");
  // Gouge at the threshold is allowed.
  Patch p = good_patch();
  p.error.judged_gouge = o.thresholds.gouge;
  EXPECT_EQ(reject_reason(p, o), "");
}

TEST(RejectReason, JudgedGougeAboveTheThreshold) {
  const GrowOptions o = reject_options();
  Patch p = good_patch();
  p.error.judged_gouge = 1.01 * o.thresholds.gouge;
  EXPECT_NE(reject_reason(p, o).find("gouge"), std::string::npos) << reject_reason(p, o);
  // The judged gouge decides, not the one reported against Φ as given (a scan's noise).
  Patch noisy = good_patch();
  noisy.error.max_gouge = 10 * o.thresholds.gouge;
  noisy.error.judged_gouge = 0.5 * o.thresholds.gouge;
  EXPECT_EQ(reject_reason(noisy, o), "");
}

TEST(RejectReason, RadiusOutOfTheRange) {
  GrowOptions o = reject_options();
  o.fit.radius_max = 6.0;  // the cone's spheres reach ~7
  EXPECT_NE(reject_reason(good_patch(), o).find("radius"), std::string::npos) << reject_reason(good_patch(), o);
  o = reject_options();
  o.fit.radius_min = 4.5;  // the cone's spheres start at ~4
  EXPECT_NE(reject_reason(good_patch(), o).find("radius"), std::string::npos);
  // A spline profile that dips below the range only between its ends is caught too.
  Patch dip = good_patch();
  dip.cutter = Cutter::constant(CutterKind::spline, 50.0, 5.0);
  dip.cutter.coeffs(4) = dip.cutter.coeffs(5) = 0.5;
  ASSERT_LT(dip.cutter.radius(0.5), 2.0);
  ASSERT_GT(dip.cutter.radius(0.0), 2.0);
  ASSERT_GT(dip.cutter.radius(1.0), 2.0);
  EXPECT_NE(reject_reason(dip, reject_options()).find("radius"), std::string::npos) << reject_reason(dip, reject_options());
  // No bounds (0): any radius.
  o = reject_options();
  o.fit.radius_min = o.fit.radius_max = 0.0;
  EXPECT_EQ(reject_reason(good_patch(), o), "");
}

TEST(RejectReason, CoversNothing) {
  Patch p = good_patch();
  p.covered_vertices.clear();
  p.covered_area = 0.0;
  EXPECT_NE(reject_reason(p, reject_options()).find("covers nothing"), std::string::npos);
}

TEST(RejectReason, CutterShorterThanTheMinimum) {
  GrowOptions o = reject_options();
  o.length_min = 60.0;
  EXPECT_NE(reject_reason(good_patch(), o).find("shorter"), std::string::npos) << reject_reason(good_patch(), o);
}

TEST(RejectReason, HolderCollisionAndInvalidCutter) {
  GrowOptions o = reject_options();
  o.evaluate.holder = true;
  o.evaluate.holder_length = 30, o.evaluate.holder_radius = 8;
  Patch p = good_patch();
  p.collision.checked = true;
  p.collision.holder_clear = false;
  EXPECT_NE(reject_reason(p, o).find("holder"), std::string::npos);
  // Not checked (no holder in the options): no reason.
  EXPECT_EQ(reject_reason(p, reject_options()), "");
  Patch steep = good_patch();
  steep.cutter.coeffs << 1.0, 80.0;  // |d′| = 79 > L = 50: no meridian
  ASSERT_FALSE(steep.cutter.valid());
  GrowOptions wide = reject_options();
  wide.fit.radius_min = wide.fit.radius_max = 0.0;
  EXPECT_NE(reject_reason(steep, wide).find("invalid"), std::string::npos) << reject_reason(steep, wide);
}

// The reasons on patches measured on the exact cone part with its true motion: spheres half a
// tolerance thinner than the true cone's leave material within tolerance (a good patch); a
// tip sphere 3 tolerances thicker gouges 3 tolerances there while the rest of the cutter
// still covers (gouges); 2 tolerances thinner everywhere covers nothing.
TEST(RejectReason, TrueMotionWithCuttersOffTheTrueOne) {
  const SynthResult part = testing::paper_part(PaperTool::cone, 61, 21);
  const SurfaceIndex index(part.mesh);
  const GrowOptions o = decompose_like(index.diagonal(), CutterKind::cone);
  const double tol = o.thresholds.tolerance;
  const Motion motion = testing::true_motion(40);
  EvaluateOptions eo = o.evaluate;
  eo.tolerance = tol;
  auto measure = [&](double tip, double end) {
    Cutter c = cone_from_end_radii(kPaperToolLength, 4.0, 7.0);
    c.coeffs(0) += tip * tol;
    c.coeffs(1) += end * tol;
    const Patch p = evaluate_patch(index, motion, c, eo);
    std::printf("[ reject ] spheres %+.1f..%+.1f tol: judged gouge %.2f tol, covers %.3f: '%s'\n", tip, end,
                p.error.judged_gouge / tol, p.coverage_fraction, reject_reason(p, o).c_str());
    return p;
  };
  const Patch thinner = measure(-0.5, -0.5);
  EXPECT_GT(thinner.coverage_fraction, 0.9);
  EXPECT_EQ(reject_reason(thinner, o), "");
  const Patch thick_tip = measure(3.0, 0.0);
  EXPECT_GT(thick_tip.coverage_fraction, 0.1);
  EXPECT_NEAR(thick_tip.error.judged_gouge, 3.0 * tol, 0.5 * tol);
  EXPECT_NE(reject_reason(thick_tip, o).find("gouge"), std::string::npos) << reject_reason(thick_tip, o);
  const Patch too_thin = measure(-2.0, -2.0);
  EXPECT_EQ(too_thin.coverage_fraction, 0.0);
  EXPECT_NE(reject_reason(too_thin, o).find("covers nothing"), std::string::npos) << reject_reason(too_thin, o);
}

// ---------------------------------------------------------------------------------------------
// finish_patch

// The options solver/decompose.cpp finishes with (`fo`), on a grid half as fine (spacing
// 0.5% of the diagonal, not 0.25%) to keep the sanitizer run short.
FinishOptions finish_like(const GrowOptions& go, double diag, std::vector<CutterKind> simpler) {
  const DecomposeOptions d;
  FinishOptions fo;
  fo.grow = go;
  fo.simpler = std::move(simpler);
  fo.evaluate = go.evaluate;
  fo.evaluate.rows = d.final_rows;
  fo.evaluate.cols = d.final_cols;
  fo.evaluate.spacing = 2.0 * d.final_spacing * diag;
  fo.evaluate.envelope = true;
  return fo;
}

// A patch as grow_patch evaluates it (coarse grid, covered set) for a given motion and cutter.
Patch evaluated(const SurfaceIndex& index, const Motion& motion, const Cutter& cutter, const GrowOptions& go) {
  EvaluateOptions eo = go.evaluate;
  eo.tolerance = go.thresholds.tolerance;
  return evaluate_patch(index, motion, cutter, eo);
}

// A finished patch holds no sample out of tolerance on its own evaluation grid, carries Ω on
// that grid, reports an error (grid and Φ's vertices) within tolerance on a clean exact part,
// and is a valid patch.
void expect_finished(const SurfaceIndex& index, const Patch& p, const FinishOptions& fo) {
  const double tol = fo.grow.thresholds.tolerance;
  EvaluateOptions eo = fo.evaluate;
  eo.tolerance = tol;
  const auto [rows, cols] = evaluation_grid(p.motion, p.cutter, eo);
  EXPECT_EQ(p.envelope.rows, rows);
  EXPECT_EQ(p.envelope.cols, cols);
  const ErrorGrid grid = sample_errors(index, p.motion, p.cutter, rows, cols);
  const std::vector<SampleClass> cls = classify_samples(grid, tol);
  EXPECT_EQ(std::count(cls.begin(), cls.end(), SampleClass::outside), 0) << to_string(p.cutter.kind);
  EXPECT_GT(std::count(cls.begin(), cls.end(), SampleClass::within), 0) << to_string(p.cutter.kind);
  EXPECT_LE(p.error.max, tol) << to_string(p.cutter.kind);
  EXPECT_LE(p.error.max_gouge, tol) << to_string(p.cutter.kind);
  EXPECT_EQ(reject_reason(p, fo.grow), "");
}

// A spline cutter of constant radius 5 on the true motion of the exact cylinder part: the
// cylinder's least-squares radii equal the spline's, so the patch comes back as the true
// cylinder when the cylinder is allowed, and as the spline when no simpler kind is.
TEST(FinishPatch, ConstantSplineOnTheCylinderPartBecomesTheCylinder) {
  const SynthResult part = testing::paper_part(PaperTool::cylinder, kRows, kCols);
  const SurfaceIndex index(part.mesh);
  const double diag = index.diagonal();
  const GrowOptions go = decompose_like(diag, CutterKind::spline);
  const Patch spline = evaluated(index, testing::true_motion(16), Cutter::constant(CutterKind::spline, kPaperToolLength, 5.0), go);
  print("spline", spline, diag);
  ASSERT_EQ(reject_reason(spline, go), "");

  FinishOptions fo = finish_like(go, diag, {CutterKind::cylinder, CutterKind::cone, CutterKind::barrel});
  const std::optional<Patch> simple = finish_patch(index, spline, fo);
  ASSERT_TRUE(simple.has_value());
  print("finished", *simple, diag);
  EXPECT_EQ(simple->cutter.kind, CutterKind::cylinder);
  EXPECT_NEAR(simple->cutter.radius(0.5), 5.0, 0.01);
  EXPECT_GE(simple->coverage_fraction, 0.95);
  expect_finished(index, *simple, fo);

  fo.simpler.clear();
  const std::optional<Patch> unchanged = finish_patch(index, spline, fo);
  ASSERT_TRUE(unchanged.has_value());
  EXPECT_EQ(unchanged->cutter.kind, CutterKind::spline);
  EXPECT_GE(unchanged->coverage_fraction, 0.95);
  expect_finished(index, *unchanged, fo);
}

// The spline through the true cone's sphere radii, along the true motion of the exact cone
// part `index`.
Patch spline_of_the_cone(const SurfaceIndex& index, const GrowOptions& go) {
  const Cutter cone = cone_from_end_radii(kPaperToolLength, 4.0, 7.0);
  std::vector<double> s(101), r(101);
  for (int k = 0; k <= 100; ++k) s[k] = k / 100.0, r[k] = cone.radius(s[k]);
  return evaluated(index, testing::true_motion(16), Cutter::fit(CutterKind::spline, kPaperToolLength, s, r), go);
}

// The spline through the true cone's sphere radii on the exact cone part: the cylinder's
// least-squares radii are 1.5 mm off (far beyond thresholds.simplify), the cone's are exact,
// so it comes back as the cone (the true one), not as the simplest kind allowed.
TEST(FinishPatch, SplineOfAConeBecomesTheConeNotTheCylinder) {
  const SynthResult part = testing::paper_part(PaperTool::cone, kRows, kCols);
  const SurfaceIndex index(part.mesh);
  const double diag = index.diagonal();
  const GrowOptions go = decompose_like(diag, CutterKind::spline);
  const Patch spline = spline_of_the_cone(index, go);
  ASSERT_EQ(reject_reason(spline, go), "");
  const FinishOptions fo = finish_like(go, diag, {CutterKind::cylinder, CutterKind::cone, CutterKind::barrel});
  const std::optional<Patch> simple = finish_patch(index, spline, fo);
  ASSERT_TRUE(simple.has_value());
  print("finished", *simple, diag);
  EXPECT_EQ(simple->cutter.kind, CutterKind::cone);
  const Vec2 ends = simple->cutter.cone_end_radii();
  const double k = (ends(1) - ends(0)) / simple->cutter.length;
  EXPECT_NEAR(k, 3.0 / 50.0, 0.002);
  expect_finished(index, *simple, fo);
}

// A simpler kind must cut the same surface, not merely as much of it: the same spline patch,
// told that half of what it covers lies elsewhere (every other covered vertex dropped, its
// area kept), keeps its kind, though the cone refit covers as much area as before (on the
// unchanged patch the cone is kept: the test above).
TEST(FinishPatch, ASimplerKindMustCoverTheSameVertices) {
  const SynthResult part = testing::paper_part(PaperTool::cone, kRows, kCols);
  const SurfaceIndex index(part.mesh);
  const double diag = index.diagonal();
  const GrowOptions go = decompose_like(diag, CutterKind::spline);
  Patch spline = spline_of_the_cone(index, go);
  ASSERT_EQ(reject_reason(spline, go), "");
  std::vector<int> half;
  for (std::size_t k = 0; k < spline.covered_vertices.size(); k += 2) half.push_back(spline.covered_vertices[k]);
  spline.covered_vertices = half;
  const FinishOptions fo = finish_like(go, diag, {CutterKind::cylinder, CutterKind::cone, CutterKind::barrel});
  const std::optional<Patch> finished = finish_patch(index, spline, fo);
  ASSERT_TRUE(finished.has_value());
  EXPECT_EQ(finished->cutter.kind, CutterKind::spline);
}

// A patch grown from the true axis of the exact cylinder part with the spline kind (as
// decompose grows candidates when only the spline fits their line): finished with no simpler
// kind allowed it keeps its kind, and it holds nothing out of tolerance on its own grid.
TEST(FinishPatch, GrownSplineKeepsItsKindWithoutSimplerKinds) {
  const SynthResult part = testing::paper_part(PaperTool::cylinder, kRows, kCols);
  const SurfaceIndex index(part.mesh);
  const double diag = index.diagonal();
  const GrowOptions go = decompose_like(diag, CutterKind::spline);
  const Grown g = grow_patch(index, true_axis_candidate(index, CutterKind::spline, go.thresholds), go);
  ASSERT_FALSE(g.patches.empty());
  const Patch& grown = g.patches.front();
  ASSERT_EQ(grown.cutter.kind, CutterKind::spline);
  const FinishOptions fo = finish_like(go, diag, {});
  const std::optional<Patch> finished = finish_patch(index, grown, fo);
  ASSERT_TRUE(finished.has_value());
  print("finished", *finished, diag);
  EXPECT_EQ(finished->cutter.kind, CutterKind::spline);
  EXPECT_GE(finished->covered_area, 0.95 * grown.covered_area);
  expect_finished(index, *finished, fo);
}


}  // namespace
}  // namespace flank
