// Patch evaluation (solver/evaluate_patch.h) against ground truth: the true cutter on the true
// motion of an exact envelope machines it within the mesh's own chord error; the machined
// surface Ω, not the spheres, decides what is cut (a cutter sliding along its own axis cuts
// nothing new though every sphere touches Φ); the reported error also counts Φ's vertices
// between the samples; a smoothed index and the surface as given play their separate parts;
// and the evaluation grid follows the requested spacing.
#include "solver/evaluate_patch.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

#include "kernels/bspline.h"
#include "kernels/parallel.h"
#include "solver/grow_patch.h"
#include "test_parts.h"

namespace flank {
namespace {

using testing::PaperTool;

// The plate z = 0 over [0, sx] × [0, sy], unit cells, two triangles each, counter-clockwise
// seen from +z (the tool side).
Mesh plate(int sx, int sy) {
  Mesh m;
  m.V.resize(static_cast<Eigen::Index>(sx + 1) * (sy + 1), 3);
  for (int j = 0; j <= sy; ++j)
    for (int i = 0; i <= sx; ++i) m.V.row(j * (sx + 1) + i) << i, j, 0.0;
  m.F.resize(2 * static_cast<Eigen::Index>(sx) * sy, 3);
  Eigen::Index f = 0;
  for (int j = 0; j < sy; ++j)
    for (int i = 0; i < sx; ++i) {
      const int v00 = j * (sx + 1) + i, v10 = v00 + 1, v01 = v00 + sx + 1, v11 = v01 + 1;
      m.F.row(f++) << v00, v10, v11;
      m.F.row(f++) << v00, v11, v01;
    }
  return m;
}

int plate_vertex(int sx, int x, int y) { return y * (sx + 1) + x; }

// A clamped cubic motion from its control points (rows of a; b = a + offset).
Motion motion_from(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  Motion m;
  m.knots = clamped_uniform_knots(static_cast<int>(a.size()));
  m.a.resize(static_cast<Eigen::Index>(a.size()), 3);
  m.b.resize(static_cast<Eigen::Index>(b.size()), 3);
  for (std::size_t k = 0; k < a.size(); ++k) {
    m.a.row(static_cast<Eigen::Index>(k)) = a[k].transpose();
    m.b.row(static_cast<Eigen::Index>(k)) = b[k].transpose();
  }
  return m;
}

// A cylinder of radius 5 lying on the plate (axis at z = 5 along x, from x = 10 to 60)
// sweeping across it in y from 5 to 35 at constant speed (equally spaced Bézier points).
Motion plate_sweep() {
  std::vector<Vec3> a, b;
  for (int k = 0; k < 4; ++k) {
    a.emplace_back(10.0, 5.0 + 10.0 * k, 5.0);
    b.emplace_back(60.0, 5.0 + 10.0 * k, 5.0);
  }
  return motion_from(a, b);
}

// ---------------------------------------------------------------------------------------------
// The exact cone part

TEST(EvaluatePatch, TrueCutterOnTrueMotionIsWithinTheChordError) {
  const SynthResult part = testing::paper_part(PaperTool::cone, 121, 31);
  ASSERT_EQ(part.invalid, 0);
  const SurfaceIndex index(part.mesh);
  const double diag = index.diagonal();
  const Motion motion = testing::true_motion(40);
  // How far the spline motion is from the true one (it is not polynomial).
  const AxisMotion truth = guide_motion(paper_guides(), kPaperToolLength);
  double motion_error = 0.0;
  for (int i = 0; i <= 1000; ++i) {
    const double t = i / 1000.0;
    motion_error = std::max({motion_error, (motion.a_at(t) - truth.a(t, 0)).norm(), (motion.b_at(t) - truth.b(t, 0)).norm()});
  }
  EvaluateOptions eo;
  eo.tolerance = 1e-4 * diag;
  const Patch p = evaluate_patch(index, motion, cone_from_end_radii(kPaperToolLength, 4.0, 7.0), eo);
  std::printf("[ evaluate ] true cone: max |e| %.3e, gouge %.3e (judged %.3e), rms %.3e; chord error %.3e, motion "
              "fit %.1e; coverage %.4f\n",
              p.error.max, p.error.max_gouge, p.error.judged_gouge, p.error.rms, part.chord_error, motion_error,
              p.coverage_fraction);
  EXPECT_LT(motion_error, 0.01 * part.chord_error);
  EXPECT_LE(p.error.max, part.chord_error);
  EXPECT_LE(p.error.max_gouge, part.chord_error);
  EXPECT_LE(p.error.rms, p.error.max);
  EXPECT_NEAR(p.error.max_relative, p.error.max / diag, 1e-15);
  EXPECT_GE(p.coverage_fraction, 0.95);
  EXPECT_NEAR(p.coverage_fraction, p.covered_area / total_area(part.mesh), 1e-12);
  // Ω as a mesh on the evaluation grid, with its errors.
  EXPECT_EQ(p.envelope.rows, eo.rows);
  EXPECT_EQ(p.envelope.cols, eo.cols);
  EXPECT_EQ(p.envelope.V.rows(), eo.rows * eo.cols);
  EXPECT_EQ(p.envelope.error.size(), eo.rows * eo.cols);
  // Every sample of the grid over Φ is within tolerance (the spheres too).
  const ErrorGrid grid = sample_errors(index, motion, p.cutter, eo.rows, eo.cols);
  const std::vector<SampleClass> cls = classify_samples(grid, eo.tolerance);
  EXPECT_EQ(std::count(cls.begin(), cls.end(), SampleClass::outside), 0);
  EXPECT_GT(std::count(cls.begin(), cls.end(), SampleClass::within), static_cast<long>(0.9 * cls.size()));
  for (int i = 0; i < grid.rows; ++i) EXPECT_TRUE(grid.sweeps[static_cast<std::size_t>(i)]) << i;

  // The wrong cutter is seen: spheres 3 tolerances thicker gouge by 3 tolerances and cover
  // nothing; the cylinder of the mean radius is out of tolerance almost everywhere.
  Cutter thick = cone_from_end_radii(kPaperToolLength, 4.0, 7.0);
  thick.coeffs.array() += 3.0 * eo.tolerance;
  const Patch gouging = evaluate_patch(index, motion, thick, eo);
  EXPECT_NEAR(gouging.error.max_gouge, 3.0 * eo.tolerance, part.chord_error);
  EXPECT_EQ(gouging.coverage_fraction, 0.0);
  EXPECT_TRUE(gouging.covered_vertices.empty());
}

// The same patch whatever the thread count: Ω's mesh and its index, the vertices near it, the
// largest errors refined and the coverage are each made in blocks on every thread, combined
// in block order. A grid of 400 × 120 samples: several blocks of each.
TEST(EvaluatePatch, SameAnswerWhateverTheThreadCount) {
  const SynthResult part = testing::paper_part(PaperTool::cone, 121, 31);
  const SurfaceIndex index(part.mesh);
  EvaluateOptions eo;
  eo.tolerance = 1e-4 * index.diagonal();
  eo.rows = 400, eo.cols = 120;
  eo.vertex_side = true;
  eo.refine_max = 20;
  const auto evaluated = [&](int threads) {
    const ThreadLimit limit(threads);
    const Cutter cone = cone_from_end_radii(kPaperToolLength, 4.0, 7.0);
    return evaluate_patch(index, testing::true_motion(40), cone, eo);
  };
  const Patch one = evaluated(1), two = evaluated(2);
  EXPECT_GT(one.envelope.F.rows(), 2 * 8192);
  EXPECT_GT(one.covered_vertices.size(), 1000u);
  EXPECT_GT(one.error.max, 0.0);
  EXPECT_EQ(one.error.max, two.error.max);
  EXPECT_EQ(one.error.max_gouge, two.error.max_gouge);
  EXPECT_EQ(one.error.rms, two.error.rms);
  EXPECT_EQ(one.covered_vertices, two.covered_vertices);
  EXPECT_EQ(one.covered_area, two.covered_area);
  EXPECT_TRUE(one.envelope.F == two.envelope.F);
  EXPECT_TRUE(one.envelope.V == two.envelope.V);
}

// ---------------------------------------------------------------------------------------------
// Ω, not the spheres

// A cylinder of radius 5 lies on the plate (axis 5 above it, along x). For t < 0.6 it sweeps
// across the plate in y; for t > 0.6 it only slides along its own axis (x), which cuts
// nothing new. Every sphere touches the plate exactly all along, so by the spheres every
// sample is within tolerance; Ω exists only where the axis sweeps across itself, so the
// sliding rows do not sweep and their samples count as outside.
TEST(EvaluatePatch, SlidingAlongItsOwnAxisIsNoSweep) {
  const int sx = 80, sy = 30;
  const SurfaceIndex index(plate(sx, sy));
  std::vector<Vec3> a;
  const double ys[] = {5, 10, 15, 20, 20, 20, 20, 20}, xs[] = {10, 10, 10, 10, 10, 14, 18, 22};
  for (int k = 0; k < 8; ++k) a.emplace_back(xs[k], ys[k], 5.0);
  std::vector<Vec3> b;
  for (const Vec3& p : a) b.push_back(p + Vec3(50.0, 0.0, 0.0));
  const Motion motion = motion_from(a, b);  // 5 spans: y is constant on the last two, t ≥ 0.6
  const Cutter cylinder = Cutter::constant(CutterKind::cylinder, 50.0, 5.0);
  const double tol = 0.01;
  const int rows = 101, cols = 21;
  const ErrorGrid grid = sample_errors(index, motion, cylinder, rows, cols);
  const std::vector<SampleClass> cls = classify_samples(grid, tol);
  int sliding_rows = 0, sweeping_rows = 0;
  for (int i = 0; i < rows; ++i) {
    const double t = static_cast<double>(i) / (rows - 1);
    for (int j = 0; j < cols; ++j) EXPECT_NEAR(grid.sphere_error(static_cast<Eigen::Index>(grid.index(i, j))), 0.0, 1e-9);
    if (t >= 0.61) {
      ++sliding_rows;
      EXPECT_FALSE(grid.sweeps[static_cast<std::size_t>(i)]) << "t " << t;
      for (int j = 0; j < cols; ++j) {
        EXPECT_FALSE(grid.omega_valid[grid.index(i, j)]) << t;
        EXPECT_EQ(cls[grid.index(i, j)], SampleClass::outside) << "t " << t << " s " << j;
      }
    } else if (t <= 0.5) {
      ++sweeping_rows;
      EXPECT_TRUE(grid.sweeps[static_cast<std::size_t>(i)]) << "t " << t;
      for (int j = 0; j < cols; ++j) {
        EXPECT_TRUE(grid.inside(i, j));
        EXPECT_NEAR(grid.at(i, j), 0.0, 1e-9);
        EXPECT_EQ(cls[grid.index(i, j)], SampleClass::within) << "t " << t << " s " << j;
      }
    }
  }
  EXPECT_GT(sliding_rows, 30);
  EXPECT_GT(sweeping_rows, 40);
  // The patch covers what was swept across (x 10..60, y 5..20 and the cylinder's reach on the
  // plate's side), never the strip the sliding spheres touch beyond x = 60.
  EvaluateOptions eo;
  eo.tolerance = tol;
  const Patch p = evaluate_patch(index, motion, cylinder, eo);
  EXPECT_GT(p.covered_area, 0.95 * 50.0 * 15.0);
  for (int v : p.covered_vertices) {
    const Vec3 x = index.mesh().V.row(v).transpose();
    EXPECT_LE(x.x(), 60.0 + 1e-9) << x.transpose();
    EXPECT_LE(x.y(), 20.0 + 1e-9) << x.transpose();
  }
}

// ---------------------------------------------------------------------------------------------
// The vertex side of the reported error

// The plate with vertex (31, 21) raised by `h` toward the tool: under the patch, between the
// samples of every grid below.
Mesh bumped_plate(double h) {
  Mesh m = plate(70, 40);
  m.V(plate_vertex(70, 31, 21), 2) = h;
  return m;
}

TEST(EvaluatePatch, ReportedErrorSeesTheVertexBetweenSamples) {
  const double tol = 0.01, h = 1.5 * tol;
  const SurfaceIndex index(bumped_plate(h));
  const Motion motion = plate_sweep();
  const Cutter cylinder = Cutter::constant(CutterKind::cylinder, 50.0, 5.0);
  // The bump at (31, 21) is at t = 16/30, s = 21/50: on none of these grids' samples.
  for (auto [rows, cols] : {std::pair{200, 60}, std::pair{101, 31}, std::pair{64, 19}, std::pair{37, 11}, std::pair{23, 7}}) {
    EvaluateOptions eo;
    eo.tolerance = tol;
    eo.rows = rows, eo.cols = cols;
    const Patch p = evaluate_patch(index, motion, cylinder, eo);
    EXPECT_NEAR(p.error.max, h, 1e-9) << rows << " x " << cols;
    EXPECT_NEAR(p.error.max_gouge, h, 1e-9) << rows << " x " << cols;
    EXPECT_NEAR(p.error.max_relative, h / index.diagonal(), 1e-12);
    // The grid alone sees less: Ω's samples lie beside the peak, the spheres above its flanks.
    const ErrorGrid grid = sample_errors(index, motion, cylinder, rows, cols);
    double grid_max = 0.0, sphere_gouge = 0.0;
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j < cols; ++j) {
        if (grid.inside(i, j)) grid_max = std::max(grid_max, std::abs(grid.at(i, j)));
        sphere_gouge = std::max(sphere_gouge, -grid.sphere_error(static_cast<Eigen::Index>(grid.index(i, j))));
      }
    std::printf("[ evaluate ] %d x %d: reported %.4f, grid alone %.4f (spheres %.4f), bump %.4f\n", rows, cols,
                p.error.max, grid_max, sphere_gouge, h);
    EXPECT_LT(grid_max, 0.9 * h) << rows << " x " << cols;
    EXPECT_LT(sphere_gouge, h) << rows << " x " << cols;
    // The raised vertex is out of tolerance: not covered; its neighbours within it are.
    const std::vector<int>& c = p.covered_vertices;
    EXPECT_EQ(std::count(c.begin(), c.end(), plate_vertex(70, 31, 21)), 0);
    EXPECT_EQ(std::count(c.begin(), c.end(), plate_vertex(70, 33, 21)), 1);
  }
}

// PatchError::judged_gouge is max_gouge when there is no smoothed copy: a patch that gouges a
// vertex between its samples (the bump, by 1.5 tolerances) is judged on that, not on the
// grid's samples alone.
TEST(EvaluatePatch, WithoutASmoothedCopyTheJudgedGougeIsTheReportedOne) {
  const double tol = 0.01, h = 1.5 * tol;
  const SurfaceIndex index(bumped_plate(h));
  EvaluateOptions eo;
  eo.tolerance = tol;
  eo.rows = 64, eo.cols = 19;
  const Patch p = evaluate_patch(index, plate_sweep(), Cutter::constant(CutterKind::cylinder, 50.0, 5.0), eo);
  EXPECT_NEAR(p.error.max_gouge, h, 1e-9);
  EXPECT_EQ(p.error.judged_gouge, p.error.max_gouge);
  GrowOptions go;
  go.thresholds = thresholds_for(tol);  // gouge threshold: one tolerance
  EXPECT_NE(reject_reason(p, go).find("gouge"), std::string::npos) << "'" << reject_reason(p, go) << "'";
}

// ---------------------------------------------------------------------------------------------
// A smoothed index and Φ as given

TEST(EvaluatePatch, JudgedOnTheIndexReportedOnTheGivenSurface) {
  const double tol = 0.01, h = 1.5 * tol;
  const SurfaceIndex flat(plate(70, 40));          // the bump smoothed away
  const SurfaceIndex bumped(bumped_plate(h));      // Φ as given
  const Motion motion = plate_sweep();
  const Cutter cylinder = Cutter::constant(CutterKind::cylinder, 50.0, 5.0);
  EvaluateOptions eo;
  eo.tolerance = tol;
  const int bump = plate_vertex(70, 31, 21);
  // Smoothed index, bumped Φ: judged on the flat plate (no gouge), reported against the bump.
  const Patch p = evaluate_patch(flat, motion, cylinder, eo, &bumped);
  EXPECT_LE(p.error.judged_gouge, 1e-9);
  EXPECT_NEAR(p.error.max, h, 1e-9);
  EXPECT_NEAR(p.error.max_gouge, h, 1e-9);
  EXPECT_EQ(std::count(p.covered_vertices.begin(), p.covered_vertices.end(), bump), 0);
  // The other way round: judged on the bump (its spheres reach into it), reported against the
  // flat plate (no error, the vertex covered).
  const Patch q = evaluate_patch(bumped, motion, cylinder, eo, &flat);
  EXPECT_GT(q.error.judged_gouge, 0.25 * h);
  EXPECT_LE(q.error.judged_gouge, h + 1e-9);
  EXPECT_LE(q.error.max, 1e-9);
  EXPECT_LE(q.error.max_gouge, 1e-9);
  EXPECT_EQ(std::count(q.covered_vertices.begin(), q.covered_vertices.end(), bump), 1);
  // Ω kept in the patch carries the given surface's errors.
  ASSERT_EQ(p.envelope.error.size(), eo.rows * eo.cols);
  double envelope_max = 0.0;
  for (Eigen::Index k = 0; k < p.envelope.error.size(); ++k)
    if (std::isfinite(p.envelope.error(k))) envelope_max = std::max(envelope_max, std::abs(p.envelope.error(k)));
  EXPECT_GT(envelope_max, 0.0);
  for (Eigen::Index k = 0; k < q.envelope.error.size(); ++k)
    if (std::isfinite(q.envelope.error(k))) {
      EXPECT_LE(std::abs(q.envelope.error(k)), 1e-9);
    }
}

// ---------------------------------------------------------------------------------------------
// evaluation_grid

// The largest distance between neighbouring axis samples of a rows × cols grid.
double largest_gap(const Motion& m, int rows, int cols) {
  double gap = 0.0;
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < cols; ++j) {
      const double t = static_cast<double>(i) / (rows - 1), s = static_cast<double>(j) / (cols - 1);
      const Vec3 p = m.point(t, s);
      if (i + 1 < rows) gap = std::max(gap, (m.point(static_cast<double>(i + 1) / (rows - 1), s) - p).norm());
      if (j + 1 < cols) gap = std::max(gap, (m.point(t, static_cast<double>(j + 1) / (cols - 1)) - p).norm());
    }
  return gap;
}

