// flank_grow_pairs: a change to the fit judged on the very candidates decompose grows.
//
// decompose's outcome is chaotic: any change to how a candidate is fitted picks other lines
// later, then other patches, and moves a part's final coverage by a few points either way
// (scripts/coverage_curves.py --spread). This runs decompose once with its defaults (A) and,
// as each candidate is grown, grows the same candidate again with other fit settings (B). The
// pairs differ only by the settings: the best piece's covered area and the growth time of
// each, over every candidate of the run. The times are of A grown once more beside B on the
// same thread, A first for half of the candidates and B first for the other half (the second
// growth of a candidate finds its part of the index in the cache); that growth must repeat
// decompose's A exactly, and the tool fails where it does not.
//
//   flank_grow_pairs MESH [--tolerance-rel 1e-4] [--threads 2] [--iterations N]
//                         [--refit-iterations N] [--samples TxS] [--extrapolations N] [--same]
//                         [--json FILE]
//
// --same makes B exactly A: every pair's areas are then equal, and the time ratio is the
// noise floor of the measurement.
//
// Prints one line: the candidates, the summed best areas of A and B and their ratio, how many
// candidates B grows into a valid patch where A does not and the other way round, and the
// summed growth times and their ratio. --json writes every pair (sorted by the candidate's
// line, so the file does not depend on the order the tasks finish in).
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <string>
#include <string_view>
#include <tuple>
#include <vector>

#include "io/read_mesh.h"
#include "io/write_mesh.h"
#include "kernels/memory.h"
#include "kernels/parallel.h"
#include "solver/decompose.h"

namespace {

struct Pair {
  std::array<double, 6> line;  // the candidate's ends: the sort key
  double best_a = 0, best_b = 0;
  int valid_a = 0, valid_b = 0;
  double seconds_a = 0, seconds_b = 0;
};

double best_area(const flank::Grown& g) { return g.patches.empty() ? 0.0 : g.patches.front().covered_area; }

}  // namespace

