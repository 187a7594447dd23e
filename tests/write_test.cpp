// io writers: meshes round-trip through read_mesh, patches.json keeps its keys in order and is
// byte-deterministic, PLY colours follow the maps, APT has one GOTO per step at the cutter's
// end-face centre and a CUTTER/ of the real tool, and writes are atomic.
#include "report/write.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "io/read_mesh.h"
#include "io/write_mesh.h"
#include "kernels/cutter.h"
#include "solver/motion.h"
#include "tests/saddle_mesh.h"
#include "tests/test_files.h"

namespace flank::report {
namespace {

using io::Error;
using io::LoadedMesh;
using io::read_mesh;
using io::write_file_atomic;
using io::write_mesh;

namespace fs = std::filesystem;

const std::string kData = FLANK_TEST_DATA_DIR;

using testing::count_of;
using testing::slurp;


// Each of `keys` occurs after the previous one, starting at `from`; returns the last position.
std::size_t expect_in_order(const std::string& text, std::initializer_list<std::string> keys,
                            std::size_t from = 0) {
  for (const std::string& key : keys) {
    const std::size_t pos = text.find("\"" + key + "\":", from);
    EXPECT_NE(pos, std::string::npos) << "missing or out of order: " << key;
    if (pos == std::string::npos) return from;
    from = pos + 1;
  }
  return from;
}

Mesh saddle() { return testing::saddle_mesh(5, 4); }

Patch make_patch(int id, char tip, double x0) {
  Patch p;
  p.id = id;
  p.tip = tip;
  std::vector<Line> lines;
  for (int i = 0; i <= 10; ++i) lines.push_back({Vec3(x0 + i, 0, 0), Vec3(x0 + i, 0, 50)});
  p.motion = Motion::fit(lines, 4);
  p.cutter = cone_from_end_radii(50.0, 4.0, 7.0);
  p.error = {0.01, 0.005, 0.002, 1e-4};
  p.covered_area = 12.5;
  p.coverage_fraction = 0.25;
  p.envelope.V.resize(4, 3);
  p.envelope.V << x0, 0, 0, x0 + 1, 0, 0, x0 + 1, 1, 0, x0, 1, 0;
  p.envelope.F.resize(2, 3);
  p.envelope.F << 0, 1, 2, 0, 2, 3;
  p.envelope.error.resize(4);
  p.envelope.error << -0.2, -0.05, 0.0, 0.1;
  p.envelope.rows = p.envelope.cols = 2;
  return p;
}

// One patch's block of toolpath.apt: the `$$` comments before its CUTTER/, the seven CUTTER/
// parameters and the GOTO rows (x, y, z, i, j, k).
struct AptBlock {
  std::vector<std::string> comments;
  std::vector<double> cutter;
  std::vector<std::array<double, 6>> gotos;
};

std::vector<double> comma_numbers(const std::string& list) {
  std::vector<double> out;
  const char* at = list.c_str();
  while (*at) {
    char* stop = nullptr;
    out.push_back(std::strtod(at, &stop));
    at = *stop == ',' ? stop + 1 : stop;
    if (stop == at && *at) break;  // not a number: stop rather than loop
  }
  return out;
}

std::vector<AptBlock> apt_blocks(const std::string& text) {
  std::vector<AptBlock> blocks;
  std::vector<std::string> comments;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("$$", 0) == 0) {
      comments.push_back(line);
    } else if (line.rfind("CUTTER/", 0) == 0) {
      blocks.push_back({comments, comma_numbers(line.substr(7)), {}});
      comments.clear();
    } else if (line.rfind("GOTO/", 0) == 0 && !blocks.empty()) {
      const std::vector<double> v = comma_numbers(line.substr(5));
      EXPECT_EQ(v.size(), 6u) << line;
      if (v.size() == 6) blocks.back().gotos.push_back({v[0], v[1], v[2], v[3], v[4], v[5]});
    }
  }
  return blocks;
}

bool mentions(const AptBlock& block, const std::string& what) {
  for (const std::string& line : block.comments)
    if (line.find(what) != std::string::npos) return true;
  return false;
}

