// Shared pieces of the flank subcommands: option parsing helpers, mesh loading with one-line
// errors, progress lines on stderr.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "io/cad.h"
#include "io/output_set.h"
#include "io/read_mesh.h"
#include "report/write.h"
#include "solver/motion.h"
#include "solver/patch.h"

namespace CLI {
class App;
}

namespace flank::cli {

// Progress on stderr: each stage line carries the elapsed time; silent with --quiet.
class Progress {
 public:
  Progress(std::string command, bool quiet);
  void stage(const std::string& what);
  double elapsed() const;

 private:
  std::string command_;
  bool quiet_;
  std::chrono::steady_clock::time_point start_;
};

// Options every patch-producing command takes (fit, decompose).
struct PatchArgs {
  std::string mesh, out_dir, holder, faces;
  std::optional<double> tolerance, tolerance_rel;
  int threads = 0, apt_steps = 200;
  bool flip = false, quiet = false, no_report = false;
};
void add_patch_options(CLI::App* cmd, PatchArgs& a);

// The design surface Φ: a mesh file as read, or the chosen faces of a STEP/IGES file sewn and
// tessellated with a chord deviation under a tenth of the tolerance.
struct Design {
  io::LoadedMesh lm;
  double tolerance = 0.0;        // resolved against the diagonal of what was read
  bool cad = false;
  std::vector<int> faces;        // CAD: the faces used (1-based), all when --faces is not given
  double chord_deviation = 0.0;  // CAD: the largest chord deviation measured, mm
  double chord_target = 0.0;     // CAD: the deviation asked of the tessellation, mm
  std::shared_ptr<const io::CadPart> part;  // CAD: the file as read (info lists its faces)
};
// `count_components`: MeshReport::components counted (flank info); the solver's commands
// leave it −1 (io::ReadOptions says what it costs).
Design read_design(const PatchArgs& a, Progress& progress, bool count_components = false);
// --faces "1,3,7-9" → {1, 3, 7, 8, 9}; throws UsageError naming the option.
std::vector<int> parse_faces(const std::string& text);
// What the design adds to patches.json's settings: the input format and, for CAD, the faces
// and the chord deviation.
void add_design_settings(const Design& d, std::vector<report::Setting>& settings);

// The output folder a.out_dir, checked and created before any work (io::OutputSet).
// The files a run writes there, report.html first (what a person opens).
std::vector<std::string> output_names(const PatchArgs& a);
// "results in FOLDER: report.html patches.json …", the last line of a run.
std::string results_line(const PatchArgs& a);
std::unique_ptr<io::OutputSet> open_outputs(const PatchArgs& a);
// report.html (unless --no-report), patches.json, envelopes.ply, design.ply, toolpath.apt,
// patches.step and tools.step, written into `out` and moved into place together: the earlier
// run's set is replaced all or nothing. Fills in what `run` says of the input file.
void write_outputs(io::OutputSet& out, const PatchArgs& a, const Design& design, report::RunInfo run,
                   const std::vector<Patch>& patches, const Mesh& mesh,
                   const std::vector<int>& vertex_patch, double tolerance);

// An impossible option or unusable value: the CLI prints "flank CMD: message" and exits 2.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// `text` with control characters escaped (a newline as \n, others as \xNN): a path or a
// file's bytes echoed in a message stay one line and cannot drive the terminal.
std::string printable(const std::string& text);

// Makes `run` the subcommand's action: its return value is the exit code, and any exception
// becomes one line "flank CMD: message" on stderr and exit code 2.
void set_action(CLI::App* cmd, int* exit_code, std::function<int()> run);

// "x0,y0,z0,x1,y1,z1" → Line; throws UsageError naming the option.
Line parse_line(const std::string& text, const std::string& option);
// "A,B" → two positive numbers.
std::pair<double, double> parse_pair(const std::string& text, const std::string& option);
// The axes of a --lines file (io/read_lines.h); io::Error on unreadable or malformed files.
std::vector<Line> read_lines_file(const std::string& path);

// Resolves --tolerance / --tolerance-rel against the diagonal (default 1e-4 × diagonal).
double resolve_tolerance(std::optional<double> absolute, std::optional<double> relative,
                         double diagonal);

}  // namespace flank::cli