int main(int argc, char** argv) {
  flank::retain_freed_memory();  // as the flank command line runs
  if (const char* h = std::getenv("FLANK_HUGE_PAGES"); !h || std::string_view(h) != "0") flank::prefer_huge_pages();
  CLI::App app{"Grow decompose's candidates twice, with its fit settings (A) and with others (B)"};
  std::string mesh_path, json_path;
  double tolerance_rel = 1e-4;
  int threads = 2, iterations = 0, refit_iterations = 0, extrapolations = -1;
  std::string samples;
  app.add_option("MESH", mesh_path, "STL, OBJ or PLY mesh")->required();
  app.add_option("--tolerance-rel", tolerance_rel, "Allowed error as a fraction of the bbox diagonal")
      ->check(CLI::PositiveNumber);
  app.add_option("--threads", threads, "Worker threads")->check(CLI::Range(1, 1024));
  app.add_option("--iterations", iterations, "B: Gauss-Newton iterations of a first fit")->check(CLI::Range(1, 1000));
  app.add_option("--refit-iterations", refit_iterations, "B: iterations of a refit (after a trim, of a piece)")
      ->check(CLI::Range(1, 1000));
  app.add_option("--samples", samples, "B: fit samples along the motion x along the axis, e.g. 48x16");
  app.add_option("--extrapolations", extrapolations, "B: step extensions (up to 2^N steps)")->check(CLI::Range(0, 10));
  bool same = false;
  app.add_flag("--same", same, "B is A (the time ratio is then the measurement's noise)");
  app.add_option("--json", json_path, "Write every pair here");
  CLI11_PARSE(app, argc, argv);
  if (same == (iterations > 0 || refit_iterations > 0 || !samples.empty() || extrapolations >= 0)) {
    std::fprintf(stderr, "flank_grow_pairs: give B's fit settings, or --same (not both)\n");
    return 2;
  }
  int samples_t = 0, samples_s = 0;
  if (!samples.empty() && (std::sscanf(samples.c_str(), "%dx%d", &samples_t, &samples_s) != 2 || samples_t < 8 ||
                           samples_s < 4)) {
    std::fprintf(stderr, "flank_grow_pairs: --samples %s: expected TxS, at least 8x4, e.g. 48x16\n", samples.c_str());
    return 2;
  }

  try {
    flank::ThreadLimit limit(threads);
    const flank::io::LoadedMesh lm = flank::io::read_mesh(mesh_path);
    const flank::SurfaceIndex index(lm.mesh);
    flank::DecomposeOptions o;
    o.tolerance = tolerance_rel * index.diagonal();
    std::mutex mutex;
    std::vector<Pair> pairs;
    int not_repeated = 0;
    o.on_grown = [&](const flank::SurfaceIndex& work, const flank::LineCandidate& c, const flank::GrowOptions& go,
                     const flank::Grown& a) {
      flank::GrowOptions gb = go;
      if (iterations > 0) gb.fit.max_iterations = iterations;
      if (refit_iterations > 0) gb.refit_iterations = refit_iterations;
      if (samples_t > 0) gb.fit.samples_t = samples_t, gb.fit.samples_s = samples_s;
      if (extrapolations >= 0) gb.fit.max_extrapolations = extrapolations;
      // Which goes first: a bit of the candidate's line, so that it does not depend on timing.
      const bool b_first = (std::bit_cast<std::uint64_t>(c.line.a.x() + c.line.b.y()) >> 12) & 1;
      flank::Grown again, b;
      if (b_first) b = flank::grow_patch(work, c, gb);
      again = flank::grow_patch(work, c, go);
      if (!b_first) b = flank::grow_patch(work, c, gb);
      Pair p{{c.line.a.x(), c.line.a.y(), c.line.a.z(), c.line.b.x(), c.line.b.y(), c.line.b.z()},
             best_area(a), best_area(b), static_cast<int>(a.patches.size()), static_cast<int>(b.patches.size()),
             again.seconds, b.seconds};
      const std::lock_guard<std::mutex> lock(mutex);
      pairs.push_back(p);
      if (best_area(again) != best_area(a) || again.patches.size() != a.patches.size()) ++not_repeated;
    };
    if (std::string e = o.validate(); !e.empty()) {
      std::fprintf(stderr, "flank_grow_pairs: %s\n", e.c_str());
      return 2;
    }
    const flank::DecomposeResult r = flank::decompose(index, o);
    if (not_repeated > 0) {
      std::fprintf(stderr, "flank_grow_pairs: %s: %d candidates grew otherwise when grown again with A's settings\n",
                   mesh_path.c_str(), not_repeated);
      return 1;
    }
    std::sort(pairs.begin(), pairs.end(), [](const Pair& x, const Pair& y) {
      return std::tie(x.line, x.best_a, x.best_b) < std::tie(y.line, y.best_a, y.best_b);
    });
    double area_a = 0, area_b = 0, time_a = 0, time_b = 0;
    int only_a = 0, only_b = 0;
    for (const Pair& p : pairs) {
      area_a += p.best_a, area_b += p.best_b, time_a += p.seconds_a, time_b += p.seconds_b;
      only_a += p.valid_a > 0 && p.valid_b == 0;
      only_b += p.valid_b > 0 && p.valid_a == 0;
    }
    std::printf("%s: %zu candidates; best area A %.6g B %.6g mm^2 (B/A %.4f); valid only with A %d, only with B %d; "
                "growth A %.3f s B %.3f s (B/A %.3f); decompose: %zu patches, %.2f%%\n",
                mesh_path.c_str(), pairs.size(), area_a, area_b, area_a > 0 ? area_b / area_a : 1.0, only_a, only_b,
                time_a, time_b, time_a > 0 ? time_b / time_a : 1.0, r.patches.size(), 100.0 * r.coverage);
    if (!json_path.empty()) {
      nlohmann::json j;
      j["mesh"] = mesh_path;
      j["tolerance_rel"] = tolerance_rel;
      j["columns"] = {"best_area_a", "best_area_b", "valid_a", "valid_b", "seconds_a", "seconds_b"};
      j["pairs"] = nlohmann::json::array();
      for (const Pair& p : pairs)
        j["pairs"].push_back({p.best_a, p.best_b, p.valid_a, p.valid_b, p.seconds_a, p.seconds_b});
      flank::io::write_file_atomic(json_path, [&](std::ostream& f) { f << j.dump() << "\n"; });
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "flank_grow_pairs: %s\n", e.what());
    return 1;
  }
  return 0;
}
