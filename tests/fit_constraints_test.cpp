// Cutter constraints of fit_motion (DESIGN "Real surfaces are not exact envelopes": every
// fitted cutter stays a real tool): the radius range and the slope margin hold for every s,
// not only at the samples; bounds that do not bind change nothing; the active-set step is
// the exact constrained minimiser.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "io/read_mesh.h"
#include "kernels/parallel.h"
#include "solver/evaluate_patch.h"
#include "solver/fit_motion.h"
#include "solver/propagate.h"
#include "solver/trim.h"
#include "test_parts.h"

namespace flank {
namespace {

using testing::PaperTool;

// The setup on Rotor 67 (upper face, 192 mm): 14 rulings from hub to tip spread along
// the chord (columns 5, 17, …, 155 of the face's 161 × 121 lofted grid, from its hub row to its
// tip row), each end 7 mm off the face along its normal, in chord order. A spline fit of this
// 147 mm sweep without bounds collapses the cutter to sphere radii of a few hundredths of a mm.
const double kBladeLines[][6] = {
    {96.5577, 8.0267, -3.3836, 243.7922, 6.7908, 17.1253},
    {97.5292, 13.4277, 2.6235, 243.3278, 13.1986, 20.0279},
    {98.2610, 17.8980, 8.3527, 242.7141, 19.0365, 22.7287},
    {99.5459, 22.5282, 15.1552, 241.8268, 25.3564, 25.7190},
    {100.5243, 26.1159, 21.6724, 240.8167, 31.0972, 28.5037},
    {101.9138, 29.4383, 29.0730, 239.4863, 37.2914, 31.5835},
    {103.2785, 31.8971, 36.0255, 238.0649, 42.9066, 34.4568},
    {104.7668, 33.9514, 43.8363, 236.3061, 48.9416, 37.6445},
    {106.0563, 35.1933, 51.1794, 234.5113, 54.3816, 40.6069},
    {107.3438, 35.7589, 59.3554, 232.3432, 60.3002, 43.9699},
    {108.4460, 35.4543, 66.9410, 230.2203, 65.6931, 47.3337},
    {109.5948, 34.0998, 75.1812, 227.8861, 71.3729, 51.3251},
    {110.6370, 31.8507, 82.5459, 225.7484, 76.3834, 55.2515},
    {111.8124, 28.2252, 90.2637, 223.4101, 81.6241, 59.8460},
};

Motion blade_start() {
  std::vector<Line> lines;
  for (const auto& l : kBladeLines) lines.push_back({Vec3(l[0], l[1], l[2]), Vec3(l[3], l[4], l[5])});
  return motion_from_lines(lines, 40);
}

// Extremes of d and |d′| on 1001 parameters: the constraints must hold between samples too.
struct ProfileRange {
  double d_min = 1e300, d_max = -1e300, slope_max = 0.0;
};
ProfileRange profile_range(const Cutter& c) {
  ProfileRange r;
  for (int i = 0; i <= 1000; ++i) {
    const double s = i / 1000.0;
    r.d_min = std::min(r.d_min, c.radius(s));
    r.d_max = std::max(r.d_max, c.radius(s));
    r.slope_max = std::max(r.slope_max, std::abs(c.slope(s)));
  }
  return r;
}

class RotorBlade : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    mesh_ = new io::LoadedMesh(io::read_mesh(FLANK_TEST_DATA_DIR "/rotor67_blade_upper.stl"));
    index_ = new SurfaceIndex(mesh_->mesh);
  }
  static void TearDownTestSuite() {
    delete index_;
    delete mesh_;
  }
  static FitOptions spline_options(bool bounded) {
    FitOptions o;
    o.kind = CutterKind::spline;
    if (bounded) o.radius_min = 0.01 * index_->diagonal(), o.radius_max = 0.10 * index_->diagonal();
    return o;
  }
  static io::LoadedMesh* mesh_;
  static SurfaceIndex* index_;
};
io::LoadedMesh* RotorBlade::mesh_ = nullptr;
SurfaceIndex* RotorBlade::index_ = nullptr;

