// The scaling ladder (scripts/scaling-report): every stage of flank on a ladder of mesh sizes
// of six parts, at 1 and 2 threads, so that time can be plotted against size and compared
// with the raw closest-point rate measured on the same mesh in the same run.
//
// Parts: `cone`, the forward-model part (the Li–Mann–Bedi cone 4→7 envelope) synthesised at
// about 1k, 4k, 16k, 64k, 256k and 1M triangles; `blade`, the bundled propeller blade
// (data/propeller_blade_upper.stl, 522 triangles) re-meshed finer by midpoint subdivision,
// 2k to 535k triangles on exactly the same surface; `hecc_a`, `hecc_b`, `rotor_upper` and
// `rotor_lower`, the four real blade faces of tests/data (hecc_splitter_blade_side_a/b, 24k
// triangles, rotor67_blade_upper/lower, 38k), each at its native resolution and once
// subdivided (4×), `rotor_upper` also twice (614k): what users run, and the same surface on
// a finer mesh. Names:
//   Ladder/<stage>/<part>/tri_k:<thousands of triangles>/threads:<1|2>
// Stages:
//   read       the rung's file read and repaired (io::read_mesh): a face's own STL, a PLY of
//              the others' meshes, as the command stage reads them (its components not
//              counted: only `flank info` prints them).
//   index      search tree (oriented boxes, kernels/obb_tree.h) and adjacency build.
//   query      raw cold closest points (batch, no hints) at the sample points of the scoring
//              lines: the limit the other stages are measured against.
//   query_warm the same points line by line, each warm-started from the previous sample's
//              footpoint face (coherent queries, as movability and the fit ask them).
//   query_embree  the same points cold through Embree's BVH (QueryEngine::kEmbree): the
//              reference rate the box tree is judged against.
//   scoring    candidate-line movability, 2048 lines × 30 samples, warm hints along a line,
//              lines in parallel, as decompose issues them.
//   fit        one Gauss–Newton motion fit from a perturbed start; GN time shares.
//   decompose  the whole pipeline, time per stage. Its tolerance is the part's: 1e-3 × the
//              diagonal with cone and barrel cutters (cone only on the cone) for `cone` and
//              `blade`; the acceptance tolerance 1e-4 × the diagonal with every cutter kind
//              (the CLI's defaults) on the four faces, the product's real workload. The
//              `tolerance_rel` counter says which.
//   command    the same decompose as a user runs it: `flank decompose` in a process of its own,
//              timed from outside (start, reading the file, every output written), on the
//              rungs up to 64k triangles. The loop stages above run warm in one process; a
//              user's run is cold, and pays for loading the libraries, creating the threads
//              and faulting in fresh pages, which only this stage sees. Counters: the
//              process's own decompose time (patches.json), page faults, peak memory.
//              The last two come from GNU time (/usr/bin/time, Debian's `time`), which
//              starts flank: a child this process started itself would report this
//              process's peak as its own (Linux counts the memory of the process a spawn
//              starts from until the exec; gigabytes here, with the large rungs built).
//              Without /usr/bin/time the command is timed all the same, without them.
//              At one thread the process runs on one core (its affinity), as the two-thread
//              run runs on two: the command opens its CAD module on a thread of its own,
//              which, left free, takes the idle core at `--threads 1` and a share of the two
//              at `--threads 2`, so that from one thread to two the efficiency would count
//              the opening's 20-odd ms against the second core. Counter unpinned_s: the same
//              one-thread command run right after, on every core, as a user runs it.
// The lines, query points, fit starts and decompose tolerance depend on the part, not on the
// rung, so rungs of a part differ only in the mesh.
#include "bench/ladder.h"

#include <benchmark/benchmark.h>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <sched.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "bench/runs.h"
#include "io/read_mesh.h"
#include "io/write_mesh.h"
#include "kernels/mesh.h"
#include "kernels/movability.h"
#include "kernels/parallel.h"
#include "kernels/surface_index.h"
#include "solver/decompose.h"
#include "solver/fit_motion.h"
#include "solver/propagate.h"
#include "solver/synth.h"

extern char** environ;

