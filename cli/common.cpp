#include "cli/common.h"

#include <CLI/CLI.hpp>
#include <filesystem>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <exception>
#include <fstream>
#include <sstream>
#include <vector>

#include "io/cad.h"
#include "kernels/parallel.h"
#include "report/write_html.h"
#include "report/write_step.h"
#include "io/read_lines.h"

namespace flank::cli {

namespace {
// The most triangles a STEP/IGES tessellation may be refined to: the ladder's largest rung.
// Beyond it a tolerance asks for more than the rest of flank is built for, and OCCT's time
// and memory grow faster than its meshes on some faces (a fitted face of patches.step: 33 s
// and 1 GB for 80k triangles); refusing beats running out of memory (the old halving reached
// 21 GB on tools.step).
constexpr double kMaxCadTriangles = 1e6;

// A plain decimal number: digits with an optional point and exponent. strtod would also take
// hexadecimal ("0x10" = 16), "inf" and "nan", none of which a length written by a person is.
bool is_decimal(const std::string& t) {
  std::size_t i = 0, digits = 0;
  if (i < t.size() && (t[i] == '+' || t[i] == '-')) ++i;
  for (; i < t.size() && std::isdigit(static_cast<unsigned char>(t[i])); ++i) ++digits;
  if (i < t.size() && t[i] == '.')
    for (++i; i < t.size() && std::isdigit(static_cast<unsigned char>(t[i])); ++i) ++digits;
  if (digits == 0) return false;
  if (i < t.size() && (t[i] == 'e' || t[i] == 'E')) {
    ++i;
    if (i < t.size() && (t[i] == '+' || t[i] == '-')) ++i;
    std::size_t exp_digits = 0;
    for (; i < t.size() && std::isdigit(static_cast<unsigned char>(t[i])); ++i) ++exp_digits;
    if (exp_digits == 0) return false;
  }
  return i == t.size();
}

// Numbers separated by commas (or blanks); an empty item ("1,,2", "1,") is an error, not
// skipped: a value left out by mistake must not shift the others.
std::vector<double> parse_numbers(const std::string& text, const std::string& option) {
  std::vector<double> out;
  std::string item;
  std::istringstream items(text);
  while (std::getline(items, item, ',')) {
    std::istringstream in(item);
    std::string token;
    int tokens = 0;
    while (in >> token) {
      ++tokens;
      const double v = is_decimal(token) ? std::strtod(token.c_str(), nullptr) : NAN;
      if (!std::isfinite(v)) throw UsageError(option + ": '" + token + "' is not a finite decimal number");
      out.push_back(v);
    }
    if (tokens == 0) throw UsageError(option + ": an empty value between commas in '" + text + "'");
  }
  if (!text.empty() && text.back() == ',') throw UsageError(option + ": a trailing comma in '" + text + "'");
  return out;
}

// Runs `f`; what it throws is kept in `failed`, for the caller to rethrow in its own order.
void capture(std::exception_ptr& failed, const std::function<void()>& f) {
  try {
    f();
  } catch (...) {
    failed = std::current_exception();
  }
}

}  // namespace

Line parse_line(const std::string& text, const std::string& option) {
  const std::vector<double> v = parse_numbers(text, option);
  if (v.size() != 6) throw UsageError(option + " takes six numbers x0,y0,z0,x1,y1,z1");
  Line l{Vec3(v[0], v[1], v[2]), Vec3(v[3], v[4], v[5])};
  if (!(l.length() > 0)) throw UsageError(option + ": the two endpoints coincide");
  return l;
}

std::pair<double, double> parse_pair(const std::string& text, const std::string& option) {
  const std::vector<double> v = parse_numbers(text, option);
  if (v.size() != 2) throw UsageError(option + " takes two numbers A,B");
  if (!(v[0] > 0 && v[1] > 0)) throw UsageError(option + ": both values must be positive");
  return {v[0], v[1]};
}

std::vector<Line> read_lines_file(const std::string& path) {
  std::vector<Line> lines;
  for (const io::AxisRow& row : io::read_lines_file(path)) lines.push_back({row.a, row.b});
  return lines;
}

std::string printable(const std::string& text) {
  std::string out;
  for (const char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (u == '\n') {
      out += "\\n";
    } else if (u < 0x20 || u == 0x7f) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02x", u);
      out += hex;
    } else {
      out += c;
    }
  }
  return out;
}