TEST_F(RotorBlade, SplineStaysInTheRadiusRangeWhereItCollapsedWithout) {
  const Motion init = blade_start();
  const FitOptions bounded = spline_options(true);
  ASSERT_TRUE(bounded.validate().empty());

  const FitResult free_fit = fit_motion(*index_, init, spline_options(false));
  const ProfileRange f = profile_range(free_fit.cutter);
  std::printf("[ unbounded ] %s: sphere radii %.4f .. %.4f mm\n", free_fit.brief_report().c_str(),
              f.d_min, f.d_max);
  // The issue: without bounds the cutter shrinks far below 1% of the diagonal.
  EXPECT_LT(f.d_min, bounded.radius_min);
  EXPECT_FALSE(free_fit.radius_at_bound());

  const FitResult r = fit_motion(*index_, init, bounded);
  const ProfileRange b = profile_range(r.cutter);
  std::printf("[  bounded  ] %s: sphere radii %.4f .. %.4f mm, max |d'|/L %.4f\n",
              r.brief_report().c_str(), b.d_min, b.d_max, b.slope_max / r.cutter.length);
  EXPECT_TRUE(r.ok()) << to_string(r.status);
  EXPECT_NE(r.status, FitStatus::invalid_cutter);
  EXPECT_TRUE(r.cutter.valid());
  EXPECT_GE(b.d_min, bounded.radius_min - 1e-9);
  EXPECT_LE(b.d_max, bounded.radius_max + 1e-9);
  EXPECT_LT(b.slope_max, r.cutter.length);
  EXPECT_LE(b.slope_max, bounded.max_slope_fraction * r.cutter.length + 1e-9);
  // The fit pushes against the lower bound, and says so.
  EXPECT_TRUE(r.radius_at_min);
  EXPECT_NE(r.brief_report().find("lower bound"), std::string::npos) << r.brief_report();
  // The projection in the step extension and after each step keeps every coefficient inside.
  EXPECT_GE(r.cutter.coeffs.minCoeff(), bounded.radius_min);
  EXPECT_LE(r.cutter.coeffs.maxCoeff(), bounded.radius_max);
}

TEST_F(RotorBlade, EveryKindStaysARealTool) {
  const Motion init = blade_start();
  for (CutterKind kind : {CutterKind::cylinder, CutterKind::cone, CutterKind::barrel}) {
    FitOptions o = spline_options(true);
    o.kind = kind;
    const FitResult r = fit_motion(*index_, init, o);
    const ProfileRange b = profile_range(r.cutter);
    EXPECT_NE(r.status, FitStatus::invalid_cutter) << to_string(kind);
    EXPECT_TRUE(r.cutter.valid()) << to_string(kind);
    EXPECT_GE(b.d_min, o.radius_min - 1e-9) << to_string(kind);
    EXPECT_LE(b.d_max, o.radius_max + 1e-9) << to_string(kind);
    EXPECT_LE(b.slope_max, o.max_slope_fraction * r.cutter.length + 1e-9) << to_string(kind);
  }
}

TEST_F(RotorBlade, SameResultWhateverTheThreadCount) {
  const Motion init = blade_start();
  FitResult r[2];
  for (int threads : {1, 2}) {
    ThreadLimit limit(threads);
    r[threads - 1] = fit_motion(*index_, init, spline_options(true));
  }
  EXPECT_EQ(r[0].iterations, r[1].iterations);
  EXPECT_EQ(r[0].final_cost, r[1].final_cost);
  EXPECT_EQ(r[0].motion.a, r[1].motion.a);
  EXPECT_EQ(r[0].motion.b, r[1].motion.b);
  EXPECT_EQ(r[0].cutter.coeffs, r[1].cutter.coeffs);
  EXPECT_EQ(r[0].radius_at_min, r[1].radius_at_min);
  // On two threads the factorisations of rejected steps' retries are made ahead when the
  // other thread is free, and the fit takes the same steps: as many factorisations, the same
  // result. How many were made ahead depends on the machine's load (none, under ctest -j2 on
  // a busy machine): that is forced below, and counted by the benchmarks.
  EXPECT_EQ(r[0].timing.factorisations, r[1].timing.factorisations);
  EXPECT_GT(r[0].timing.factorisations, r[0].iterations) << "no step was rejected: nothing to make ahead";
  EXPECT_EQ(r[0].timing.made_ahead, 0);
  std::printf("%d factorisations for %d iterations, %d made ahead on 2 threads\n",
              r[1].timing.factorisations, r[1].iterations, r[1].timing.made_ahead);

  // Every retry's factorisation made ahead: the same steps and result again.
  ThreadLimit limit(2);
  const OffersAlwaysTaken taken;
  const FitResult ahead = fit_motion(*index_, init, spline_options(true));
  EXPECT_GT(ahead.timing.made_ahead, 0);
  EXPECT_EQ(ahead.timing.factorisations, r[0].timing.factorisations);
  EXPECT_EQ(ahead.iterations, r[0].iterations);
  EXPECT_EQ(ahead.final_cost, r[0].final_cost);
  EXPECT_EQ(ahead.motion.a, r[0].motion.a);
  EXPECT_EQ(ahead.motion.b, r[0].motion.b);
  EXPECT_EQ(ahead.cutter.coeffs, r[0].cutter.coeffs);
}

