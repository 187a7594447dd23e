// report.html: the page template, style and script of report/web (embedded at build time by
// cmake/embed_assets.cmake) with the run's data spliced in. Every byte is deterministic: the
// data is written in a fixed order with fixed formats, meshes as float32/uint32/int32 arrays.
#include "report/write_html.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <utility>

#include "io/encode.h"
#include "io/read_mesh.h"
#include "io/write_mesh.h"
#include "report/html_assets.h"
#include "report/palette.h"

namespace flank::report {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::ordered_json;

constexpr long long kEnvelopeVertices = 40000;

// A JSON number, or null where the value is not finite (JSON has no NaN or infinity).
Json finite_or_null(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

// RFC 4648 base64 with padding: what the page's atob() reads.
std::string base64(const std::string& bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  const auto byte = [&](std::size_t k) { return static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[k])); };
  for (; i + 2 < bytes.size(); i += 3) {
    const std::uint32_t v = (byte(i) << 16) | (byte(i + 1) << 8) | byte(i + 2);
    for (int s = 18; s >= 0; s -= 6) out += kAlphabet[(v >> s) & 63u];
  }
  if (i + 1 == bytes.size()) {
    const std::uint32_t v = byte(i) << 16;
    out += kAlphabet[(v >> 18) & 63u];
    out += kAlphabet[(v >> 12) & 63u];
    out += "==";
  } else if (i + 2 == bytes.size()) {
    const std::uint32_t v = (byte(i) << 16) | (byte(i + 1) << 8);
    out += kAlphabet[(v >> 18) & 63u];
    out += kAlphabet[(v >> 12) & 63u];
    out += kAlphabet[(v >> 6) & 63u];
    out += '=';
  }
  return out;
}

std::string positions(const Points& V) {
  io::Bytes b;
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    for (int k = 0; k < 3; ++k) b.f32(V(i, k));
  return base64(b.str());
}

std::string indices(const Faces& F) {
  io::Bytes b;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) b.u32(static_cast<std::uint32_t>(F(f, k)));
  return base64(b.str());
}

std::string hex(const Rgb& c) {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string s = "#";
  for (std::uint8_t v : c) {
    s += kDigits[v >> 4];
    s += kDigits[v & 15u];
  }
  return s;
}

Json design_json(const fs::path& path, const Mesh& mesh, const std::vector<int>& vertex_patch) {
  if (vertex_patch.size() != static_cast<std::size_t>(mesh.vertex_count()))
    throw io::Error(path.string() + ": vertex_patch has " + std::to_string(vertex_patch.size()) +
                    " entries for " + std::to_string(mesh.vertex_count()) + " vertices");
  io::Bytes patch;
  for (int id : vertex_patch) patch.i32(id < 0 ? -1 : id);
  return Json{{"vertices", mesh.vertex_count()},
              {"triangles", mesh.face_count()},
              {"position", positions(mesh.V)},
              {"index", indices(mesh.F)},
              {"patch", base64(patch.str())}};
}

// Ω for the page: only the vertices its triangles use (Ω's grid also holds points where the
// envelope does not exist), and, when the grid has more than `budget` vertices, every k-th row
// and column of it (the last ones kept), a coarse cell drawn where its three corners are on Ω.
// The error shown is then Ω's error at the kept samples; the table's max |e| stays exact.
Json envelope_json(const EnvelopeMesh& env, long long budget) {
  const Eigen::Index n = env.V.rows();
  std::vector<char> used(static_cast<std::size_t>(n), 0);
  for (Eigen::Index f = 0; f < env.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      if (env.F(f, k) < 0 || env.F(f, k) >= n)
        throw io::Error("report.html: an envelope triangle refers to vertex " + std::to_string(env.F(f, k)) +
                        " of " + std::to_string(n));
      used[static_cast<std::size_t>(env.F(f, k))] = 1;
    }
  const bool grid = env.rows >= 2 && env.cols >= 2 && static_cast<Eigen::Index>(env.rows) * env.cols == n;
  int step = 1;
  if (grid && budget > 0)
    while (static_cast<long long>((env.rows + step - 1) / step + 1) * ((env.cols + step - 1) / step + 1) > budget) ++step;
  Faces F;
  if (step == 1) {
    F = env.F;
  } else {
    auto samples = [step](int count) {
      std::vector<int> at;
      for (int i = 0; i < count - 1; i += step) at.push_back(i);
      at.push_back(count - 1);
      return at;
    };
    const std::vector<int> rows = samples(env.rows), cols = samples(env.cols);
    std::vector<Eigen::Vector3i> faces;
    auto add = [&](int p, int q, int r) {
      if (used[static_cast<std::size_t>(p)] && used[static_cast<std::size_t>(q)] && used[static_cast<std::size_t>(r)])
        faces.emplace_back(p, q, r);
    };
    for (std::size_t i = 0; i + 1 < rows.size(); ++i)
      for (std::size_t j = 0; j + 1 < cols.size(); ++j) {
        const int v00 = rows[i] * env.cols + cols[j], v01 = rows[i] * env.cols + cols[j + 1];
        const int v10 = rows[i + 1] * env.cols + cols[j], v11 = rows[i + 1] * env.cols + cols[j + 1];
        add(v00, v10, v11);  // the orientation of Ω's own triangles (evaluate_patch)
        add(v00, v11, v01);
      }
    F.resize(static_cast<Eigen::Index>(faces.size()), 3);
    for (std::size_t f = 0; f < faces.size(); ++f) F.row(static_cast<Eigen::Index>(f)) = faces[f].transpose();
  }
  // Keep the vertices the triangles use, in their order.
  std::vector<int> renumber(static_cast<std::size_t>(n), -1);
  int kept = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      int& r = renumber[static_cast<std::size_t>(F(f, k))];
      if (r < 0) r = kept++;
      F(f, k) = r;
    }
  Points V(kept, 3);
  io::Bytes error;
  std::vector<double> e(static_cast<std::size_t>(kept), std::numeric_limits<double>::quiet_NaN());
  for (Eigen::Index v = 0; v < n; ++v) {
    const int r = renumber[static_cast<std::size_t>(v)];
    if (r < 0) continue;
    V.row(r) = env.V.row(v);
    if (v < env.error.size()) e[static_cast<std::size_t>(r)] = env.error(v);
  }
  for (double x : e) error.f32(x);
  return Json{{"vertices", V.rows()},
              {"triangles", F.rows()},
              {"sampled_every", step},
              {"position", positions(V)},
              {"index", indices(F)},
              {"error", base64(error.str())}};
}