namespace flank {
namespace {

constexpr int kLines = 2048;
constexpr int kSamples = 30;  // DESIGN: n = 30 samples per candidate line
// The decompose tolerance (× diagonal) of the cone and the blade. At the default 1e-4 the
// coarse rungs' own chord error is above the tolerance and no line is good enough to grow; at
// 1e-3 most rungs grow and fit candidates. The `grown` counter says how many, so that a rung's
// fit time is read with the work it did.
constexpr double kLadderTolerance = 1e-3;
// The real faces' decompose tolerance (× diagonal): the acceptance tests' (tests/
// decompose_acceptance.py), which users run them at.
constexpr double kAcceptanceTolerance = 1e-4;

enum class Part { cone, blade, hecc_a, hecc_b, rotor_upper, rotor_lower };

const char* name(Part p) {
  switch (p) {
    case Part::cone: return "cone";
    case Part::blade: return "blade";
    case Part::hecc_a: return "hecc_a";
    case Part::hecc_b: return "hecc_b";
    case Part::rotor_upper: return "rotor_upper";
    case Part::rotor_lower: return "rotor_lower";
  }
  return "";
}

// The file a read part comes from: every part but the cone, which is synthesised.
std::string mesh_path(Part p) {
  switch (p) {
    case Part::cone: break;
    case Part::blade: return FLANK_DATA_DIR "/propeller_blade_upper.stl";
    case Part::hecc_a: return FLANK_TEST_DATA_DIR "/hecc_splitter_blade_side_a.stl";
    case Part::hecc_b: return FLANK_TEST_DATA_DIR "/hecc_splitter_blade_side_b.stl";
    case Part::rotor_upper: return FLANK_TEST_DATA_DIR "/rotor67_blade_upper.stl";
    case Part::rotor_lower: return FLANK_TEST_DATA_DIR "/rotor67_blade_lower.stl";
  }
  return "";
}

// A rung: `level` is the cone's grid step count across (rows = 4·level + 1, cols = level + 1)
// or the number of subdivisions of a read part's mesh.
struct Rung {
  Part part;
  int level;
  long long triangles;
};

Mesh cone_mesh(int level) {
  SynthOptions so;
  so.cols = level + 1;
  so.rows = 4 * level + 1;
  return synth_envelope(guide_motion(paper_guides(), kPaperToolLength),
                        cone_profile(kPaperToolLength, 4, 7), so)
      .mesh;
}

// A read part's mesh as read (the blade's 522 triangles, a face's 24k–38k), kept for the
// process: the rungs are built from it and the part's lines and fit start drawn on it.
const Mesh& read_part(Part p) {
  static std::map<Part, Mesh> cache;
  static std::mutex mutex;
  const std::lock_guard lock(mutex);
  auto it = cache.find(p);
  if (it == cache.end()) it = cache.emplace(p, io::read_mesh(mesh_path(p)).mesh).first;
  return it->second;
}

// What one rung's benchmarks share, built on first use and kept for the process.
struct RungData {
  Mesh mesh;
  std::unique_ptr<SurfaceIndex> index;
  std::unique_ptr<SurfaceIndex> embree;  // built by the first query_embree benchmark
};

// What a part's rungs share: the scoring lines, their sample points, the fit start, how
// decompose runs.
struct PartData {
  std::vector<std::pair<Vec3, Vec3>> lines;
  Points samples;                 // kLines·kSamples rows, line by line
  std::optional<Motion> fit_start;
  CutterKind fit_kind = CutterKind::cone;
  std::string fit_error;
  double diagonal = 0.0;
  double decompose_tolerance = kLadderTolerance;  // × diagonal
  std::vector<CutterKind> decompose_kinds;
};

std::mutex cache_mutex;

RungData& rung_data(const Rung& r) {
  static std::map<std::pair<int, int>, std::unique_ptr<RungData>> cache;
  const std::lock_guard lock(cache_mutex);
  auto& slot = cache[{static_cast<int>(r.part), r.level}];
  if (!slot) {
    // Keep one rung in memory at a time: the million-triangle rungs are large.
    cache.clear();
    auto d = std::make_unique<RungData>();
    if (r.part == Part::cone) {
      d->mesh = cone_mesh(r.level);
    } else {
      d->mesh = read_part(r.part);
      for (int k = 0; k < r.level; ++k) d->mesh = subdivide_midpoint(d->mesh);
    }
    d->index = std::make_unique<SurfaceIndex>(d->mesh);
    auto& fresh = cache[{static_cast<int>(r.part), r.level}];
    fresh = std::move(d);
    return *fresh;
  }
  return *slot;
}

// Candidate-like lines over a reference mesh of the part: a point on Φ (area-weighted), lifted
// 2% of the diagonal along the normal, a random direction in the tangent plane, 30% of the
// diagonal long.
void make_lines(const Mesh& reference, PartData& p) {
  const VecX area = face_areas(reference);
  const Points normals = face_normals(reference);
  p.diagonal = bbox_diagonal(reference);
  std::mt19937 rng(20261121);
  std::discrete_distribution<int> face(area.data(), area.data() + area.size());
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  p.samples.resize(static_cast<Eigen::Index>(kLines) * kSamples, 3);
  for (int l = 0; l < kLines; ++l) {
    const int f = face(rng);
    double u = unit(rng), v = unit(rng);
    if (u + v > 1) u = 1 - u, v = 1 - v;
    const Vec3 a = reference.V.row(reference.F(f, 0)), b = reference.V.row(reference.F(f, 1)),
               c = reference.V.row(reference.F(f, 2));
    const Vec3 n = normals.row(f);
    const Vec3 t1 = (b - a).normalized(), t2 = n.cross(t1);
    const double angle = 2 * std::numbers::pi * unit(rng);
    const Vec3 dir = std::cos(angle) * t1 + std::sin(angle) * t2;
    const Vec3 mid = a + u * (b - a) + v * (c - a) + 0.02 * p.diagonal * n;
    const Vec3 e0 = mid - 0.15 * p.diagonal * dir, e1 = mid + 0.15 * p.diagonal * dir;
    p.lines.emplace_back(e0, e1);
    for (int i = 0; i < kSamples; ++i) {
      const double s = static_cast<double>(i) / (kSamples - 1);
      p.samples.row(l * kSamples + i) = ((1 - s) * e0 + s * e1).transpose();
    }
  }
}

// Seven lines across a motion, 2% of their length off it and turned 2°: a start the fit has
// to work from, as a propagated candidate is.
Motion perturbed_start(const AxisMotion& motion) {
  std::vector<Line> lines;
  for (int i = 0; i < 7; ++i) {
    const double t = i / 6.0;
    const Vec3 a = motion.a(t, 0), b = motion.b(t, 0);
    const double length = (b - a).norm();
    const Vec3 u = (b - a) / length;
    const Vec3 n = (i % 2 ? 1.0 : -1.0) * u.cross(motion.a(t, 1)).normalized();
    const Vec3 mid = 0.5 * (a + b) + 0.02 * length * n;
    const Vec3 u2 = Eigen::AngleAxisd(2.0 * std::numbers::pi / 180.0, u.cross(n)) * u;
    lines.push_back({mid - 0.5 * length * u2, mid + 0.5 * length * u2});
  }
  return motion_from_lines(lines, 40);
}

const PartData& part_data(Part part) {
  static std::map<Part, std::unique_ptr<PartData>> cache;
  static std::mutex mutex;
  const std::lock_guard lock(mutex);
  auto& slot = cache[part];
  if (slot) return *slot;
  slot = std::make_unique<PartData>();
  PartData& p = *slot;
  if (part == Part::cone) {
    make_lines(cone_mesh(60), p);
    p.fit_start = perturbed_start(guide_motion(paper_guides(), kPaperToolLength));
    p.fit_kind = CutterKind::cone;
    p.decompose_kinds = {CutterKind::cone};
  } else {
    // A read part's own motion is unknown: start the fit from the patch decompose finds on
    // the part as read (the coarse blade, a face at its native resolution) at a loose
    // tolerance, perturbed. The surface is the same on every rung.
    const Mesh& base = read_part(part);
    make_lines(base, p);
    if (part == Part::blade) {
      p.decompose_kinds = {CutterKind::cone, CutterKind::barrel};
    } else {
      p.decompose_tolerance = kAcceptanceTolerance;
      p.decompose_kinds = DecomposeOptions{}.kinds;
    }
    const SurfaceIndex index(base);
    DecomposeOptions o;
    o.tolerance = kLadderTolerance * index.diagonal();
    o.kinds = p.decompose_kinds;
    const DecomposeResult r = decompose(index, o);
    if (r.patches.empty()) {
      p.fit_error = std::string("decompose found no patch on ") + name(part) +
                    " as read (tolerance 1e-3) to start a fit from";
    } else {
      p.fit_start = perturbed_start(spline_motion(r.patches.front().motion));
      p.fit_kind = r.patches.front().cutter.kind;
    }
  }
  return p;
}

void bench_index(benchmark::State& state, Rung r, int threads) {
  const Mesh& mesh = rung_data(r).mesh;
  const ThreadLimit limit(threads);
  for (auto _ : state) {
    const SurfaceIndex index(mesh);
    benchmark::DoNotOptimize(&index);
  }
  state.counters["triangles"] = static_cast<double>(mesh.face_count());
}

void query_counters(benchmark::State& state, const SurfaceIndex& index, Eigen::Index rows) {
  const auto queries = static_cast<double>(rows);
  state.counters["triangles"] = static_cast<double>(index.mesh().face_count());
  state.counters["queries"] = queries;
  state.counters["queries_per_s"] =
      benchmark::Counter(queries * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void bench_query(benchmark::State& state, Rung r, int threads) {
  const SurfaceIndex& index = *rung_data(r).index;
  const PartData& p = part_data(r.part);
  const ThreadLimit limit(threads);
  // Cold: no hint for any query (an empty hint list would chain each to the previous answer).
  const std::vector<int> cold(static_cast<std::size_t>(p.samples.rows()), -1);
  for (auto _ : state) {
    const std::vector<ClosestPoint> cp = index.closest_points(p.samples, cold);
    benchmark::DoNotOptimize(cp.data());
  }
  query_counters(state, index, p.samples.rows());
}

void bench_query_warm(benchmark::State& state, Rung r, int threads) {
  const SurfaceIndex& index = *rung_data(r).index;
  const PartData& p = part_data(r.part);
  const ThreadLimit limit(threads);
  const auto lines = static_cast<std::size_t>(p.samples.rows() / kSamples);
  std::vector<int> faces(static_cast<std::size_t>(p.samples.rows()));
  for (auto _ : state) {
    parallel_for(0, lines, [&](std::size_t b, std::size_t e) {
      for (std::size_t l = b; l < e; ++l) {
        int hint = -1;
        for (int i = 0; i < kSamples; ++i) {
          const auto row = static_cast<Eigen::Index>(l * kSamples + static_cast<std::size_t>(i));
          hint = index.closest_point(p.samples.row(row), hint).face;
          faces[static_cast<std::size_t>(row)] = hint;
        }
      }
    }, 16);
    benchmark::DoNotOptimize(faces.data());
  }
  query_counters(state, index, p.samples.rows());
}

void bench_query_embree(benchmark::State& state, Rung r, int threads) {
  RungData& d = rung_data(r);
  {
    const std::lock_guard lock(cache_mutex);
    if (!d.embree) d.embree = std::make_unique<SurfaceIndex>(d.mesh, QueryEngine::kEmbree);
  }
  const SurfaceIndex& index = *d.embree;
  const PartData& p = part_data(r.part);
  const ThreadLimit limit(threads);
  // Cold: no hint for any query (an empty hint list would chain each to the previous answer).
  const std::vector<int> cold(static_cast<std::size_t>(p.samples.rows()), -1);
  for (auto _ : state) {
    const std::vector<ClosestPoint> cp = index.closest_points(p.samples, cold);
    benchmark::DoNotOptimize(cp.data());
  }
  query_counters(state, index, p.samples.rows());
}

void bench_scoring(benchmark::State& state, Rung r, int threads) {
  const SurfaceIndex& index = *rung_data(r).index;
  const PartData& p = part_data(r.part);
  const ThreadLimit limit(threads);
  MovabilityOptions mo;
  mo.samples = kSamples;
  std::vector<double> values(p.lines.size());
  for (auto _ : state) {
    parallel_for(0, p.lines.size(), [&](std::size_t b, std::size_t e) {
      std::vector<int> hints(kSamples, -1);
      for (std::size_t k = b; k < e; ++k) {
        std::fill(hints.begin(), hints.end(), -1);
        values[k] = movability(index, p.lines[k].first, p.lines[k].second, mo, hints).value;
      }
    }, 16);
    benchmark::DoNotOptimize(values.data());
  }
  state.counters["triangles"] = static_cast<double>(index.mesh().face_count());
  state.counters["samples"] = kSamples;
  state.counters["lines_per_s"] = benchmark::Counter(
      static_cast<double>(p.lines.size()) * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void bench_fit(benchmark::State& state, Rung r, int threads) {
  const PartData& p = part_data(r.part);
  if (!p.fit_start) {
    state.SkipWithError(p.fit_error.c_str());
    return;
  }
  const SurfaceIndex& index = *rung_data(r).index;
  const ThreadLimit limit(threads);
  FitOptions fo;
  fo.kind = p.fit_kind;
  bench::run_fit(state, index, *p.fit_start, fo);
}

void bench_decompose(benchmark::State& state, Rung r, int threads) {
  const Mesh& mesh = rung_data(r).mesh;
  const PartData& p = part_data(r.part);
  const ThreadLimit limit(threads);
  bench::run_decompose(state, mesh, p.decompose_tolerance, p.decompose_kinds);
  // What the report states beside each decompose row: the parts run at different tolerances.
  state.counters["tolerance_rel"] = p.decompose_tolerance;
  state.counters["cutter_kinds"] = static_cast<double>(p.decompose_kinds.size());
}

// A folder of this process's own for the command stage's files, removed at exit.
const std::filesystem::path& scratch_dir() {
  struct Scratch {
    std::filesystem::path path;
    Scratch() {
      path = std::filesystem::temp_directory_path() / ("flank-ladder-" + std::to_string(::getpid()));
      std::filesystem::create_directories(path);
    }
    ~Scratch() {
      std::error_code ignored;
      std::filesystem::remove_all(path, ignored);
    }
  };
  static const Scratch scratch;
  return scratch.path;
}

// The rung as the file a user would give: a read part's own file, or the rung's mesh written.
std::filesystem::path command_input(const Rung& r) {
  if (r.part != Part::cone && r.level == 0) return mesh_path(r.part);
  const std::filesystem::path path =
      scratch_dir() / (std::string(name(r.part)) + "_" + std::to_string(r.level) + ".ply");
  if (!std::filesystem::exists(path)) io::write_mesh(path, rung_data(r).mesh);
  return path;
}

void bench_read(benchmark::State& state, Rung r, int threads) {
  const std::filesystem::path input = command_input(r);
  const ThreadLimit limit(threads);
  int triangles = 0;
  io::ReadOptions as_the_command_reads;  // cli/common.cpp, read_design
  as_the_command_reads.count_components = false;
  for (auto _ : state) {
    const io::LoadedMesh m = io::read_mesh(input.string(), as_the_command_reads);
    triangles = m.mesh.face_count();
    benchmark::DoNotOptimize(&m);
  }
  state.counters["triangles"] = static_cast<double>(triangles);
}

constexpr const char* kGnuTime = "/usr/bin/time";

// While alive, the calling thread (and the processes it starts, which inherit its affinity)
// runs only on the first core it may run on; the affinity it had is restored after. Where
// the affinity cannot be read or set, nothing changes.
class OneCore {
 public:
  OneCore() {
    if (sched_getaffinity(0, sizeof before_, &before_) != 0) return;
    for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu)
      if (CPU_ISSET(cpu, &before_)) {
        cpu_set_t one;
        CPU_ZERO(&one);
        CPU_SET(cpu, &one);
        pinned_ = sched_setaffinity(0, sizeof one, &one) == 0;
        return;
      }
  }
  ~OneCore() {
    if (pinned_) sched_setaffinity(0, sizeof before_, &before_);
  }
  OneCore(const OneCore&) = delete;
  OneCore& operator=(const OneCore&) = delete;

 private:
  cpu_set_t before_{};
  bool pinned_ = false;
};

void bench_command(benchmark::State& state, Rung r, int threads) {
  const PartData& p = part_data(r.part);
  const std::filesystem::path input = command_input(r);
  const std::filesystem::path out = scratch_dir() / "out";
  std::string tools;
  for (CutterKind k : p.decompose_kinds) {
    if (!tools.empty()) tools += ',';
    tools += to_string(k);
  }
  char tolerance[32];
  std::snprintf(tolerance, sizeof tolerance, "%g", p.decompose_tolerance);
  std::vector<std::string> args = {FLANK_CLI, "decompose", input.string(), "-o", out.string(), "-q",
                                   "--threads", std::to_string(threads), "--tolerance-rel", tolerance};
  if (!tools.empty()) args.insert(args.end(), {"--tool", tools});
  // GNU time runs flank from its own, small process and writes flank's peak resident KB
  // and minor and major page faults to `usage_file`.
  const std::filesystem::path usage_file = scratch_dir() / "usage.txt";
  const bool measured = access(kGnuTime, X_OK) == 0;
  if (measured) args.insert(args.begin(), {kGnuTime, "-f", "%M %R %F", "-o", usage_file.string()});
  static const bool warned = [&] {
    if (!measured) std::cerr << "Ladder/command: no " << kGnuTime << " (Debian's `time`): no page faults or peak memory\n";
    return true;
  }();
  (void)warned;
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t quiet;
  posix_spawn_file_actions_init(&quiet);
  posix_spawn_file_actions_addopen(&quiet, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&quiet, 2, "/dev/null", O_WRONLY, 0);
  // Runs the command to its end; false (the state told why) if it could not start or failed.
  const auto run = [&] {
    pid_t pid = 0;
    if (posix_spawn(&pid, argv[0], &quiet, nullptr, argv.data(), environ) != 0) {
      state.SkipWithError((std::string("cannot start ") + argv[0]).c_str());
      return false;
    }
    int status = 0;
    if (waitpid(pid, &status, 0) != pid || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
      state.SkipWithError(("flank decompose " + input.string() + " failed").c_str());
      return false;
    }
    return true;
  };
  double faults = 0, peak_kb = 0, decompose_s = 0, unpinned_s = 0;
  for (auto _ : state) {
    {
      std::optional<OneCore> one_core;
      if (threads == 1) one_core.emplace();
      if (!run()) break;
    }
    state.PauseTiming();
    if (measured) {
      double kb = 0, minor = 0, major = 0;
      std::ifstream in(usage_file);
      if (!(in >> kb >> minor >> major)) {
        state.SkipWithError(("no usage in " + usage_file.string()).c_str());
        break;
      }
      faults += minor + major;
      peak_kb = std::max(peak_kb, kb);
    }
    try {
      std::ifstream in(out / "patches.json");
      decompose_s += nlohmann::json::parse(in).at("timing_s").at("total").get<double>();
    } catch (const std::exception& e) {
      state.SkipWithError(("no decompose time in " + (out / "patches.json").string() + ": " + e.what()).c_str());
      break;
    }
    if (threads == 1) {
      const auto start = std::chrono::steady_clock::now();
      if (!run()) break;
      unpinned_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    }
    state.ResumeTiming();
  }
  posix_spawn_file_actions_destroy(&quiet);
  const auto n = static_cast<double>(std::max<benchmark::IterationCount>(1, state.iterations()));
  state.counters["triangles"] = static_cast<double>(rung_data(r).mesh.face_count());
  state.counters["decompose_s"] = decompose_s / n;
  if (threads == 1) state.counters["unpinned_s"] = unpinned_s / n;
  if (measured) {
    state.counters["page_faults"] = faults / n;
    state.counters["peak_mb"] = peak_kb / 1024.0;
  }
  state.counters["tolerance_rel"] = p.decompose_tolerance;
}

// A ladder benchmark; at two threads, with the cache line's round trip between the cores
// measured just before it (counter line_rt_ns, bench::line_round_trip_ns).
void probed(benchmark::State& state, void (*fn)(benchmark::State&, Rung, int), Rung r,
            int threads) {
  const double round_trip = threads == 2 ? bench::line_round_trip_ns() : 0.0;
  fn(state, r, threads);
  if (threads == 2) state.counters["line_rt_ns"] = round_trip;
}

}  // namespace

void register_ladder_benchmarks() {
  std::vector<Rung> rungs;
  for (int level : {11, 22, 45, 89, 179, 358})  // 8·level² triangles: 1k … 1M
    rungs.push_back({Part::cone, level, 8LL * level * level});
  // Read parts: (part, subdivision levels). The blade's 522 triangles are too few for a rung;
  // a face's native mesh is what users run, and rotor_upper's second subdivision (614k) is
  // the faces' large rung.
  const std::pair<Part, std::vector<int>> read_parts[] = {
      {Part::blade, {1, 2, 3, 4, 5}}, {Part::hecc_a, {0, 1}},          {Part::hecc_b, {0, 1}},
      {Part::rotor_upper, {0, 1, 2}}, {Part::rotor_lower, {0, 1}}};
  for (const auto& [part, levels] : read_parts) {
    try {
      const long long base = read_part(part).face_count();
      for (int level : levels) rungs.push_back({part, level, base << (2 * level)});
    } catch (const std::exception& e) {
      std::cerr << "ladder: the " << name(part) << " rungs are left out: " << e.what() << "\n";
    }
  }
  using Fn = void (*)(benchmark::State&, Rung, int);
  const std::pair<const char*, Fn> stages[] = {
      {"index", bench_index},          {"query", bench_query},     {"query_warm", bench_query_warm},
      {"query_embree", bench_query_embree}, {"scoring", bench_scoring}, {"fit", bench_fit},
      {"decompose", bench_decompose}, {"command", bench_command}};
  // The whole command up to 64k triangles: the faces as read (24k-38k, what users run) and the
  // cone and blade rungs around them. What it adds to the decompose stage, the start and the
  // outputs, does not need the nightly ladder's large rungs.
  constexpr long long kCommandMaxTriangles = 65'000;
  const auto bench_name = [](std::string_view stage, const Rung& r, int threads) {
    return "Ladder/" + std::string(stage) + "/" + name(r.part) + "/tri_k:" +
           std::to_string(std::llround(static_cast<double>(r.triangles) / 1000.0)) + "/threads:" +
           std::to_string(threads);
  };
  // Rung by rung, so that each mesh is built once.
  for (const Rung& r : rungs)
    for (const auto& [stage, fn] : stages)
      for (int threads : {1, 2}) {
        if (std::string_view(stage) == "command" && r.triangles > kCommandMaxTriangles) continue;
        // No MinTime or Iterations here: they would become part of the name. The script passes
        // --benchmark_min_time; decompose runs once whenever it takes longer than that.
        benchmark::RegisterBenchmark(bench_name(stage, r, threads).c_str(), probed, fn, r, threads)
            ->UseRealTime()
            ->Unit(std::string(stage) == "decompose" || std::string(stage) == "command" ? benchmark::kSecond
                                                                                       : benchmark::kMillisecond);
      }
  // The read stage after every other (benchmarks run in the order registered, the ladder in
  // one process): run first for each rung, its buffers moved where the rung's own data landed
  // in memory, and the queries after it ran 10-17% slower on the small cones in a --check
  // against the baseline (the two binaries alone: the same speed). A rung's mesh is built again
  // here only where its file was not written before (over 64k triangles).
  for (const Rung& r : rungs)
    for (int threads : {1, 2})
      benchmark::RegisterBenchmark(bench_name("read", r, threads).c_str(), probed, bench_read, r,
                                   threads)
          ->UseRealTime()
          ->Unit(benchmark::kMillisecond);
}

}  // namespace flank
