// report.html: the run's data comes back from the page exactly (meshes, patch ids, motions,
// errors as typed arrays), hostile text cannot end the data early, the page is the same bytes
// for the same run, and it carries no external reference. What a browser makes of it is
// tests/report_browser_test.mjs's job.
#include "report/write_html.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "io/read_mesh.h"
#include "kernels/cutter.h"
#include "solver/motion.h"
#include "tests/saddle_mesh.h"
#include "tests/test_files.h"

namespace flank::report {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

using testing::count_of;
using testing::slurp;


std::string unbase64(const std::string& text) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::string out;
  std::uint32_t bits = 0;
  int count = 0;
  for (char c : text) {
    const int v = value(c);
    if (v < 0) break;  // padding
    bits = (bits << 6) | static_cast<std::uint32_t>(v);
    count += 6;
    if (count >= 8) {
      count -= 8;
      out += static_cast<char>((bits >> count) & 0xffu);
    }
  }
  return out;
}

template <typename T>
std::vector<T> typed(const Json& b64) {
  const std::string bytes = unbase64(b64.get<std::string>());
  EXPECT_EQ(bytes.size() % sizeof(T), 0u);
  std::vector<T> out(bytes.size() / sizeof(T));
  std::memcpy(out.data(), bytes.data(), out.size() * sizeof(T));  // the test machine is little-endian
  return out;
}

// The JSON between <script id="flank-data" type="application/json"> and its </script>.
Json page_data(const std::string& page) {
  const std::string open = "<script id=\"flank-data\" type=\"application/json\">";
  const std::size_t begin = page.find(open);
  EXPECT_NE(begin, std::string::npos);
  if (begin == std::string::npos) return Json();
  const std::size_t from = begin + open.size();
  const std::size_t end = page.find("</script>", from);
  return Json::parse(page.substr(from, end - from));
}

Mesh html_saddle() { return testing::saddle_mesh(6, 5); }

Patch make_patch(int id, double x0) {
  Patch p;
  p.id = id;
  p.tip = id % 2 ? 'b' : 'a';
  std::vector<Line> lines;
  for (int i = 0; i <= 10; ++i) lines.push_back({Vec3(x0 + i, 0.1 * i * i, 0), Vec3(x0 + i, 0, 50)});
  p.motion = Motion::fit(lines, 5);
  p.cutter = cone_from_end_radii(50.0, 4.0, 7.0);
  p.error = {0.01, 0.005, 0.002, 1e-4};
  p.covered_area = 12.5;
  p.coverage_fraction = 0.25;
  p.envelope.V.resize(4, 3);
  p.envelope.V << x0, 0, 0, x0 + 1, 0, 0, x0 + 1, 1, 0, x0, 1, 0;
  p.envelope.F.resize(2, 3);
  p.envelope.F << 0, 1, 2, 0, 2, 3;
  p.envelope.error.resize(4);
  p.envelope.error << -0.2, std::numeric_limits<double>::quiet_NaN(), 0.0, 0.1;
  return p;
}

class WriteHtml : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("flank_write_html_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    mesh_ = html_saddle();
    run_.command = "decompose";
    run_.input_path = "parts/blade.step";
    run_.input_format = "step";
    run_.input_bytes = 123456;
    run_.vertices = mesh_.vertex_count();
    run_.triangles = mesh_.face_count();
    run_.bbox_diagonal = 3.5;
    run_.settings = {{"tolerance", 0.05}, {"tool", std::string("cone")}, {"radius", std::vector<double>{2.0, 8.0}}};
    run_.tolerance = 0.05;
    run_.coverage_fraction = 0.4;
    run_.total_area = 10.0;
    run_.uncovered_area = 6.0;
    run_.coverage_curve = {0.25, 0.4};
    run_.uncovered = {{6.0, Vec3(1, 2, 3), 12}};
    run_.timing_s = {{"index", 0.1}, {"fit", 0.3}, {"total", 0.5}};
    patches_ = {make_patch(0, 0.0), make_patch(1, 20.0)};
    patches_[1].collision.checked = true;
    patches_[1].collision.holder_clear = false;
    patches_[1].collision.min_clearance = -0.5;
    patches_[1].collision.holder_length = 30.0;
    patches_[1].collision.holder_radius = 10.0;
    vertex_patch_.assign(static_cast<std::size_t>(mesh_.vertex_count()), -1);
    for (std::size_t v = 0; v < vertex_patch_.size(); ++v) vertex_patch_[v] = static_cast<int>(v % 3) - 1;
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string write(const std::string& name = "report.html") {
    write_report_html(dir_ / name, run_, patches_, mesh_, vertex_patch_);
    return slurp(dir_ / name);
  }

  fs::path dir_;
  Mesh mesh_;
  RunInfo run_;
  std::vector<Patch> patches_;
  std::vector<int> vertex_patch_;
};