TEST_F(RotorBlade, TraceGoesToTheCallback) {
  FitOptions o = spline_options(true);
  o.max_iterations = 3;
  std::vector<std::string> lines;
  o.trace = [&lines](const std::string& line) { lines.push_back(line); };
  fit_motion(*index_, blade_start(), o);
  ASSERT_GE(lines.size(), 3u);
  for (const char* word : {"iter 0", "lambda", "cost", "interior", "|step|", "active"})
    EXPECT_NE(lines.front().find(word), std::string::npos) << lines.front();
}

// The Li–Mann–Bedi cone part (true meridian radii 4 → 7 mm) from the recovery tests' start.
struct ConeCase {
  SynthResult part = testing::paper_part(PaperTool::cone);
  SurfaceIndex index{part.mesh};
  Motion init = motion_from_lines(testing::perturbed_axes(7, 1.0, 2.0), 40);
};

TEST(FitConstraints, BoundsThatDoNotBindChangeNothing) {
  const ConeCase cone;
  const double diag = cone.index.diagonal();
  Patch patch[2];
  FitPatchResult fit[2];
  for (int bounded : {0, 1}) {
    FitPatchOptions fo;
    fo.fit.kind = CutterKind::cone;
    fo.tolerance = 1e-4 * diag;
    if (bounded) fo.fit.radius_min = 1.0, fo.fit.radius_max = 10.0;
    fit[bounded] = fit_and_trim(cone.index, cone.init, fo);
    ASSERT_EQ(fit[bounded].status, FitPatchStatus::ok) << fit[bounded].message;
    EvaluateOptions eo;
    eo.tolerance = fo.tolerance;
    patch[bounded] = evaluate_patch(cone.index, fit[bounded].fit.motion, fit[bounded].fit.cutter, eo);
  }
  EXPECT_FALSE(fit[1].fit.radius_at_bound());
  EXPECT_FALSE(fit[1].fit.slope_at_limit);
  EXPECT_NEAR(patch[1].coverage_fraction, patch[0].coverage_fraction, 1e-3);
  EXPECT_GE(patch[1].coverage_fraction, 0.95);
  EXPECT_LE(patch[1].error.max, 2e-5 * diag);
  for (double s : {0.0, 0.25, 0.5, 0.75, 1.0})
    EXPECT_NEAR(fit[1].fit.cutter.radius(s), fit[0].fit.cutter.radius(s), 1e-3) << "s " << s;
}

TEST(FitConstraints, RadiusMaxBindsOnTheCone) {
  const ConeCase cone;
  FitOptions o;
  o.kind = CutterKind::cone;
  o.radius_max = 6.0;  // the true sphere radii run 4.0 → 7.0
  const FitResult r = fit_motion(cone.index, cone.init, o);
  const ProfileRange b = profile_range(r.cutter);
  std::printf("[  bounded  ] cone under 6 mm: %s, sphere radii %.4f .. %.4f\n",
              r.brief_report().c_str(), b.d_min, b.d_max);
  EXPECT_TRUE(r.ok()) << to_string(r.status);
  EXPECT_TRUE(r.cutter.valid());
  EXPECT_LE(b.d_max, 6.0 + 1e-9);
  EXPECT_TRUE(r.radius_at_max);
  EXPECT_FALSE(r.radius_at_min);
  EXPECT_NE(r.brief_report().find("upper bound"), std::string::npos) << r.brief_report();
  // The tip end is not held: the fit still finds the part's radius there.
  EXPECT_LT(r.cutter.radius(0.0), 5.5);

  FitResult again[2];
  for (int threads : {1, 2}) {
    ThreadLimit limit(threads);
    again[threads - 1] = fit_motion(cone.index, cone.init, o);
  }
  EXPECT_EQ(again[0].motion.a, again[1].motion.a);
  EXPECT_EQ(again[0].motion.b, again[1].motion.b);
  EXPECT_EQ(again[0].cutter.coeffs, again[1].cutter.coeffs);
}