Json patch_json(const Patch& p, double adds, long long envelope_budget) {
  const Cutter& c = p.cutter;
  const bool profiled = c.coeffs.size() == coefficient_count(c.kind) && c.length > 0 && std::isfinite(c.length);
  Json out;
  out["id"] = p.id;
  out["kind"] = std::string(to_string(c.kind));
  out["tip"] = std::string(1, p.tip);
  out["length"] = finite_or_null(c.length);
  Json profile = Json::array();
  if (profiled) {
    out["sphere_radius"] = Json::array({finite_or_null(c.radius(0.0)), finite_or_null(c.radius(1.0))});
    out["end_radius"] = Json::array({finite_or_null(c.meridian(0.0)(1)), finite_or_null(c.meridian(1.0)(1))});
    constexpr int kProfileSamples = 101;
    for (int i = 0; i < kProfileSamples; ++i) {
      const Vec2 m = c.meridian(i / static_cast<double>(kProfileSamples - 1));
      profile.push_back(Json::array({finite_or_null(m(0)), finite_or_null(m(1))}));
    }
  } else {
    out["sphere_radius"] = Json::array({nullptr, nullptr});
    out["end_radius"] = Json::array({nullptr, nullptr});
  }
  out["error"] = Json{{"max", finite_or_null(p.error.max)}, {"rms", finite_or_null(p.error.rms)}, {"max_gouge", finite_or_null(p.error.max_gouge)}};
  out["coverage"] = Json{{"area", finite_or_null(p.covered_area)}, {"fraction", finite_or_null(p.coverage_fraction)}, {"adds", finite_or_null(adds)}};
  out["collision"] = Json{
      {"checked", p.collision.checked},
      {"holder_clear", p.collision.holder_clear},
      {"min_clearance", p.collision.checked ? finite_or_null(p.collision.min_clearance) : Json(nullptr)},
      {"holder", p.collision.checked
                     ? Json::array({finite_or_null(p.collision.holder_length), finite_or_null(p.collision.holder_radius)})
                     : Json(nullptr)}};
  out["profile"] = std::move(profile);
  // The axis sampled uniformly in t: the page moves the cutter along these, no spline code there.
  io::Bytes a, b;
  const bool moving = p.motion.count() >= 4 && p.motion.knots.size() == static_cast<std::size_t>(p.motion.count() + 4);
  const int steps = moving ? kReportMotionSteps : -1;
  for (int i = 0; i <= steps; ++i) {
    const double t = i / static_cast<double>(steps);
    const Vec3 pa = p.motion.a_at(t), pb = p.motion.b_at(t);
    for (int k = 0; k < 3; ++k) a.f32(pa(k));
    for (int k = 0; k < 3; ++k) b.f32(pb(k));
  }
  out["motion"] = Json{{"steps", std::max(steps, 0)}, {"a", base64(a.str())}, {"b", base64(b.str())}};
  out["envelope"] = envelope_json(p.envelope, envelope_budget);
  return out;
}