double degrees(double radians) { return radians * 180.0 / std::numbers::pi; }

// A moving, turning axis of length 50 (so that the end face's offset shows in every coordinate).
Motion turning_motion() {
  std::vector<Line> lines;
  for (int i = 0; i <= 10; ++i) {
    const double angle = 0.05 * i;
    const Vec3 a(2.0 * i, 0.3 * i * i, 1.0);
    lines.push_back({a, a + 50.0 * Vec3(std::sin(angle), 0.2, std::cos(angle)).normalized()});
  }
  return Motion::fit(lines, 5);
}

Cutter barrel_cutter() {
  Cutter c;
  c.kind = CutterKind::barrel;
  c.length = 50.0;
  c.coeffs.resize(3);
  c.coeffs << 5.0, 6.5, 5.5;
  return c;
}

// The free-form profile of tests/decompose_acceptance.py's spline case.
Cutter spline_cutter() {
  Cutter c;
  c.kind = CutterKind::spline;
  c.length = 50.0;
  c.coeffs.resize(kSplineProfileCoefficients);
  c.coeffs << 5, 5.6, 6.4, 7, 6.6, 6, 6.3, 7.2, 8, 8.4;
  return c;
}

class Write : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("flank_write_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  int entries() const {
    int n = 0;
    for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir_)) ++n;
    return n;
  }

  fs::path dir_;
};

TEST_F(Write, MeshRoundTripsInAllFormats) {
  const Mesh m = saddle();
  for (const char* name : {"saddle.obj", "saddle.ply"}) {  // exact: shortest text / doubles
    SCOPED_TRACE(name);
    write_mesh(dir_ / name, m);
    const LoadedMesh back = read_mesh((dir_ / name).string());
    EXPECT_EQ(back.mesh.V, m.V);
    EXPECT_EQ(back.mesh.F, m.F);
    EXPECT_EQ(back.report.flipped_faces, 0);
  }
  write_mesh(dir_ / "saddle.stl", m);  // float32: same topology, coordinates to float precision
  const LoadedMesh stl = read_mesh((dir_ / "saddle.stl").string());
  EXPECT_EQ(stl.report.format, "stl-binary");
  EXPECT_EQ(stl.mesh.vertex_count(), m.vertex_count());
  EXPECT_EQ(stl.mesh.face_count(), m.face_count());
  EXPECT_EQ(stl.report.flipped_faces, 0);
  EXPECT_NEAR(total_area(stl.mesh), total_area(m), 1e-5);
  EXPECT_NEAR(face_normals(stl.mesh).col(2).sum(), face_normals(m).col(2).sum(), 1e-5);
  EXPECT_EQ(entries(), 3);  // no temporaries left behind

  const Mesh cube = read_mesh(kData + "/cube_quads.obj").mesh;
  write_mesh(dir_ / "cube.STL", cube);
  const Mesh cube_back = read_mesh((dir_ / "cube.STL").string()).mesh;
  ASSERT_EQ(cube_back.face_count(), cube.face_count());
  for (int f = 0; f < cube.face_count(); ++f)  // faces and corners keep their order
    for (int k = 0; k < 3; ++k)
      EXPECT_EQ(Vec3(cube_back.V.row(cube_back.F(f, k))), Vec3(cube.V.row(cube.F(f, k))));
}

TEST_F(Write, BadDestinationThrows) {
  const Mesh m = saddle();
  try {
    write_mesh(dir_ / "mesh.xyz", m);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("unsupported"), std::string::npos) << e.what();
  }
  const fs::path missing = dir_ / "no_such_folder" / "mesh.stl";
  try {
    write_mesh(missing, m);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()).rfind(missing.string() + ": ", 0), 0u) << e.what();
  }
  EXPECT_THROW(write_patches_json(missing.parent_path() / "patches.json", {}, {}), Error);
  // The PLY writers hand their bytes over whole (no stream): the same refusal, no temporary.
  for (const char* name : {"envelopes.ply", "design.ply"}) {
    const fs::path ply = missing.parent_path() / name;
    try {
      if (name[0] == 'e')
        write_envelopes_ply(ply, {make_patch(0, 'a', 0.0)}, 0.01);
      else
        write_design_ply(ply, m, std::vector<int>(static_cast<std::size_t>(m.vertex_count()), -1));
      ADD_FAILURE() << name;
    } catch (const Error& e) {
      EXPECT_EQ(std::string(e.what()), ply.string() + ": output folder does not exist");
    }
  }
  EXPECT_EQ(entries(), 0);
}