TEST(EvaluationGrid, WithoutSpacingTheGivenCounts) {
  EvaluateOptions eo;
  eo.tolerance = 0.01;
  eo.rows = 37, eo.cols = 11;
  const auto [rows, cols] = evaluation_grid(plate_sweep(), Cutter::constant(CutterKind::cylinder, 50.0, 5.0), eo);
  EXPECT_EQ(rows, 37);
  EXPECT_EQ(cols, 11);
}

// A radial ruling (from 20 to 70 mm off the centre) turning by one radian about the z axis at
// constant angular speed: the tip travels 20 mm, the spindle end 70 mm.
Motion turning_motion() {
  std::vector<Line> rulings;
  std::vector<double> params;
  for (int i = 0; i <= 200; ++i) {
    const double t = i / 200.0;
    const Vec3 r(std::cos(t), std::sin(t), 0.0);
    rulings.push_back({20.0 * r + Vec3(0, 0, 5), 70.0 * r + Vec3(0, 0, 5)});
    params.push_back(t);
  }
  return Motion::fit(rulings, 40, params);
}

void expect_gap_bound(const Motion& m, const char* what) {
  const Cutter cylinder = Cutter::constant(CutterKind::cylinder, m.mean_length(), 5.0);
  for (double spacing : {2.0, 0.5, 0.3}) {
    EvaluateOptions eo;
    eo.tolerance = 0.01;
    eo.rows = eo.cols = 2;
    eo.spacing = spacing;
    const auto [rows, cols] = evaluation_grid(m, cylinder, eo);
    const double gap = largest_gap(m, rows, cols);
    EXPECT_LE(gap, spacing * (1 + 1e-6)) << what << ": " << rows << " x " << cols << ", spacing " << spacing;
    // And not much finer than asked.
    EXPECT_GT(gap, 0.8 * spacing) << what << ": " << rows << " x " << cols;
    // Never fewer than the counts asked for.
    eo.rows = 500, eo.cols = 300;
    const auto [r2, c2] = evaluation_grid(m, cylinder, eo);
    EXPECT_EQ(r2, 500) << what;
    EXPECT_EQ(c2, 300) << what;
  }
}

