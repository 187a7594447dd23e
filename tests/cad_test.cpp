// CAD in and out (issue 11): B-spline faces and solids of revolution written as STEP/IGES and
// read back with OCCT; tessellations sewn and within their chord deviation; patches.step and
// tools.step of a real run against patches.json; bad CAD files refused in one line.
#include "io/cad.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "io/read_mesh.h"
#include "kernels/bspline.h"
#include "kernels/cutter.h"
#include "kernels/envelope.h"
#include "kernels/parallel.h"
#include "report/write_step.h"
#include "solver/motion.h"
#include "tests/cli_run.h"
#include "tests/test_files.h"

namespace flank {
namespace {

namespace fs = std::filesystem;
using cli_test::Cli;

// A quarter of a cylinder of radius 10 around z, z ∈ [0, 20], on a (2r − 1) × (2c − 1) grid.
Points cylinder_grid(int rows, int cols, double z0 = 0.0) {
  const int fr = 2 * rows - 1, fc = 2 * cols - 1;
  Points P(static_cast<Eigen::Index>(fr) * fc, 3);
  for (int i = 0; i < fr; ++i)
    for (int j = 0; j < fc; ++j) {
      const double a = 0.5 * M_PI * i / (fr - 1), z = z0 + 20.0 * j / (fc - 1);
      P.row(static_cast<Eigen::Index>(i) * fc + j) << 10 * std::cos(a), 10 * std::sin(a), z;
    }
  return P;
}

using testing::slurp;

class CadIo : public Cli {};

// Whether a library whose name holds `name` is mapped into this process.
bool mapped(const std::string& name) {
  std::ifstream maps("/proc/self/maps");
  for (std::string line; std::getline(maps, line);)
    if (line.find(name) != std::string::npos) return true;
  return false;
}
// Whether Open CASCADE's kernel library is mapped into this process.
bool occt_mapped() { return mapped("libTKernel"); }
// Read before main, before any test could open the CAD module.
const bool kOcctBeforeMain = occt_mapped();

// The programs (this one links flank_io as flank does) start without Open CASCADE: it comes
// with the CAD module, opened on a thread of its own by preload or on first use.
TEST(CadModule, OpenCascadeComesWithTheModuleNotWithTheProgram) {
  EXPECT_FALSE(kOcctBeforeMain);
  io::preload_cad_module();
  io::preload_cad_module();  // a second call neither waits nor opens it again
  const io::SplineSurface s = io::SplineSurface::fit("cylinder", cylinder_grid(6, 6), 11, 11, 0.0);
  EXPECT_TRUE(occt_mapped());
  EXPECT_NEAR(s.point(0.0, 0.0).x(), 10.0, 1e-9);
  io::require_cad_module("again");
  // Names travel without OCCT's XCAF documents, whose libraries (the 3D viewer's among them)
  // were a third of the module's opening: none of them comes with it.
  for (const char* library : {"libTKXCAF", "libTKLCAF", "libTKV3d", "libTKService"})
    EXPECT_FALSE(mapped(library)) << library;
  // STEP's module, which every decompose and fit opens, leaves IGES's translator and the
  // libraries it needs (a fifth of the opening) to IGES's module, opened for IGES files.
  for (const char* library : {"libTKIGES.so", "libTKBool.so", "libTKBO.so", "libflank_cad_iges.so"})
    EXPECT_FALSE(mapped(library)) << library;
  io::require_cad_module("part.igs");
  for (const char* library : {"libTKIGES.so", "libTKBool.so", "libTKBO.so", "libflank_cad_iges.so"})
    EXPECT_TRUE(mapped(library)) << library;
}

TEST_F(CadIo, SplineSurfaceFollowsTheExactSurfaceBetweenItsPoints) {
  const report::FittedSurface f = report::fit_exact_grid("cylinder", cylinder_grid(20, 6), 20, 6, 1e-7);
  // Measured at the grid points, edge midpoints and cell centres against the exact cylinder.
  EXPECT_LT(f.deviation, 1e-5);
  for (double u : {0.0, 0.137, 0.5, 1.0}) {
    const Vec3 p = f.surface.point(u, 0.3);
    EXPECT_NEAR(std::hypot(p.x(), p.y()), 10.0, 1e-5);
    EXPECT_NEAR(p.z(), 6.0, 1e-5);
  }
}

// One pole per grid point at uniform parameters is an interpolation whose collocation matrix is
// exactly singular in double at 324 points (a Rotor 67 patch's 324 rows made decompose fail);
// the second fit must stay well conditioned at every count, and still refine the first.
TEST_F(CadIo, SplineSurfaceFitsAnyGridSize) {
  for (const int rows : {19, 120, 324, 397}) {
    SCOPED_TRACE(rows);
    // A target the half-pole fit misses, so that the second fit runs.
    const report::FittedSurface f = report::fit_exact_grid("cylinder", cylinder_grid(rows, 6), rows, 6, 1e-14);
    EXPECT_LT(f.deviation, 1e-5);  // as the 20-row fit above
  }
}

// Ω's exact point of patch `p` at (t, s), on the side −1.
EnvelopePoint exact_point(const Patch& p, double t, double s) {
  const Line l = p.motion.ruling(t);
  return envelope_point(l.point(s), p.motion.velocity(t, s), l.b - l.a, p.cutter.radius(s), p.cutter.slope(s), -1);
}

// p.envelope: a rows × cols grid of exact points; where Ω does not exist, the axis point
// moved by `off_axis`.
void sample_envelope(Patch& p, int rows, int cols, const Vec3& off_axis) {
  p.envelope.rows = rows, p.envelope.cols = cols;
  p.envelope.V.resize(static_cast<Eigen::Index>(rows) * cols, 3);
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < cols; ++j) {
      const double t = i / (rows - 1.0), s = j / (cols - 1.0);
      const EnvelopePoint e = exact_point(p, t, s);
      p.envelope.V.row(static_cast<Eigen::Index>(i) * cols + j) =
          (e.valid ? e.point : p.motion.ruling(t).point(s) + off_axis).transpose();
    }
}

// A cylinder of radius 5 sweeping 40 mm along x (from rest when `stalled`), `shift` mm up z:
// Ω is the plane y = −5.
Patch sweeping_cylinder(bool stalled, double shift = 0.0) {
  Patch p;
  p.id = 0;
  p.motion.knots = clamped_uniform_knots(6);
  p.motion.a.resize(6, 3);
  p.motion.b.resize(6, 3);
  for (int k = 0; k < 6; ++k) {
    const double x = stalled && k == 0 ? 0.0 : 10.0 * (stalled ? k - 1 : k);
    p.motion.a.row(k) << std::max(0.0, x), 0.0, shift;
    p.motion.b.row(k) << std::max(0.0, x), 0.0, shift + 20.0;
  }
  p.cutter = Cutter::constant(CutterKind::cylinder, 20.0, 5.0);
  sample_envelope(p, 60, 12, Vec3(0, -5, 0));
  return p;
}

// The deviation a face reports is measured on the tensor product of its poles, not through
// OCCT: it must be what OCCT's own evaluation of the written face gives at the same points,
// on a trimmed (t, s) domain too, for a coarse fit (large deviation) and a fine one.
TEST_F(CadIo, FaceDeviationIsTheWrittenFaces) {
  for (const auto& [rows, cols, target] : {std::tuple{5, 4, 1.0}, std::tuple{30, 7, 1e-14}}) {
    for (const report::FaceDomain& domain : {report::FaceDomain{}, report::FaceDomain{0.25, 0.75, 0.1, 1.0}}) {
      SCOPED_TRACE(::testing::Message() << rows << " rows, domain t0 " << domain.t0);
      const Points fine = cylinder_grid(rows, cols);
      const report::FittedSurface f = report::fit_exact_grid("cylinder", fine, rows, cols, target, domain);
      const int fr = 2 * rows - 1, fc = 2 * cols - 1;
      double worst = 0.0;
      for (int i = 0; i < fr; ++i)
        for (int j = 0; j < fc; ++j)
          worst = std::max(worst, (f.surface.point(i / (fr - 1.0), j / (fc - 1.0)) -
                                   fine.row(static_cast<Eigen::Index>(i) * fc + j).transpose())
                                      .norm());
      EXPECT_GT(worst, 0.0);
      EXPECT_NEAR(f.deviation, worst, 1e-12 + 1e-9 * worst);
    }
  }
}

// A motion that starts at rest has no Ω at t = 0 (the sphere family does not move: no
// characteristic circle). patches.step's face then stops short of it: its (t, s) domain starts
// after the stall, and within it the face follows the exact Ω (the plane y = −5 of a cylinder
// of radius 5 sweeping along x). A patch whose Ω exists everywhere keeps [0, 1]².
TEST_F(CadIo, PatchFaceStopsWhereOmegaEnds) {
  for (const bool stalled : {false, true}) {
    SCOPED_TRACE(stalled ? "starts at rest" : "moves throughout");
    const Patch p = sweeping_cylinder(stalled);
    const std::vector<report::WrittenFace> faces = report::write_patches_step(dir_ / "p.step", {p}, 0.01);
    ASSERT_EQ(faces.size(), 1u);
    ASSERT_TRUE(std::isfinite(faces[0].deviation));
    EXPECT_LE(faces[0].deviation, 0.01 / 150.0);
    const report::FaceDomain& d = faces[0].domain;
    if (stalled) {
      EXPECT_GT(d.t0, 0.0);
      EXPECT_LT(d.t0, 0.1);
    } else {
      EXPECT_EQ(d.t0, 0.0);
    }
    EXPECT_EQ(d.t1, 1.0);
    EXPECT_EQ(d.s0, 0.0);
    EXPECT_EQ(d.s1, 1.0);
    // The face as read back lies on the plane y = −5.
    const io::CadPart part = io::CadPart::read((dir_ / "p.step").string());
    ASSERT_EQ(part.faces().size(), 1u);
    for (double u : {0.0, 0.3, 1.0})
      for (double v : {0.0, 0.5, 1.0}) {
        EXPECT_NEAR(part.face_point(1, u, v).y(), -5.0, 1e-6);
      }
  }
}

// A spline cutter (a bulging profile) sweeping a wavy path: a motion of 9 pieces, Ω curved
// along both directions, its curvature jumping where the motion or the profile changes piece.
Patch wavy_spline_patch() {
  Patch p;
  constexpr int K = 12;
  Points a(K, 3), b(K, 3);
  for (int k = 0; k < K; ++k) {
    const double x = 60.0 * k / (K - 1);
    a.row(k) << x, 2.0 * std::sin(0.1 * x), 0.0;
    b.row(k) << x + 2.0 * std::cos(0.1 * x), 2.0 * std::sin(0.1 * x) + 1.0, 20.0;
  }
  p.motion = Motion::from_control_points(a, b);
  std::vector<double> s(21), r(21);
  for (int i = 0; i <= 20; ++i) s[i] = i / 20.0, r[i] = 5.0 + 1.5 * std::sin(M_PI * s[i]) + 0.5 * s[i];
  p.cutter = Cutter::fit(CutterKind::spline, 20.0, s, r);
  sample_envelope(p, 120, 30, Vec3::Zero());
  return p;
}

// The face's knots follow Ω: double knots where the motion and the profile change piece, more
// where the error is. With them the face meets its target on a third of the grid's points as
// poles and follows Ω between the samples too, off every grid point; without the pieces'
// knots even four fifths as many poles as points miss it (the curvature jumps).
TEST_F(CadIo, PatchFaceKnotsFollowOmega) {
  const Patch p = wavy_spline_patch();
  int rows = p.envelope.rows, cols = p.envelope.cols;
  Points fine;
  report::FaceDomain domain;
  ASSERT_TRUE(report::exact_omega_grid(p, rows, cols, fine, &domain));
  ASSERT_EQ(domain.t0, 0.0);
  ASSERT_EQ(domain.t1, 1.0);
  const report::FaceBreaks breaks = report::face_breaks(p);
  EXPECT_EQ(breaks.t.size(), 8u);
  EXPECT_EQ(breaks.s.size(), static_cast<std::size_t>(kSplineProfileCoefficients - 4));
  const double tolerance = 0.01, target = tolerance / 150.0;
  const report::FittedSurface f = report::fit_exact_grid("wavy", fine, rows, cols, target, domain, breaks);
  const report::FittedSurface plain = report::fit_exact_grid("wavy", fine, rows, cols, target, domain);
  EXPECT_LE(f.deviation, target);
  EXPECT_GT(plain.deviation, target);
  EXPECT_LT(f.surface.poles_u() * f.surface.poles_v(), rows * cols / 3);
  double worst = 0.0;
  for (int i = 0; i < 997; ++i) {
    const double t = std::fmod(0.618034 * i + 0.01, 1.0), sj = std::fmod(0.414214 * i + 0.02, 1.0);
    const EnvelopePoint e = exact_point(p, t, sj);
    ASSERT_TRUE(e.valid);
    worst = std::max(worst, (f.surface.point(t, sj) - e.point).norm());
  }
  EXPECT_LE(worst, 0.01 * tolerance);
}

// The search for a face goes to denser grids only while the best face's miss halves each
// time the points double both ways, and to denser rows for knots that follow Ω only while the
// target is within their reach; where Ω cannot be followed, it stops with the best face.
TEST_F(CadIo, PatchFaceSearchStopsWhereDenserGridsDoNotHelp) {
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_TRUE(report::denser_grids_may_help(inf, 3.0));     // the first face
  EXPECT_TRUE(report::denser_grids_may_help(18e-3, 2e-3));  // converging (a blade face's end)
  EXPECT_TRUE(report::denser_grids_may_help(1.0, 0.5));
  EXPECT_FALSE(report::denser_grids_may_help(1.0, 0.5000001));
  EXPECT_FALSE(report::denser_grids_may_help(11.4, 11.39));  // the 2k blade rung's faces
  EXPECT_FALSE(report::denser_grids_may_help(2.85, 2.05));
  EXPECT_FALSE(report::denser_grids_may_help(inf, std::nullopt));  // no grid of Ω at 2 × 2 either
  // The first pass (knots that follow Ω, on up to 8 × the rows where they could not be laid)
  // goes on while the knots' miss is within 16× their target per doubling left.
  const double target = 5.19267e-4;  // the 2k blade rung's knots' target: half of tolerance/150
  EXPECT_FALSE(report::knots_within_reach(12.2918, target, 1, 8));  // its face that Ω folds on
  EXPECT_FALSE(report::knots_within_reach(11.5655, target, 2, 8));
  EXPECT_TRUE(report::knots_within_reach(2.17e-4, 1.91531e-4, 1, 8));  // Rotor 67 upper, 3e-4: met on 4×
  EXPECT_TRUE(report::knots_within_reach(7.77e-4, 1.91531e-4, 2, 8));
  EXPECT_TRUE(report::knots_within_reach(18.0, 1.0, 1, 8));  // a made-up blade's face: met on 2×
  EXPECT_TRUE(report::knots_within_reach(4096.0, 1.0, 1, 8));
  EXPECT_FALSE(report::knots_within_reach(4097.0, 1.0, 1, 8));
  EXPECT_FALSE(report::knots_within_reach(17.0, 1.0, 4, 8));
  EXPECT_TRUE(report::knots_within_reach(inf, 1.0, 1, 8));  // no knots tried: not judged
  // Ω jumping between its two sides halfway along t (the envelope grid, which picks the side,
  // is mirrored from there on): 10 mm apart, which no spline follows at any density. The
  // face is still written, the best found, with its miss.
  Patch p = sweeping_cylinder(false);
  for (int i = p.envelope.rows / 2; i < p.envelope.rows; ++i)
    for (int j = 0; j < p.envelope.cols; ++j) p.envelope.V(static_cast<Eigen::Index>(i) * p.envelope.cols + j, 1) *= -1.0;
  const std::vector<report::WrittenFace> faces = report::write_patches_step(dir_ / "jump.step", {p}, 0.01);
  ASSERT_EQ(faces.size(), 1u);
  EXPECT_TRUE(std::isfinite(faces[0].deviation));
  EXPECT_GT(faces[0].deviation, 1.0);
  const io::CadPart part = io::CadPart::read((dir_ / "jump.step").string());
  EXPECT_EQ(part.faces().size(), 1u);
}

// patches.step's faces are fitted concurrently: the file, the deviations and the domains are
// those of one thread. A fixture of its own, so that the TSan pass (which leaves out CadIo.*)
// runs it.
class PatchFaces : public Cli {};

TEST_F(PatchFaces, SameFacesWhateverTheThreadCount) {
  std::vector<Patch> patches;
  for (int k = 0; k < 6; ++k) {
    patches.push_back(sweeping_cylinder(k % 2 == 1, 25.0 * k));
    patches.back().id = k;
  }
  std::vector<std::vector<report::WrittenFace>> faces;
  std::vector<std::string> bytes;
  for (const int threads : {1, 2}) {
    ThreadLimit limit(threads);
    const fs::path dir = dir_ / std::to_string(threads);
    fs::create_directories(dir);
    faces.push_back(report::write_patches_step(dir / "patches.step", patches, 0.01));
    bytes.push_back(slurp(dir / "patches.step"));
  }
  ASSERT_EQ(faces[0].size(), patches.size());
  ASSERT_EQ(faces[1].size(), patches.size());
  for (std::size_t k = 0; k < patches.size(); ++k) {
    SCOPED_TRACE(k);
    ASSERT_TRUE(std::isfinite(faces[0][k].deviation));
    EXPECT_EQ(faces[0][k].deviation, faces[1][k].deviation);
    EXPECT_EQ(faces[0][k].domain.t0, faces[1][k].domain.t0);
    EXPECT_EQ(faces[0][k].domain.t1, faces[1][k].domain.t1);
  }
  EXPECT_GT(faces[1][1].domain.t0, 0.0);  // the stalled ones were trimmed
  EXPECT_EQ(bytes[0], bytes[1]);
}

TEST_F(CadIo, FacesReadBackAsWrittenInStepAndIges) {
  const report::FittedSurface f = report::fit_exact_grid("cylinder", cylinder_grid(20, 6), 20, 6, 1e-7);
  for (const char* name : {"face.step", "face.igs"}) {
    SCOPED_TRACE(name);
    const fs::path path = dir_ / name;
    io::write_surfaces(path, {{"P7", f.surface}});
    const io::CadPart part = io::CadPart::read(path.string());
    ASSERT_EQ(part.faces().size(), 1u);
    EXPECT_EQ(part.faces()[0].surface, "bspline");
    EXPECT_NEAR(part.faces()[0].area, 0.5 * M_PI * 10 * 20, 1e-3);
    EXPECT_EQ(part.face_name(1), "P7");
    for (double u : {0.0, 0.25, 0.8, 1.0})
      for (double v : {0.0, 0.5, 1.0}) EXPECT_LT((part.face_point(1, u, v) - f.surface.point(u, v)).norm(), 1e-9);
    // The same input gives the same bytes (no time stamp, no scratch name).
    const std::string first = slurp(path);
    io::write_surfaces(path, {{"P7", f.surface}});
    EXPECT_EQ(slurp(path), first);
  }
}

// Several named faces in one file, as patches.step holds them: read back in the order written,
// each with its own name, whatever its length, spaces and underscores included (IGES keeps the
// whole name in a name property beside the 8-character label).
TEST_F(CadIo, EveryFaceKeepsItsNameInOrder) {
  const report::FittedSurface f = report::fit_exact_grid("cylinder", cylinder_grid(20, 6), 20, 6, 1e-7);
  const report::FittedSurface g = report::fit_exact_grid("cylinder", cylinder_grid(20, 6, 30.0), 20, 6, 1e-7);
  const std::vector<std::string> names = {"P0", "a_face_named_at_length", "P 2"};
  for (const char* file : {"faces.step", "faces.igs"}) {
    SCOPED_TRACE(file);
    const fs::path path = dir_ / file;
    io::write_surfaces(path, {{names[0], f.surface}, {names[1], g.surface}, {names[2], f.surface}});
    const io::CadPart part = io::CadPart::read(path.string());
    ASSERT_EQ(part.faces().size(), 3u);
    for (int i = 1; i <= 3; ++i) EXPECT_EQ(part.face_name(i), names[static_cast<std::size_t>(i - 1)]);
    EXPECT_NEAR(part.face_point(2, 0.0, 0.0).z(), g.surface.point(0.0, 0.0).z(), 1e-9);
  }
  EXPECT_NE(slurp(dir_ / "faces.step").find("PRODUCT('a_face_named_at_length','a_face_named_at_length'"),
            std::string::npos);
}

TEST_F(CadIo, SolidOfRevolutionFollowsItsMeridian) {
  // A barrel-like meridian, as tools.step writes a cutter.
  io::RevolvedSolid s;
  s.name = "P0-tool";
  for (int k = 0; k <= 100; ++k) {
    const double z = 40.0 * k / 100;
    s.meridian.push_back({z, 5.0 + 2.0 * std::sin(M_PI * z / 40.0)});
  }
  s.origin = Vec3(1, 2, 3);
  s.axis = Vec3(1, 1, 2).normalized();
  io::write_solids(dir_ / "tools.step", {s});
  const io::CadPart part = io::CadPart::read((dir_ / "tools.step").string());
  EXPECT_EQ(part.face_name(1), "P0-tool");
  const Vec3 radial = s.axis.unitOrthogonal(), other = s.axis.cross(radial);
  double worst = 0;
  for (const Vec2& m : s.meridian)
    for (double angle : {0.0, 1.0, 2.5, 4.0}) {
      const Vec3 p = s.origin + m.x() * s.axis + m.y() * (std::cos(angle) * radial + std::sin(angle) * other);
      worst = std::max(worst, part.distance(p));
    }
  EXPECT_LT(worst, 1e-6);
  // Closed by flat ends: the tip face's centre lies on the solid.
  EXPECT_LT(part.distance(s.origin + 0.5 * radial), 1e-9);
}

TEST_F(CadIo, TessellationIsSewnAndWithinItsDeviation) {
  // Two faces meeting along z = 20, written separately: sewn into one component.
  const report::FittedSurface lower = report::fit_exact_grid("lower", cylinder_grid(20, 6), 20, 6, 1e-7);
  const report::FittedSurface upper = report::fit_exact_grid("upper", cylinder_grid(20, 6, 20.0), 20, 6, 1e-7);
  io::write_surfaces(dir_ / "two.step", {{"lower", lower.surface}, {"upper", upper.surface}});
  const io::CadPart part = io::CadPart::read((dir_ / "two.step").string());
  ASSERT_EQ(part.faces().size(), 2u);
  for (double deviation : {0.05, 0.005}) {
    const io::CadTessellation t = part.tessellate({}, deviation);
    EXPECT_LE(t.deviation, deviation * 1.2) << deviation;
    EXPECT_EQ(t.mesh.report.components, 1);
    EXPECT_EQ(t.mesh.report.non_manifold_edges, 0);
    EXPECT_TRUE(t.mesh.report.orientable);
    // Every vertex on the faces, which are within their fit's deviation of the cylinder.
    for (int v = 0; v < t.mesh.mesh.vertex_count(); ++v)
      EXPECT_NEAR(std::hypot(t.mesh.mesh.V(v, 0), t.mesh.mesh.V(v, 1)), 10.0,
                  std::max(lower.deviation, upper.deviation) + 1e-9);
  }
  const io::CadTessellation one = part.tessellate({2}, 0.01);
  EXPECT_EQ(one.faces, 1);
  EXPECT_GT(one.mesh.mesh.V.col(2).minCoeff(), 20.0 - 1e-9);
  EXPECT_THROW(part.tessellate({3}, 0.01), io::Error);
}

// A face is meshed in pieces, on as many threads as the command has: the mesh is the same on
// one thread and two, and its pieces are sewn (no crack: every open edge is on the face's own
// border, the quarter cylinder's two straight sides and two arcs).
TEST_F(CadIo, FaceMeshedInPiecesIsOneMeshWhateverTheThreadCount) {
  const report::FittedSurface f = report::fit_exact_grid("cylinder", cylinder_grid(20, 6), 20, 6, 1e-7);
  io::write_surfaces(dir_ / "one.step", {{"P0", f.surface}});
  const io::CadPart part = io::CadPart::read((dir_ / "one.step").string());
  ASSERT_EQ(part.faces().size(), 1u);
  std::vector<io::CadTessellation> t;
  for (const int threads : {1, 2}) {
    ThreadLimit limit(threads);
    t.push_back(part.tessellate({}, 2e-4));
  }
  const Mesh& m = t[0].mesh.mesh;
  EXPECT_GT(m.face_count(), 1000);
  EXPECT_EQ(m.V, t[1].mesh.mesh.V);
  EXPECT_EQ(m.F, t[1].mesh.mesh.F);
  EXPECT_EQ(t[0].deviation, t[1].deviation);
  EXPECT_EQ(t[0].mesh.report.components, 1);
  EXPECT_EQ(t[0].mesh.report.non_manifold_edges, 0);
  std::map<std::pair<int, int>, int> uses;
  for (int k = 0; k < m.face_count(); ++k)
    for (int c = 0; c < 3; ++c) {
      const int a = m.F(k, c), b = m.F(k, (c + 1) % 3);
      ++uses[{std::min(a, b), std::max(a, b)}];
    }
  const auto on_border = [&](int v) {
    const double x = m.V(v, 0), y = m.V(v, 1), z = m.V(v, 2);
    return std::abs(z) < 1e-6 || std::abs(z - 20.0) < 1e-6 || std::abs(x) < 1e-6 || std::abs(y) < 1e-6;
  };
  int open = 0;
  for (const auto& [edge, count] : uses) {
    if (count != 1) continue;
    ++open;
    EXPECT_TRUE(on_border(edge.first) && on_border(edge.second)) << m.V.row(edge.first) << " " << m.V.row(edge.second);
  }
  EXPECT_EQ(open, t[0].mesh.report.boundary_edges);
}

TEST_F(CadIo, BadFilesAreRefusedInOneLine) {
  const report::FittedSurface f = report::fit_exact_grid("cylinder", cylinder_grid(20, 6), 20, 6, 1e-7);
  io::write_surfaces(dir_ / "good.step", {{"P0", f.surface}});
  const std::string good = slurp(dir_ / "good.step");
  const std::string header = good.substr(0, good.find("DATA;"));
  struct Bad {
    std::string name, content, expect;
  };
  for (const Bad& b : {Bad{"empty.step", "", "empty file"},
                       Bad{"garbage.step", "\x01\x02 this is not STEP at all\n", "not a STEP file"},
                       Bad{"truncated.step", good.substr(0, good.size() / 2), ""},
                       Bad{"nofaces.step", header + "DATA;\nENDSEC;\nEND-ISO-10303-21;\n", "no faces"},
                       Bad{"garbage.igs", "hello\nworld\n", ""},
                       Bad{"garbage.iges", std::string(4000, 'x'), ""}}) {
    SCOPED_TRACE(b.name);
    const fs::path path = file(b.name, b.content);
    std::string message;
    try {
      io::CadPart::read(path.string());
    } catch (const io::Error& e) {
      message = e.what();
    }
    ASSERT_FALSE(message.empty()) << "accepted";
    EXPECT_EQ(message.rfind(path.string() + ": ", 0), 0u) << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    EXPECT_NE(message.find(b.expect), std::string::npos) << message;
  }
  std::string message;
  try {
    io::CadPart::read(dir_.string() + "/missing.stp");
  } catch (const io::Error& e) {
    message = e.what();
  }
  EXPECT_NE(message.find("cannot open"), std::string::npos) << message;
}

// Files that make Open CASCADE itself crash (a STEP point referring to nothing: SEGV inside
// StepGeom_CartesianPoint) or run away (an IGES edge list whose count is a billion, from 6 KB),
// both found by fuzz_step / fuzz_iges: refused in one line, the process unharmed.
TEST_F(CadIo, FilesThatBreakOpenCascadeAreRefused) {
  const std::string data = FLANK_TEST_DATA_DIR "/cad/";
  auto message_of = [](const std::string& path, double seconds) {
    try {
      io::CadPart::read(path, seconds);
    } catch (const io::Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const std::string crash = message_of(data + "occt_crash.step", 0);
  EXPECT_EQ(crash.rfind(data + "occt_crash.step: Open CASCADE crashed", 0), 0u) << crash;
  const std::string slow = message_of(data + "occt_huge_count.igs", 2.0);
  EXPECT_EQ(slow.rfind(data + "occt_huge_count.igs: Open CASCADE did not finish reading this file in 2 s", 0), 0u)
      << slow;
}

// The command line: bad CAD input is exit 2 with one line and no output; info lists the faces.
TEST_F(CadIo, CommandLineRefusesBadCadAndListsFaces) {
  file("bad.step", "ISO-10303-21;\nHEADER;\nENDSEC;\nDATA;\nENDSEC;\nEND-ISO-10303-21;\n");
  file("junk.igs", "not iges\n");
  for (const char* name : {"bad.step", "junk.igs"}) {
    const fs::path out = dir_ / (std::string("out_") + name);
    for (const std::string cmd : {"decompose", "fit"}) {
      const std::string extra = cmd == "fit" ? " --line 0,0,0,0,0,10" : "";
      const cli_test::CliRun r = cli_test::run(cmd + " " + (dir_ / name).string() + " -q -o " + out.string() + extra);
      EXPECT_EQ(r.code, 2) << r.err;
      expect_clean_failure(r, (dir_ / name).string() + ": ", out);
    }
    const cli_test::CliRun info = cli_test::run("info " + (dir_ / name).string());
    EXPECT_EQ(info.code, 2);
    EXPECT_EQ(std::count(info.err.begin(), info.err.end(), '\n'), 1) << info.err;
  }
  const report::FittedSurface f = report::fit_exact_grid("cylinder", cylinder_grid(20, 6), 20, 6, 1e-7);
  io::write_surfaces(dir_ / "two.step", {{"lower", f.surface}, {"upper", f.surface}});
  const cli_test::CliRun info = cli_test::run("info " + (dir_ / "two.step").string());
  EXPECT_EQ(info.code, 0) << info.err;
  EXPECT_NE(info.out.find("   1  bspline"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("   2  bspline"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("chord deviation"), std::string::npos) << info.out;
  const cli_test::CliRun wrong = cli_test::run("info " + (dir_ / "two.step").string() + " --faces 3");
  EXPECT_EQ(wrong.code, 2);
  EXPECT_NE(wrong.err.find("face 3 does not exist"), std::string::npos) << wrong.err;
  const cli_test::CliRun mesh_faces = cli_test::run("decompose " + (dir_ / "bad.stl").string() + " --faces 1 -o " +
                                                    (dir_ / "o").string());
  EXPECT_EQ(mesh_faces.code, 2);
}

// A tolerance far finer than a face needs is refused from coarse looks, in one line naming
// the file, before any tessellation that could exhaust memory: at 1e-7 mm the cylinder would
// take hundreds of millions of triangles, which the old loop asked OCCT for outright (the
// demo's face at 1e-4 mm was still in its first tessellation after 2 minutes, at 2.7 GB).
TEST_F(CadIo, ToleranceTooFineForTheFacesIsRefusedBeforeTessellating) {
  const report::FittedSurface f = report::fit_exact_grid("cylinder", cylinder_grid(20, 6), 20, 6, 1e-7);
  const fs::path part = dir_ / "part.step";
  io::write_surfaces(part, {{"face", f.surface}});
  const cli_test::CliRun info = cli_test::run("info " + part.string() + " --tolerance 1e-7");
  const fs::path out = dir_ / "out";
  expect_clean_failure(info, part.string() + ": a chord deviation under a tenth of the tolerance (1e-08 mm) would take about ",
                       out);
  EXPECT_NE(info.err.find("pass a larger --tolerance or fewer --faces"), std::string::npos) << info.err;
  const cli_test::CliRun r = cli_test::run("decompose " + part.string() + " --tolerance 1e-7 -q -o " + out.string());
  EXPECT_EQ(r.code, 2);
  expect_clean_failure(r, part.string() + ": a chord deviation under a tenth of the tolerance", out);
  // A sane tolerance on the same file reads.
  EXPECT_EQ(cli_test::run("info " + part.string() + " --tolerance-rel 1e-3").code, 0);
}

// An environment variable set for the commands a test runs, unset when it ends.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const std::string& value) : name_(name) { ::setenv(name, value.c_str(), 1); }
  ~ScopedEnv() { ::unsetenv(name_); }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

 private:
  const char* name_;
};

// An installation without the CAD module (libflank_cad.so lost): what needs no CAD runs; a
// STEP input, and decompose's patches.step, are refused in one line naming the file and the
// module, with nothing written.
TEST_F(CadIo, CommandLineWithoutTheModuleRefusesOnlyCad) {
  const report::FittedSurface f = report::fit_exact_grid("cylinder", cylinder_grid(20, 6), 20, 6, 1e-7);
  io::write_surfaces(dir_ / "part.step", {{"face", f.surface}});
  const fs::path mesh = dir_ / "cone.stl";
  ASSERT_EQ(cli_test::run("synth --guides seed003 --tool cone:4,7 --resolution 121x31 -o " + mesh.string()).code, 0);
  const ScopedEnv env("FLANK_CAD_MODULE", (dir_ / "missing" / "libflank_cad.so").string());
  EXPECT_EQ(cli_test::run("info " + mesh.string()).code, 0);
  EXPECT_EQ(cli_test::run("movability " + mesh.string() + " " + cli_test::kLine).code, 0);
  const fs::path out = dir_ / "out";
  const cli_test::CliRun r = cli_test::run("decompose " + mesh.string() + " --tool cone -q -o " + out.string());
  EXPECT_EQ(r.code, 2);
  expect_clean_failure(r, (out / "patches.step").string() + ": ", out);
  EXPECT_NE(r.err.find("libflank_cad.so"), std::string::npos) << r.err;
  const cli_test::CliRun info = cli_test::run("info " + (dir_ / "part.step").string());
  EXPECT_EQ(info.code, 2);
  expect_clean_failure(info, (dir_ / "part.step").string() + ": ", out);
  EXPECT_NE(info.err.find("libflank_cad.so"), std::string::npos) << info.err;
}

// Without IGES's module (libflank_cad_iges.so lost), IGES files alone are refused: STEP files
// read, and decompose writes its STEP files, through STEP's module.
TEST_F(CadIo, CommandLineWithoutTheIgesModuleRefusesOnlyIges) {
  const report::FittedSurface f = report::fit_exact_grid("cylinder", cylinder_grid(20, 6), 20, 6, 1e-7);
  io::write_surfaces(dir_ / "part.step", {{"face", f.surface}});
  io::write_surfaces(dir_ / "part.igs", {{"face", f.surface}});
  const fs::path mesh = dir_ / "cone.stl";
  ASSERT_EQ(cli_test::run("synth --guides seed003 --tool cone:4,7 --resolution 121x31 -o " + mesh.string()).code, 0);
  const ScopedEnv env("FLANK_CAD_IGES_MODULE", (dir_ / "missing" / "libflank_cad_iges.so").string());
  EXPECT_EQ(cli_test::run("info " + (dir_ / "part.step").string()).code, 0);
  const fs::path out = dir_ / "out";
  const cli_test::CliRun r =
      cli_test::run("decompose " + mesh.string() + " --tool cone -q --max-patches 1 -o " + out.string());
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(out / "patches.step"));
  const cli_test::CliRun info = cli_test::run("info " + (dir_ / "part.igs").string());
  EXPECT_EQ(info.code, 2);
  expect_clean_failure(info, (dir_ / "part.igs").string() + ": IGES files need flank's IGES module", dir_ / "none");
  EXPECT_NE(info.err.find("libflank_cad_iges.so"), std::string::npos) << info.err;
}

// A command that ends early (here a fit refused for its gouge, after some tens of ms) while
// the CAD module it preloaded is still opening waits for it before the process exits: exit's
// destructors must not run under the opening thread. The slow stand-in module aborts the
// process if they do (tests/slow_cad_module.cpp; seen with the real module as a segfault in
// about one run in twenty).
TEST_F(CadIo, ACommandEndingWhileTheModuleOpensWaitsForIt) {
  const fs::path mesh = dir_ / "part.stl";
  ASSERT_EQ(cli_test::run("synth --guides seed003 --tool cylinder:5 --resolution 61x21 -o " + mesh.string()).code, 0);
  const ScopedEnv env("FLANK_CAD_MODULE", FLANK_SLOW_CAD_MODULE);
  const fs::path out = dir_ / "out";
  const cli_test::CliRun r = cli_test::run("fit " + mesh.string() + " " + cli_test::kLine +
                                           " --samples-t 8 --samples-s 4 -q -o " + out.string());
  EXPECT_EQ(r.code, 1) << r.err;
  expect_clean_failure(r, "gouge", out);
}

// A real run: patches.step read back agrees with envelopes.ply and with Ω rebuilt from
// patches.json (its motion and cutter, through the forward model) within 1% of the tolerance, and tools.step's solids with
// the meridian in patches.json within 1e-6 mm.
TEST_F(CadIo, PatchesAndToolsStepAgreeWithPatchesJson) {
  const fs::path part = dir_ / "cone.stl", out = dir_ / "out";
  ASSERT_EQ(cli_test::run("synth --guides seed003 --tool cone:4,7 --resolution 121x31 -o " + part.string()).code, 0);
  const cli_test::CliRun r =
      cli_test::run("decompose " + part.string() + " --tool cone -q --max-patches 1 -o " + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  nlohmann::json data;
  std::ifstream(out / "patches.json") >> data;
  ASSERT_GE(data["patches"].size(), 1u);
  const double tol = data["coverage"]["tolerance"].get<double>();
  const io::CadPart faces = io::CadPart::read((out / "patches.step").string());
  // envelopes.ply's vertices (float32 samples of every patch's Ω) lie on patches.step's faces.
  const io::LoadedMesh envelopes = io::read_mesh((out / "envelopes.ply").string());
  double ply_worst = 0;
  // 200 of them: a distance to a B-spline face costs OCCT tens of milliseconds.
  const int stride = std::max(1, envelopes.mesh.vertex_count() / 200);
  for (int v = 0; v < envelopes.mesh.vertex_count(); v += stride)
    ply_worst = std::max(ply_worst, faces.distance(envelopes.mesh.V.row(v).transpose()));
  EXPECT_LE(ply_worst, 0.01 * tol) << "envelopes.ply to patches.step";
  const io::CadPart tools = io::CadPart::read((out / "tools.step").string());
  for (const nlohmann::json& p : data["patches"]) {
    const std::string name = "P" + std::to_string(p["id"].get<int>());
    int index = 0;
    for (const io::CadFace& f : faces.faces())
      if (faces.face_name(f.index) == name) index = f.index;
    ASSERT_GT(index, 0) << name;
    EXPECT_LE(p["nurbs"]["max_deviation"].get<double>(), 0.01 * tol);
    // The motion and the cutter as patches.json gives them.
    const auto& m = p["motion"];
    const auto& a = m["a"];
    const auto& b = m["b"];
    Points A(static_cast<Eigen::Index>(a.size()), 3), B(static_cast<Eigen::Index>(b.size()), 3);
    for (std::size_t k = 0; k < a.size(); ++k)
      for (int c = 0; c < 3; ++c) {
        A(static_cast<Eigen::Index>(k), c) = a[k][c].get<double>();
        B(static_cast<Eigen::Index>(k), c) = b[k][c].get<double>();
      }
    Motion motion;
    motion.a = A;
    motion.b = B;
    motion.knots = m["knots"].get<std::vector<double>>();
    Cutter cutter;
    cutter.kind = CutterKind::cone;
    ASSERT_EQ(p["tool"]["kind"], "cone");
    cutter.length = p["tool"]["length"].get<double>();
    const auto coefficients = p["tool"]["coefficients"].get<std::vector<double>>();
    cutter.coeffs = Eigen::Map<const VecX>(coefficients.data(), static_cast<Eigen::Index>(coefficients.size()));
    double worst = 0;
    for (int i = 0; i <= 40; ++i)
      for (int j = 0; j <= 10; ++j) {
        const double t = i / 40.0, s = j / 10.0;
        const Line l = motion.ruling(t);
        const Vec3 rt = (1 - s) * motion.a_at(t, 1) + s * motion.b_at(t, 1);
        const Vec3 face = faces.face_point(index, t, s);
        double best = 1e300;
        for (int side : {+1, -1}) {
          const EnvelopePoint e = envelope_point(l.point(s), rt, l.b - l.a, cutter.radius(s), cutter.slope(s), side);
          if (e.valid) best = std::min(best, (e.point - face).norm());
        }
        worst = std::max(worst, best);
      }
    EXPECT_LE(worst, 0.01 * tol) << name << " deviates " << worst << " from the rebuilt Ω (tol " << tol << ")";

    // tools.step: the meridian samples, revolved about the axis at t = 0, lie on the solid.
    const Line axis = motion.ruling(0.0);
    const Vec3 u = (axis.b - axis.a).normalized(), radial = u.unitOrthogonal(), other = u.cross(radial);
    double tool_worst = 0;
    for (const auto& zr : p["tool"]["profile"])
      for (double angle : {0.3, 2.0, 4.4}) {
        const Vec3 q = axis.a + zr[0].get<double>() * u +
                       zr[1].get<double>() * (std::cos(angle) * radial + std::sin(angle) * other);
        tool_worst = std::max(tool_worst, tools.distance(q));
      }
    EXPECT_LE(tool_worst, 1e-6) << name;
  }
}

}  // namespace
}  // namespace flank
