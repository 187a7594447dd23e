// Candidate lines (solver/candidate_lines.h) against ground truth: the free run along a line
// over a flat rectangle ends at its edges and at covered faces, as the geometry says; a line
// is laid over a run as the header promises; and at a seed in the middle of the exact cone
// part the best candidate lies along the true axis, spans the part's width, gets the cone's
// kind (or at most the barrel's) and sweeps over most of it.
#include "solver/candidate_lines.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>

#include "kernels/parallel.h"
#include "solver/seed_tiles.h"
#include "solver/thresholds.h"
#include "test_parts.h"

namespace flank {
namespace {

using testing::PaperTool;

// The plate z = 0 over [0, sx] × [0, sy], nx × ny cells, two triangles each, counter-clockwise
// seen from +z (the tool side).
Mesh plate(int nx, int ny, double sx, double sy) {
  Mesh m;
  m.V.resize(static_cast<Eigen::Index>(nx + 1) * (ny + 1), 3);
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) m.V.row(j * (nx + 1) + i) << sx * i / nx, sy * j / ny, 0.0;
  m.F.resize(2 * static_cast<Eigen::Index>(nx) * ny, 3);
  Eigen::Index f = 0;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const int v00 = j * (nx + 1) + i, v10 = v00 + 1, v01 = v00 + nx + 1, v11 = v01 + 1;
      m.F.row(f++) << v00, v10, v11;
      m.F.row(f++) << v00, v11, v01;
    }
  return m;
}

Vec3 centroid(const Mesh& m, int f) {
  return (m.V.row(m.F(f, 0)) + m.V.row(m.F(f, 1)) + m.V.row(m.F(f, 2))).transpose() / 3.0;
}

// free_run bisects each end to 1/64 of a step of reach/64, and reports the middle of the last
// bracket: within half of that of the true end.
double run_precision(double reach) { return reach / 64.0 / 64.0; }

// ---------------------------------------------------------------------------------------------
// free_run

TEST(FreeRun, EndsAtThePlateEdges) {
  // Plate [0, 40] × [0, 20]; a line 2 mm above it along x through x = 15: the edges are 15 mm
  // behind and 25 mm ahead.
  const SurfaceIndex index(plate(40, 20, 40.0, 20.0));
  const Vec3 mid(15.0, 7.3, 2.0), u = Vec3::UnitX();
  const double reach = 30.0;
  const FreeRun run = free_run(index, mid, u, reach, {});
  EXPECT_NEAR(run.low, 15.0, run_precision(reach));
  EXPECT_NEAR(run.high, 25.0, run_precision(reach));
  EXPECT_FALSE(run.low_open);
  EXPECT_FALSE(run.high_open);
  // Along −x the same run, mirrored.
  const FreeRun back = free_run(index, mid, -u, reach, {});
  EXPECT_NEAR(back.low, 25.0, run_precision(reach));
  EXPECT_NEAR(back.high, 15.0, run_precision(reach));
}

TEST(FreeRun, AnEdgeBeyondTheReachIsOpen) {
  const SurfaceIndex index(plate(40, 20, 40.0, 20.0));
  const Vec3 mid(15.0, 7.3, 2.0), u = Vec3::UnitX();
  const double reach = 20.0;  // the +x edge is 25 mm away, the −x edge 15
  const FreeRun run = free_run(index, mid, u, reach, {});
  EXPECT_NEAR(run.low, 15.0, run_precision(reach));
  EXPECT_FALSE(run.low_open);
  EXPECT_TRUE(run.high_open);
  EXPECT_DOUBLE_EQ(run.high, reach);
  // Both beyond: both open, both at the reach.
  const FreeRun short_run = free_run(index, mid, u, 10.0, {});
  EXPECT_TRUE(short_run.low_open);
  EXPECT_TRUE(short_run.high_open);
  EXPECT_DOUBLE_EQ(short_run.low, 10.0);
  EXPECT_DOUBLE_EQ(short_run.high, 10.0);
}