// Where the axis points move at constant speed, rows and columns grow until neighbouring axis
// samples are at most `spacing` apart, along the sweep as along the axis; the farthest
// travelling point (here the spindle end) sets the rows.
TEST(EvaluationGrid, SpacingBoundsTheGapBetweenAxisSamples) {
  expect_gap_bound(plate_sweep(), "plate sweep");
  expect_gap_bound(turning_motion(), "turning");
}

// The same on a motion whose speed in t varies (the paper part's true motion, a few per cent):
// rows sized by the path length alone gave gaps 2.9–5% above the spacing.
TEST(EvaluationGrid, SpacingBoundsTheGapOnAMotionOfVaryingSpeed) {
  expect_gap_bound(testing::true_motion(40), "paper part");
}

TEST(EvaluationGrid, TheProductStaysWithinTheBudget) {
  const Cutter cylinder = Cutter::constant(CutterKind::cylinder, 50.0, 5.0);
  EvaluateOptions eo;
  eo.tolerance = 0.01;
  eo.rows = 10, eo.cols = 10;
  eo.spacing = 0.05;  // about 613 × 1001 unbounded
  eo.max_samples = 1000000000;
  const auto [free_rows, free_cols] = evaluation_grid(plate_sweep(), cylinder, eo);
  EXPECT_GT(free_rows, 600);
  EXPECT_EQ(free_cols, 1001);
  eo.max_samples = 20000;
  const auto [rows, cols] = evaluation_grid(plate_sweep(), cylinder, eo);
  EXPECT_LE(static_cast<long>(rows) * cols, eo.max_samples);
  EXPECT_GT(static_cast<long>(rows) * cols, 0.95 * eo.max_samples);
  // The two shrink in proportion.
  EXPECT_NEAR(static_cast<double>(rows) / cols, static_cast<double>(free_rows) / free_cols, 0.01);
  EXPECT_GE(rows, eo.rows);
  EXPECT_GE(cols, eo.cols);
}

TEST(EvaluateOptions, ValidateNamesTheProblem) {
  EvaluateOptions o;
  EXPECT_NE(o.validate().find("tolerance"), std::string::npos);
  o.tolerance = 0.01;
  EXPECT_TRUE(o.validate().empty());
  o.rows = 1;
  EXPECT_NE(o.validate().find("2 by 2"), std::string::npos);
  o.rows = 10;
  o.omega_band = 0.5;
  EXPECT_NE(o.validate().find("band"), std::string::npos);
}

}  // namespace
}  // namespace flank