void set_action(CLI::App* cmd, int* exit_code, std::function<int()> run) {
  cmd->callback([cmd, exit_code, run = std::move(run)]() {
    try {
      // An option given an empty value ('--holder ""') is a mistake, not "not given".
      for (const CLI::Option* opt : cmd->get_options())
        if (opt->get_expected_min() > 0)
          for (const std::string& value : opt->results())
            if (value.empty()) throw UsageError(opt->get_name() + ": empty value");
      *exit_code = run();
    } catch (const std::exception& e) {
      std::fprintf(stderr, "flank %s: %s\n", cmd->get_name().c_str(), printable(e.what()).c_str());
      *exit_code = 2;
    } catch (...) {
      std::fprintf(stderr, "flank %s: unexpected error\n", cmd->get_name().c_str());
      *exit_code = 2;
    }
    // A command that ends early (bad input, no patch) may end while the CAD module it preloaded
    // is still opening; exit must not destroy Open CASCADE's statics under that thread.
    io::settle_cad_module();
  });
}

Progress::Progress(std::string command, bool quiet)
    : command_(std::move(command)), quiet_(quiet), start_(std::chrono::steady_clock::now()) {}

double Progress::elapsed() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void Progress::stage(const std::string& what) {
  if (quiet_) return;
  std::fprintf(stderr, "[%6.2fs] flank %s: %s\n", elapsed(), command_.c_str(), printable(what).c_str());
  std::fflush(stderr);
}

double resolve_tolerance(std::optional<double> absolute, std::optional<double> relative,
                         double diagonal) {
  if (absolute && relative) throw UsageError("give --tolerance or --tolerance-rel, not both");
  if (absolute) {
    if (!(*absolute > 0) || !std::isfinite(*absolute))
      throw UsageError("--tolerance must be a positive length");
    return *absolute;
  }
  const double r = relative ? *relative : 1e-4;
  if (!(r > 0) || !(r < 1)) throw UsageError("--tolerance-rel must be in (0, 1)");
  return r * diagonal;
}