TEST_F(WriteHtml, DataComesBackExactly) {
  const Json d = page_data(write());
  EXPECT_EQ(d["format"], "flank-report/1");
  EXPECT_EQ(d["command"], "decompose");
  EXPECT_EQ(d["input"]["path"], "parts/blade.step");
  EXPECT_EQ(d["input"]["bytes"], 123456);
  EXPECT_EQ(d["input"]["format"], "step");
  EXPECT_EQ(d["tolerance"], 0.05);
  EXPECT_EQ(d["coverage"]["curve"].size(), 2u);
  EXPECT_EQ(d["coverage"]["regions"][0]["vertices"], 12);
  EXPECT_EQ(d["settings"]["tool"], "cone");
  EXPECT_EQ(d["timing_s"]["total"], 0.5);
  EXPECT_EQ(d["palette"].size(), 11u);
  EXPECT_EQ(d["palette"][0], "#1f77b4");
  EXPECT_EQ(d["uncovered_colour"], "#ff00ff");

  // The design: float32 positions, uint32 indices, int32 patch ids, as given.
  const Json& design = d["design"];
  EXPECT_EQ(design["vertices"], mesh_.vertex_count());
  const std::vector<float> position = typed<float>(design["position"]);
  ASSERT_EQ(position.size(), static_cast<std::size_t>(3 * mesh_.vertex_count()));
  for (int v = 0; v < mesh_.vertex_count(); ++v)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(position[3 * v + k], static_cast<float>(mesh_.V(v, k)));
  const std::vector<std::uint32_t> index = typed<std::uint32_t>(design["index"]);
  ASSERT_EQ(index.size(), static_cast<std::size_t>(3 * mesh_.face_count()));
  for (int f = 0; f < mesh_.face_count(); ++f)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(index[3 * f + k], static_cast<std::uint32_t>(mesh_.F(f, k)));
  EXPECT_EQ(typed<std::int32_t>(design["patch"]), std::vector<std::int32_t>(vertex_patch_.begin(), vertex_patch_.end()));

  ASSERT_EQ(d["patches"].size(), 2u);
  for (std::size_t k = 0; k < 2; ++k) {
    const Json& p = d["patches"][k];
    const Patch& q = patches_[k];
    EXPECT_EQ(p["id"], q.id);
    EXPECT_EQ(p["kind"], "cone");
    EXPECT_EQ(p["tip"], std::string(1, q.tip));
    EXPECT_DOUBLE_EQ(p["sphere_radius"][1].get<double>(), q.cutter.radius(1.0));
    EXPECT_DOUBLE_EQ(p["end_radius"][0].get<double>(), q.cutter.meridian(0.0)(1));
    EXPECT_EQ(p["profile"].size(), 101u);
    EXPECT_DOUBLE_EQ(p["coverage"]["adds"].get<double>(), k == 0 ? 0.25 : 0.4 - 0.25);
    // The motion sampled uniformly in t.
    const int steps = p["motion"]["steps"];
    EXPECT_EQ(steps, kReportMotionSteps);
    const std::vector<float> a = typed<float>(p["motion"]["a"]), b = typed<float>(p["motion"]["b"]);
    ASSERT_EQ(a.size(), static_cast<std::size_t>(3 * (steps + 1)));
    ASSERT_EQ(b.size(), a.size());
    for (int i : {0, steps / 3, steps}) {
      const double t = i / static_cast<double>(steps);
      for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(a[3 * i + c], static_cast<float>(q.motion.a_at(t)(c)));
        EXPECT_EQ(b[3 * i + c], static_cast<float>(q.motion.b_at(t)(c)));
      }
    }
    const std::vector<float> error = typed<float>(p["envelope"]["error"]);
    ASSERT_EQ(error.size(), 4u);
    EXPECT_EQ(error[0], -0.2f);
    EXPECT_TRUE(std::isnan(error[1]));  // unknown stays unknown, not 0
    EXPECT_EQ(typed<std::uint32_t>(p["envelope"]["index"]).size(), 6u);
  }
  EXPECT_FALSE(d["patches"][0]["collision"]["checked"]);
  EXPECT_TRUE(d["patches"][0]["collision"]["min_clearance"].is_null());
  EXPECT_FALSE(d["patches"][1]["collision"]["holder_clear"]);
  EXPECT_EQ(d["patches"][1]["collision"]["holder"][1], 10.0);
}

TEST_F(WriteHtml, NoPatchesIsStillAPage) {
  patches_.clear();
  run_.coverage_curve.clear();
  std::fill(vertex_patch_.begin(), vertex_patch_.end(), -1);
  const Json d = page_data(write());
  EXPECT_TRUE(d["patches"].is_array());
  EXPECT_TRUE(d["patches"].empty());
  EXPECT_EQ(typed<std::int32_t>(d["design"]["patch"]), std::vector<std::int32_t>(vertex_patch_.size(), -1));
}