TEST_F(Write, AtomicWriteLeavesOldFileWhenFillThrows) {
  const fs::path path = dir_ / "out.txt";
  write_file_atomic(path, [](std::ostream& out) { out << "old"; });
  EXPECT_EQ(slurp(path), "old");
  EXPECT_THROW(write_file_atomic(path,
                                 [](std::ostream& out) {
                                   out << "half of the new content";
                                   throw std::runtime_error("solver failed");
                                 }),
               std::runtime_error);
  EXPECT_EQ(slurp(path), "old");
  EXPECT_EQ(entries(), 1);
  write_file_atomic(path, [](std::ostream& out) { out << "new"; });
  EXPECT_EQ(slurp(path), "new");
  EXPECT_EQ(entries(), 1);
}

TEST_F(Write, PatchesJsonHasTheFormat) {
  RunInfo run;
  run.input_path = "parts/blade.stl";
  run.vertices = 291;
  run.triangles = 522;
  run.bbox_diagonal = 120.5;
  run.settings = {{"tolerance", 0.05},
                  {"tool", std::string("cone")},
                  {"threads", 2LL},
                  {"flip", false},
                  {"radius", std::vector<double>{2.0, 8.0}}};
  run.coverage_fraction = 0.75;
  run.tolerance = 0.05;
  run.uncovered_area = std::numeric_limits<double>::quiet_NaN();
  run.timing_s = {{"index", 0.1}, {"candidates", 0.2}, {"fit", 0.3}, {"cover", 0.01}, {"total", 0.7}};
  std::vector<Patch> patches = {make_patch(0, 'a', 0.0), make_patch(1, 'b', 20.0)};
  patches[1].collision.checked = true;
  patches[1].collision.min_clearance = 1.5;
  patches[1].collision.holder_length = 30.0;
  patches[1].collision.holder_radius = 10.0;
  patches[1].error.rms = std::numeric_limits<double>::infinity();

  const fs::path path = dir_ / "patches.json";
  write_patches_json(path, run, patches);
  const std::string text = slurp(path);
  EXPECT_EQ(text.rfind("{", 0), 0u);
  std::size_t at = expect_in_order(text, {"format", "units", "input", "path", "vertices", "triangles",
                                          "bbox_diagonal", "settings", "tolerance", "tool",
                                          "threads", "flip", "radius", "coverage", "fraction",
                                          "tolerance", "uncovered_area", "timing_s", "index",
                                          "candidates", "fit", "cover", "total", "patches"});
  for (int id = 0; id < 2; ++id)
    at = expect_in_order(text, {"id", "tool", "kind", "length", "radii", "s", "d", "coefficients",
                                "profile", "motion", "degree", "knots", "a", "b", "tip", "error",
                                "max", "rms", "max_gouge", "max_relative", "coverage", "area",
                                "fraction", "collision", "holder_clear", "min_clearance", "holder"},
                         at);
  EXPECT_NE(text.find("\"format\": \"flank-patches/1\""), std::string::npos);
  EXPECT_NE(text.find("\"units\": \"mm\""), std::string::npos);
  EXPECT_NE(text.find("\"kind\": \"cone\""), std::string::npos);
  EXPECT_NE(text.find("\"uncovered_area\": null"), std::string::npos);  // NaN
  EXPECT_NE(text.find("\"rms\": null"), std::string::npos);             // inf
  EXPECT_NE(text.find("\"min_clearance\": null"), std::string::npos);   // not checked
  EXPECT_NE(text.find("\"holder\": null"), std::string::npos);
  EXPECT_NE(text.find("\"min_clearance\": 1.5"), std::string::npos);
  EXPECT_NE(text.find("\"tip\": \"b\""), std::string::npos);
  EXPECT_EQ(text.find("nan"), std::string::npos);
  EXPECT_EQ(text.find("inf"), std::string::npos);

  // 101 uniform radius samples, and as many d values and profile points.
  const std::size_t s_open = text.find("\"s\": [");
  const std::size_t s_close = text.find(']', s_open);
  ASSERT_NE(s_close, std::string::npos);
  const std::string s_array = text.substr(s_open, s_close - s_open);
  EXPECT_EQ(count_of(s_array, ","), 100);
  EXPECT_NE(s_array.find("0.5,"), std::string::npos);
  const std::size_t d_open = text.find("\"d\": [", s_close);
  EXPECT_EQ(count_of(text.substr(d_open, text.find(']', d_open) - d_open), ","), 100);

  // Byte-deterministic.
  write_patches_json(dir_ / "again.json", run, patches);
  EXPECT_EQ(slurp(dir_ / "again.json"), text);
}