TEST(FitConstraints, InitialProfileIsMadeFeasible) {
  const ConeCase cone;
  FitOptions o;
  o.kind = CutterKind::cone;
  o.radius_min = 4.5, o.radius_max = 5.0;
  o.max_iterations = 1;
  // A seed far outside the range and steeper than the cutter is long.
  Cutter seed;
  seed.kind = CutterKind::cone;
  seed.length = kPaperToolLength;
  seed.coeffs = Eigen::Vector2d(-30.0, 80.0);
  const FitResult r = fit_motion(cone.index, cone.init, o, &seed);
  const ProfileRange b = profile_range(r.cutter);
  EXPECT_GE(b.d_min, 4.5 - 1e-9);
  EXPECT_LE(b.d_max, 5.0 + 1e-9);
  EXPECT_TRUE(r.cutter.valid());
}

TEST(FitConstraints, ValidateNamesAnEmptyRange) {
  FitOptions o;
  o.radius_min = 5.0, o.radius_max = 1.0;
  const std::string e = o.validate();
  EXPECT_NE(e.find("radius"), std::string::npos) << e;
  EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  o.radius_max = 5.0;  // a single radius is a range
  EXPECT_TRUE(o.validate().empty()) << o.validate();
  o.radius_min = -1.0;
  EXPECT_NE(o.validate().find("radius"), std::string::npos);
  o = FitOptions{};
  o.radius_max = 3.0;  // only an upper bound
  EXPECT_TRUE(o.validate().empty());
  o.max_slope_fraction = 1.0;
  EXPECT_NE(o.validate().find("slope"), std::string::npos);
  o.max_slope_fraction = 0.0;  // no slope bound
  EXPECT_TRUE(o.validate().empty());
}

// ½ δᵀHδ + gᵀδ.
double model(const MatX& H, const VecX& g, const VecX& d) { return 0.5 * d.dot(H * d) + g.dot(d); }

// The exact minimum by enumeration: every subset of constraints held as equalities, the
// feasible minimisers compared (one of them is the optimum of the strictly convex QP).
double brute_force_minimum(const MatX& H, const VecX& g, const MatX& A, const VecX& b,
                           double tolerance) {
  const int m = static_cast<int>(A.rows());
  double best = 1e300;
  for (int mask = 0; mask < (1 << m); ++mask) {
    std::vector<int> rows;
    for (int i = 0; i < m; ++i)
      if (mask >> i & 1) rows.push_back(i);
    const int w = static_cast<int>(rows.size()), n = static_cast<int>(H.rows());
    MatX K = MatX::Zero(n + w, n + w);
    VecX rhs(n + w);
    K.topLeftCorner(n, n) = H;
    rhs.head(n) = -g;
    for (int r = 0; r < w; ++r) {
      K.block(n + r, 0, 1, n) = A.row(rows[r]);
      K.block(0, n + r, n, 1) = A.row(rows[r]).transpose();
      rhs(n + r) = b(rows[r]);
    }
    const Eigen::FullPivLU<MatX> lu(K);
    if (!lu.isInvertible()) continue;
    const VecX d = lu.solve(rhs).head(n);
    if (((A * d - b).array() <= tolerance).all()) best = std::min(best, model(H, g, d));
  }
  return best;
}

