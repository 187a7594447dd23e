// flank movability MESH --line ...: how well one line can sweep along the surface (F_l),
// optionally after the local endpoint search of the paper's Fig. 8.
#include <CLI/CLI.hpp>
#include <cstdio>

#include "cli/commands.h"
#include "cli/common.h"
#include "io/read_mesh.h"
#include "kernels/movability.h"
#include "kernels/parallel.h"
#include "solver/propagate.h"

namespace flank::cli {

namespace {
const char* status_text(MovabilityStatus s) {
  switch (s) {
    case MovabilityStatus::ok: return "ok";
    case MovabilityStatus::left_surface: return "left the surface";
    case MovabilityStatus::jump: return "footpoints jump (two branches)";
    case MovabilityStatus::degenerate: return "degenerate";
  }
  return "?";
}
void print(const char* label, const Line& l, const Movability& m) {
  const Vec3 va = m.velocity(0), vb = m.velocity(1);
  std::printf("%s line      %.6f,%.6f,%.6f,%.6f,%.6f,%.6f\n", label, l.a.x(), l.a.y(), l.a.z(),
              l.b.x(), l.b.y(), l.b.z());
  std::printf("%s movability %.6e (%s, %d of %d footpoints beyond the boundary)\n", label,
              m.value, status_text(m.status), m.boundary_samples, m.samples);
  std::printf("%s velocity   a: %.6f %.6f %.6f  b: %.6f %.6f %.6f\n", label, va.x(), va.y(),
              va.z(), vb.x(), vb.y(), vb.z());
}
}  // namespace

void register_movability(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "movability", "Score a line as a cutter axis: F_l = 0 means it can sweep tangentially");
  struct Args {
    std::string mesh, line;
    int samples = 30, threads = 0;
    bool refine = false, flip = false;
  };
  auto args = std::make_shared<Args>();
  cmd->add_option("MESH", args->mesh, "Design surface: STL, OBJ or PLY")->required();
  cmd->add_option("--line", args->line, "Axis as x0,y0,z0,x1,y1,z1 (tip first), in mm")->required();
  cmd->add_option("--samples", args->samples, "Points sampled on the line (n)")->check(CLI::Range(3, 100000));
  cmd->add_flag("--refine", args->refine, "Also search the endpoints' neighbourhoods for a better line");
  cmd->add_option("--threads", args->threads, "Worker threads (default: all cores)")->check(CLI::Range(1, 1024));
  cmd->add_flag("--flip", args->flip, "Reverse the surface orientation");
  set_action(cmd, exit_code, [=] {
    const Line line = parse_line(args->line, "--line");
    ThreadLimit limit(args->threads);
    start_worker_threads();  // while the input is read
    io::ReadOptions ro;
    ro.flip = args->flip;
    ro.count_components = false;  // the solver does not read them
    const io::LoadedMesh lm = io::read_mesh(args->mesh, ro);
    const SurfaceIndex index(lm.mesh);
    MovabilityOptions mo;
    mo.samples = args->samples;
    print("given  ", line, movability(index, line.a, line.b, mo));
    if (args->refine) {
      RefineLineOptions ro2;
      ro2.movability = mo;
      const RefinedLine best = refine_line(index, line, ro2);
      print("refined", best.line, best.movability);
      std::printf("refined evaluated  %d lines\n", best.evaluated);
    }
    return 0;
  });
}

}  // namespace flank::cli
