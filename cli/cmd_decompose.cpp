// flank decompose: the whole part in, a small set of flank-millable patches out, with no line
// drawn by hand.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <sstream>

#include "cli/commands.h"
#include "cli/common.h"
#include "io/read_mesh.h"
#include "report/write.h"
#include "kernels/parallel.h"
#include "solver/decompose.h"

namespace flank::cli {

namespace {

struct DecomposeArgs : PatchArgs {
  std::string tools = "cylinder,cone,barrel,spline", radius, length;
  int max_patches = 20;
  double coverage = 0.95;
};

std::vector<CutterKind> parse_kinds(const std::string& text) {
  std::vector<CutterKind> kinds;
  std::stringstream in(text + ",");  // so that a trailing comma gives an empty last item
  std::string item;
  while (std::getline(in, item, ',')) {
    CutterKind k;
    if (!parse_cutter_kind(item, &k))
      throw UsageError("--tool takes cylinder, cone, barrel or spline (comma-separated), not '" + item + "'");
    kinds.push_back(k);
  }
  if (kinds.empty()) throw UsageError("--tool needs at least one cutter kind");
  return kinds;
}

// Cutters far smaller or larger than the part are refused, not searched for: a length of
// 1e-300 mm would make the search lay out lines that cut nothing. The floors are far below
// any real tool on a part of that size (the defaults are 1% and 3% of the diagonal).
void check_ranges(const DecomposeOptions& o, double diagonal) {
  auto mm = [](double v) { return std::to_string(v) + " mm"; };
  if (o.length_min > 0 && o.length_min < 0.01 * diagonal)
    throw UsageError("--length MIN is below 1% of the part's diagonal (" + mm(0.01 * diagonal) + ")");
  if (o.length_max > 2.0 * diagonal)
    throw UsageError("--length MAX is above twice the part's diagonal (" + mm(2.0 * diagonal) + ")");
  if (o.radius_min > 0 && o.radius_min < 0.001 * diagonal)
    throw UsageError("--radius MIN is below 0.1% of the part's diagonal (" + mm(0.001 * diagonal) + ")");
  if (o.radius_max > diagonal)
    throw UsageError("--radius MAX is above the part's diagonal (" + mm(diagonal) + ")");
}

int run_decompose(const DecomposeArgs& a) {
  Progress progress("decompose", a.quiet);
  DecomposeOptions o;
  o.kinds = parse_kinds(a.tools);
  if (!a.radius.empty()) std::tie(o.radius_min, o.radius_max) = parse_pair(a.radius, "--radius");
  if (!a.length.empty()) std::tie(o.length_min, o.length_max) = parse_pair(a.length, "--length");
  if (!a.holder.empty()) {
    o.holder = true;
    std::tie(o.holder_length, o.holder_radius) = parse_pair(a.holder, "--holder");
  }
  if (!(a.coverage > 0 && a.coverage <= 1)) throw UsageError("--coverage must be in (0, 1]");
  o.coverage_target = a.coverage;
  o.max_patches = a.max_patches;
  resolve_tolerance(a.tolerance, a.tolerance_rel, 1.0);  // refuse bad values before any work
  o.tolerance = 1.0;                                     // placeholder until the diagonal is known
  if (std::string e = o.validate(); !e.empty()) throw UsageError(e);
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
  o.tolerance = resolve_tolerance(a.tolerance, a.tolerance_rel, diagonal);
  progress.stage("indexed; tolerance " + std::to_string(o.tolerance) + " mm");
  check_ranges(o, diagonal);

  // Diagnostics for developers: every candidate line, grown piece and round on stderr.
  if (std::getenv("FLANK_TRACE_DECOMPOSE")) o.trace = [](const std::string& s) { std::fprintf(stderr, "%s\n", s.c_str()); };
  const DecomposeResult r = decompose(index, o, [&](const std::string& s) { progress.stage(s); });
  const double total = progress.elapsed();

  report::RunInfo run;
  run.command = "decompose";
  run.vertices = lm.mesh.vertex_count();
  run.triangles = lm.mesh.face_count();
  run.bbox_diagonal = diagonal;
  std::string kinds_text;
  for (CutterKind k : o.kinds) kinds_text += (kinds_text.empty() ? "" : ",") + std::string(to_string(k));
  const ToolRanges ranges = tool_ranges(o, diagonal);
  run.settings = {{"command", std::string("decompose")},
                  {"tolerance", o.tolerance},
                  {"tool", kinds_text},
                  {"radius", std::vector<double>{ranges.radius_min, ranges.radius_max}},
                  {"length", std::vector<double>{ranges.length_min, ranges.length_max}},
                  {"coverage_target", o.coverage_target},
                  {"max_patches", static_cast<long long>(o.max_patches)},
                  {"max_rounds", static_cast<long long>(o.max_rounds)},
                  {"candidates_per_seed", std::vector<double>{double(o.directions), double(o.tilts),
                                                              double(o.radii), double(o.directions_kept),
                                                              double(o.lengths)}},
                  {"control_points", static_cast<long long>(o.control_points)},
                  {"noise_sigma", r.noise.sigma},
                  {"smoothed", r.smoothed},
                  {"flip", a.flip}};
  if (o.holder) run.settings.push_back({"holder", std::vector<double>{o.holder_length, o.holder_radius}});
  add_design_settings(design, run.settings);
  run.tolerance = o.tolerance;
  run.coverage_fraction = r.coverage;
  // Area sums in a different order can leave -1e-11 mm^2 where nothing is left.
  const double uncovered_area = std::max(0.0, r.total_area - r.covered_area);
  run.uncovered_area = uncovered_area;
  run.total_area = r.total_area;
  run.coverage_curve = r.coverage_curve;
  for (const UncoveredRegion& u : r.uncovered) run.uncovered.push_back({u.area, u.centroid, u.vertices});
  run.timing_s = {{"index", index_s},   {"seeds", r.times.seeds},   {"candidates", r.times.candidates},
                  {"fit", r.times.fit}, {"cover", r.times.cover},   {"finish", r.times.finish},
                  {"total", total}};

  write_outputs(*out, a, design, run, r.patches, lm.mesh, r.vertex_patch, o.tolerance);
  const double writing = progress.elapsed() - total;  // after patches.json: not in its timing_s

  std::printf("%s: %zu patch%s cover %.2f%% of %.4g mm^2 within %.3g mm\n", printable(a.mesh).c_str(),
              r.patches.size(), r.patches.size() == 1 ? "" : "es", 100.0 * r.coverage, r.total_area,
              o.tolerance);
  if (r.smoothed)
    std::printf("  the surface is noisy (scatter %.3g mm, %.0f%% of the tolerance): fitted on a smoothed copy; "
                "errors and coverage are against the surface as given\n",
                r.noise.sigma, 100.0 * r.noise.sigma / o.tolerance);
  double worst = 0.0;
  for (const Patch& p : r.patches) {
    worst = std::max(worst, p.error.max);
    std::printf("  patch %d: %-8s cutter, L %.2f mm, sphere radii %.3f..%.3f mm, covers %.2f%% (adds %.2f%%), "
                "max |e| %.2e mm, max gouge %.2e mm%s\n",
                p.id, std::string(to_string(p.cutter.kind)).c_str(), p.cutter.length, p.cutter.radius(0),
                p.cutter.radius(1), 100.0 * p.coverage_fraction,
                100.0 * (r.coverage_curve[static_cast<std::size_t>(p.id)] -
                         (p.id > 0 ? r.coverage_curve[static_cast<std::size_t>(p.id) - 1] : 0.0)),
                p.error.max, p.error.max_gouge,
                p.collision.checked ? (p.collision.holder_clear ? ", holder clear" : ", HOLDER COLLIDES") : "");
  }
  if (r.patches.empty())
    std::printf("  no patch meets the tolerance with the allowed cutters: try a larger --tolerance, "
                "other --tool kinds or wider --radius/--length ranges\n");
  if (r.uncovered.empty() && uncovered_area <= 1e-9 * r.total_area)
    std::printf("worst error %.3e mm; nothing left for ball-end finishing", worst);
  else
    std::printf("worst error %.3e mm; left for ball-end finishing: %.4g mm^2 in %zu region%s", worst,
                uncovered_area, r.uncovered.size(), r.uncovered.size() == 1 ? "" : "s");
  for (std::size_t k = 0; k < std::min<std::size_t>(3, r.uncovered.size()); ++k)
    std::printf("%s %.3g mm^2 at (%.1f, %.1f, %.1f)", k ? "," : ":", r.uncovered[k].area,
                r.uncovered[k].centroid.x(), r.uncovered[k].centroid.y(), r.uncovered[k].centroid.z());
  std::printf("\n");
  std::printf("coverage after 1..%zu patches:", r.coverage_curve.size());
  for (double c : r.coverage_curve) std::printf(" %.1f%%", 100.0 * c);
  std::printf("\n");
  std::printf("time: index %.2fs, seeds %.2fs, candidates %.2fs (%lld lines scored, %d laid out, %d seeds reused), "
              "fit %.2fs (%d grown, %d reused), cover %.2fs, finish %.2fs, total %.2fs; outputs written in %.2fs\n",
              index_s, r.times.seeds, r.times.candidates, r.lines_scored, r.candidates, r.seeds_reused, r.times.fit,
              r.grown, r.regrown, r.times.cover, r.times.finish, total, writing);
  std::printf("%s\n", results_line(a).c_str());
  return 0;
}

}  // namespace

void register_decompose(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "decompose", "Find, fully automatically, a few large flank-millable patches covering the part");
  auto a = std::make_shared<DecomposeArgs>();
  add_patch_options(cmd, *a);
  cmd->add_option("--tool", a->tools,
                  "Cutter shapes allowed, comma-separated: cylinder, cone, barrel, spline (default: every "
                  "kind; each patch gets the simplest that cuts its surface)");
  cmd->add_option("--radius", a->radius,
                  "Allowed sphere radii of the cutter MIN,MAX in mm (default 1%..10% of the diagonal)");
  cmd->add_option("--length", a->length,
                  "Allowed cutter lengths MIN,MAX in mm (default 3%..45% of the diagonal)");
  cmd->add_option("--coverage", a->coverage, "Stop when this fraction of the area is covered (default 0.95)")
      ->check(CLI::Range(0.01, 1.0));
  cmd->add_option("--max-patches", a->max_patches, "At most this many patches (default 20)")->check(CLI::Range(1, 10000));
  set_action(cmd, exit_code, [a] { return run_decompose(*a); });
}

}  // namespace flank::cli