TEST(ActiveSetStep, IsTheExactConstrainedMinimiser) {
  std::mt19937 rng(20261122);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  int constrained = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const int n = 5, m = 7;
    MatX R(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) R(i, j) = normal(rng);
    const MatX H = R.transpose() * R + 0.1 * MatX::Identity(n, n);
    VecX g(n);
    for (int i = 0; i < n; ++i) g(i) = 3.0 * normal(rng);
    MatX A(m, n);
    VecX b(m);
    for (int i = 0; i < m; ++i) {
      for (int j = 0; j < n; ++j) A(i, j) = normal(rng);
      b(i) = trial % 3 == 0 ? 0.0 : uniform(rng);  // δ = 0 on the boundary of all, or inside
    }
    const Eigen::LLT<MatX> llt(H);
    const auto solve = [&llt](const VecX& rhs, VecX* x) {
      *x = llt.solve(rhs);
      return true;
    };
    const VecX free_step = llt.solve(-g);
    // Above the rounding of δ (|δ_free| up to ~50, A_W H⁻¹ A_Wᵀ of random rows far from
    // well-conditioned at times).
    const double tolerance = 1e-8 * (1.0 + free_step.norm());
    const ActiveSetStep s = active_set_step(solve, free_step, A, b, tolerance, 100);
    ASSERT_TRUE(s.ok);
    ASSERT_TRUE(s.optimal) << "trial " << trial;
    if (!s.active.empty()) ++constrained;
    // KKT: feasible, multipliers non-negative, active rows tight, H δ + g + A_Wᵀ λ = 0.
    EXPECT_LE((A * s.step - b).maxCoeff(), tolerance) << "trial " << trial;
    VecX stationarity = H * s.step + g;
    for (std::size_t k = 0; k < s.active.size(); ++k) {
      const int row = s.active[k];
      EXPECT_GE(s.multipliers(static_cast<Eigen::Index>(k)), -1e-12);
      EXPECT_NEAR(A.row(row).dot(s.step), b(row), tolerance);
      stationarity += s.multipliers(static_cast<Eigen::Index>(k)) * A.row(row).transpose();
    }
    EXPECT_LE(stationarity.norm(), 1e-8 * (1.0 + g.norm())) << "trial " << trial;
    EXPECT_NEAR(model(H, g, s.step), brute_force_minimum(H, g, A, b, 1e-10 * (1.0 + free_step.norm())), 1e-7 * (1.0 + g.norm()))
        << "trial " << trial;
  }
  EXPECT_GT(constrained, 200);  // the test exercised the active set, not only free steps
}

TEST(ActiveSetStep, FreeStepInsideIsKeptAsIs) {
  const MatX H = Eigen::Vector3d(1.0, 2.0, 4.0).asDiagonal();
  const VecX g = Eigen::Vector3d(-1.0, 1.0, -2.0);
  const VecX free_step = -H.inverse() * g;
  MatX A(2, 3);
  A << 1, 0, 0, 0, 0, 1;
  const VecX b = Eigen::Vector2d(2.0, 2.0);
  const auto solve = [&H](const VecX& rhs, VecX* x) {
    *x = H.inverse() * rhs;
    return true;
  };
  const ActiveSetStep s = active_set_step(solve, free_step, A, b, 1e-12, 10);
  ASSERT_TRUE(s.ok && s.optimal);
  EXPECT_EQ(s.step, free_step);
  EXPECT_TRUE(s.active.empty());
}

TEST(ActiveSetStep, DependentAndCutShortStaysFeasible) {
  // Box |δ_k| ≤ 1 on a pull toward (5, −5, 5), each bound given twice (dependent rows).
  const MatX H = MatX::Identity(3, 3);
  const VecX free_step = Eigen::Vector3d(5.0, -5.0, 5.0);
  MatX A(12, 3);
  VecX b(12);
  for (int rep = 0; rep < 2; ++rep)
    for (int k = 0; k < 3; ++k) {
      A.row(6 * rep + 2 * k) = VecX::Unit(3, k).transpose();
      A.row(6 * rep + 2 * k + 1) = -VecX::Unit(3, k).transpose();
      b(6 * rep + 2 * k) = b(6 * rep + 2 * k + 1) = 1.0;
    }
  const auto solve = [](const VecX& rhs, VecX* x) {
    *x = rhs;
    return true;
  };
  const ActiveSetStep s = active_set_step(solve, free_step, A, b, 1e-12, 50);
  ASSERT_TRUE(s.ok && s.optimal);
  EXPECT_NEAR((s.step - Eigen::Vector3d(1.0, -1.0, 1.0)).norm(), 0.0, 1e-12);
  EXPECT_EQ(s.active.size(), 3u);
  // One iteration: short of the optimum, but feasible and no worse than δ = 0.
  const ActiveSetStep one = active_set_step(solve, free_step, A, b, 1e-12, 1);
  ASSERT_TRUE(one.ok);
  EXPECT_FALSE(one.optimal);
  EXPECT_LE((A * one.step - b).maxCoeff(), 1e-12);
  EXPECT_LT(model(H, -free_step, one.step), 0.0);
  // A failing solve is reported, not hidden.
  const auto broken = [](const VecX&, VecX*) { return false; };
  EXPECT_FALSE(active_set_step(broken, free_step, A, b, 1e-12, 50).ok);
}

}  // namespace
}  // namespace flank
