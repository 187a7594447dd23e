#include "cli/common.h"

#include <CLI/CLI.hpp>
#include <filesystem>

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "io/read_lines.h"

namespace flank::cli {

namespace {
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

std::unique_ptr<io::OutputSet> open_outputs(const PatchArgs& a) {
  return std::make_unique<io::OutputSet>(
      a.out_dir, std::vector<std::string>{"patches.json", "envelopes.ply", "design.ply", "toolpath.apt"});
}

void write_outputs(io::OutputSet& out, const PatchArgs& a, const report::RunInfo& run,
                   const std::vector<Patch>& patches, const Mesh& mesh,
                   const std::vector<int>& vertex_patch, double tolerance) {
  report::write_patches_json(out.staged("patches.json"), run, patches);
  report::write_envelopes_ply(out.staged("envelopes.ply"), patches, tolerance);
  report::write_design_ply(out.staged("design.ply"), mesh, vertex_patch);
  report::write_toolpath_apt(out.staged("toolpath.apt"), patches, a.apt_steps,
                         std::filesystem::path(a.mesh).stem().string());
  out.commit();
}

}  // namespace flank::cli
