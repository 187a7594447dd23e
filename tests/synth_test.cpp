// The forward model: exact envelopes of the paper-2 test part (Table 1 guides, Fig. 6 cutters).
#include "solver/synth.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>
#include <string>
#include <tuple>

#include <unistd.h>

#include "io/read_lines.h"
#include "io/read_mesh.h"
#include "kernels/bspline.h"
#include "kernels/cutter.h"
#include "kernels/envelope.h"
#include "kernels/mesh.h"

namespace flank {
namespace {

enum class Tool { cylinder, cone, barrel };

const char* tool_name(Tool t) {
  switch (t) {
    case Tool::cylinder: return "cylinder";
    case Tool::cone: return "cone";
    case Tool::barrel: return "barrel";
  }
  return "?";
}

// Fig. 6 of paper 2: cylinder R = 5, cone 4 → 7, barrel R0 = 418.17 (our r_end = 5), h = 50.
ToolProfile paper_tool(Tool t) {
  switch (t) {
    case Tool::cylinder: return cylinder_profile(kPaperToolLength, 5.0);
    case Tool::cone: return cone_profile(kPaperToolLength, 4.0, 7.0);
    case Tool::barrel:
      return barrel_profile(kPaperToolLength, kPaperBarrelR0, kPaperBarrelEndRadius);
  }
  return {};
}

AxisMotion paper_motion() { return guide_motion(paper_guides(), kPaperToolLength); }

double grid_param(int i, int n) { return i == n - 1 ? 1.0 : static_cast<double>(i) / (n - 1); }

Vec3 centre(const AxisMotion& m, double t, double s) {
  return (1 - s) * m.a(t, 0) + s * m.b(t, 0);
}
Vec3 centre_t(const AxisMotion& m, double t, double s) {
  return (1 - s) * m.a(t, 1) + s * m.b(t, 1);
}

// Distance from p to triangle abc: the minimum over the interior (when p projects inside)
// and the three edges.
double point_triangle_distance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  auto segment = [&p](const Vec3& x, const Vec3& y) {
    const double u = std::clamp((p - x).dot(y - x) / (y - x).squaredNorm(), 0.0, 1.0);
    return (p - (x + u * (y - x))).norm();
  };
  double best = std::min({segment(a, b), segment(b, c), segment(c, a)});
  const Vec3 n = (b - a).cross(c - a).normalized();
  const Vec3 q = p - n * n.dot(p - a);
  const bool inside = (b - a).cross(q - a).dot(n) >= 0 && (c - b).cross(q - b).dot(n) >= 0 &&
                      (a - c).cross(q - c).dot(n) >= 0;
  if (inside) best = std::min(best, std::abs(n.dot(p - a)));
  return best;
}

void expect_near_vec(const Vec3& got, const Vec3& want, double tol, const std::string& what) {
  EXPECT_LE((got - want).norm(), tol * (1.0 + want.norm()))
      << what << ": got " << got.transpose() << " want " << want.transpose();
}

TEST(Synth, PaperGuidesAreTable1) {
  const GuideCurves g = paper_guides();
  EXPECT_EQ(g.top[0], Vec3(75, 15, -5));
  EXPECT_EQ(g.top[1], Vec3(30, 30, -5));
  EXPECT_EQ(g.top[2], Vec3(0, 60, -5));
  EXPECT_EQ(g.bottom[0], Vec3(60, 0, -45));
  EXPECT_EQ(g.bottom[1], Vec3(30, 30, -45));
  EXPECT_EQ(g.bottom[2], Vec3(15, 75, -45));
  // Bézier end interpolation.
  EXPECT_EQ(bezier2(g.top, 0.0), g.top[0]);
  EXPECT_EQ(bezier2(g.top, 1.0), g.top[2]);
}

TEST(Synth, GuideMotionDerivativesMatchFiniteDifferences) {
  const GuideCurves g = paper_guides();
  const AxisMotion m = guide_motion(g, kPaperToolLength);
  const double h = 1e-5;
  for (double t : {0.0, 0.1, 0.37, 0.5, 0.81, 1.0}) {
    // The axis starts at the bottom curve, points at the top curve and has length L.
    EXPECT_EQ(m.a(t, 0), bezier2(g.bottom, t));
    const Vec3 axis = m.b(t, 0) - m.a(t, 0);
    EXPECT_NEAR(axis.norm(), kPaperToolLength, 1e-12);
    const Vec3 toward = bezier2(g.top, t) - bezier2(g.bottom, t);
    EXPECT_NEAR(axis.normalized().dot(toward.normalized()), 1.0, 1e-14);
    // Central differences (the curves extend analytically beyond [0, 1]).
    for (const auto* curve : {&m.a, &m.b}) {
      const auto& f = *curve;
      const Vec3 d1 = (f(t + h, 0) - f(t - h, 0)) / (2 * h);
      const Vec3 d2 = (f(t + h, 1) - f(t - h, 1)) / (2 * h);
      const Vec3 d2p = (f(t + 10 * h, 0) - 2 * f(t, 0) + f(t - 10 * h, 0)) / (100 * h * h);
      expect_near_vec(f(t, 1), d1, 1e-8, "first derivative");
      expect_near_vec(f(t, 2), d2, 1e-8, "second derivative from first");
      expect_near_vec(f(t, 2), d2p, 1e-5, "second derivative from positions");
    }
    // Rigid motion: (b − a)·(b′ − a′) = 0.
    EXPECT_NEAR(axis.dot(m.b(t, 1) - m.a(t, 1)), 0.0, 1e-9);
  }
}

// Every grid point of every paper cutter on both sides is an exact envelope point.
class SynthEnvelope : public ::testing::TestWithParam<std::tuple<Tool, int>> {};

TEST_P(SynthEnvelope, PointsAreExactEnvelopePoints) {
  const auto [tool_kind, side] = GetParam();
  const AxisMotion m = paper_motion();
  const ToolProfile tool = paper_tool(tool_kind);
  ASSERT_EQ(tool.validate(), "");
  SynthOptions opt;
  opt.rows = 61;
  opt.cols = 21;
  opt.side = side;
  const SynthResult r = synth_envelope(m, tool, opt);
  ASSERT_EQ(r.invalid, 0);
  ASSERT_EQ(r.mesh.vertex_count(), opt.rows * opt.cols);
  ASSERT_EQ(r.mesh.face_count(), 2 * (opt.rows - 1) * (opt.cols - 1));

  for (int i = 0; i < opt.rows; ++i)
    for (int j = 0; j < opt.cols; ++j) {
      const double t = grid_param(i, opt.rows), s = grid_param(j, opt.cols);
      const Vec3 X = r.mesh.V.row(i * opt.cols + j).transpose();
      const Vec3 R = centre(m, t, s), Rt = centre_t(m, t, s);
      const Vec3 Rs = m.b(t, 0) - m.a(t, 0);
      const double d = tool.radius(s), dd = tool.slope(s);
      const Vec3 n = X - R;
      ASSERT_NEAR(n.norm(), d, 1e-9) << "t " << t << " s " << s;
      ASSERT_NEAR(n.dot(Rt), 0.0, 1e-9 * d * Rt.norm()) << "t " << t << " s " << s;
      ASSERT_NEAR(n.dot(Rs), -d * dd, 1e-9 * d * Rs.norm()) << "t " << t << " s " << s;
    }

  // The envelope property: no envelope point lies inside another sphere of the family.
  // A subset of points against all spheres on a fine (t′, s′) grid.
  // Plain arrays: this loop is 12 million sphere tests, and must stay quick in Debug builds.
  const int ft = 801, fs = 201;
  std::vector<double> cx(static_cast<std::size_t>(ft) * fs), cy(cx.size()), cz(cx.size()),
      rad(cx.size());
  for (int p = 0; p < ft; ++p) {
    const double t = grid_param(p, ft);
    for (int q = 0; q < fs; ++q) {
      const double s = grid_param(q, fs);
      const Vec3 c = centre(m, t, s);
      const std::size_t k = static_cast<std::size_t>(p) * fs + q;
      cx[k] = c.x(), cy[k] = c.y(), cz[k] = c.z(), rad[k] = tool.radius(s);
    }
  }
  double worst = std::numeric_limits<double>::infinity();
  for (int i = 0; i < opt.rows; i += 4)
    for (int j = 0; j < opt.cols; j += 2) {
      const double x = r.mesh.V(i * opt.cols + j, 0), y = r.mesh.V(i * opt.cols + j, 1),
                   z = r.mesh.V(i * opt.cols + j, 2);
      for (std::size_t k = 0; k < cx.size(); ++k) {
        const double dx = x - cx[k], dy = y - cy[k], dz = z - cz[k];
        worst = std::min(worst, std::sqrt(dx * dx + dy * dy + dz * dz) - rad[k]);
      }
    }
  EXPECT_GE(worst, -1e-9) << tool_name(tool_kind) << " side " << side;

  // Face normals point toward the tool: toward the sphere centres of their vertices.
  const Points N = face_normals(r.mesh);
  int wrong = 0;
  for (int f = 0; f < r.mesh.face_count(); ++f) {
    Vec3 toward = Vec3::Zero();
    for (int k = 0; k < 3; ++k) {
      const int v = r.mesh.F(f, k);
      const double t = grid_param(v / opt.cols, opt.rows), s = grid_param(v % opt.cols, opt.cols);
      toward += centre(m, t, s) - r.mesh.V.row(v).transpose();
    }
    if (N.row(f).dot(toward) <= 0.0) ++wrong;
  }
  EXPECT_EQ(wrong, 0) << tool_name(tool_kind) << " side " << side;
}

std::string envelope_case_name(const ::testing::TestParamInfo<std::tuple<Tool, int>>& param) {
  return std::string(tool_name(std::get<0>(param.param))) +
         (std::get<1>(param.param) > 0 ? "_plus" : "_minus");
}

INSTANTIATE_TEST_SUITE_P(
    Synth, SynthEnvelope,
    ::testing::Combine(::testing::Values(Tool::cylinder, Tool::cone, Tool::barrel),
                       ::testing::Values(+1, -1)),
    envelope_case_name);

// chord_error bounds the distance from the exact envelope to the mesh: exact points at random
// parameters lie within it of their cell's triangles (up to the sampling of the cell).
TEST(Synth, ChordErrorBoundsTheMeshDeviation) {
  const AxisMotion m = paper_motion();
  const ToolProfile tool = paper_tool(Tool::cone);
  SynthOptions opt;
  opt.rows = 31;
  opt.cols = 11;
  const SynthResult r = synth_envelope(m, tool, opt);
  ASSERT_EQ(r.invalid, 0);
  ASSERT_GT(r.chord_error, 0.0);
  // The default resolution is ~8x finer in t: second order convergence.
  const SynthResult fine = synth_envelope(m, tool, {});
  EXPECT_LT(fine.chord_error, r.chord_error / 20.0);

  // Exact points at random parameters against the two triangles of their cell.
  const Mesh& mesh = r.mesh;
  double worst = 0.0;
  unsigned state = 12345u;
  auto uniform = [&state]() {
    state = state * 1664525u + 1013904223u;
    return (state >> 8) / 16777216.0;
  };
  for (int k = 0; k < 2000; ++k) {
    const double t = uniform(), s = uniform();
    const EnvelopePoint e = envelope_point(centre(m, t, s), centre_t(m, t, s),
                                           m.b(t, 0) - m.a(t, 0), tool.radius(s),
                                           tool.slope(s), opt.side);
    ASSERT_TRUE(e.valid);
    const int i = std::min(static_cast<int>(t * (opt.rows - 1)), opt.rows - 2);
    const int j = std::min(static_cast<int>(s * (opt.cols - 1)), opt.cols - 2);
    const int f = 2 * (i * (opt.cols - 1) + j);
    double best = std::numeric_limits<double>::infinity();
    for (int g = f; g < f + 2; ++g)
      best = std::min(best, point_triangle_distance(e.point, mesh.V.row(mesh.F(g, 0)),
                                                    mesh.V.row(mesh.F(g, 1)),
                                                    mesh.V.row(mesh.F(g, 2))));
    worst = std::max(worst, best);
  }
  EXPECT_LE(worst, 1.25 * r.chord_error) << "chord_error " << r.chord_error;
  EXPECT_GE(worst, 0.2 * r.chord_error) << "chord_error " << r.chord_error;
}

// The accuracy of the default resolution, and the resolution the exact-recovery tests need
// (chord_error < 5e-6 of the bbox diagonal). On this part the error is dominated by the
// envelope's twist (the n·X_ts term of a bilinear cell), so it falls like 1/(rows·cols):
// 241x61 gives 4.6e-6 .. 9.4e-6 of the diagonal; 241x121 gives at most 3.8e-6 for all
// three cutters on both sides.
TEST(Synth, ChordErrorAtDefaultAndRecoveryResolution) {
  const AxisMotion m = paper_motion();
  for (const Tool kind : {Tool::cylinder, Tool::cone, Tool::barrel}) {
    const ToolProfile tool = paper_tool(kind);
    for (int side : {+1, -1})
      for (const auto& [rows, cols, limit] :
           {std::tuple{241, 61, 1e-5}, std::tuple{241, 121, 5e-6}}) {
        SynthOptions opt;
        opt.rows = rows;
        opt.cols = cols;
        opt.side = side;
        const SynthResult r = synth_envelope(m, tool, opt);
        ASSERT_EQ(r.invalid, 0);
        const double diag = bbox_diagonal(r.mesh);
        std::printf("[ synth    ] %-8s side %+d %4dx%-4d %6d vertices: chord %.3e mm = %.3e of "
                    "diagonal %.3f\n",
                    tool_name(kind), side, rows, cols, r.mesh.vertex_count(), r.chord_error,
                    r.chord_error / diag, diag);
        EXPECT_LT(r.chord_error / diag, limit) << tool_name(kind) << " " << rows << "x" << cols;
      }
  }
}

TEST(Synth, BarrelProfileMatchesTheArc) {
  const double L = kPaperToolLength, R0 = kPaperBarrelR0, r_end = kPaperBarrelEndRadius;
  const ToolProfile p = barrel_profile(L, R0, r_end);
  ASSERT_EQ(p.validate(), "");
  const double sag = R0 - std::sqrt(R0 * R0 - 0.25 * L * L);
  const double rc = r_end + sag - R0;
  EXPECT_NEAR(sag, 0.747973, 1e-6);
  auto meridian = [&](double s) {
    const double d = p.radius(s), dd = p.slope(s), q = dd / L;
    return Vec2(s * L - d * q, d * std::sqrt(1.0 - q * q));
  };
  // Every meridian point lies on the arc of radius R0 about (L/2, rc).
  for (int i = 0; i <= 20; ++i) {
    const Vec2 zr = meridian(i / 20.0);
    EXPECT_NEAR(std::hypot(zr(0) - 0.5 * L, zr(1) - rc), R0, 1e-9) << "s " << i / 20.0;
  }
  // Middle: radius 5 + sag, exactly (d′ = 0 there).
  EXPECT_NEAR(p.slope(0.5), 0.0, 1e-15);
  EXPECT_NEAR(meridian(0.5)(1), r_end + sag, 1e-12);
  EXPECT_NEAR(meridian(0.5)(0), 0.5 * L, 1e-12);
  // Ends: radius 5 up to the end spheres' overhang. The end sphere touches the arc where the
  // line from the arc centre through the axis end meets it, 0.30 mm beyond the end, where
  // the arc has come down by 0.018 mm: r = 4.9818 at z = −0.3020 (and L + 0.3020).
  for (double s : {0.0, 1.0}) {
    const Vec2 zr = meridian(s);
    EXPECT_NEAR(zr(1), r_end, 0.02) << "s " << s;
    EXPECT_NEAR(zr(1), 4.981804, 1e-6) << "s " << s;
    EXPECT_NEAR(std::abs(zr(0) - 0.5 * L), 0.5 * L + 0.301985, 1e-6) << "s " << s;
  }
  // Symmetric and largest in the middle.
  EXPECT_NEAR(p.radius(0.2), p.radius(0.8), 1e-12);
  EXPECT_NEAR(p.slope(0.2), -p.slope(0.8), 1e-12);
  EXPECT_GT(p.radius(0.5), p.radius(0.3));
  // Slope matches finite differences.
  for (double s : {0.1, 0.4, 0.9})
    EXPECT_NEAR(p.slope(s), (p.radius(s + 1e-6) - p.radius(s - 1e-6)) / 2e-6, 1e-6);
  // An arc shorter than the tool is rejected.
  EXPECT_NE(barrel_profile(L, 20.0, 5.0).validate(), "");
}

TEST(Synth, ConeAndCylinderProfiles) {
  const ToolProfile cone = cone_profile(50.0, 4.0, 7.0);
  ASSERT_EQ(cone.validate(), "");
  const Cutter c = cone_from_end_radii(50.0, 4.0, 7.0);
  EXPECT_NEAR(c.cone_end_radii()(0), 4.0, 1e-12);
  EXPECT_NEAR(c.cone_end_radii()(1), 7.0, 1e-12);
  for (double s : {0.0, 0.3, 1.0}) {
    EXPECT_DOUBLE_EQ(cone.radius(s), c.radius(s));
    EXPECT_DOUBLE_EQ(cone.slope(s), c.slope(s));
  }
  const ToolProfile cyl = cylinder_profile(50.0, 5.0);
  EXPECT_EQ(cyl.radius(0.7), 5.0);
  EXPECT_EQ(cyl.slope(0.7), 0.0);
  // |d′| ≥ L: the cutter surface is undefined.
  Cutter steep;
  steep.kind = CutterKind::cone;
  steep.length = 10.0;
  steep.coeffs.resize(2);
  steep.coeffs << 1.0, 12.0;
  const std::string problem = profile_from_cutter(steep).validate();
  EXPECT_NE(problem.find("reaches the axis length"), std::string::npos) << problem;
  EXPECT_NE(cylinder_profile(50.0, -1.0).validate(), "");
  EXPECT_NE(cylinder_profile(0.0, 5.0).validate(), "");
}

TEST(Synth, OptionsValidate) {
  EXPECT_EQ(SynthOptions{}.validate(), "");
  EXPECT_NE((SynthOptions{1, 5, 1}).validate(), "");
  EXPECT_NE((SynthOptions{5, 5, 0}).validate(), "");
}

TEST(Synth, InvalidEnvelopeIsCounted) {
  // A stationary axis does not sweep: no envelope point anywhere.
  AxisMotion still;
  still.a = [](double, int order) { return order == 0 ? Vec3(0, 0, 0) : Vec3::Zero().eval(); };
  still.b = [](double, int order) { return order == 0 ? Vec3(0, 0, 50) : Vec3::Zero().eval(); };
  SynthOptions opt;
  opt.rows = 5;
  opt.cols = 3;
  const SynthResult r = synth_envelope(still, cylinder_profile(50.0, 5.0), opt);
  EXPECT_EQ(r.invalid, 15);
  EXPECT_EQ(r.mesh.vertex_count(), 0);
}

class SynthMotionFile : public ::testing::Test {
 protected:
  // One folder per process and test: ctest runs this suite's tests side by side, and one's
  // TearDown removed a shared folder under the other (a TSan pass failed so, 2026-11-27).
  std::filesystem::path dir_;
  void SetUp() override {
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("flank_synth_test_motion_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << text;
    return path;
  }
  static Motion read_motion(const std::string& path) {
    io::ControlPoints rows = io::read_motion_file(path);
    return Motion::from_control_points(std::move(rows.a), std::move(rows.b));
  }
  // The io::Error message of read_motion_file, or "" if it did not throw.
  static std::string error_of(const std::string& path) {
    try {
      io::read_motion_file(path);
    } catch (const io::Error& e) {
      return e.what();
    }
    return "";
  }
};

TEST_F(SynthMotionFile, Errors) {
  const std::string good_rows =
      "0 0 0 0 0 50\n1 0 0 1 0 50\n2 0 0 2 0 50\n3 0 0 3 0 50\n";
  struct Bad {
    std::string name, text, expect;
  };
  for (const Bad& b : {Bad{"three.txt", "0 0 0 0 0 50\n1 0 0 1 0 50\n2 0 0 2 0 50\n", "at least 4"},
                       Bad{"empty.txt", "# only a comment\n\n", "at least 4"},
                       Bad{"five.txt", good_rows + "4 0 0 4 0\n", "line 5: expected 6 numbers"},
                       Bad{"seven.txt", "0 0 0 0 0 50 1\n" + good_rows, "line 1: expected 6"},
                       Bad{"word.txt", good_rows + "4 0 0 4 0 fifty\n", "'fifty' is not a finite"},
                       Bad{"nan.txt", "nan 0 0 0 0 50\n" + good_rows, "'nan' is not a finite"},
                       Bad{"inf.txt", good_rows + "4 0 0 4 0 inf\n", "'inf' is not a finite"},
                       Bad{"huge.txt", good_rows + "4 0 0 4 0 1e999\n", "is not a finite"},
                       Bad{"glued.txt", good_rows + "4 0 0 4 0 5x\n", "'5x' is not a finite"},
                       Bad{"zero.txt", good_rows + "4 0 0 4 0 0\n", "line 5: a and b coincide"}}) {
    const std::string path = write(b.name, b.text);
    const std::string msg = error_of(path);
    EXPECT_EQ(msg.rfind(path + ": ", 0), 0u) << b.name << ": " << msg;
    EXPECT_NE(msg.find(b.expect), std::string::npos) << b.name << ": " << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << b.name;
  }
  const std::string missing = (dir_ / "missing.txt").string();
  EXPECT_NE(error_of(missing).find(missing + ": cannot open"), std::string::npos);
  EXPECT_NE(error_of(dir_.string()).find("is a directory"), std::string::npos);

  const std::string ok = write("ok.txt", "# a b\n\n" + good_rows + "  4 0 0 4 0 50 # last\n");
  EXPECT_EQ(error_of(ok), "");
  const Motion m = read_motion(ok);
  EXPECT_EQ(m.count(), 5);
  EXPECT_EQ(m.knots, clamped_uniform_knots(5));
}

// A motion fitted to the paper's guide motion, written to a file, read back and swept, gives
// the same envelope as the analytic guide motion (up to the fit).
TEST_F(SynthMotionFile, SplineMotionRoundTrip) {
  const AxisMotion guide = paper_motion();
  std::vector<Line> rulings;
  for (int i = 0; i <= 200; ++i) {
    const double t = i / 200.0;
    rulings.push_back({guide.a(t, 0), guide.b(t, 0)});
  }
  std::vector<double> params(rulings.size());
  for (std::size_t i = 0; i < params.size(); ++i) params[i] = i / 200.0;
  const Motion fitted = Motion::fit(rulings, 24, params);

  std::ostringstream text;
  text << std::setprecision(17) << "# fitted to Table 1\n";
  for (int k = 0; k < fitted.count(); ++k)
    text << fitted.a.row(k) << ' ' << fitted.b.row(k) << '\n';
  const Motion read = read_motion(write("fitted.txt", text.str()));
  ASSERT_EQ(read.count(), fitted.count());
  EXPECT_EQ(read.knots, fitted.knots);
  EXPECT_EQ((read.a - fitted.a).norm(), 0.0);
  EXPECT_EQ((read.b - fitted.b).norm(), 0.0);

  const AxisMotion spline = spline_motion(read);
  for (double t : {0.0, 0.25, 0.6, 1.0})
    for (int order = 0; order <= 2; ++order) {
      EXPECT_EQ(spline.a(t, order), fitted.a_at(t, order));
      EXPECT_EQ(spline.b(t, order), fitted.b_at(t, order));
    }
  const double h = 1e-6;
  for (double t : {0.2, 0.55})
    expect_near_vec(spline.b(t, 1), (spline.b(t + h, 0) - spline.b(t - h, 0)) / (2 * h), 1e-7,
                    "spline b′");

  SynthOptions opt;
  opt.rows = 41;
  opt.cols = 11;
  const ToolProfile tool = paper_tool(Tool::cone);
  const SynthResult exact = synth_envelope(guide, tool, opt);
  const SynthResult approx = synth_envelope(spline, tool, opt);
  ASSERT_EQ(approx.invalid, 0);
  double fit_error = 0.0;
  for (int i = 0; i <= 200; ++i)
    fit_error = std::max({fit_error, (read.a_at(i / 200.0) - rulings[i].a).norm(),
                          (read.b_at(i / 200.0) - rulings[i].b).norm()});
  EXPECT_LT(fit_error, 0.01);
  const double diff = (exact.mesh.V - approx.mesh.V).rowwise().norm().maxCoeff();
  EXPECT_LT(diff, 0.1) << "fit error " << fit_error;
}

}  // namespace
}  // namespace flank