TEST(FreeRun, DiagonalDirectionEndsAtTheEdgesItCrosses) {
  // Along (1, 1)/√2 from (10, 5): the run meets y = 0 after 5√2 behind and y = 20 after 15√2
  // ahead (x stays inside [0, 40]).
  const SurfaceIndex index(plate(40, 20, 40.0, 20.0));
  const Vec3 mid(10.0, 5.0, 1.0), u = Vec3(1.0, 1.0, 0.0).normalized();
  const double reach = 30.0;
  const FreeRun run = free_run(index, mid, u, reach, {});
  EXPECT_NEAR(run.low, 5.0 * std::sqrt(2.0), run_precision(reach));
  EXPECT_NEAR(run.high, 15.0 * std::sqrt(2.0), run_precision(reach));
  EXPECT_FALSE(run.low_open);
  EXPECT_FALSE(run.high_open);
}

TEST(FreeRun, CoveredFacesStopTheRunWhereTheyBegin) {
  const Mesh m = plate(40, 20, 40.0, 20.0);
  const SurfaceIndex index(m);
  // Faces over x > 30 are covered: the run along +x from x = 12 stops at x = 30, 18 mm on,
  // though Φ goes on to x = 40.
  CoveredFaces covered(static_cast<std::size_t>(m.face_count()), 0);
  for (int f = 0; f < m.face_count(); ++f) covered[static_cast<std::size_t>(f)] = centroid(m, f).x() > 30.0;
  const Vec3 mid(12.0, 9.6, 3.0), u = Vec3::UnitX();
  const double reach = 35.0;
  const FreeRun run = free_run(index, mid, u, reach, covered);
  EXPECT_NEAR(run.low, 12.0, run_precision(reach));   // the plate's edge
  EXPECT_NEAR(run.high, 18.0, run_precision(reach));  // the covered area
  EXPECT_FALSE(run.low_open);
  EXPECT_FALSE(run.high_open);
  // Nothing covered: the plate's edge, 28 mm on.
  EXPECT_NEAR(free_run(index, mid, u, reach, {}).high, 28.0, run_precision(reach));
  // An all-zero mask is the same as none.
  const CoveredFaces none(static_cast<std::size_t>(m.face_count()), 0);
  EXPECT_NEAR(free_run(index, mid, u, reach, none).high, 28.0, run_precision(reach));
}

// ---------------------------------------------------------------------------------------------
// lay_line

struct Laid {
  double from, to;  // the line's ends as signed distances from mid along u
};

Laid laid(const FreeRun& run, double L, double overhang) {
  const Vec3 mid(1.0, -2.0, 3.0), u = Vec3(2.0, -1.0, 2.0).normalized();
  const Line l = lay_line(mid, u, L, run, overhang);
  // Length L and direction u, always.
  EXPECT_NEAR(l.length(), L, 1e-12 * L);
  EXPECT_NEAR((l.b - l.a).normalized().dot(u), 1.0, 1e-12);
  // On the line through mid along u.
  EXPECT_NEAR((l.a - mid).cross(u).norm(), 0.0, 1e-12 * L);
  return {(l.a - mid).dot(u), (l.b - mid).dot(u)};
}

TEST(LayLine, ShorterRunGetsTheLineCentredOnIt) {
  // Run [−3, 5] (8 long) under a line of 20: the line's middle is the run's middle, +1.
  const Laid l = laid({3.0, 5.0, false, false}, 20.0, 0.03);
  EXPECT_NEAR(0.5 * (l.from + l.to), 1.0, 1e-12);
  EXPECT_NEAR(l.from, -9.0, 1e-12);
  // A run exactly L long: centred too.
  const Laid e = laid({4.0, 16.0, false, false}, 20.0, 0.03);
  EXPECT_NEAR(e.from, -4.0, 1e-12);
  EXPECT_NEAR(e.to, 16.0, 1e-12);
}

