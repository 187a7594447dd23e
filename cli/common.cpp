#include "cli/common.h"

#include <CLI/CLI.hpp>
#include <filesystem>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

namespace flank::cli {

namespace {
std::vector<double> parse_numbers(std::string text, const std::string& option) {
  for (char& c : text)
    if (c == ',') c = ' ';
  std::istringstream in(text);
  std::vector<double> out;
  std::string token;
  while (in >> token) {
    std::size_t used = 0;
    double v = 0;
    try {
      v = std::stod(token, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != token.size() || !std::isfinite(v))
      throw UsageError(option + ": '" + token + "' is not a finite number");
    out.push_back(v);
  }
  return out;
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
  std::ifstream in(path);
  if (!in) throw io::Error(path + ": cannot open lines file");
  std::vector<Line> lines;
  std::string row;
  int number = 0;
  while (std::getline(in, row)) {
    ++number;
    if (const auto hash = row.find('#'); hash != std::string::npos) row.resize(hash);
    if (row.find_first_not_of(" \t\r,") == std::string::npos) continue;
    try {
      lines.push_back(parse_line(row, "line " + std::to_string(number)));
    } catch (const UsageError& e) {
      throw io::Error(path + ": " + e.what());
    }
  }
  if (lines.size() < 2) throw io::Error(path + ": needs at least two lines, in motion order");
  return lines;
}

void set_action(CLI::App* cmd, int* exit_code, std::function<int()> run) {
  cmd->callback([cmd, exit_code, run = std::move(run)]() {
    try {
      *exit_code = run();
    } catch (const std::exception& e) {
      std::fprintf(stderr, "flank %s: %s\n", cmd->get_name().c_str(), e.what());
      *exit_code = 2;
    } catch (...) {
      std::fprintf(stderr, "flank %s: unexpected error\n", cmd->get_name().c_str());
      *exit_code = 2;
    }
  });
}

Progress::Progress(std::string command, bool quiet)
    : command_(std::move(command)), quiet_(quiet), start_(std::chrono::steady_clock::now()) {}

double Progress::elapsed() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void Progress::stage(const std::string& what) {
  if (quiet_) return;
  std::fprintf(stderr, "[%6.2fs] flank %s: %s\n", elapsed(), command_.c_str(), what.c_str());
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

void add_patch_options(CLI::App* cmd, PatchArgs& a) {
  cmd->add_option("MESH", a.mesh, "Design surface: STL, OBJ or PLY")->required();
  cmd->add_option("-o,--output", a.out_dir, "Folder for patches.json, envelopes.ply, design.ply, toolpath.apt")
      ->required();
  cmd->add_option("--tolerance", a.tolerance, "Allowed error in mm");
  cmd->add_option("--tolerance-rel", a.tolerance_rel,
                  "Allowed error as a fraction of the bounding-box diagonal (default 1e-4)");
  cmd->add_option("--holder", a.holder,
                  "Check the holder: LEN,RADIUS of a cylinder beyond the cutter's spindle end, in mm");
  cmd->add_option("--threads", a.threads, "Worker threads (default: all cores)")->check(CLI::Range(1, 1024));
  cmd->add_option("--apt-steps", a.apt_steps, "GOTO steps per patch in toolpath.apt (default 200)")
      ->check(CLI::Range(2, 1000000));
  cmd->add_flag("--flip", a.flip, "Reverse the surface orientation (tools live on the normals' side)");
  cmd->add_flag("-q,--quiet", a.quiet, "No progress lines on stderr");
}

void write_outputs(const PatchArgs& a, const io::RunInfo& run, const std::vector<Patch>& patches,
                   const Mesh& mesh, const std::vector<int>& vertex_patch, double tolerance) {
  std::error_code ec;
  std::filesystem::create_directories(a.out_dir, ec);
  if (ec) throw io::Error(a.out_dir + ": cannot create output folder: " + ec.message());
  const std::filesystem::path dir(a.out_dir);
  io::write_patches_json(dir / "patches.json", run, patches);
  io::write_envelopes_ply(dir / "envelopes.ply", patches, tolerance);
  io::write_design_ply(dir / "design.ply", mesh, vertex_patch);
  io::write_toolpath_apt(dir / "toolpath.apt", patches, a.apt_steps,
                         std::filesystem::path(a.mesh).stem().string());
}

}  // namespace flank::cli