TEST_F(WriteHtml, HostileTextCannotEndTheData) {
  const int closings = count_of(write("plain.html"), "</script>");
  run_.input_path = "a</script><script>alert(1)</script>\n.stl";
  run_.settings.push_back({"note", std::string("</SCRIPT></style><!--")});
  const std::string page = write();
  EXPECT_EQ(count_of(page, "</script>"), closings);
  const Json d = page_data(page);
  EXPECT_EQ(d["input"]["path"], run_.input_path);
  EXPECT_EQ(d["settings"]["note"], "</SCRIPT></style><!--");
}

TEST_F(WriteHtml, SameRunSameBytes) { EXPECT_EQ(write("one.html"), write("two.html")); }

// Self-contained: nothing is fetched, the inlined libraries keep their licence.
TEST_F(WriteHtml, SelfContainedWithLicences) {
  const std::string page = write();
  for (const char* external : {"src=\"http", "src='http", "href=\"http", "href='http", "url(http", "@import", "src=\"//"})
    EXPECT_EQ(page.find(external), std::string::npos) << external;
  EXPECT_NE(page.find("three.js authors"), std::string::npos);
  EXPECT_NE(page.find("MIT"), std::string::npos);
  EXPECT_EQ(page.find("/*FLANK_"), std::string::npos);  // every marker filled
}

// A large Ω is shown on every k-th row and column of its grid: the page's envelopes stay
// within the budget (40,000 vertices, or the design's count), each kept vertex is one of Ω's
// with its own error, and grid points off Ω (no triangle uses them) are never sent.
TEST_F(WriteHtml, LargeEnvelopesAreSampledOnTheirGrid) {
  const int rows = 401, cols = 151;  // 60,551 vertices per patch, two patches
  for (Patch& p : patches_) {
    EnvelopeMesh& env = p.envelope;
    env.rows = rows, env.cols = cols;
    env.V.resize(rows * cols, 3);
    env.error.resize(rows * cols);
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j < cols; ++j) {
        const int k = i * cols + j;
        env.V.row(k) << i * 0.1, j * 0.2, std::sin(i * 0.01) + p.id;
        env.error(k) = 1e-3 * (i - j);
      }
    // Ω does not exist on the last 20 columns: NaN points no triangle uses.
    std::vector<Eigen::Vector3i> faces;
    for (int i = 0; i + 1 < rows; ++i)
      for (int j = 0; j + 1 < cols - 20; ++j) {
        const int v00 = i * cols + j;
        faces.emplace_back(v00, v00 + cols, v00 + cols + 1);
        faces.emplace_back(v00, v00 + cols + 1, v00 + 1);
      }
    for (int i = 0; i < rows; ++i)
      for (int j = cols - 19; j < cols; ++j) env.V.row(i * cols + j).setConstant(std::numeric_limits<double>::quiet_NaN());
    env.F.resize(static_cast<Eigen::Index>(faces.size()), 3);
    for (std::size_t f = 0; f < faces.size(); ++f) env.F.row(static_cast<Eigen::Index>(f)) = faces[f].transpose();
  }
  const Json d = page_data(write());
  long long shown = 0;
  for (std::size_t k = 0; k < 2; ++k) {
    const Json& env = d["patches"][k]["envelope"];
    EXPECT_GT(env["sampled_every"].get<int>(), 1);
    const std::vector<float> position = typed<float>(env["position"]), error = typed<float>(env["error"]);
    const std::vector<std::uint32_t> index = typed<std::uint32_t>(env["index"]);
    const std::size_t n = error.size();
    ASSERT_EQ(position.size(), 3 * n);
    shown += static_cast<long long>(n);
    EXPECT_GT(index.size(), 3 * n);  // a surface, not scattered points
    for (std::uint32_t v : index) ASSERT_LT(v, n);
    for (std::size_t v = 0; v < n; ++v) {
      ASSERT_TRUE(std::isfinite(position[3 * v])) << v;
      // Back to the grid: x = 0.1 i, y = 0.2 j, and the error of that grid point.
      const int i = static_cast<int>(std::lround(position[3 * v] / 0.1f));
      const int j = static_cast<int>(std::lround(position[3 * v + 1] / 0.2f));
      ASSERT_LT(j, cols - 20);
      EXPECT_FLOAT_EQ(error[v], static_cast<float>(1e-3 * (i - j)));
    }
  }
  EXPECT_LE(shown, 40000);
  EXPECT_GT(shown, 20000);
}

TEST_F(WriteHtml, MismatchedPatchIdsThrow) {
  vertex_patch_.pop_back();
  EXPECT_THROW(write(), io::Error);
  EXPECT_FALSE(fs::exists(dir_ / "report.html"));
}

}  // namespace
}  // namespace flank::report