TEST(LayLine, AgainstTheNearEndWithTheOverhang) {
  const double L = 10.0, overhang = 0.03;
  // The low end 2 from mid (< 3/4 L), the high one far: the line starts overhang·L before it.
  const Laid low = laid({2.0, 30.0, false, false}, L, overhang);
  EXPECT_NEAR(low.from, -2.0 - overhang * L, 1e-12);
  // The high end 4 from mid: the line ends overhang·L past it.
  const Laid high = laid({30.0, 4.0, false, false}, L, overhang);
  EXPECT_NEAR(high.to, 4.0 + overhang * L, 1e-12);
  // Both ends within 3/4 L: the nearer one (ties go low).
  const Laid both = laid({6.0, 5.0, false, false}, L, overhang);
  EXPECT_NEAR(both.to, 5.0 + overhang * L, 1e-12);
  const Laid tie = laid({5.5, 5.5, false, false}, L, overhang);
  EXPECT_NEAR(tie.from, -5.5 - overhang * L, 1e-12);
  // No overhang: exactly at the end.
  EXPECT_NEAR(laid({2.0, 30.0, false, false}, L, 0.0).from, -2.0, 1e-12);
}

TEST(LayLine, CentredOnMidWhenNoEndIsNear) {
  const double L = 10.0;
  // Both ends beyond 3/4 L.
  const Laid far = laid({8.0, 20.0, false, false}, L, 0.03);
  EXPECT_NEAR(far.from, -5.0, 1e-12);
  EXPECT_NEAR(far.to, 5.0, 1e-12);
  // Just past 3/4 L is far, just inside it is near.
  EXPECT_NEAR(laid({7.5 + 1e-9, 20.0, false, false}, L, 0.03).from, -5.0, 1e-12);
  EXPECT_NEAR(laid({7.5 - 1e-9, 20.0, false, false}, L, 0.03).from, -7.5 + 1e-9 - 0.3, 1e-12);
  // An open end is no end, however near its distance (it is only the reach).
  const Laid open = laid({2.0, 20.0, true, false}, L, 0.03);
  EXPECT_NEAR(open.from, -5.0, 1e-12);
  const Laid open_high = laid({2.0, 2.5, true, false}, 4.0, 0.03);  // run 4.5 > L = 4, high near
  EXPECT_NEAR(open_high.to, 2.5 + 0.03 * 4.0, 1e-12);
}

// ---------------------------------------------------------------------------------------------
// seed_candidates on the exact cone part

// The options solver/decompose.cpp derives from the diagonal (`lo`), with the given kinds.
CandidateLineOptions decompose_like(double diag, std::vector<CutterKind> kinds) {
  CandidateLineOptions o;
  o.kinds = std::move(kinds);
  o.radius_min = 0.01 * diag, o.radius_max = 0.10 * diag;
  o.length_min = 0.03 * diag, o.length_max = 0.45 * diag;
  o.step = 0.015 * diag;
  o.max_travel = 2.0 * diag;
  return o;
}