TEST_F(Write, PatchesJsonRejectsBrokenCutter) {
  std::vector<Patch> patches = {make_patch(3, 'a', 0.0)};
  patches[0].cutter.coeffs.resize(1);
  EXPECT_THROW(write_patches_json(dir_ / "patches.json", {}, patches), Error);
  EXPECT_EQ(entries(), 0);
}

TEST_F(Write, EnvelopesPlyCarriesErrorAndColour) {
  const std::vector<Patch> patches = {make_patch(0, 'a', 0.0), make_patch(7, 'a', 5.0)};
  const fs::path path = dir_ / "envelopes.ply";
  write_envelopes_ply(path, patches, 0.1);
  const LoadedMesh back = read_mesh(path.string());
  EXPECT_EQ(back.report.format, "ply-binary");
  EXPECT_EQ(back.mesh.vertex_count(), 8);
  EXPECT_EQ(back.mesh.face_count(), 4);
  EXPECT_EQ(back.report.components, 2);

  const std::string text = slurp(path);
  EXPECT_NE(text.find("property float error\n"), std::string::npos);
  EXPECT_NE(text.find("property int patch\n"), std::string::npos);
  const std::size_t body = text.find("end_header\n") + 11;
  const std::size_t stride = 4 * 4 + 3 + 4;
  const unsigned char expected[4][3] = {{255, 0, 0}, {255, 128, 128}, {255, 255, 255}, {0, 0, 255}};
  for (int v = 0; v < 8; ++v) {
    const std::size_t at = body + v * stride;
    float e;
    std::memcpy(&e, text.data() + at + 12, 4);
    EXPECT_FLOAT_EQ(e, static_cast<float>(patches[v / 4].envelope.error(v % 4)));
    for (int k = 0; k < 3; ++k)
      EXPECT_EQ(static_cast<unsigned char>(text[at + 16 + k]), expected[v % 4][k]) << v;
    std::int32_t id;
    std::memcpy(&id, text.data() + at + 19, 4);
    EXPECT_EQ(id, patches[v / 4].id);
  }
  EXPECT_EQ(text.size(), body + 8 * stride + 4 * 13);
}

TEST_F(Write, DesignPlyColoursPatches) {
  const Mesh m = saddle();
  std::vector<int> vertex_patch(m.vertex_count(), 0);
  vertex_patch[1] = -1;
  vertex_patch[2] = 4;
  const fs::path path = dir_ / "design.ply";
  write_design_ply(path, m, vertex_patch);
  const LoadedMesh back = read_mesh(path.string());
  EXPECT_EQ(back.mesh.vertex_count(), m.vertex_count());
  EXPECT_EQ(back.mesh.F, m.F);
  const std::string text = slurp(path);
  const std::size_t body = text.find("end_header\n") + 11;
  const std::size_t stride = 3 * 4 + 3 + 4;
  const auto rgb = [&](int v) {
    const std::size_t at = body + v * stride + 12;
    return std::vector<int>{static_cast<unsigned char>(text[at]),
                            static_cast<unsigned char>(text[at + 1]),
                            static_cast<unsigned char>(text[at + 2])};
  };
  EXPECT_EQ(rgb(1), (std::vector<int>{255, 0, 255}));
  EXPECT_EQ(rgb(0), rgb(3));
  EXPECT_NE(rgb(0), rgb(2));
  std::int32_t id;
  std::memcpy(&id, text.data() + body + stride + 15, 4);
  EXPECT_EQ(id, -1);

  vertex_patch.pop_back();
  EXPECT_THROW(write_design_ply(dir_ / "short.ply", m, vertex_patch), Error);
  EXPECT_FALSE(fs::exists(dir_ / "short.ply"));
}