std::vector<int> parse_faces(const std::string& text) {
  std::vector<int> out;
  std::string item;
  std::istringstream items(text);
  auto number = [&](const std::string& t) {
    if (t.empty() || t.size() > 9 || !std::all_of(t.begin(), t.end(), [](char c) { return c >= '0' && c <= '9'; }))
      throw UsageError("--faces: '" + t + "' is not a face index (1, 2, … as flank info lists them)");
    const int v = std::stoi(t);
    if (v < 1) throw UsageError("--faces: face indices start at 1");
    return v;
  };
  while (std::getline(items, item, ',')) {
    const std::size_t dash = item.find('-');
    if (dash == std::string::npos) {
      out.push_back(number(item));
    } else {
      const int lo = number(item.substr(0, dash)), hi = number(item.substr(dash + 1));
      if (hi < lo || hi - lo > 1'000'000) throw UsageError("--faces: '" + item + "' is not a range LOW-HIGH");
      for (int f = lo; f <= hi; ++f) out.push_back(f);
    }
  }
  if (out.empty() || text.back() == ',') throw UsageError("--faces: an empty item in '" + text + "'");
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

namespace {
// The chosen faces tessellated with a chord deviation of at most a tenth of the tolerance,
// asking OCCT for 9% of it first. `asked` is the deflection the answer was asked with.
io::CadTessellation tessellate_within(const io::CadPart& part, const std::vector<int>& faces, double cad_tolerance,
                                      const io::ReadOptions& ro, const std::string& path, Progress& progress,
                                      double& asked) {
  const double bound = 0.1 * cad_tolerance;
  const auto refuse = [&](double predicted) {
    char text[160];
    std::snprintf(text, sizeof text, "a chord deviation under a tenth of the tolerance (%.3g mm) would take about %.3g",
                  bound, predicted);
    return io::Error(path + ": " + text + " triangles; pass a larger --tolerance or fewer --faces");
  };
  asked = 0.09 * cad_tolerance;
  // Looks first, from a thousandth of the faces' diagonal down by eighths to 8 times the
  // deflection: OCCT's meshes grow about as 1/deflection (11k, 21k, 45k, 80k triangles as it
  // halved on a fitted face of patches.step), so a tolerance far under what the faces need
  // would otherwise exhaust memory before anything is measured. Each look is predicted to fit
  // before it is made; OCCT's time grows faster than its meshes, so the looks cost little.
  const double diagonal = part.bounding_box(faces).diagonal();
  double look_at = 8 * asked;
  while (look_at * 8 <= 1e-3 * diagonal) look_at *= 8;
  for (; look_at >= 8 * asked; look_at /= 8) {
    const double predicted = part.tessellate(faces, look_at, ro).mesh.mesh.face_count() * (look_at / asked);
    if (predicted > kMaxCadTriangles) throw refuse(predicted);
  }
  io::CadTessellation t = part.tessellate(faces, asked, ro);
  // OCCT's deflection is a target, not a bound (on the fitted faces of HECC a's patches.step
  // the chord deviation measured 5 to 45 times the deflection asked). Over a tenth of the
  // tolerance, ask again, a few times at most, for the deflection scaled by the miss (with a
  // margin, and at least halved): halvings alone took four tessellations, each slower than the
  // last, where one scaled request meets the bound. The triangles grow about as the deflection
  // shrinks, so stop before a tessellation would outgrow what the rest can work with. A
  // request that does not help does not end the search: OCCT's deviation is not always
  // monotone in the deflection asked, and the next one may meet the tenth.
  for (int again = 0; again < 4 && std::isfinite(t.deviation) && t.deviation > bound; ++again) {
    const double next = asked * std::min(0.5, 0.7 * bound / t.deviation);
    const double predicted = t.mesh.mesh.face_count() * (asked / next);
    if (predicted > kMaxCadTriangles) throw refuse(predicted);
    progress.stage("tessellated " + std::to_string(t.mesh.mesh.face_count()) + " triangles, chord deviation " +
                   std::to_string(t.deviation) + " mm over " + std::to_string(bound) + " mm: again, asking " +
                   std::to_string(next) + " mm");
    asked = next;
    t = part.tessellate(faces, asked, ro);
  }
  if (!(t.deviation <= bound))
    throw io::Error(path + ": the tessellation's chord deviation stays at " + std::to_string(t.deviation) +
                    " mm, over a tenth of the tolerance (" + std::to_string(bound) + " mm)");
  return t;
}
}  // namespace

Design read_design(const PatchArgs& a, Progress& progress, bool count_components) {
  Design d;
  io::ReadOptions ro;
  ro.flip = a.flip;
  ro.count_components = count_components;
  if (!io::is_cad_path(a.mesh)) {
    if (!a.faces.empty()) throw UsageError("--faces picks faces of a STEP or IGES file; " + a.mesh + " is a mesh");
    d.lm = io::read_mesh(a.mesh, ro);
    progress.stage("read " + std::to_string(d.lm.mesh.vertex_count()) + " vertices, " +
                   std::to_string(d.lm.mesh.face_count()) + " triangles");
    d.tolerance = resolve_tolerance(a.tolerance, a.tolerance_rel, bounding_box(d.lm.mesh).diagonal());
    return d;
  }
  d.cad = true;
  if (!a.faces.empty()) d.faces = parse_faces(a.faces);
  d.part = std::make_shared<const io::CadPart>(io::CadPart::read(a.mesh));
  const io::CadPart& part = *d.part;
  part.check_faces(d.faces);
  if (d.faces.empty())
    for (const io::CadFace& f : part.faces()) d.faces.push_back(f.index);
  progress.stage("read " + part.format() + ": " + std::to_string(part.faces().size()) + " faces, using " +
                 std::to_string(d.faces.size()));
  // The tolerance follows the B-rep's diagonal; the tessellation asks for 9% of it, so that the
  // tenth still holds against the (slightly smaller) diagonal of the mesh.
  const double cad_tolerance = resolve_tolerance(a.tolerance, a.tolerance_rel, part.bounding_box(d.faces).diagonal());
  io::CadTessellation t = tessellate_within(part, d.faces, cad_tolerance, ro, a.mesh, progress, d.chord_target);
  d.lm = std::move(t.mesh);
  d.chord_deviation = t.deviation;
  d.tolerance = resolve_tolerance(a.tolerance, a.tolerance_rel, bounding_box(d.lm.mesh).diagonal());
  progress.stage("tessellated " + std::to_string(t.faces) + " faces: " + std::to_string(d.lm.mesh.vertex_count()) +
                 " vertices, " + std::to_string(d.lm.mesh.face_count()) + " triangles, chord deviation " +
                 std::to_string(d.chord_deviation) + " mm");
  return d;
}

void add_design_settings(const Design& d, std::vector<report::Setting>& settings) {
  settings.push_back({"input_format", d.lm.report.format});
  if (!d.cad) return;
  std::vector<double> faces(d.faces.begin(), d.faces.end());
  settings.push_back({"faces", faces});
  settings.push_back({"chord_deviation", d.chord_deviation});
  settings.push_back({"chord_deviation_target", d.chord_target});
}

void add_patch_options(CLI::App* cmd, PatchArgs& a) {
  cmd->add_option("MESH", a.mesh, "Design surface: STL, OBJ or PLY mesh, or STEP/IGES B-rep")->required();
  cmd->add_option("--faces", a.faces,
                  "STEP/IGES only: the faces to machine, by index as flank info lists them (e.g. 1,3,7-9; default all)");
  cmd->add_option("-o,--output", a.out_dir, "Folder for report.html, patches.json, envelopes.ply, design.ply, toolpath.apt, patches.step, tools.step")
      ->required();
  cmd->add_option("--tolerance", a.tolerance, "Allowed error in mm");
  cmd->add_option("--tolerance-rel", a.tolerance_rel,
                  "Allowed error as a fraction of the bounding-box diagonal (default 1e-4)");
  cmd->add_option("--holder", a.holder,
                  "Check the holder: LEN,RADIUS of a cylinder beyond the cutter's spindle end, in mm");
  cmd->add_option("--threads", a.threads, "Worker threads (default: all cores)")->check(CLI::Range(1, 1024));
  cmd->add_option("--apt-steps", a.apt_steps, "GOTO steps per patch in toolpath.apt (default 200)")
      ->check(CLI::Range(2, 1000000));
  cmd->add_flag("--no-report", a.no_report, "Do not write report.html (an earlier run's report.html is removed)");
  cmd->add_flag("--flip", a.flip, "Reverse the surface orientation (tools live on the normals' side)");
  cmd->add_flag("-q,--quiet", a.quiet, "No progress lines on stderr");
}

std::string results_line(const PatchArgs& a) {
  std::string line = "results in " + printable(a.out_dir) + ":";
  for (const std::string& n : output_names(a)) line += " " + n;
  return line;
}

std::vector<std::string> output_names(const PatchArgs& a) {
  std::vector<std::string> names{"patches.json", "envelopes.ply", "design.ply", "toolpath.apt", "patches.step",
                                 "tools.step"};
  if (!a.no_report) names.insert(names.begin(), "report.html");
  return names;
}

std::unique_ptr<io::OutputSet> open_outputs(const PatchArgs& a) {
  // Under --no-report an earlier run's report.html would describe another run: it goes.
  return std::make_unique<io::OutputSet>(a.out_dir, output_names(a),
                                         a.no_report ? std::vector<std::string>{"report.html"}
                                                     : std::vector<std::string>{});
}

void write_outputs(io::OutputSet& out, const PatchArgs& a, const Design& design, report::RunInfo run,
                   const std::vector<Patch>& patches, const Mesh& mesh,
                   const std::vector<int>& vertex_patch, double tolerance) {
  run.input_path = a.mesh;
  run.input_format = design.lm.report.format;
  std::error_code ec;
  const std::uintmax_t bytes = std::filesystem::file_size(std::filesystem::path(a.mesh), ec);
  run.input_bytes = ec ? -1 : static_cast<long long>(bytes);
  // The files are independent but for patches.json, which records patches.step's fitted
  // faces: Open CASCADE's two writers and then patches.json run as one chain (OCCT's writers
  // share global settings), each of our own writers beside it. Each file's bytes do not depend
  // on which runs first; a failure is reported as the first failing file in this order.
  const report::RunInfo before_step = run;
  const std::string stem = std::filesystem::path(a.mesh).stem().string();
  const std::vector<std::function<void()>> writers{
      [&] {
        // patches.step's faces are fitted (flank's own work) while the CAD module is waited for
        // and tools.step written: on one patch the fit is most of this chain. Errors in the
        // chain's order: the module (the one line names the file a user asked for, not its
        // staged copy), patches.step, tools.step.
        std::exception_ptr no_module, fit_failed, tools_failed;
        std::vector<report::PatchFace> faces;
        run_beside(
            [&] {
              capture(no_module, [&] {
                io::require_cad_module((std::filesystem::path(a.out_dir) / "patches.step").string());
              });
              if (!no_module) capture(tools_failed, [&] { report::write_tools_step(out.staged("tools.step"), patches); });
            },
            [&] {
              capture(fit_failed, [&] {
                faces = report::fit_patch_faces(out.staged("patches.step").string(), patches, tolerance);
              });
            });
        for (const std::exception_ptr& e : {no_module, fit_failed})
          if (e) std::rethrow_exception(e);
        for (const report::WrittenFace& f : report::write_patches_step(out.staged("patches.step"), patches, faces))
          run.nurbs.push_back({f.deviation, f.domain.t0, f.domain.t1, f.domain.s0, f.domain.s1});
        if (tools_failed) std::rethrow_exception(tools_failed);
        report::write_patches_json(out.staged("patches.json"), run, patches);
      },
      [&] {
        if (!a.no_report)
          report::write_report_html(out.staged("report.html"), before_step, patches, mesh, vertex_patch);
      },
      [&] { report::write_envelopes_ply(out.staged("envelopes.ply"), patches, tolerance); },
      [&] { report::write_design_ply(out.staged("design.ply"), mesh, vertex_patch); },
      [&] { report::write_toolpath_apt(out.staged("toolpath.apt"), patches, a.apt_steps, stem); },
  };
  std::vector<std::exception_ptr> failed(writers.size());
  parallel_invoke_each(writers.size(), [&](std::size_t k) { capture(failed[k], writers[k]); });
  for (const std::exception_ptr& e : failed)
    if (e) std::rethrow_exception(e);
  out.commit();
}

}  // namespace flank::cli
