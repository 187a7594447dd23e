// flank synth: the forward model. A known cutter moved along a known motion gives the exact
// machined surface, written as a mesh: the test parts that fit/decompose must recover.
#include <CLI/CLI.hpp>
#include <charconv>
#include <cmath>
#include <exception>
#include <iostream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "cli/commands.h"
#include "cli/common.h"
#include "io/output_set.h"
#include "io/read_mesh.h"
#include "io/cad.h"
#include "io/read_lines.h"
#include "io/write_mesh.h"
#include "kernels/cutter.h"
#include "kernels/mesh.h"
#include "report/write_step.h"
#include "solver/synth.h"

namespace flank::cli {

namespace {

double parse_number(const std::string& text, const std::string& what) {
  const char* begin = text.data();
  const char* end = begin + text.size();
  if (begin != end && *begin == '+') ++begin;
  double v = 0.0;
  const auto [stop, ec] = std::from_chars(begin, end, v);
  if (begin == end || ec != std::errc() || stop != end || !std::isfinite(v))
    throw UsageError(what + ": '" + text + "' is not a number");
  return v;
}

std::vector<double> parse_list(const std::string& text, const std::string& what) {
  std::vector<double> out;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = text.find(',', start);
    out.push_back(parse_number(text.substr(start, comma - start), what));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

std::string number(double v) {
  std::ostringstream out;
  out << v;
  return out.str();
}

// The longest cutter accepted (mm): far beyond any tool, short of lengths whose envelope
// has no point in double precision.
constexpr double kMaxLength = 1e5;

double positive(double v, const std::string& what) {
  if (!(v > 0.0)) throw UsageError(what + " must be positive (got " + number(v) + ")");
  return v;
}

ToolProfile parse_tool(const std::string& spec, double length) {
  const std::string what = "--tool " + spec;
  const std::size_t colon = spec.find(':');
  if (colon == std::string::npos)
    throw UsageError(what + ": expected KIND:VALUES, e.g. cylinder:5, cone:4,7, barrel:418.17,5");
  const std::string kind = spec.substr(0, colon);
  const std::vector<double> v = parse_list(spec.substr(colon + 1), what);
  auto need = [&](std::size_t lo, std::size_t hi, const char* form) {
    if (v.size() < lo || v.size() > hi)
      throw UsageError(what + ": expected " + form + ", got " + std::to_string(v.size()) +
                       " value(s)");
  };
  if (kind == "cylinder") {
    need(1, 1, "cylinder:R");
    return cylinder_profile(length, positive(v[0], what + ": the radius R"));
  }
  if (kind == "cone") {
    need(2, 2, "cone:R_TIP,R_END");
    return cone_profile(length, positive(v[0], what + ": R_TIP"), positive(v[1], what + ": R_END"));
  }
  if (kind == "barrel") {
    need(1, 2, "barrel:R0[,R_END]");
    const double r0 = positive(v[0], what + ": the arc radius R0");
    const double r_end = v.size() > 1 ? positive(v[1], what + ": R_END") : kPaperBarrelEndRadius;
    if (!(r0 > 0.5 * length))
      throw UsageError(what + ": the arc radius R0 = " + number(r0) +
                       " must exceed half the tool length (" + number(0.5 * length) + ")");
    return barrel_profile(length, r0, r_end);
  }
  if (kind == "spline") {
    need(kSplineProfileCoefficients, kSplineProfileCoefficients, "spline:d0,...,d9 (10 values)");
    Cutter c;
    c.kind = CutterKind::spline;
    c.length = length;
    c.coeffs = Eigen::Map<const VecX>(v.data(), static_cast<Eigen::Index>(v.size()));
    ToolProfile p = profile_from_cutter(c);
    std::ostringstream text;
    text << "spline cutter d = " << spec.substr(colon + 1) << ", L = " << length;
    p.description = text.str();
    return p;
  }
  throw UsageError(what + ": unknown cutter kind '" + kind +
                   "' (use cylinder, cone, barrel or spline)");
}

void parse_resolution(const std::string& text, SynthOptions* options) {
  const std::size_t x = text.find_first_of("xX");
  const std::string what = "--resolution " + text;
  if (x == std::string::npos) throw UsageError(what + ": expected ROWSxCOLS, e.g. 241x61");
  auto count = [&](const std::string& part) {
    const double v = parse_number(part, what);
    if (v != std::floor(v) || v < 2 || v > 1e6)
      throw UsageError(what + ": '" + part + "' must be a whole number from 2 to 1000000");
    return static_cast<int>(v);
  };
  options->rows = count(text.substr(0, x));
  options->cols = count(text.substr(x + 1));
}

int parse_side(const std::string& text) {
  if (text == "+1" || text == "1") return +1;
  if (text == "-1") return -1;
  throw UsageError("--side " + text + ": expected +1 or -1");
}

void check_length(double length) {
  positive(length, "--length");
  if (length > kMaxLength) throw UsageError("--length must be at most " + std::to_string(kMaxLength) + " mm");
}

struct SynthArgs {
  std::string guides, motion_file, tool, resolution = "241x61", side = "+1", output;
  double length = kPaperToolLength;
};

void run_synth(const SynthArgs& args, bool length_given) {
  if (args.guides.empty() == args.motion_file.empty())
    throw UsageError("give exactly one of --guides NAME or --motion FILE");
  SynthOptions options;
  parse_resolution(args.resolution, &options);
  options.side = parse_side(args.side);
  // --side is checked by parse_side: what validate() can still refuse is the resolution.
  if (const std::string problem = options.validate(); !problem.empty()) throw UsageError("--resolution: " + problem);
  io::check_output_file(args.output);  // before any work

  AxisMotion motion;
  std::string source;
  double length = args.length;
  if (!args.guides.empty()) {
    if (args.guides != "seed003" && args.guides != "li-mann-bedi")
      throw UsageError("--guides " + args.guides +
                       ": unknown guiding curves (known: seed003, li-mann-bedi)");
    check_length(length);
    motion = guide_motion(paper_guides(), length);
    source = "guides " + args.guides;
  } else {
    io::ControlPoints rows = io::read_motion_file(args.motion_file);
    const Motion m = Motion::from_control_points(std::move(rows.a), std::move(rows.b));
    // The sphere radii of a cone or barrel are laid out over the axis length; a motion file
    // carries its own axis, so its mean length is the default.
    if (!length_given) length = m.mean_length();
    check_length(length);
    motion = spline_motion(m);
    source = "motion " + args.motion_file;
  }

  const ToolProfile tool = parse_tool(args.tool, length);
  if (const std::string problem = tool.validate(); !problem.empty())
    throw UsageError("--tool " + args.tool + ": " + problem);

  const SynthResult result = synth_envelope(motion, tool, options);
  if (result.invalid > 0 || result.mesh.face_count() == 0) {
    std::ostringstream msg;
    msg << result.invalid << " sample(s) have no envelope point (first at t = "
        << result.invalid_t << ", s = " << result.invalid_s
        << "): the axis does not sweep across itself there or |d'| reaches the axis length; "
           "nothing written (check --tool, --length and the motion)";
    throw UsageError(msg.str());
  }
  std::string nurbs;
  if (io::is_cad_path(args.output)) {
    // The envelope as one B-spline face: fitted to the grid, its deviation measured against the
    // exact envelope on a grid twice as fine (cell centres and edge midpoints included).
    SynthOptions fine_options = options;
    fine_options.rows = 2 * options.rows - 1;
    fine_options.cols = 2 * options.cols - 1;
    const SynthResult fine = synth_envelope(motion, tool, fine_options);
    if (fine.invalid > 0 || fine.mesh.face_count() == 0)
      throw UsageError("the envelope has no point at some parameters of the fine grid; nothing written");
    Points grid = fine.mesh.V;
    // The face's normal ∂u × ∂v must point toward the tool, as the mesh's triangles do.
    const int fc = fine_options.cols;
    const Vec3 du = fine.mesh.V.row(fc) - fine.mesh.V.row(0), dv = fine.mesh.V.row(1) - fine.mesh.V.row(0);
    const Vec3 p0 = fine.mesh.V.row(fine.mesh.F(0, 0)), p1 = fine.mesh.V.row(fine.mesh.F(0, 1)),
               p2 = fine.mesh.V.row(fine.mesh.F(0, 2));
    if (du.cross(dv).dot((p1 - p0).cross(p2 - p0)) < 0)
      for (int i = 0; i < fine_options.rows; ++i)
        grid.middleRows(static_cast<Eigen::Index>(i) * fc, fc).colwise().reverseInPlace();
    const double diagonal = bbox_diagonal(result.mesh);
    const report::FittedSurface f =
        report::fit_exact_grid(args.output, grid, options.rows, options.cols, 2e-7 * diagonal);
    io::write_surfaces(args.output, {{"envelope", f.surface}});
    std::ostringstream n;
    n << "; B-spline face " << f.surface.poles_u() << "x" << f.surface.poles_v() << " poles, degree "
      << f.surface.degree_u() << "x" << f.surface.degree_v() << ", max deviation from the exact envelope "
      << f.deviation << " mm (" << f.deviation / diagonal << " of the diagonal)";
    nurbs = n.str();
  } else {
    io::write_mesh(args.output, result.mesh);
  }

  const double diagonal = bbox_diagonal(result.mesh);
  std::ostringstream out;
  out << "wrote " << printable(args.output) << " (" << source << ", " << tool.description << ", side "
      << (options.side > 0 ? "+1" : "-1") << ", " << options.rows << "x" << options.cols
      << "): " << result.mesh.vertex_count() << " vertices, " << result.mesh.face_count()
      << " triangles, bbox diagonal " << diagonal << " mm, chord error " << result.chord_error
      << " mm (" << (diagonal > 0 ? result.chord_error / diagonal : 0.0) << " of the diagonal)" << nurbs;
  std::cout << out.str() << std::endl;
}

}  // namespace

void register_synth(CLI::App& app, int* exit_code) {
  auto args = std::make_shared<SynthArgs>();
  CLI::App* sub = app.add_subcommand(
      "synth",
      "Write the exact surface a known cutter machines along a known motion (flank milling), "
      "as a triangle mesh. Used to make test parts with a known answer.");
  CLI::Option* guides = sub->add_option(
      "--guides", args->guides,
      "Tool path from the two guiding curves of Li, Mann & Bedi, Table 1 (names: seed003, "
      "li-mann-bedi): tool tip on the bottom curve, axis through the top curve");
  guides->type_name("NAME");
  CLI::Option* motion = sub->add_option(
      "--motion", args->motion_file,
      "Tool path from a motion file: one row per control point 'ax ay az bx by bz' (tip a, "
      "spindle-side axis point b), at least 4 rows, '#' comments; clamped cubic B-spline");
  motion->type_name("FILE");
  guides->excludes(motion);
  motion->excludes(guides);
  sub->add_option("--tool", args->tool,
                  "Cutter, sizes in mm: cylinder:R | cone:R_TIP,R_END (radius at the tip and at "
                  "the spindle end) | barrel:R0[,R_END] (arc radius of the side, end radius, "
                  "default 5) | spline:d0,...,d9 (10 B-spline sphere-radius coefficients)")
      ->type_name("SPEC")
      ->required();
  CLI::Option* length = sub->add_option(
      "--length", args->length,
      "Cutter (axis) length in mm, from the tip; default 50, or the mean axis length of a "
      "motion file");
  length->type_name("MM");
  sub->add_option("--resolution", args->resolution,
                  "Mesh samples ROWSxCOLS: rows along the tool path, columns along the tool "
                  "axis (default 241x61)")
      ->type_name("ROWSxCOLS");
  sub->add_option("--side", args->side,
                  "Which side of the tool path the machined surface lies on: +1 or -1 "
                  "(default +1)")
      ->type_name("+1|-1");
  sub->add_option("-o,--output", args->output, "Output: a mesh (.stl, .obj, .ply) or one B-spline face (.step, .stp, .iges, .igs)")
      ->type_name("MESH")
      ->required();
  set_action(sub, exit_code, [args, length] {
    run_synth(*args, length->count() > 0);
    return 0;
  });
}

}  // namespace flank::cli