TEST_F(Write, ToolpathAptHasOneGotoPerStep) {
  const std::vector<Patch> patches = {make_patch(0, 'a', 0.0), make_patch(1, 'b', 20.0)};
  const fs::path path = dir_ / "toolpath.apt";
  write_toolpath_apt(path, patches, 40, "BLADE");
  const std::string text = slurp(path);
  EXPECT_EQ(text.rfind("$$ flank toolpath", 0), 0u);
  EXPECT_NE(text.find("\nPARTNO/BLADE\n"), std::string::npos);
  EXPECT_NE(text.find("\nUNITS/MM\n"), std::string::npos);
  EXPECT_EQ(count_of(text, "\nMULTAX/ON\n"), 2);
  EXPECT_EQ(count_of(text, "\nGOTO/"), 2 * 41);
  EXPECT_EQ(count_of(text, "FINI"), 1);
  EXPECT_EQ(text.substr(text.size() - 5), "FINI\n");
  // The cone r(z) = 4 + k z, k = 3/50, on axes along +z: sphere s touches it on the circle
  // z(s) = sL − d d′/L, so the end face lies r_tip k/(1 + k²) beyond the tip-end sphere's
  // centre, away from the spindle, and the flutes are L/(1 + k²) long. Tip a: from a(t) toward
  // b(t), the end face below a(t); tip b: from b(t) toward a(t), the end face below b(t) too.
  const double k = 3.0 / 50.0, shrink = 1.0 / (1.0 + k * k);
  char line[160];
  for (const double x : {0.0, 10.0}) {
    std::snprintf(line, sizeof line, "\nGOTO/%.6f,0.000000,%.6f,0.000000,0.000000,1.000000\n", x,
                  -4.0 * k * shrink);
    EXPECT_NE(text.find(line), std::string::npos) << line;
  }
  std::snprintf(line, sizeof line, "\nGOTO/20.000000,0.000000,%.6f,0.000000,0.000000,-1.000000\n",
                50.0 - 7.0 * k * shrink);
  EXPECT_NE(text.find(line), std::string::npos) << line;
  // CUTTER/d,r,e,f,alpha,beta,h: the diameter at the end face, widening toward the spindle for
  // tip a and narrowing for tip b.
  std::snprintf(line, sizeof line, "\nCUTTER/%.6f,0.000000,0.000000,0.000000,0.000000,%.6f,%.6f\n",
                8.0 * shrink, degrees(std::atan(k)), 50.0 * shrink);
  EXPECT_NE(text.find(line), std::string::npos) << line;
  std::snprintf(line, sizeof line, "\nCUTTER/%.6f,0.000000,0.000000,0.000000,0.000000,%.6f,%.6f\n",
                14.0 * shrink, -degrees(std::atan(k)), 50.0 * shrink);
  EXPECT_NE(text.find(line), std::string::npos) << line;
  EXPECT_EQ(text.find("tools.step"), std::string::npos);  // a cone is described exactly
  EXPECT_EQ(text.find("-0.000000"), std::string::npos);

  write_toolpath_apt(dir_ / "again.apt", patches, 40, "BLADE");
  EXPECT_EQ(slurp(dir_ / "again.apt"), text);

  EXPECT_THROW(write_toolpath_apt(dir_ / "zero.apt", patches, 0, "BLADE"), Error);
  std::vector<Patch> broken = patches;
  broken[1].motion = Motion();
  EXPECT_THROW(write_toolpath_apt(dir_ / "broken.apt", broken, 10, "BLADE"), Error);
  broken = patches;
  broken[0].cutter.length = 0.0;
  EXPECT_THROW(write_toolpath_apt(dir_ / "broken.apt", broken, 10, "BLADE"), Error);
  EXPECT_EQ(entries(), 2);
}