// The data inside <script type="application/json">: "</" would end the element early.
std::string script_safe(const std::string& json) {
  std::string out;
  out.reserve(json.size());
  for (std::size_t i = 0; i < json.size(); ++i) {
    out += json[i];
    if (json[i] == '<' && i + 1 < json.size() && json[i + 1] == '/') out += '\\';
  }
  return out;
}

// The template with each marker replaced by its value. Markers are found in the template
// alone (each exactly once), so nothing in a value, a path say, can be taken for one.
std::string fill(std::string_view page, const std::vector<std::pair<std::string_view, const std::string*>>& values) {
  std::vector<std::pair<std::size_t, std::size_t>> at;  // (position in page, index in values)
  for (std::size_t k = 0; k < values.size(); ++k) {
    const std::size_t first = page.find(values[k].first);
    if (first == std::string_view::npos || page.find(values[k].first, first + 1) != std::string_view::npos)
      throw io::Error("report.html: the embedded template must hold " + std::string(values[k].first) +
                      " exactly once");
    at.emplace_back(first, k);
  }
  std::sort(at.begin(), at.end());
  std::string out;
  std::size_t from = 0;
  for (const auto& [position, k] : at) {
    out.append(page.substr(from, position - from));
    out += *values[k].second;
    from = position + values[k].first.size();
  }
  out.append(page.substr(from));
  return out;
}

}  // namespace

void write_report_html(const fs::path& path, const RunInfo& run, const std::vector<Patch>& patches,
                       const Mesh& mesh, const std::vector<int>& vertex_patch) {
  Json data;
  data["format"] = "flank-report/1";
  data["command"] = run.command;
  data["input"] = Json{{"path", run.input_path},
                       {"bytes", run.input_bytes},
                       {"format", run.input_format},
                       {"vertices", run.vertices},
                       {"triangles", run.triangles},
                       {"bbox_diagonal", finite_or_null(run.bbox_diagonal)}};
  data["tolerance"] = finite_or_null(run.tolerance);
  Json curve = Json::array();
  for (double c : run.coverage_curve) curve.push_back(finite_or_null(c));
  Json regions = Json::array();
  for (const RunInfo::Region& r : run.uncovered)
    regions.push_back(Json{{"area", finite_or_null(r.area)},
                           {"centroid", Json::array({finite_or_null(r.centroid.x()), finite_or_null(r.centroid.y()), finite_or_null(r.centroid.z())})},
                           {"vertices", r.vertices}});
  data["coverage"] = Json{{"fraction", finite_or_null(run.coverage_fraction)},
                          {"total_area", finite_or_null(run.total_area)},
                          {"uncovered_area", finite_or_null(run.uncovered_area)},
                          {"curve", std::move(curve)},
                          {"regions", std::move(regions)}};
  data["settings"] = Json::parse(settings_json(run.settings));
  Json timing = Json::object();
  for (const auto& [name, seconds] : run.timing_s) timing[name] = finite_or_null(seconds);
  data["timing_s"] = std::move(timing);
  Json palette = Json::array();
  for (const Rgb& c : kPalette) palette.push_back(hex(c));
  data["palette"] = std::move(palette);
  data["uncovered_colour"] = hex(kUncovered);
  data["design"] = design_json(path, mesh, vertex_patch);
  // Ω's vertices in the page, over all patches: about the design's, and never fewer than
  // kEnvelopeVertices, so that the page stays small and quick to open (issue 12) while Ω
  // keeps a sample at least every few rulings.
  long long envelope_vertices = 0;
  for (const Patch& p : patches) envelope_vertices += p.envelope.V.rows();
  const long long budget = std::max<long long>(kEnvelopeVertices, mesh.vertex_count());
  Json list = Json::array();
  for (std::size_t k = 0; k < patches.size(); ++k) {
    // What this patch adds to the coverage: the step of the curve, or its own fraction (fit).
    double adds = patches[k].coverage_fraction;
    if (k < run.coverage_curve.size()) adds = run.coverage_curve[k] - (k > 0 ? run.coverage_curve[k - 1] : 0.0);
    // Each patch's share of the budget follows its own size.
    const long long share = envelope_vertices > budget
                                ? std::max<long long>(64, budget * patches[k].envelope.V.rows() / envelope_vertices)
                                : 0;
    list.push_back(patch_json(patches[k], adds, share));
  }
  data["patches"] = std::move(list);

  const std::string style(html_assets::kStyle), script(html_assets::kScript);
  const std::string json = script_safe(data.dump(-1, ' ', false, Json::error_handler_t::replace));
  const std::string page =
      fill(html_assets::kTemplate, {{"/*FLANK_STYLE*/", &style}, {"/*FLANK_DATA*/", &json}, {"/*FLANK_SCRIPT*/", &script}});
  io::write_file_atomic(path, [&](std::ostream& out) { out << page; });
}

}  // namespace flank::report