// The true ruling nearest to point p (by distance to the axis segment), on a fine t grid.
double nearest_true_t(const AxisMotion& m, const Vec3& p) {
  double best_t = 0.0, best = std::numeric_limits<double>::infinity();
  for (int i = 0; i <= 2000; ++i) {
    const double t = i / 2000.0;
    const Vec3 a = m.a(t, 0), b = m.b(t, 0);
    const double s = std::clamp((p - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
    const double d = (p - (a + s * (b - a))).norm();
    if (d < best) best = d, best_t = t;
  }
  return best_t;
}

double degrees_between_lines(const Vec3& x, const Vec3& y) {
  return std::acos(std::min(1.0, std::abs(x.normalized().dot(y.normalized())))) * 180.0 / std::numbers::pi;
}

// How far (degrees) a candidate's direction is from the true axis where it lies.
double degrees_off_axis(const AxisMotion& truth, const Line& l) {
  const double t = nearest_true_t(truth, 0.5 * (l.a + l.b));
  return degrees_between_lines(l.b - l.a, truth.b(t, 0) - truth.a(t, 0));
}

// A seed at one vertex: seed_tiles with only that vertex allowed (its frame as the solver
// computes it).
Seed seed_at(const Mesh& mesh, int vertex, double spacing) {
  SeedOptions so;
  so.spacing = spacing;
  so.allowed.assign(static_cast<std::size_t>(mesh.vertex_count()), 0);
  so.allowed[static_cast<std::size_t>(vertex)] = 1;
  const std::vector<Seed> seeds = seed_tiles(mesh, so);
  EXPECT_EQ(seeds.size(), 1u);
  return seeds.empty() ? Seed{} : seeds[0];
}

// The exact cone part at 121 × 31 (t × s): vertex (i, j) lies on the contact curve of the
// true ruling at t = i / 120.
constexpr int kRows = 121, kCols = 31;

struct ConePart {
  SynthResult part = testing::paper_part(PaperTool::cone, kRows, kCols);
  SurfaceIndex index{part.mesh};
  double diag = index.diagonal();
  double area = total_area(part.mesh);
  AxisMotion truth = guide_motion(paper_guides(), kPaperToolLength);
};

void print(const char* what, const std::vector<LineCandidate>& c, const ConePart& p) {
  for (std::size_t k = 0; k < c.size(); ++k)
    std::printf("[ candidates ] %s %zu: %s L %.2f, %.2f deg off the axis, F_l %.2e, rms %.2e, radii %.2f..%.2f, "
                "estimate %.3f of the area\n",
                what, k, std::string(to_string(c[k].kind)).c_str(), c[k].line.length(),
                degrees_off_axis(p.truth, c[k].line), c[k].movability.value, c[k].movability.profile_rms,
                c[k].movability.radius_min, c[k].movability.radius_max, c[k].estimate / p.area);
}

// The properties every candidate list has: best estimate first, from this seed, each with its
// probe sweep (≥ 4 rulings) and the kind the header promises: the simplest allowed kind whose
// profile fits the line's footpoint distances within kind_misfit (the most general one within
// line_misfit).
void expect_well_formed(const SurfaceIndex& index, const std::vector<LineCandidate>& c, int seed_id,
                        const CandidateLineOptions& o, const Thresholds& th) {
  for (std::size_t k = 0; k < c.size(); ++k) {
    EXPECT_EQ(c[k].seed, seed_id);
    EXPECT_GE(c[k].sweep.rulings.size(), 4u);
    EXPECT_EQ(c[k].sweep.fresh.size(), c[k].sweep.rulings.size());
    EXPECT_GE(c[k].line.length(), o.length_min * (1 - 1e-9));
    EXPECT_LE(c[k].line.length(), o.length_max * (1 + 1e-9));
    if (k > 0) {
      EXPECT_GE(c[k - 1].estimate, c[k].estimate) << k;
    }
    // A real tool, with the slack the search allows before the fit corrects the line.
    EXPECT_GE(c[k].movability.radius_min, 0.9 * o.radius_min) << k;
    EXPECT_LE(c[k].movability.radius_max, 1.1 * o.radius_max) << k;
    const double limit = c[k].kind == o.kinds.back() ? th.line_misfit : th.kind_misfit;
    EXPECT_LE(c[k].movability.profile_rms, limit) << k;
    MovabilityOptions mo;
    mo.samples = o.fine_samples;
    for (CutterKind simpler : o.kinds) {
      if (simpler == c[k].kind) break;
      mo.profile = simpler;
      const Movability m = movability(index, c[k].line.a, c[k].line.b, mo);
      // Either it does not fit, or its radii/slope make no real tool (acceptable() in the code).
      const bool fits = m.ok() && m.profile_rms <= th.kind_misfit && m.max_slope < 0.9 * c[k].line.length() &&
                        m.radius_min >= 0.9 * o.radius_min && m.radius_max <= 1.1 * o.radius_max;
      EXPECT_FALSE(fits) << k << ": " << to_string(simpler) << " fits within " << m.profile_rms;
    }
  }
}

// At the seed in the middle of the exact cone part, (t, s) = (0.5, 0.5), with the kinds up to
// the barrel allowed (directions scored with the barrel's profile): the best candidate lies
// along the true axis, as long as the part is wide (the 50 mm tool) plus the overhang at both
// edges, of the cone's kind or at most the barrel's (a line 1° off the axis does not follow a
// cone's distances within kind_misfit, a quarter of the tolerance), and its probe sweep passes
// over nearly all of the part.
TEST(SeedCandidates, ExactConePartGivesTheTrueAxisAcrossThePart) {
  const ConePart p;
  ASSERT_EQ(p.part.invalid, 0);
  const int vertex = (kRows / 2) * kCols + kCols / 2;
  const Seed seed = seed_at(p.part.mesh, vertex, 0.12 * p.diag);
  ASSERT_EQ(seed.vertex, vertex);
  const CandidateLineOptions o = decompose_like(p.diag, {CutterKind::cylinder, CutterKind::cone, CutterKind::barrel});
  ASSERT_TRUE(o.validate().empty()) << o.validate();
  const Thresholds th = thresholds_for(1e-4 * p.diag);
  long long scored = 0;
  const std::vector<LineCandidate> c = seed_candidates(p.index, seed, 7, {}, o, th, &scored);
  print("middle", c, p);
  ASSERT_FALSE(c.empty());
  EXPECT_GE(scored, o.directions * o.tilts * o.radii);  // every coarse line at least
  expect_well_formed(p.index, c, 7, o, th);

  const LineCandidate& best = c.front();
  EXPECT_NEAR(nearest_true_t(p.truth, 0.5 * (best.line.a + best.line.b)), 0.5, 0.05);
  EXPECT_LT(degrees_off_axis(p.truth, best.line), 3.0);
  EXPECT_NEAR(best.line.length(), kPaperToolLength * (1.0 + 2.0 * o.overhang), 0.03 * kPaperToolLength);
  EXPECT_TRUE(best.kind == CutterKind::cone || best.kind == CutterKind::barrel) << to_string(best.kind);
  EXPECT_GT(best.estimate, 0.9 * p.area);
  EXPECT_LT(best.estimate, 1.05 * p.area);
}

// The same at seeds across the part, with the cone alone and with the kinds up to the barrel:
// at each some candidate lies within a few degrees of the true axis.
TEST(SeedCandidates, SomeCandidateFollowsTheTrueAxisAcrossThePart) {
  const ConePart p;
  const Thresholds th = thresholds_for(1e-4 * p.diag);
  for (const std::vector<CutterKind>& kinds :
       {std::vector<CutterKind>{CutterKind::cone}, std::vector<CutterKind>{CutterKind::cone, CutterKind::barrel}}) {
    const CandidateLineOptions o = decompose_like(p.diag, kinds);
    for (auto [row, col] : {std::pair{30, 22}, std::pair{60, 8}, std::pair{100, 22}}) {
      const Seed seed = seed_at(p.part.mesh, row * kCols + col, 0.12 * p.diag);
      long long scored = 0;
      const std::vector<LineCandidate> c = seed_candidates(p.index, seed, 0, {}, o, th, &scored);
      ASSERT_FALSE(c.empty());
      expect_well_formed(p.index, c, 0, o, th);
      double closest = 180.0;
      for (const LineCandidate& x : c) closest = std::min(closest, degrees_off_axis(p.truth, x.line));
      EXPECT_LT(closest, 3.0) << "seed at row " << row << " col " << col << " kinds up to "
                              << to_string(kinds.back());
    }
  }
}

// With the spline among the allowed kinds (the default of DecomposeOptions) fewer seeds lay a
// line along the axis of the exact cone part: the spline fits the distances of a line in
// almost any direction, and this part's axis surface is nearly developable, so lines 15–80°
// off the axis also have F_l near 0 and score as well. Some seeds still find it (4 of 27 here,
// all 27 with the kinds up to the barrel), and decompose needs one: with every kind allowed
// the part still comes back as one patch (decompose_test, DecomposeExact with default kinds).
TEST(SeedCandidates, AllKindsAllowedSomeSeedsFindTheTrueAxis) {
  const ConePart p;
  const CandidateLineOptions o =
      decompose_like(p.diag, {CutterKind::cylinder, CutterKind::cone, CutterKind::barrel, CutterKind::spline});
  const Thresholds th = thresholds_for(1e-4 * p.diag);
  int seeds = 0, found = 0;
  for (int row = 20; row <= 100; row += 10)
    for (int col : {8, 15, 22}) {
      const Seed seed = seed_at(p.part.mesh, row * kCols + col, 0.12 * p.diag);
      long long scored = 0;
      const std::vector<LineCandidate> c = seed_candidates(p.index, seed, 0, {}, o, th, &scored);
      double closest = 180.0;
      for (const LineCandidate& x : c) closest = std::min(closest, degrees_off_axis(p.truth, x.line));
      ++seeds;
      found += closest < 3.0;
    }
  std::printf("[ candidates ] all kinds: %d of %d seeds have a candidate within 3 degrees of the axis\n", found, seeds);
  EXPECT_GE(found, 1);
}

// With the part before t = 0.5 covered, the estimate of a seed past the middle counts only
// what is still to cut: about the uncovered half, not the whole part it sweeps over.
TEST(SeedCandidates, EstimateCountsOnlyUncoveredArea) {
  const ConePart p;
  const Seed seed = seed_at(p.part.mesh, (kRows / 2 + 10) * kCols + kCols / 2, 0.12 * p.diag);
  const CandidateLineOptions o = decompose_like(p.diag, {CutterKind::cone});
  const Thresholds th = thresholds_for(1e-4 * p.diag);
  long long scored = 0;
  const std::vector<LineCandidate> all = seed_candidates(p.index, seed, 0, {}, o, th, &scored);
  CoveredFaces covered(static_cast<std::size_t>(p.part.mesh.face_count()), 0);
  double covered_area = 0.0;
  const VecX fa = face_areas(p.part.mesh);
  const Mesh& m = p.part.mesh;
  for (int f = 0; f < m.face_count(); ++f) {
    const bool c = m.F(f, 0) / kCols < kRows / 2 && m.F(f, 1) / kCols < kRows / 2 && m.F(f, 2) / kCols < kRows / 2;
    covered[static_cast<std::size_t>(f)] = c;
    if (c) covered_area += fa(f);
  }
  const std::vector<LineCandidate> half = seed_candidates(p.index, seed, 0, covered, o, th, &scored);
  print("free", all, p);
  print("half covered", half, p);
  ASSERT_FALSE(all.empty());
  ASSERT_FALSE(half.empty());
  expect_well_formed(p.index, half, 0, o, th);
  const double uncovered = p.area - covered_area;
  EXPECT_GT(all[0].estimate, 0.9 * p.area);
  EXPECT_LT(half[0].estimate, 1.05 * uncovered);
  EXPECT_GT(half[0].estimate, 0.8 * uncovered);
}

// decompose reuses a seed's search in a later round when its free runs come out the same under
// the new cover: the lines found under one cover, ranked for another, must be exactly those a
// search under the other finds. Covering a corner of the part, off the lines through the seed,
// leaves its free runs as they were but changes what the sweeps pass over.
TEST(SeedCandidates, LinesFoundUnderOneCoverRankForAnotherAsASearchThere) {
  const ConePart p;
  const Mesh& m = p.part.mesh;
  const Seed seed = seed_at(m, (kRows / 2 + 10) * kCols + kCols / 2, 0.12 * p.diag);
  const CandidateLineOptions o = decompose_like(p.diag, {CutterKind::cone});
  const Thresholds th = thresholds_for(1e-4 * p.diag);
  // Faces whose vertices all lie in rows [0, rows) and columns [cols, kCols).
  auto block = [&](int rows, int cols) {
    CoveredFaces c(static_cast<std::size_t>(m.face_count()), 0);
    for (int f = 0; f < m.face_count(); ++f) {
      bool in = true;
      for (int k = 0; k < 3; ++k) in &= m.F(f, k) / kCols < rows && m.F(f, k) % kCols >= cols;
      c[static_cast<std::size_t>(f)] = in;
    }
    return c;
  };
  const CoveredFaces first = block(kRows / 8, kCols - kCols / 8), later = block(kRows / 3, kCols - kCols / 3);
  long long scored = 0;
  std::vector<FreeRunRecord> runs;
  std::vector<LineCandidate> reused = seed_candidates(p.index, seed, 0, first, o, th, &scored, &runs);
  ASSERT_FALSE(reused.empty());
  ASSERT_FALSE(runs.empty());
  std::vector<double> before;
  for (const LineCandidate& c : reused) before.push_back(c.estimate);
  ASSERT_TRUE(free_runs_hold(p.index, runs, later));
  rank_candidates(reused, later);
  const std::vector<LineCandidate> searched = seed_candidates(p.index, seed, 0, later, o, th, &scored);
  ASSERT_EQ(reused.size(), searched.size());
  bool changed = false;
  for (std::size_t k = 0; k < reused.size(); ++k) {
    EXPECT_EQ(reused[k].order, searched[k].order) << k;
    EXPECT_EQ(reused[k].line.a, searched[k].line.a) << k;
    EXPECT_EQ(reused[k].line.b, searched[k].line.b) << k;
    EXPECT_EQ(reused[k].kind, searched[k].kind) << k;
    EXPECT_EQ(reused[k].estimate, searched[k].estimate) << k;
    EXPECT_EQ(reused[k].swept, searched[k].swept) << k;
    EXPECT_EQ(reused[k].sweep.fresh, searched[k].sweep.fresh) << k;
    changed |= std::find(before.begin(), before.end(), searched[k].estimate) == before.end();
  }
  EXPECT_TRUE(changed) << "the later cover should change what some sweep passes over";
  // Covering the seed's own rows changes its free runs: its search is not reused.
  EXPECT_FALSE(free_runs_hold(p.index, runs, block(kRows / 2 + 12, 0)));
}

// A seed's search runs its lines concurrently and joins what each found in a fixed order: at
// one thread and at two it finds the same lines in the same order, records the same free runs
// in the same order (what decompose's reuse of a search compares) and counts the same lines.
// With the kinds up to the barrel, two profiles steer the search (two refinements per
// direction), and under a partial cover the lines are also laid across the covered part.
TEST(SeedCandidates, TheSameLinesRunsAndCountAtEveryThreadCount) {
  const ConePart p;
  const Mesh& m = p.part.mesh;
  const Seed seed = seed_at(m, (kRows / 2 + 10) * kCols + kCols / 2, 0.12 * p.diag);
  const Thresholds th = thresholds_for(1e-4 * p.diag);
  CoveredFaces covered(static_cast<std::size_t>(m.face_count()), 0);
  for (int f = 0; f < m.face_count(); ++f)
    covered[static_cast<std::size_t>(f)] = m.F(f, 0) / kCols < kRows / 3 && m.F(f, 1) / kCols < kRows / 3 &&
                                           m.F(f, 2) / kCols < kRows / 3;
  for (const std::vector<CutterKind>& kinds :
       {std::vector<CutterKind>{CutterKind::cone, CutterKind::barrel},
        std::vector<CutterKind>{CutterKind::cylinder, CutterKind::cone, CutterKind::barrel, CutterKind::spline}}) {
    const CandidateLineOptions o = decompose_like(p.diag, kinds);
    struct Search {
      std::vector<LineCandidate> lines;
      std::vector<FreeRunRecord> runs;
      long long scored = 0;
    };
    auto search = [&](int threads) {
      const ThreadLimit limit(threads);
      Search s;
      s.lines = seed_candidates(p.index, seed, 0, covered, o, th, &s.scored, &s.runs);
      return s;
    };
    const Search one = search(1);
    ASSERT_GE(one.lines.size(), 4u) << to_string(kinds.back());
    for (int round = 0; round < 3; ++round) {
      const Search two = search(2);
      EXPECT_EQ(two.scored, one.scored);
      ASSERT_EQ(two.lines.size(), one.lines.size());
      for (std::size_t k = 0; k < one.lines.size(); ++k) {
        EXPECT_EQ(two.lines[k].order, one.lines[k].order) << k;
        EXPECT_EQ(two.lines[k].line.a, one.lines[k].line.a) << k;
        EXPECT_EQ(two.lines[k].line.b, one.lines[k].line.b) << k;
        EXPECT_EQ(two.lines[k].kind, one.lines[k].kind) << k;
        EXPECT_EQ(two.lines[k].estimate, one.lines[k].estimate) << k;
        EXPECT_EQ(two.lines[k].sweep.rulings.size(), one.lines[k].sweep.rulings.size()) << k;
      }
      ASSERT_EQ(two.runs.size(), one.runs.size());
      for (std::size_t k = 0; k < one.runs.size(); ++k) {
        EXPECT_EQ(two.runs[k].mid, one.runs[k].mid) << k;
        EXPECT_EQ(two.runs[k].u, one.runs[k].u) << k;
        EXPECT_EQ(two.runs[k].run, one.runs[k].run) << k;
      }
    }
  }
}

// A search another thread may stop (decompose stops the seeds searched beside one whose
// lines end its search): unset, the flag changes nothing; set before the search, nothing is
// searched; set part-way (here from the trace of the first refinement), the search stops at
// the next stage and says so. Each stopped search reports `stopped`, which is how decompose
// knows to discard it.
TEST(SeedCandidates, AStopEndsTheSearchAndSaysSo) {
  const ConePart p;
  const Mesh& m = p.part.mesh;
  const Seed seed = seed_at(m, (kRows / 2 + 10) * kCols + kCols / 2, 0.12 * p.diag);
  const Thresholds th = thresholds_for(1e-4 * p.diag);
  CandidateLineOptions o = decompose_like(p.diag, {CutterKind::cone, CutterKind::barrel});
  long long scored_free = 0;
  const std::vector<LineCandidate> free = seed_candidates(p.index, seed, 0, {}, o, th, &scored_free);
  ASSERT_GE(free.size(), 4u);
  for (int threads : {1, 2}) {
    const ThreadLimit limit(threads);
    std::atomic<bool> flag{false};
    SearchStop unset{&flag};
    long long scored = 0;
    const std::vector<LineCandidate> same = seed_candidates(p.index, seed, 0, {}, o, th, &scored, nullptr, &unset);
    EXPECT_FALSE(unset.stopped);
    EXPECT_EQ(scored, scored_free);
    ASSERT_EQ(same.size(), free.size());
    for (std::size_t k = 0; k < free.size(); ++k) EXPECT_EQ(same[k].line.a, free[k].line.a) << k;

    flag = true;
    SearchStop before{&flag};
    scored = 0;
    EXPECT_TRUE(seed_candidates(p.index, seed, 0, {}, o, th, &scored, nullptr, &before).empty());
    EXPECT_TRUE(before.stopped) << threads;
    EXPECT_EQ(scored, 0);

    flag = false;
    CandidateLineOptions traced = o;
    traced.trace = [&](const std::string&) { flag = true; };
    SearchStop part_way{&flag};
    scored = 0;
    EXPECT_TRUE(seed_candidates(p.index, seed, 0, {}, traced, th, &scored, nullptr, &part_way).empty());
    EXPECT_TRUE(part_way.stopped) << threads;
    EXPECT_GT(scored, 0);
    EXPECT_LT(scored, scored_free);
  }
}

TEST(CandidateLineOptions, ValidateNamesTheProblem) {
  CandidateLineOptions o;
  EXPECT_NE(o.validate().find("radius"), std::string::npos);
  o = decompose_like(100.0, {CutterKind::cone});
  EXPECT_TRUE(o.validate().empty());
  o.kinds.clear();
  EXPECT_NE(o.validate().find("kind"), std::string::npos);
  o = decompose_like(100.0, {CutterKind::cone});
  o.overhang = 0.5;
  EXPECT_NE(o.validate().find("overhang"), std::string::npos);
  o = decompose_like(100.0, {CutterKind::cone});
  o.step = 0;
  EXPECT_NE(o.validate().find("step"), std::string::npos);
}

}  // namespace
}  // namespace flank