// CUTTER/ of a cylinder and of cones both ways round: exactly the tool, taper positive when the
// tool widens toward the spindle, whichever end of the axis the tip is at.
TEST_F(Write, AptCutterIsExactForCylinderAndCone) {
  const double k = 3.0 / 50.0, shrink = 1.0 / (1.0 + k * k), beta = degrees(std::atan(k));
  const Cutter cylinder = Cutter::constant(CutterKind::cylinder, 50.0, 5.0);
  struct Case {
    const char* name;
    Cutter cutter;
    char tip;
    std::array<double, 7> expected;  // d, r, e, f, alpha, beta, h
    double face;                     // the end face's offset from the tip-end axis point
  };
  const std::vector<Case> cases = {
      {"cylinder", cylinder, 'a', {10, 0, 0, 0, 0, 0, 50}, 0.0},
      {"cylinder tip b", cylinder, 'b', {10, 0, 0, 0, 0, 0, 50}, 0.0},
      {"cone widening", cone_from_end_radii(50.0, 4.0, 7.0), 'a',
       {8 * shrink, 0, 0, 0, 0, beta, 50 * shrink}, -4 * k * shrink},
      {"cone narrowing", cone_from_end_radii(50.0, 7.0, 4.0), 'a',
       {14 * shrink, 0, 0, 0, 0, -beta, 50 * shrink}, 7 * k * shrink},
      {"cone widening toward a, tip b", cone_from_end_radii(50.0, 7.0, 4.0), 'b',
       {8 * shrink, 0, 0, 0, 0, beta, 50 * shrink}, -4 * k * shrink},
      {"cone narrowing toward a, tip b", cone_from_end_radii(50.0, 4.0, 7.0), 'b',
       {14 * shrink, 0, 0, 0, 0, -beta, 50 * shrink}, 7 * k * shrink},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    Patch p = make_patch(0, c.tip, 0.0);
    p.cutter = c.cutter;
    write_toolpath_apt(dir_ / "toolpath.apt", {p}, 10, "PART");
    const std::vector<AptBlock> blocks = apt_blocks(slurp(dir_ / "toolpath.apt"));
    ASSERT_EQ(blocks.size(), 1u);
    ASSERT_EQ(blocks[0].cutter.size(), 7u);
    for (int i = 0; i < 7; ++i) EXPECT_NEAR(blocks[0].cutter[i], c.expected[i], 1e-6) << i;
    EXPECT_FALSE(mentions(blocks[0], "tools.step"));
    // Axes along +z from a at z = 0 to b at z = 50; the CL point is the end face's centre.
    ASSERT_EQ(blocks[0].gotos.size(), 11u);
    for (int i = 0; i <= 10; ++i) {
      const std::array<double, 6>& g = blocks[0].gotos[i];
      const double direction = c.tip == 'a' ? 1.0 : -1.0;
      EXPECT_NEAR(g[0], i, 1e-6);
      EXPECT_NEAR(g[1], 0.0, 1e-6);
      EXPECT_NEAR(g[2], (c.tip == 'a' ? 0.0 : 50.0) + direction * c.face, 1e-6);
      EXPECT_NEAR(g[5], direction, 1e-6);
    }
  }
}

