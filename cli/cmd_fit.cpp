// flank fit: one patch from a user's start — a single line (line-driven, paper §4.2–4.3) or
// ordered lines (surface-driven, §4.4) — fitted, trimmed, evaluated and written out.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstdlib>
#include <optional>

#include "cli/commands.h"
#include "cli/common.h"
#include "io/read_mesh.h"
#include "report/write.h"
#include "kernels/parallel.h"
#include "solver/evaluate_patch.h"
#include "solver/propagate.h"
#include "solver/trim.h"

namespace flank::cli {

namespace {

// Allowed sphere radii when --radius is not given, as fractions of Φ's bbox diagonal: the
// same range as decompose's.
constexpr double kDefaultRadiusMin = 0.01;
constexpr double kDefaultRadiusMax = 0.10;
// The shortest --line accepted, as a fraction of the diagonal.
constexpr double kMinLine = 1e-3;
// The fit's sample grid, at most: 2,000 × 200 samples already resolve a sweep far finer than
// any tolerance, and the Jacobian of a larger grid would not fit in memory.
constexpr int kMaxSamplesT = 2000, kMaxSamplesS = 200;

struct FitArgs : PatchArgs {
  std::string line, lines_file, tool = "cone", radius;
  int control_points = 40, samples_t = 100, samples_s = 30;
};

// Most axis samples behind Φ's faces means the normals point away from the tool.
void check_side(const SurfaceIndex& index, const Motion& motion) {
  int behind = 0, inside = 0;
  for (int i = 0; i < 21; ++i) {
    const ClosestPoint f = index.closest_point(motion.point(i / 20.0, 0.5));
    if (f.boundary || f.face < 0) continue;
    ++inside;
    if (f.signed_distance < 0) ++behind;
  }
  if (inside > 0 && 2 * behind > inside)
    throw UsageError(
        "the cutter axis lies behind the surface (its normals point away from the tool); "
        "pass --flip");
}

int run_fit(const FitArgs& a) {
  Progress progress("fit", a.quiet);
  CutterKind kind;
  if (!parse_cutter_kind(a.tool, &kind))
    throw UsageError("--tool must be cylinder, cone, barrel or spline, not '" + a.tool + "'");
  if (a.line.empty() == a.lines_file.empty())
    throw UsageError("give exactly one of --line and --lines");
  std::optional<std::pair<double, double>> holder;
  if (!a.holder.empty()) holder = parse_pair(a.holder, "--holder");
  std::optional<std::pair<double, double>> radius;
  if (!a.radius.empty()) {
    radius = parse_pair(a.radius, "--radius");
    if (radius->first > radius->second)
      throw UsageError("--radius MIN,MAX needs MIN <= MAX, not " + a.radius);
  }
  std::optional<Line> user_line;
  if (!a.line.empty()) user_line = parse_line(a.line, "--line");
  std::vector<Line> user_lines;
  if (!a.lines_file.empty()) user_lines = read_lines_file(a.lines_file);

  resolve_tolerance(a.tolerance, a.tolerance_rel, 1.0);  // refuse bad values before any work
  const std::unique_ptr<io::OutputSet> out = open_outputs(a);  // checked before any work
  ThreadLimit limit(a.threads);
  start_worker_threads();  // while the input is read
  io::preload_cad_module();  // patches.step and tools.step need Open CASCADE: opened meanwhile
  const Design design = read_design(a, progress);
  const io::LoadedMesh& lm = design.lm;
  const double t_index = progress.elapsed();
  const SurfaceIndex index(lm.mesh);
  const double index_s = progress.elapsed() - t_index;
  const double diagonal = index.diagonal();
  const double tol = resolve_tolerance(a.tolerance, a.tolerance_rel, diagonal);
  // A line far shorter than the part is no cutter axis (a typo, or coordinates in metres).
  if (user_line && user_line->length() < kMinLine * diagonal)
    throw UsageError("--line is " + std::to_string(user_line->length()) + " mm long; a cutter axis needs at least " +
                     std::to_string(kMinLine * diagonal) + " mm (0.1% of the part's diagonal)");
  const double radius_min = radius ? radius->first : kDefaultRadiusMin * diagonal;
  const double radius_max = radius ? radius->second : kDefaultRadiusMax * diagonal;
  progress.stage("indexed; tolerance " + std::to_string(tol) + " mm, sphere radii " +
                 std::to_string(radius_min) + ".." + std::to_string(radius_max) + " mm");

  Motion init;
  std::vector<report::Setting> settings;
  if (user_line) {
    const LineStart start = line_driven_start(index, *user_line, kind, a.control_points);
    progress.stage("line-driven start: best of " + std::to_string(start.refined.evaluated) +
                   " nearby lines has movability " + std::to_string(start.refined.movability.value) +
                   "; swept " + std::to_string(start.propagation.rulings.size()) + " rulings (stops: " +
                   to_string(start.propagation.stop_backward) + " / " +
                   to_string(start.propagation.stop_forward) + ")");
    if (!start.ok) throw UsageError(start.message + ": try another line or --lines");
    init = start.motion;
    const Line& l = *user_line;
    settings.push_back({"start", std::string("line")});
    settings.push_back({"line", std::vector<double>{l.a.x(), l.a.y(), l.a.z(), l.b.x(), l.b.y(), l.b.z()}});
  } else {
    init = motion_from_lines(user_lines, a.control_points);
    settings.push_back({"start", std::string("lines")});
    settings.push_back({"lines_file", a.lines_file});
    settings.push_back({"lines", static_cast<long long>(user_lines.size())});
  }
  check_side(index, init);

  FitPatchOptions fo;
  fo.fit.kind = kind;
  fo.fit.control_points = a.control_points;
  fo.fit.samples_t = a.samples_t;
  fo.fit.samples_s = a.samples_s;
  fo.fit.radius_min = radius_min;  // kept inside the fit: the cutter stays a real tool
  fo.fit.radius_max = radius_max;
  // The library traces through a callback; the environment switch lives here, at the edge.
  if (std::getenv("FLANK_TRACE_FIT"))
    fo.fit.trace = [](const std::string& line) { std::fprintf(stderr, "%s\n", line.c_str()); };
  fo.tolerance = tol;
  if (std::string e = fo.validate(); !e.empty()) throw UsageError(e);
  const FitPatchResult fit = fit_and_trim(index, init, fo);
  progress.stage("fit: " + fit.fit.brief_report() + ", " + std::to_string(fit.rounds) + " trims");
  if (fit.status != FitPatchStatus::ok) {
    std::fprintf(stderr, "flank fit: %s: no patch (%s)\n", printable(a.mesh).c_str(), fit.message.c_str());
    return 1;
  }

  EvaluateOptions eo;
  eo.tolerance = tol;
  eo.rows = std::max(200, 2 * a.samples_t);
  eo.cols = std::max(60, 2 * a.samples_s);
  // The check samples densely on its own, whatever --samples-t/-s the fit used: neighbouring
  // axis samples at most 0.25% of the diagonal apart, as decompose's final evaluation.
  eo.spacing = 0.0025 * diagonal;
  if (holder) eo.holder = true, eo.holder_length = holder->first, eo.holder_radius = holder->second;
  Patch patch = evaluate_patch(index, fit.fit.motion, fit.fit.cutter, eo);
  patch.id = 0;
  // A cutter that gouges the part is never a result, however the fit was sampled.
  if (patch.error.max_gouge > tol) {
    std::fprintf(stderr,
                 "flank fit: %s: no patch: the fitted cutter gouges the part by %.4g mm, beyond the tolerance "
                 "%.4g mm (try more --samples-t or another start); nothing written\n",
                 printable(a.mesh).c_str(), patch.error.max_gouge, tol);
    return 1;
  }
  progress.stage("evaluated: max |e| " + std::to_string(patch.error.max) + " mm, coverage " +
                 std::to_string(100.0 * patch.coverage_fraction) + "%");

  report::RunInfo run;
  run.command = "fit";
  run.vertices = lm.mesh.vertex_count();
  run.triangles = lm.mesh.face_count();
  run.bbox_diagonal = diagonal;
  settings.insert(settings.begin(), {"command", std::string("fit")});
  settings.push_back({"tolerance", tol});
  settings.push_back({"tool", a.tool});
  settings.push_back({"radius", std::vector<double>{fo.fit.radius_min, fo.fit.radius_max}});
  settings.push_back({"control_points", static_cast<long long>(a.control_points)});
  settings.push_back({"samples", std::vector<double>{double(a.samples_t), double(a.samples_s)}});
  settings.push_back({"weights", std::vector<double>{fo.fit.weight_plane, fo.fit.weight_fair,
                                                     fo.fit.weight_point, fo.fit.weight_rigid}});
  if (holder) settings.push_back({"holder", std::vector<double>{holder->first, holder->second}});
  settings.push_back({"flip", a.flip});
  run.settings = settings;
  add_design_settings(design, run.settings);
  run.tolerance = tol;
  run.coverage_fraction = patch.coverage_fraction;
  run.total_area = total_area(lm.mesh);
  run.uncovered_area = std::max(0.0, run.total_area - patch.covered_area);
  run.coverage_curve = {patch.coverage_fraction};
  run.timing_s = {{"index", index_s}, {"fit", fit.fit.timing.total_s}, {"total", progress.elapsed()}};

  std::vector<Patch> patches{std::move(patch)};
  std::vector<int> vertex_patch(static_cast<std::size_t>(lm.mesh.vertex_count()), -1);
  for (int v : patches[0].covered_vertices) vertex_patch[static_cast<std::size_t>(v)] = 0;
  write_outputs(*out, a, design, run, patches, lm.mesh, vertex_patch, tol);
  const Patch& p = patches[0];
  std::printf("patch 0: %s cutter, length %.4f mm, sphere radii %.4f..%.4f mm\n",
              std::string(to_string(p.cutter.kind)).c_str(), p.cutter.length, p.cutter.radius(0),
              p.cutter.radius(1));
  std::printf("  error max %.3e mm (%.2e x diagonal), rms %.3e mm, max gouge %.3e mm\n",
              p.error.max, p.error.max_relative, p.error.rms, p.error.max_gouge);
  std::printf("  covers %.2f%% of the surface (%.4g mm^2) within %.3g mm\n",
              100.0 * p.coverage_fraction, p.covered_area, tol);
  if (p.collision.checked)
    std::printf("  holder %s (min clearance %.4g mm)\n", p.collision.holder_clear ? "clear" : "COLLIDES",
                p.collision.min_clearance);
  std::printf("%s\n", results_line(a).c_str());
  return 0;
}

}  // namespace

void register_fit(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "fit", "Fit one flank-millable patch from a start you give: one line or ordered lines");
  auto a = std::make_shared<FitArgs>();
  add_patch_options(cmd, *a);
  cmd->add_option("--line", a->line,
                  "Line-driven start: a cutter axis x0,y0,z0,x1,y1,z1 in mm, tip first; flank "
                  "improves it locally and sweeps it both ways");
  cmd->add_option("--lines", a->lines_file,
                  "Surface-driven start: a text file, one axis per row 'x0 y0 z0 x1 y1 z1', in "
                  "the order the cutter should pass them");
  cmd->add_option("--tool", a->tool, "Cutter shape: cylinder, cone, barrel or spline (default cone)");
  cmd->add_option("--radius", a->radius,
                  "Allowed cutter (sphere) radii MIN,MAX in mm, kept during the fit (default 1%..10% "
                  "of the diagonal)");
  cmd->add_option("--control-points", a->control_points, "B-spline control points per axis end curve (default 40)")
      ->check(CLI::Range(4, 200));
  cmd->add_option("--samples-t", a->samples_t, "Samples along the motion (default 100)")->check(CLI::Range(8, kMaxSamplesT));
  cmd->add_option("--samples-s", a->samples_s, "Samples along the axis (default 30)")->check(CLI::Range(4, kMaxSamplesS));
  set_action(cmd, exit_code, [a] { return run_fit(*a); });
}

}  // namespace flank::cli
