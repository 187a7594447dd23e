// Writers of a run's results for a person or a machine: patches.json, envelopes.ply,
// design.ply, toolpath.apt. Each goes through io::write_file_atomic, so a failure never leaves
// a half-written output (DESIGN "Command line"); failures throw io::Error.
#pragma once

#include <filesystem>
#include <string>
#include <variant>
#include <vector>

#include "kernels/mesh.h"
#include "solver/patch.h"

namespace flank::report {

using SettingValue = std::variant<double, long long, bool, std::string, std::vector<double>>;
struct Setting {
  std::string key;
  SettingValue value;
};

struct RunInfo {
  std::string command;       // decompose, fit
  std::string input_path;
  std::string input_format;  // stl, obj, ply, step, iges
  long long input_bytes = 0;
  int vertices = 0;
  int triangles = 0;
  double bbox_diagonal = 0.0;
  std::vector<Setting> settings;  // every option that shaped the result
  double coverage_fraction = 0.0;
  double tolerance = 0.0;
  double uncovered_area = 0.0;
  double total_area = 0.0;
  // The covered fraction after 1, 2, …, k patches: what each extra sweep buys.
  std::vector<double> coverage_curve;
  // Edge-connected regions left uncovered (for ball-end finishing), largest first.
  struct Region {
    double area = 0.0;
    Vec3 centroid = Vec3::Zero();
    int vertices = 0;
  };
  std::vector<Region> uncovered;
  std::vector<std::pair<std::string, double>> timing_s;  // index, candidates, fit, cover, total
  // Per patch, in order: the deviation of its B-spline face in patches.step from the exact Ω
  // (NaN: no face written) and the (t, s) range the face covers; empty when no patches.step
  // was written.
  struct Face {
    double deviation = 0.0;
    double t0 = 0.0, t1 = 1.0, s0 = 0.0, s1 = 1.0;
  };
  std::vector<Face> nurbs;
};

// The settings as one JSON object, in their order (patches.json and report.html show the same).
std::string settings_json(const std::vector<Setting>& settings);

// patches.json, format flank-patches/1 (DESIGN "Output").
void write_patches_json(const std::filesystem::path& path, const RunInfo& run,
                        const std::vector<Patch>& patches);
// envelopes.ply: every patch's Ω, binary little-endian, with per-vertex float `error`
// (signed), uchar red/green/blue from a diverging map over ±tolerance, and int `patch`.
void write_envelopes_ply(const std::filesystem::path& path, const std::vector<Patch>& patches,
                         double tolerance);
// design.ply: Φ with per-vertex int `patch` (−1 uncovered) and a colour per patch,
// uncovered vertices in their own colour (magenta).
void write_design_ply(const std::filesystem::path& path, const Mesh& mesh,
                      const std::vector<int>& vertex_patch);
// toolpath.apt: APT CL data, one block per patch: a comment header with the cutter (kind,
// length, radii, meridian), CUTTER/d,0,0,0,0,beta,h of the real tool (the cone through the
// profile's end circles: exact for a cylinder or cone; for a barrel or spline, comments give
// its deviation and where the exact profile is), MULTAX/ON, then one GOTO/x,y,z,i,j,k per step
// (centre of the cutter's end face, unit axis toward the spindle), FINI.
void write_toolpath_apt(const std::filesystem::path& path, const std::vector<Patch>& patches,
                        int steps_per_patch, const std::string& part_name);

}  // namespace flank::report
