// Writers of results: patches.json (flank-patches/1), envelopes.ply, design.ply, toolpath.apt.
// Every file goes through write_file_atomic; every byte is deterministic (fixed formats, no
// locale-dependent or pointer-dependent output).
#include "report/write.h"
#include "report/palette.h"
#include "report/write_step.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>

#include "io/encode.h"
#include "io/read_mesh.h"
#include "io/write_mesh.h"
#include "kernels/cutter.h"

namespace flank::report {
namespace {

namespace fs = std::filesystem;
using io::Bytes;
using io::Error;
using io::fixed6;
using io::shortest;
using io::write_file_atomic;
using Json = nlohmann::ordered_json;

[[noreturn]] void fail(const fs::path& path, const std::string& problem) {
  throw Error(path.string() + ": " + problem);
}

void append_faces(Bytes& b, const Faces& F, int offset) {
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    b.u8(3);
    for (int k = 0; k < 3; ++k) b.i32(F(f, k) + offset);
  }
}

Json number(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

Json point(const Eigen::Ref<const Eigen::RowVector3d>& p) {
  return Json::array({number(p(0)), number(p(1)), number(p(2))});
}

Json points(const Points& P) {
  Json out = Json::array();
  for (Eigen::Index i = 0; i < P.rows(); ++i) out.push_back(point(P.row(i)));
  return out;
}

Json setting_value(const SettingValue& value) {
  return std::visit(
      [](const auto& v) -> Json {
        using T = std::decay_t<decltype(v)>;
        if constexpr (std::is_same_v<T, double>) {
          return number(v);
        } else if constexpr (std::is_same_v<T, std::vector<double>>) {
          Json out = Json::array();
          for (double x : v) out.push_back(number(x));
          return out;
        } else {
          return Json(v);
        }
      },
      value);
}

// The cutter's coefficients must match its kind before radius() may be evaluated.
void check_cutter(const fs::path& path, const Patch& patch) {
  const Cutter& c = patch.cutter;
  if (c.coeffs.size() != coefficient_count(c.kind))
    fail(path, "patch " + std::to_string(patch.id) + ": a " + std::string(to_string(c.kind)) +
                   " cutter needs " + std::to_string(coefficient_count(c.kind)) +
                   " coefficients, it has " + std::to_string(c.coeffs.size()));
}

constexpr int kRadiusSamples = 101;

Json tool_json(const Cutter& c) {
  Json s = Json::array(), d = Json::array(), profile = Json::array(), coefficients = Json::array();
  for (int i = 0; i < kRadiusSamples; ++i) {
    const double t = i / static_cast<double>(kRadiusSamples - 1);
    s.push_back(number(t));
    d.push_back(number(c.radius(t)));
    if (c.length > 0 && std::isfinite(c.length)) {
      const Vec2 m = c.meridian(t);
      profile.push_back(Json::array({number(m(0)), number(m(1))}));
    } else {
      profile.push_back(Json::array({nullptr, nullptr}));
    }
  }
  for (Eigen::Index k = 0; k < c.coeffs.size(); ++k) coefficients.push_back(number(c.coeffs(k)));
  Json tool;
  tool["kind"] = std::string(to_string(c.kind));
  tool["length"] = number(c.length);
  tool["radii"] = Json{{"s", std::move(s)}, {"d", std::move(d)}};
  tool["coefficients"] = std::move(coefficients);
  tool["profile"] = std::move(profile);
  return tool;
}

Json patch_json(const Patch& p) {
  Json out;
  out["id"] = p.id;
  out["tool"] = tool_json(p.cutter);
  Json motion;
  motion["degree"] = 3;
  Json knots = Json::array();
  for (double k : p.motion.knots) knots.push_back(number(k));
  motion["knots"] = std::move(knots);
  motion["a"] = points(p.motion.a);
  motion["b"] = points(p.motion.b);
  out["motion"] = std::move(motion);
  out["tip"] = std::string(1, p.tip);
  out["error"] = Json{{"max", number(p.error.max)},
                      {"rms", number(p.error.rms)},
                      {"max_gouge", number(p.error.max_gouge)},
                      {"max_relative", number(p.error.max_relative)}};
  out["coverage"] = Json{{"area", number(p.covered_area)}, {"fraction", number(p.coverage_fraction)}};
  Json collision;
  collision["holder_clear"] = p.collision.holder_clear;
  collision["min_clearance"] =
      p.collision.checked ? number(p.collision.min_clearance) : Json(nullptr);
  collision["holder"] = p.collision.checked ? Json::array({number(p.collision.holder_length),
                                                           number(p.collision.holder_radius)})
                                            : Json(nullptr);
  out["collision"] = std::move(collision);
  return out;
}

// Diverging map over ±tolerance: gouge (e < 0) red, material left (e > 0) blue, white at 0.
std::array<std::uint8_t, 3> error_colour(double e, double tolerance) {
  if (!std::isfinite(e)) return {128, 128, 128};
  const double t = std::abs(e) >= tolerance ? 1.0 : std::abs(e) / tolerance;
  const auto fade = static_cast<std::uint8_t>(std::lround(255.0 * (1.0 - t)));
  if (e < 0) return {255, fade, fade};
  return {fade, fade, 255};
}


void check_motion(const fs::path& path, const Patch& p) {
  const Motion& m = p.motion;
  if (m.count() < 4 || m.b.rows() != m.a.rows() ||
      m.knots.size() != static_cast<std::size_t>(m.count() + 4))
    fail(path, "patch " + std::to_string(p.id) + " has no valid cubic motion (" +
                   std::to_string(m.count()) + " control points, " +
                   std::to_string(m.knots.size()) + " knots)");
  if (p.tip != 'a' && p.tip != 'b')
    fail(path, "patch " + std::to_string(p.id) + " has tip '" + io::one_line(std::string(1, p.tip)) +
                   "' (expected a or b)");
}

// The real tool as a post-processor sees it, in the tool's own frame: w is the distance along
// the unit axis from the tip-end axis point (a(t) for tip a, b(t) for tip b) toward the spindle.
// Sphere s (centre at z = sL from a, radius d(s)) touches the tool's surface on the circle
// z(s) = sL − d(s) d′(s)/L, r(s) = d √(1 − (d′/L)²) (Cutter::meridian), so the cutting surface
// runs from z(0) to z(1), and the end face, where a machine expects the tool tip, is the circle
// of the tip-end sphere: w = z(0) = −d(0) d′(0)/L for tip a, w = L − z(1) = d(1) d′(1)/L for
// tip b. The CL point is the tip-end axis point + w_face · axis.
//
// CUTTER/ is the cone through the real profile's two end circles: the diameter at the end face
// (APT's d), the flute length h and the CL point are then those of the real tool, exactly what
// a tool setter measures and a machine positions, and only the side between the ends deviates
// (by the barrel's bulge or the spline's waves). For a cylinder and a cone the meridian is that
// line, so CUTTER/ is exact. A least-squares cone would lower the side's largest deviation (to
// about two thirds for a symmetric barrel) but move the end-face diameter off the real tool.
struct AptTool {
  double face = 0.0;          // w of the end face (the CL point's offset along the axis)
  double diameter = 0.0;      // APT d: the diameter at the end face
  double taper = 0.0;         // APT beta in degrees, + when the tool widens toward the spindle
  double flutes = 0.0;        // APT h: w(spindle end of the profile) − w(end face)
  double inside = 0.0;        // max of (cone − real radius) at equal w: the real tool inside
  double outside = 0.0;       // max of (real − cone radius) at equal w: the real tool outside
};

constexpr int kAptDeviationSamples = 1001;

AptTool apt_tool(const Cutter& c, char tip) {
  const Vec2 tip_end = c.meridian(tip == 'a' ? 0.0 : 1.0);
  const Vec2 far_end = c.meridian(tip == 'a' ? 1.0 : 0.0);
  const auto w = [&](const Vec2& m) { return tip == 'a' ? m(0) : c.length - m(0); };
  AptTool t;
  t.face = w(tip_end);
  t.flutes = w(far_end) - t.face;
  t.diameter = 2.0 * tip_end(1);
  const double slope = (far_end(1) - tip_end(1)) / t.flutes;
  t.taper = std::atan(slope) * 180.0 / std::numbers::pi;
  for (int i = 0; i < kAptDeviationSamples; ++i) {
    const Vec2 m = c.meridian(i / static_cast<double>(kAptDeviationSamples - 1));
    const double deviation = m(1) - (tip_end(1) + slope * (w(m) - t.face));
    t.outside = std::max(t.outside, deviation);
    t.inside = std::max(t.inside, -deviation);
  }
  return t;
}

}  // namespace

std::string settings_json(const std::vector<Setting>& settings) {
  Json out = Json::object();
  for (const Setting& s : settings) out[s.key] = setting_value(s.value);
  return out.dump(-1, ' ', false, Json::error_handler_t::replace);
}

void write_patches_json(const fs::path& path, const RunInfo& run, const std::vector<Patch>& patches) {
  for (const Patch& p : patches) check_cutter(path, p);
  Json root;
  root["format"] = "flank-patches/1";
  root["units"] = "mm";
  root["input"] = Json{{"path", run.input_path},
                       {"vertices", run.vertices},
                       {"triangles", run.triangles},
                       {"bbox_diagonal", number(run.bbox_diagonal)}};
  root["settings"] = Json::parse(settings_json(run.settings));
  Json curve = Json::array();
  for (double c : run.coverage_curve) curve.push_back(number(c));
  Json regions = Json::array();
  for (const RunInfo::Region& r : run.uncovered)
    regions.push_back(Json{{"area", number(r.area)}, {"centroid", point(r.centroid.transpose())}, {"vertices", r.vertices}});
  root["coverage"] = Json{{"fraction", number(run.coverage_fraction)},
                          {"tolerance", number(run.tolerance)},
                          {"uncovered_area", number(run.uncovered_area)},
                          {"curve", std::move(curve)},
                          {"uncovered_regions", std::move(regions)}};
  Json timing = Json::object();
  for (const auto& [name, seconds] : run.timing_s) timing[name] = number(seconds);
  root["timing_s"] = std::move(timing);
  Json list = Json::array();
  for (std::size_t k = 0; k < patches.size(); ++k) {
    Json patch = patch_json(patches[k]);
    // patches.step's B-spline face of this patch and its measured deviation from the exact Ω.
    if (k < run.nurbs.size()) {
      const RunInfo::Face& f = run.nurbs[k];
      const bool written = std::isfinite(f.deviation);
      patch["nurbs"] = Json{{"file", "patches.step"},
                            {"face", written ? Json(face_name(patches[k])) : Json(nullptr)},
                            {"max_deviation", number(f.deviation)},
                            // The face's own parameters are (t, s) over this range: where the motion
                            // starts or ends with a stall, Ω does not exist and the face stops short.
                            {"t_range", written ? Json{f.t0, f.t1} : Json(nullptr)},
                            {"s_range", written ? Json{f.s0, f.s1} : Json(nullptr)}};
    }
    list.push_back(std::move(patch));
  }
  root["patches"] = std::move(list);
  // Invalid UTF-8 in a path or setting is replaced rather than thrown.
  const std::string text = root.dump(1, ' ', false, Json::error_handler_t::replace) + "\n";
  write_file_atomic(path, [&](std::ostream& out) { out << text; });
}

void write_envelopes_ply(const fs::path& path, const std::vector<Patch>& patches, double tolerance) {
  long long vertices = 0, faces = 0;
  for (const Patch& p : patches) {
    vertices += p.envelope.V.rows();
    faces += p.envelope.F.rows();
  }
  if (vertices > std::numeric_limits<int>::max() || faces > std::numeric_limits<int>::max())
    fail(path, "envelopes too large for a PLY file with int indices");
  // Without a usable tolerance, saturate at the largest |e| present.
  if (!(tolerance > 0) || !std::isfinite(tolerance)) {
    tolerance = 0.0;
    for (const Patch& p : patches)
      for (Eigen::Index i = 0; i < p.envelope.error.size(); ++i)
        if (std::isfinite(p.envelope.error(i)))
          tolerance = std::max(tolerance, std::abs(p.envelope.error(i)));
    if (!(tolerance > 0)) tolerance = 1.0;
  }
  Bytes b;
  b.text("ply\nformat binary_little_endian 1.0\n"
         "comment flank envelopes: signed error e (e > 0 material left, e < 0 gouge)\n"
         "comment colour: red gouge, white 0, blue material left, saturated at +-" +
         shortest(tolerance) + "\nelement vertex " + std::to_string(vertices) +
         "\nproperty float x\nproperty float y\nproperty float z\nproperty float error\n"
         "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty int patch\n"
         "element face " + std::to_string(faces) +
         "\nproperty list uchar int vertex_indices\nend_header\n");
  // A vertex: x, y, z, error (float), red, green, blue (uchar), patch (int); a face: 3, then
  // three ints.
  b.reserve(static_cast<std::size_t>(vertices) * 23 + static_cast<std::size_t>(faces) * 13);
  for (const Patch& p : patches) {
    const EnvelopeMesh& env = p.envelope;
    for (Eigen::Index i = 0; i < env.V.rows(); ++i) {
      const double e = i < env.error.size() ? env.error(i) : std::numeric_limits<double>::quiet_NaN();
      for (int k = 0; k < 3; ++k) b.f32(env.V(i, k));
      b.f32(e);
      for (std::uint8_t c : error_colour(e, tolerance)) b.u8(c);
      b.i32(p.id);
    }
  }
  int offset = 0;
  for (const Patch& p : patches) {
    append_faces(b, p.envelope.F, offset);
    offset += static_cast<int>(p.envelope.V.rows());
  }
  write_file_atomic(path, std::move(b).take());
}

void write_design_ply(const fs::path& path, const Mesh& mesh, const std::vector<int>& vertex_patch) {
  if (vertex_patch.size() != static_cast<std::size_t>(mesh.vertex_count()))
    fail(path, "vertex_patch has " + std::to_string(vertex_patch.size()) + " entries for " +
                   std::to_string(mesh.vertex_count()) + " vertices");
  Bytes b;
  b.text("ply\nformat binary_little_endian 1.0\n"
         "comment flank design surface: patch = covering patch id, -1 uncovered (magenta)\n"
         "element vertex " + std::to_string(mesh.vertex_count()) +
         "\nproperty float x\nproperty float y\nproperty float z\n"
         "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty int patch\n"
         "element face " + std::to_string(mesh.face_count()) +
         "\nproperty list uchar int vertex_indices\nend_header\n");
  for (int v = 0; v < mesh.vertex_count(); ++v) {
    for (int k = 0; k < 3; ++k) b.f32(mesh.V(v, k));
    const int id = vertex_patch[v];
    for (std::uint8_t c : patch_colour(id)) b.u8(c);
    b.i32(id < 0 ? -1 : id);
  }
  append_faces(b, mesh.F, 0);
  write_file_atomic(path, std::move(b).take());
}

void write_toolpath_apt(const fs::path& path, const std::vector<Patch>& patches,
                        int steps_per_patch, const std::string& part_name) {
  if (steps_per_patch < 1)
    fail(path, "steps per patch must be at least 1 (got " + std::to_string(steps_per_patch) + ")");
  const std::string name = part_name.empty() ? std::string("FLANK") : io::one_line(part_name);
  std::string s;
  s += "$$ flank toolpath - part " + name + ", " + std::to_string(patches.size()) + " patches\n";
  s += "$$ units mm; GOTO/x,y,z,i,j,k = centre of the cutter's end face (CL point), unit tool axis "
       "toward the spindle\n";
  s += "$$ no approach or retract moves between patches: the post-processor adds them\n";
  s += "PARTNO/" + name + "\n";
  s += "UNITS/MM\n";
  for (const Patch& p : patches) {
    check_cutter(path, p);
    check_motion(path, p);
    const Cutter& c = p.cutter;
    const std::string id = std::to_string(p.id);
    if (!(c.length > 0) || !std::isfinite(c.length))
      fail(path, "patch " + id + " has a cutter of length " + fixed6(c.length));
    const AptTool tool = apt_tool(c, p.tip);
    if (!std::isfinite(tool.face) || !(tool.diameter > 0) || !(tool.flutes > 0) ||
        !std::isfinite(tool.taper))
      fail(path, "patch " + id + ": the cutter has no usable profile (end face at " +
                     fixed6(tool.face) + ", diameter " + fixed6(tool.diameter) +
                     ", flute length " + fixed6(tool.flutes) + ")");
    s += "$$ patch " + id + ": " + std::string(to_string(c.kind)) + " cutter, length " +
         fixed6(c.length) + ", tip at " + p.tip + "(t), end face (CL point) " + fixed6(tool.face) +
         " from " + p.tip + "(t) along the axis\n";
    s += "$$ sphere radii d(0)=" + fixed6(c.radius(0.0)) + ", d(0.5)=" + fixed6(c.radius(0.5)) +
         ", d(1)=" + fixed6(c.radius(1.0)) + "\n";
    std::string coefficients;
    for (Eigen::Index k = 0; k < c.coeffs.size(); ++k)
      coefficients += (k ? ", " : "") + fixed6(c.coeffs(k));
    s += "$$ coefficients: " + coefficients + "\n";
    std::string meridian;
    for (int i = 0; i <= 4; ++i) {
      const Vec2 m = c.meridian(i / 4.0);
      meridian += " (" + fixed6(m(0)) + ", " + fixed6(m(1)) + ")";
    }
    s += "$$ meridian (z from a, r):" + meridian + "\n";
    s += "$$ error max " + fixed6(p.error.max) + ", rms " + fixed6(p.error.rms) + ", max gouge " +
         fixed6(p.error.max_gouge) + "\n";
    if (c.kind == CutterKind::barrel || c.kind == CutterKind::spline) {
      s += "$$ patch " + id + ": CUTTER/ is the cone through the profile's end circles; the real " +
           "profile deviates from it radially by up to " +
           fixed6(std::max(tool.inside, tool.outside)) + " mm (outside by up to " +
           fixed6(tool.outside) + ", inside by up to " + fixed6(tool.inside) + ")\n";
      s += "$$ patch " + id + ": exact profile: tools.step solid P" + id +
           "-tool, patches.json patches[" + std::to_string(&p - patches.data()) +
           "].tool.profile (z from a, r)\n";
    }
    s += "CUTTER/" + fixed6(tool.diameter) + ",0.000000,0.000000,0.000000,0.000000," +
         fixed6(tool.taper) + "," + fixed6(tool.flutes) + "\n";
    s += "MULTAX/ON\n";
    for (int i = 0; i <= steps_per_patch; ++i) {
      const double t = i / static_cast<double>(steps_per_patch);
      const Vec3 a = p.motion.a_at(t), b = p.motion.b_at(t);
      const Vec3 tip = p.tip == 'a' ? a : b;
      const Vec3 toward = p.tip == 'a' ? Vec3(b - a) : Vec3(a - b);
      const double length = toward.norm();
      if (!tip.allFinite() || !std::isfinite(length) || !(length > 0))
        fail(path, "patch " + id + " has no tool axis at t = " + fixed6(t));
      const Vec3 axis = toward / length;
      const Vec3 cl = tip + tool.face * axis;
      s += "GOTO/" + fixed6(cl(0)) + "," + fixed6(cl(1)) + "," + fixed6(cl(2)) + "," +
           fixed6(axis(0)) + "," + fixed6(axis(1)) + "," + fixed6(axis(2)) + "\n";
    }
  }
  s += "FINI\n";
  write_file_atomic(path, [&](std::ostream& out) { out << s; });
}

}  // namespace flank::report