// Barrel and spline: the cone through the profile's end circles, with the deviation from the
// real profile and where the exact profile is in comments.
TEST_F(Write, AptCutterOfBarrelAndSplineIsTheConeThroughTheEnds) {
  std::vector<Patch> patches = {make_patch(7, 'a', 0.0), make_patch(3, 'b', 20.0),
                                make_patch(5, 'a', 40.0)};
  patches[0].cutter = barrel_cutter();
  patches[1].cutter = barrel_cutter();
  patches[2].cutter = spline_cutter();
  write_toolpath_apt(dir_ / "toolpath.apt", patches, 10, "PART");
  const std::vector<AptBlock> blocks = apt_blocks(slurp(dir_ / "toolpath.apt"));
  ASSERT_EQ(blocks.size(), 3u);
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    const Cutter& c = patches[i].cutter;
    const bool tip_a = patches[i].tip == 'a';
    const std::string id = std::to_string(patches[i].id);
    SCOPED_TRACE("patch " + id);
    // The meridian (z from a, r) at the tip end and at the spindle end.
    const Vec2 tip = c.meridian(tip_a ? 0.0 : 1.0), end = c.meridian(tip_a ? 1.0 : 0.0);
    const double h = std::abs(end(0) - tip(0));
    const double slope = (end(1) - tip(1)) / h;
    ASSERT_EQ(blocks[i].cutter.size(), 7u);
    const std::array<double, 7> expected = {2 * tip(1), 0, 0, 0, 0, degrees(std::atan(slope)), h};
    for (int j = 0; j < 7; ++j) EXPECT_NEAR(blocks[i].cutter[j], expected[j], 1e-6) << j;
    double deviation = 0.0;
    for (int j = 0; j <= 20000; ++j) {
      const Vec2 m = c.meridian(j / 20000.0);
      const double from_tip = std::abs(m(0) - tip(0));
      deviation = std::max(deviation, std::abs(m(1) - (tip(1) + slope * from_tip)));
    }
    EXPECT_GT(deviation, 0.1);
    double written = -1.0;
    for (const std::string& comment : blocks[i].comments) {
      const std::size_t at = comment.find("radially by up to ");
      if (comment.rfind("$$ patch " + id + ": ", 0) == 0 && at != std::string::npos)
        written = std::strtod(comment.c_str() + at + 18, nullptr);
    }
    EXPECT_NEAR(written, deviation, 1e-5);
    EXPECT_TRUE(mentions(blocks[i], "tools.step solid P" + id + "-tool"));
    EXPECT_TRUE(
        mentions(blocks[i], "patches.json patches[" + std::to_string(i) + "].tool.profile"));
  }
}

// The CL point is the centre of the end face: on the axis, where the meridian starts at the tip
// end, for a cutter whose end face is well off the axis end point, on a moving, turning axis.
TEST_F(Write, AptClPointIsTheEndFaceCentre) {
  for (const char tip : {'a', 'b'}) {
    for (const Cutter& cutter : {barrel_cutter(), spline_cutter(), cone_from_end_radii(50, 3, 9)}) {
      SCOPED_TRACE(std::string("tip ") + tip + ", " + std::string(to_string(cutter.kind)));
      Patch p = make_patch(0, tip, 0.0);
      p.motion = turning_motion();
      p.cutter = cutter;
      const int steps = 25;
      write_toolpath_apt(dir_ / "toolpath.apt", {p}, steps, "PART");
      const std::vector<AptBlock> blocks = apt_blocks(slurp(dir_ / "toolpath.apt"));
      ASSERT_EQ(blocks.size(), 1u);
      ASSERT_EQ(blocks[0].gotos.size(), static_cast<std::size_t>(steps + 1));
      // Distance of the end face from the tip-end axis point toward the spindle, from the
      // meridian (z from a): z(0) for tip a, L − z(1) for tip b.
      const double face =
          tip == 'a' ? cutter.meridian(0.0)(0) : cutter.length - cutter.meridian(1.0)(0);
      EXPECT_GT(std::abs(face), 0.1);
      for (int i = 0; i <= steps; ++i) {
        const double t = i / static_cast<double>(steps);
        const Vec3 a = p.motion.a_at(t), b = p.motion.b_at(t);
        const Vec3 from = tip == 'a' ? a : b;
        const Vec3 axis = (tip == 'a' ? Vec3(b - a) : Vec3(a - b)).normalized();
        const std::array<double, 6>& g = blocks[0].gotos[i];
        const Vec3 cl(g[0], g[1], g[2]), printed_axis(g[3], g[4], g[5]);
        EXPECT_LT((printed_axis - axis).norm(), 2e-6) << i;
        EXPECT_NEAR((cl - from).dot(axis), face, 2e-6) << i;
        EXPECT_LT((cl - from - (cl - from).dot(axis) * axis).norm(), 2e-6) << i;  // on the axis
      }
    }
  }
}

}  // namespace
}  // namespace flank::report
