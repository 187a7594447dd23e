#include "solver/decompose.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <mutex>
#include <optional>

#include "kernels/parallel.h"
#include "solver/candidate_lines.h"
#include "solver/grow_patch.h"
#include "solver/seed_tiles.h"
#include "solver/surface_noise.h"
#include "solver/thresholds.h"

namespace flank {

std::string DecomposeOptions::validate() const {
  if (!(tolerance > 0.0) || !std::isfinite(tolerance)) return "tolerance must be positive";
  if (kinds.empty()) return "at least one cutter kind is needed";
  if (radius_min < 0 || radius_max < 0 || (radius_max > 0 && radius_min > radius_max))
    return "--radius MIN,MAX needs 0 < MIN <= MAX";
  if (length_min < 0 || length_max < 0 || (length_max > 0 && length_min > length_max))
    return "--length MIN,MAX needs 0 < MIN <= MAX";
  if (holder && !(holder_length > 0 && holder_radius > 0)) return "holder length and radius must be positive";
  if (!(coverage_target > 0 && coverage_target <= 1)) return "coverage target must be in (0, 1]";
  if (max_patches < 1) return "the patch cap must be at least 1";
  if (max_rounds < 1) return "at least one seeding round is needed";
  if (!(min_gain >= 0 && min_gain < 1)) return "the minimum gain must be in [0, 1)";
  if (!(min_round_gain >= 0 && min_round_gain < 1)) return "the minimum gain of a round must be in [0, 1)";
  if (!(seed_spacing > 0 && seed_spacing < 1) || max_seeds < 1) return "seed settings out of range";
  if (directions < 1 || tilts < 1 || radii < 1 || directions_kept < 1 || lengths < 1)
    return "candidate counts must be positive";
  if (!(probe_step > 0 && probe_step < 0.1)) return "the probe step must be in (0, 0.1) of the diagonal";
  if (grow_per_round < 1 || batch < 1) return "growth counts must be positive";
  if (control_points < 4) return "a motion needs at least 4 control points";
  if (samples_t < 8 || samples_s < 4) return "fit sample counts out of range";
  if (iterations < 1 || refit_iterations < 1) return "fit iterations must be positive";
  if (final_rows < 2 || final_cols < 2 || !(final_spacing > 0 && final_spacing < 1))
    return "final evaluation settings out of range";
  return {};
}

ToolRanges tool_ranges(const DecomposeOptions& o, double diagonal) {
  return {o.radius_min > 0 ? o.radius_min : DecomposeOptions::kDefaultRadiusMin * diagonal,
          o.radius_max > 0 ? o.radius_max : DecomposeOptions::kDefaultRadiusMax * diagonal,
          o.length_min > 0 ? o.length_min : DecomposeOptions::kDefaultLengthMin * diagonal,
          o.length_max > 0 ? o.length_max : DecomposeOptions::kDefaultLengthMax * diagonal};
}

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Kinds from the simplest to the most general: each contains the ones before it.
std::vector<CutterKind> by_generality(std::vector<CutterKind> kinds) {
  std::sort(kinds.begin(), kinds.end(),
            [](CutterKind a, CutterKind b) { return coefficient_count(a) < coefficient_count(b); });
  kinds.erase(std::unique(kinds.begin(), kinds.end()), kinds.end());
  return kinds;
}

CoveredFaces faces_of(const Mesh& mesh, const std::vector<int>& vertex_patch) {
  CoveredFaces covered(static_cast<std::size_t>(mesh.face_count()), 0);
  for (int f = 0; f < mesh.face_count(); ++f)
    covered[static_cast<std::size_t>(f)] =
        vertex_patch[mesh.F(f, 0)] >= 0 && vertex_patch[mesh.F(f, 1)] >= 0 && vertex_patch[mesh.F(f, 2)] >= 0;
  return covered;
}

// What a grown patch claims: the Φ vertices it covers and its mean axis direction.
struct Claim {
  std::vector<char> vertices;
  Vec3 axis = Vec3::Zero();
};

Claim claim_of(const Patch& p, int vertex_count) {
  Claim c;
  c.vertices.assign(static_cast<std::size_t>(vertex_count), 0);
  for (int v : p.covered_vertices) c.vertices[static_cast<std::size_t>(v)] = 1;
  for (int k = 0; k <= 8; ++k) {
    const Line l = p.motion.ruling(k / 8.0);
    c.axis += (l.b - l.a).normalized();
  }
  c.axis.normalize();
  return c;
}

// A candidate whose line lies mostly over area that a grown patch covers with an axis in about
// the same direction would grow that patch again. One across it may cut the same area in
// another way, and better.
bool already_claimed(const SurfaceIndex& index, const LineCandidate& c, const std::vector<Claim>& claims) {
  constexpr int kSamples = 16;
  const double cos_same = std::cos(20.0 * 3.14159265358979323846 / 180.0);
  const Vec3 u = (c.line.b - c.line.a).normalized();
  std::vector<int> faces;
  int hint = -1;
  for (int k = 0; k < kSamples; ++k) {
    const ClosestPoint cp = index.closest_point(c.line.point((k + 0.5) / kSamples), hint);
    if (cp.face < 0 || cp.boundary) continue;
    hint = cp.face;
    faces.push_back(cp.face);
  }
  if (faces.empty()) return false;
  const Mesh& m = index.mesh();
  for (const Claim& claim : claims) {
    if (std::abs(claim.axis.dot(u)) < cos_same) continue;
    int on = 0;
    for (int f : faces)
      on += claim.vertices[m.F(f, 0)] && claim.vertices[m.F(f, 1)] && claim.vertices[m.F(f, 2)];
    if (on >= 0.7 * static_cast<double>(faces.size())) return true;
  }
  return false;
}

// A later round often lays out exactly a line an earlier one grew: where the cover changed
// little, the same seeds find the same lines, and growth is deterministic. Its result is
// remembered and reused (the same pieces, in the same place of the pool), not fitted again.
struct GrownCache {
  struct Entry {
    Line line;
    CutterKind kind;
    std::vector<Line> rulings;
    Grown grown;
  };
  std::vector<Entry> entries;

  static bool same(const Line& x, const Line& y) { return x.a == y.a && x.b == y.b; }
  const Grown* find(const LineCandidate& c) const {
    for (const Entry& e : entries) {
      if (e.kind != c.kind || !same(e.line, c.line) || e.rulings.size() != c.sweep.rulings.size()) continue;
      if (std::equal(e.rulings.begin(), e.rulings.end(), c.sweep.rulings.begin(), same)) return &e.grown;
    }
    return nullptr;
  }
};

// Farthest-point seeding over what is still uncovered repeats most of a round's seeds once
// the cover changes little (on Rotor 67's lower face 21 of the fourth round's 24). Which lines
// a seed's search finds depends on the cover only through the free runs it lays them over;
// how much of what is still to cut their sweeps pass over is counted again for the new cover
// without a query (rank_candidates). A seed met again whose free runs all come out the same
// under the new cover (a few hundred queries, against some 30,000 for its search) would find
// the same lines: they are reused.
struct SeedCache {
  struct Entry {
    Seed seed;
    std::vector<FreeRunRecord> runs;
    std::vector<LineCandidate> lines;
  };
  std::vector<Entry> entries;

  static bool same(const Seed& x, const Seed& y) {
    return x.vertex == y.vertex && x.point == y.point && x.normal == y.normal && x.dir_min == y.dir_min &&
           x.dir_max == y.dir_max && x.k_min == y.k_min && x.k_max == y.k_max;
  }
  // The lines of the latest search at `seed` whose free runs hold under `covered`, or null.
  // Reads only: safe from concurrent tasks.
  const std::vector<LineCandidate>* find(const SurfaceIndex& index, const Seed& seed,
                                         const CoveredFaces& covered) const {
    for (auto e = entries.rbegin(); e != entries.rend(); ++e)
      if (same(e->seed, seed)) return free_runs_hold(index, e->runs, covered) ? &e->lines : nullptr;
    return nullptr;
  }
};

// The seeding of a round (SeedOptions::allowed aside): seed_spacing apart over all of Φ in
// round 0, half that over what is still uncovered after.
SeedOptions seed_options(const DecomposeOptions& o, double diagonal, int round) {
  SeedOptions so;
  so.spacing = (round == 0 ? 1.0 : 0.5) * o.seed_spacing * diagonal;
  so.max_seeds = o.max_seeds;
  return so;
}

// The stages' options, derived once from the decomposition's.
struct StageOptions {
  CandidateLineOptions lines;  // step 2
  GrowOptions grow;            // step 3
  CoverOptions cover;          // step 4
  FinishOptions finish;        // step 5
};

StageOptions stage_options(const DecomposeOptions& o, const std::vector<CutterKind>& kinds, double diagonal,
                           const SurfaceIndex* given) {
  const ToolRanges R = tool_ranges(o, diagonal);
  StageOptions s;
  CandidateLineOptions& lo = s.lines;
  lo.kinds = kinds;
  lo.radius_min = R.radius_min, lo.radius_max = R.radius_max;
  lo.length_min = R.length_min, lo.length_max = R.length_max;
  lo.directions = o.directions, lo.tilts = o.tilts, lo.radii = o.radii;
  lo.directions_kept = o.directions_kept, lo.lengths = o.lengths;
  lo.step = o.probe_step * diagonal;
  lo.max_travel = 2.0 * diagonal;
  lo.trace = o.trace;

  GrowOptions& go = s.grow;
  go.fit.kind = kinds.back();
  go.fit.control_points = o.control_points;
  go.fit.samples_t = o.samples_t;
  go.fit.samples_s = o.samples_s;
  go.fit.max_iterations = o.iterations;
  go.refit_iterations = o.refit_iterations;
  go.fit.max_extrapolations = o.extrapolations;
  go.fit.radius_min = R.radius_min;
  go.fit.radius_max = R.radius_max;
  go.length_min = R.length_min;
  go.evaluate.rows = 2 * o.samples_t;
  go.evaluate.cols = 2 * o.samples_s;
  go.evaluate.spacing = 2.0 * o.final_spacing * diagonal;
  go.evaluate.envelope = false;
  go.evaluate.vertex_side = false;  // candidates compete on coverage; the chosen get the full report
  go.evaluate.refine_max = 0;
  go.evaluate.holder = o.holder;
  go.evaluate.holder_length = o.holder_length;
  go.evaluate.holder_radius = o.holder_radius;
  go.thresholds = thresholds_for(o.tolerance);
  go.given = given;
  go.trace = o.trace;

  s.cover.coverage_target = o.coverage_target;
  s.cover.max_patches = o.max_patches;
  s.cover.min_gain = o.min_gain;

  // The chosen patches' finish (step 5): their simplest cutter kind, evaluated on the fine grid.
  FinishOptions& fo = s.finish;
  fo.grow = go;
  fo.simpler.assign(kinds.begin(), kinds.end() - 1);
  fo.evaluate = go.evaluate;
  fo.evaluate.rows = o.final_rows;
  fo.evaluate.cols = o.final_cols;
  fo.evaluate.spacing = o.final_spacing * diagonal;
  fo.evaluate.envelope = true;
  fo.evaluate.vertex_side = true;
  fo.evaluate.refine_max = EvaluateOptions{}.refine_max;
  return s;
}

// What a round judges its candidates by: the area of the target, and of nearly all of Φ.
struct RoundBars {
  int round = 0;             // from 0
  double target_area = 0.0;  // a patch that covers this covers the target alone
  // A patch that leaves less than min_round_gain of Φ uncovered (and covers the target): no
  // other candidate, nor the search of every seed, could add more than that, which is what the
  // search deems too little for another round. (A lower bar, the target itself, left the
  // spline part of scripts/coverage_curves.py with 93.5% instead of 96.7%.)
  double nearly_all = 0.0;

  bool covers_alone(const Grown& g) const { return covers(g, target_area); }
  bool ends_search(const Grown& g) const { return covers(g, nearly_all); }

 private:
  static bool covers(const Grown& g, double area) {
    return std::any_of(g.patches.begin(), g.patches.end(), [&](const Patch& p) { return p.covered_area >= area; });
  }
};

// The candidate lines of one round (step 2).
struct RoundLines {
  std::vector<LineCandidate> lines;  // best first
  bool covered_early = false;        // the search ended at a line that covers the target alone
  std::size_t looked = 0;            // seeds whose lines are in `lines`
};

// One round's search of its seeds (step 2). Each seed's lines are kept per seed and joined in
// seed order, whatever the order the threads searched them in.
struct SeedSearch {
  SeedSearch(int round_index, const std::vector<Seed>& round_seeds, CoveredFaces cover,
             bool keep_searches)
      : round(round_index),
        seeds(round_seeds),
        covered(std::move(cover)),
        keep(keep_searches),
        per_seed(round_seeds.size()),
        scored(round_seeds.size(), 0),
        reused(round_seeds.size(), 0),
        runs(round_seeds.size()),
        searched(round_seeds.size(), 0) {}

  // Takes in the seeds searched past `looked`, in seed order; with `nearly_all`, true when it
  // took in one with a line that may cover that much of Φ (the search pauses there).
  bool look(std::optional<double> nearly_all) {
    while (looked < seeds.size() && searched[looked]) {
      const std::size_t s = looked++;
      if (nearly_all && sweeps(s, *nearly_all)) return true;
    }
    return false;
  }
  // True when a line of seed `s` may cover `area` of Φ (its probe sweep's estimate).
  bool sweeps(std::size_t s, double area) const {
    return std::any_of(per_seed[s].begin(), per_seed[s].end(),
                       [&](const LineCandidate& c) { return c.estimate >= area; });
  }
  // The lines of seeds [0, seed_count), best first.
  std::vector<LineCandidate> ranked(std::size_t seed_count) const {
    std::vector<LineCandidate> lines;
    for (std::size_t s = 0; s < seed_count; ++s) lines.insert(lines.end(), per_seed[s].begin(), per_seed[s].end());
    std::stable_sort(lines.begin(), lines.end(),
                     [](const LineCandidate& x, const LineCandidate& y) { return x.estimate > y.estimate; });
    return lines;
  }

  // "round N: " for the trace.
  std::string traced() const { return "round " + std::to_string(round + 1) + ": "; }

  const int round;
  const std::vector<Seed>& seeds;
  const CoveredFaces covered;  // empty in round 0, which searches without a cover
  const bool keep;             // searches are kept for later rounds (only those with a cover)
  std::vector<std::vector<LineCandidate>> per_seed;
  std::vector<long long> scored;              // lines scored, per seed
  std::vector<char> reused;                   // per seed: an earlier round's search held
  std::vector<std::vector<FreeRunRecord>> runs;  // per seed, where kept
  std::vector<char> searched;                 // per seed
  std::size_t looked = 0;                     // seeds [0, looked) searched and looked at in order
  // A seed searched has a line that may sweep over half of what pauses the search: the seeds
  // left are searched one at a time (Decomposition::candidate_lines).
  std::atomic<bool> one_sweep{false};
};

// One decomposition's state over its rounds (steps 1-4) and finishes (step 5): the pool of
// candidate patches, what was grown and searched, and the cover.
class Decomposition {
 public:
  // `work` is Φ or its smoothed copy (then `given` is Φ); lengths scale with Φ's `diagonal`.
  // `tiler` seeds `work`'s mesh; `first_seeds`, where given, are its seeds of round 0.
  Decomposition(const SurfaceIndex& work, const SurfaceIndex* given, double diagonal, const DecomposeOptions& o,
                const std::vector<CutterKind>& kinds, const ProgressFn& say, DecomposeResult& out,
                std::unique_ptr<SeedTiler> tiler, std::optional<std::vector<Seed>> first_seeds)
      : work_(work),
        mesh_(work.mesh()),
        o_(o),
        diagonal_(diagonal),
        s_(stage_options(o, kinds, diagonal, given)),
        say_(say),
        out_(out),
        area_(vertex_areas(mesh_)),
        cover_(empty_cover(area_)),
        tiler_(std::move(tiler)),
        first_seeds_(std::move(first_seeds)) {
    out_.total_area = cover_.total_area;
  }

  // Rounds from out.rounds on, over what `cover` leaves, until one ends the search. True when
  // the last ended because its (coarse) cover met the target.
  bool rounds();
  // Finishes the pool entries `picks` not yet finished, concurrently, each in place: the
  // finished patch, or, where the finish finds no valid patch, one that covers nothing (no
  // cover picks it again; its claim stays, so its line is not grown again).
  void finish_picks(const std::vector<int>& picks);
  // The finished picks that still add enough, in the order that covers the most early on.
  Cover kept_of(const std::vector<int>& picks) const;
  // A cover of the pool as it is, from nothing.
  Cover cover_again() const;
  bool finished(int k) const { return finished_[static_cast<std::size_t>(k)] != 0; }

  const VecX& area() const { return area_; }  // per vertex of Φ
  const Cover& cover() const { return cover_; }
  void set_cover(Cover c) { cover_ = std::move(c); }
  // Moves pool entry k out (the result's patches).
  Patch take(int k) { return std::move(pool_[static_cast<std::size_t>(k)]); }

 private:
  std::vector<Seed> seeds(int round);                                             // step 1
  RoundLines candidate_lines(const RoundBars& bars, const std::vector<Seed>& seeds);  // step 2
  // Searches seed s of `r`, or takes an earlier round's search of it where that still holds;
  // false when `stop` ended the search part-way (nothing of it is kept: the seed is searched
  // again if the search goes on).
  bool search_seed(SeedSearch& r, std::size_t s, const std::atomic<bool>* stop);
  // Searches the seeds of `r` after `looked` not yet searched, one per thread, in seed order;
  // with `nearly_all`, true when one of them paused the search. Once `r.one_sweep` holds, one
  // thread goes on taking seeds and the others help inside its searches.
  bool search_beside(SeedSearch& r, std::optional<double> nearly_all);
  // Marks seed s of `r` searched, and notes where its lines hint at a part one sweep covers.
  void mark_searched(SeedSearch& r, std::size_t s, std::optional<double> nearly_all) const;
  // Counts what `r` searched, and keeps its searches for later rounds.
  void record(SeedSearch& r);
  // Step 2's try of the candidates at the head of `lines` that may cover the target alone.
  bool grow_alone(const RoundBars& bars, const std::vector<LineCandidate>& lines);
  void grow(const RoundBars& bars, const std::vector<LineCandidate>& lines);  // step 3
  // One batch of step 3: its candidates in rank order, each grown, or taken from an earlier
  // round or an early try; those after the first that covers the target alone are dropped.
  struct GrownBatch {
    std::vector<const LineCandidate*> lines;
    std::vector<Grown> grown;
    std::vector<const Grown*> known;  // grown in an earlier round (cache_), or null
    std::size_t kept = 0;             // grown[0, kept) are kept
    bool enough = false;              // grown[kept - 1] covers the target alone
  };
  GrownBatch grow_batch(const RoundBars& bars, std::vector<const LineCandidate*> lines);
  // Puts the kept patches of `b` in the pool (and what was grown anew in the cache); returns
  // the pool entry that covers the target alone, or -1.
  int take_in(const RoundBars& bars, GrownBatch& b, int& grown_this_round);

  const SurfaceIndex& work_;  // Φ, or its smoothed copy
  const Mesh& mesh_;
  const DecomposeOptions& o_;
  const double diagonal_;
  const StageOptions s_;
  const ProgressFn& say_;
  DecomposeResult& out_;
  const VecX area_;
  Cover cover_;
  // The greedy cover that grow's last look made of the pool, from cover_, while neither has
  // changed since: the round's cover starts from its picks.
  std::optional<Cover> grown_cover_;
  std::unique_ptr<SeedTiler> tiler_;  // Φ's scale and vertex grids, kept over the rounds
  std::optional<std::vector<Seed>> first_seeds_;  // round 0's, until it takes them

  std::vector<Patch> pool_;       // every valid candidate patch, in a deterministic order
  std::vector<char> finished_;    // per pool entry: replaced by its finished patch
  std::vector<Claim> claims_;     // of every pool entry
  GrownCache cache_;              // every candidate grown so far
  GrownCache early_;              // this round's candidates grown before every seed was searched
  SeedCache seed_cache_;          // every seed searched with part of Φ covered
};

bool Decomposition::rounds() {
  const DecomposeOptions& o = o_;
  for (int round = out_.rounds; round < o.max_rounds; ++round) {
    const std::size_t picks_before = cover_.picks.size();
    const double fraction_before = cover_.fraction();
    const std::vector<Seed> seeds = this->seeds(round);
    if (seeds.empty()) return false;

    RoundBars bars;
    bars.round = round;
    bars.target_area = o.coverage_target * cover_.total_area;
    bars.nearly_all = std::max(bars.target_area, (1.0 - o.min_round_gain) * cover_.total_area);
    early_ = {};
    const RoundLines found = candidate_lines(bars, seeds);
    const std::vector<LineCandidate>& lines = found.lines;
    out_.candidates += static_cast<int>(lines.size());
    if (o.trace)
      for (const LineCandidate& c : lines) {
        char line[400];
        std::snprintf(line, sizeof line,
                      "round %d seed %d line %.3f,%.3f,%.3f,%.3f,%.3f,%.3f: %s L %.2f, F_l %.2e, profile rms %.2e, "
                      "swept %.2f (%s / %s), estimate %.4g",
                      round + 1, c.seed, c.line.a.x(), c.line.a.y(), c.line.a.z(), c.line.b.x(), c.line.b.y(),
                      c.line.b.z(), std::string(to_string(c.kind)).c_str(), c.line.length(), c.movability.value,
                      c.movability.profile_rms, c.swept, to_string(c.sweep.stop_backward),
                      to_string(c.sweep.stop_forward), c.estimate);
        o.trace(line);
      }
    if (found.covered_early)
      say_("round " + std::to_string(round + 1) + ": " + std::to_string(lines.size()) + " candidate lines from the first " +
           std::to_string(found.looked) + " of " + std::to_string(seeds.size()) + " seeds, one of which covers the target alone");
    else
      say_("round " + std::to_string(round + 1) + ": " + std::to_string(seeds.size()) + " seeds, " +
           std::to_string(lines.size()) + " candidate lines");

    grow(bars, lines);

    // 4. Cover: the greedy picks, as grow's last look at the pool made them where nothing
    // has changed since (the same picks, made once), then the swaps.
    const auto t0 = Clock::now();
    if (grown_cover_) {
      cover_ = std::move(*grown_cover_);
      grown_cover_.reset();
      improve_cover(pool_, area_, o.max_swaps, &cover_);
    } else {
      extend_cover(pool_, area_, s_.cover, o.max_swaps, &cover_);
    }
    out_.times.cover += since(t0);
    out_.rounds = round + 1;
    say_("round " + std::to_string(round + 1) + ": " + std::to_string(cover_.picks.size()) + " patches cover " +
         std::to_string(100.0 * cover_.fraction()) + "%");
    if (cover_.fraction() >= o.coverage_target) return true;
    if (static_cast<int>(cover_.picks.size()) >= o.max_patches) return false;
    // Nothing new covered: the next round would seed the same uncovered area the same way.
    if (cover_.picks.size() == picks_before) return false;
    if (round > 0 && cover_.fraction() - fraction_before < o.min_round_gain) return false;
  }
  return false;
}

// 1. Seeds: over all of Φ first, then over what is still uncovered.
std::vector<Seed> Decomposition::seeds(int round) {
  const auto t0 = Clock::now();
  std::vector<Seed> seeds;
  if (round == 0 && first_seeds_) {
    seeds = std::move(*first_seeds_);
  } else {
    SeedOptions so = seed_options(o_, diagonal_, round);
    if (round > 0) {
      so.allowed.assign(static_cast<std::size_t>(mesh_.vertex_count()), 0);
      for (int v = 0; v < mesh_.vertex_count(); ++v) so.allowed[v] = cover_.vertex_patch[v] < 0;
    }
    seeds = (*tiler_)(so);
  }
  first_seeds_.reset();
  out_.times.seeds += since(t0);
  out_.seeds += static_cast<int>(seeds.size());
  return seeds;
}

// The candidates at the head of the first batch that step 3 would grow and that may cover the
// target alone, grown one at a time in rank order until one covers it. True when that one also
// covers nearly all of Φ (RoundBars::nearly_all).
bool Decomposition::grow_alone(const RoundBars& bars, const std::vector<LineCandidate>& lines) {
  int taken = 0;
  for (const LineCandidate& c : lines) {
    if (taken == o_.batch || taken == o_.grow_per_round) return false;
    if (already_claimed(work_, c, claims_)) continue;
    ++taken;
    if (c.estimate < bars.target_area) return false;
    const Grown* g = o_.reuse_grown ? cache_.find(c) : nullptr;
    if (!g) g = early_.find(c);
    if (!g) {
      early_.entries.push_back({c.line, c.kind, c.sweep.rulings, grow_patch(work_, c, s_.grow)});
      g = &early_.entries.back().grown;
    }
    if (bars.covers_alone(*g)) return bars.ends_search(*g);
  }
  return false;
}

// 2. Candidate lines, one task per seed, handed out in seed order; per-seed results keep the
// order deterministic.
bool Decomposition::search_seed(SeedSearch& r, std::size_t s, const std::atomic<bool>* stop) {
  const std::vector<LineCandidate>* known = r.keep ? seed_cache_.find(work_, r.seeds[s], r.covered) : nullptr;
  if (known) {
    r.reused[s] = 1;
    r.per_seed[s] = *known;
    for (LineCandidate& c : r.per_seed[s]) c.seed = static_cast<int>(s);
    rank_candidates(r.per_seed[s], r.covered);
    return true;
  }
  SearchStop halt{stop};
  r.per_seed[s] = seed_candidates(work_, r.seeds[s], static_cast<int>(s), r.covered, s_.lines, s_.grow.thresholds,
                                  &r.scored[s], r.keep ? &r.runs[s] : nullptr, stop ? &halt : nullptr);
  if (!halt.stopped) return true;
  r.per_seed[s].clear();
  r.scored[s] = 0;
  r.runs[s].clear();
  return false;
}

bool Decomposition::search_beside(SeedSearch& r, std::optional<double> nearly_all) {
  std::vector<std::size_t> pending;  // after a pause, those stopped part-way come again
  for (std::size_t s = r.looked; s < r.seeds.size(); ++s)
    if (!r.searched[s]) pending.push_back(s);
  if (pending.empty()) return false;
  std::mutex looked_mutex;
  std::atomic<bool> pause{false};
  std::atomic<std::size_t> next{0};
  std::atomic<int> taking{max_threads()};  // tasks that take seeds, or will
  // Where the seeds' lines hint at a part one sweep covers and the search may still pause, a
  // task leaves while another one goes on: its thread then runs the parallel loops of the
  // searches left (the scheduler's threads take such work whenever they have none of their
  // own), where a seed of its own would likely be stopped and thrown away once the seed that
  // pauses the search ends.
  const auto leave = [&] {
    for (int n = taking.load(); n > 1;)
      if (taking.compare_exchange_weak(n, n - 1)) return true;
    return false;
  };
  parallel_invoke_each(static_cast<std::size_t>(max_threads()), [&](std::size_t) {
    while (!pause) {
      if (nearly_all && r.one_sweep && leave()) return;
      const std::size_t i = next++;
      if (i >= pending.size()) break;
      const std::size_t s = pending[i];
      // Once a seed before it pauses the search, a seed still searched is stopped: the try
      // that follows gets every thread, and whether it ends the search or not, what the
      // stopped seed would give is the same when searched again.
      if (!search_seed(r, s, nearly_all ? &pause : nullptr)) {
        if (o_.trace)
          o_.trace(r.traced() + "seed " + std::to_string(s) + " stopped: a seed before it paused the search");
        continue;
      }
      const std::lock_guard<std::mutex> lock(looked_mutex);
      mark_searched(r, s, nearly_all);
      if (!pause && r.look(nearly_all)) pause = true;
    }
    --taking;
  });
  return pause;
}

// On a part one sweep covers, the line whose probe sweep passes over nearly all of it is
// often not in the first seed, and seeds before it have lines that sweep much of it: on
// exact cone and cylinder parts (the tests' and the scaling ladder's, at 1e-3 and 1e-4 of the
// diagonal) 56–66% of the area that pauses the search, though at 1e-4 the first seed's may
// sweep only 16–44%. A seed searched beside the one whose line pauses the search is stopped
// and thrown away, while that one runs on one thread (the ladder's 256k-triangle cone: its
// search 0.65 efficient). On parts that need several patches a seed's lines sweep less: at
// most 46% on the four blade faces of tests/data (every seed of their first round), but
// 50–58% on a few seeds of half the made-up faces (tests/freeform_parts.py) and 54–63% on
// the propeller blade's: there the seeds after are searched one at a time, with every
// thread inside each, at a little cost in efficiency.
// Hence the hint: a line that may sweep over half of it. Which seeds are searched, and what
// each gives, do not change: only the threads' share of them.
constexpr double kOneSweepHint = 0.5;

void Decomposition::mark_searched(SeedSearch& r, std::size_t s, std::optional<double> nearly_all) const {
  r.searched[s] = 1;
  if (nearly_all && !r.one_sweep && r.sweeps(s, kOneSweepHint * *nearly_all)) {
    r.one_sweep = true;
    if (o_.trace)
      o_.trace(r.traced() + "seed " + std::to_string(s) + " has a line that may sweep over half of the part");
  }
}

void Decomposition::record(SeedSearch& r) {
  for (std::size_t s = 0; s < r.seeds.size(); ++s) {
    if (!r.searched[s]) continue;
    out_.lines_scored += r.scored[s];
    if (r.reused[s]) ++out_.seeds_reused;
    else if (r.keep) seed_cache_.entries.push_back({r.seeds[s], std::move(r.runs[s]), r.per_seed[s]});
  }
}

RoundLines Decomposition::candidate_lines(const RoundBars& bars, const std::vector<Seed>& seeds) {
  const auto t0 = Clock::now();
  double early_s = 0.0;  // growth before every seed was searched: counted as the fit's
  CoveredFaces covered = bars.round == 0 ? CoveredFaces{} : faces_of(mesh_, cover_.vertex_patch);
  // Round 0 sees no cover (and searches without it): only later rounds' searches are kept.
  const bool keep = o_.reuse_seeds && !covered.empty();
  SeedSearch r(bars.round, seeds, std::move(covered), keep);
  // A line that may cover nearly all of Φ is tried before the seeds after its own are
  // searched (DecomposeOptions::grow_early): the search pauses at the first seed, in seed
  // order, whose lines include one. Once, in a round: where that try leaves too much, one
  // patch rarely leaves less (a coarse mesh, a surface not quite one envelope), and each try
  // costs fits.
  RoundLines out;
  bool may_pause = o_.grow_early;
  const auto pause_at = [&]() -> std::optional<double> {
    return may_pause ? std::optional<double>(bars.nearly_all) : std::nullopt;
  };
  for (;;) {
    bool paused = r.look(pause_at());  // seeds searched past the last pause
    // While Φ is nearly all uncovered (in the first round), the first seed by itself, with
    // every thread inside its search, and the next ones too once a line of those searched may
    // sweep over half of Φ (kOneSweepHint): on a part one sweep covers, one of them often has
    // the line that pauses the search, and a seed searched beside it would be searched for
    // nothing. Elsewhere this is one seed of some twenty with both threads inside instead of
    // one thread each, at some cost in efficiency.
    while (!paused && may_pause && cover_.covered_area <= cover_.total_area - bars.nearly_all &&
           r.looked < seeds.size() && !r.searched[r.looked] && (r.looked == 0 || r.one_sweep)) {
      const std::size_t s = r.looked;
      if (o_.trace) o_.trace(r.traced() + "seed " + std::to_string(s) + " searched alone");
      search_seed(r, s, nullptr);
      mark_searched(r, s, pause_at());
      paused = r.look(pause_at());
    }
    if (!paused) paused = search_beside(r, pause_at());
    if (!paused) {
      out.lines = r.ranked(seeds.size());
      break;
    }
    // Seeds [0, looked) hold a line that may cover nearly all of Φ: these seeds' lines are
    // grown as step 3 would grow them. A patch that leaves less than min_round_gain ends the
    // search, and these seeds' lines are then the round's candidates.
    std::vector<LineCandidate> first = r.ranked(r.looked);
    if (o_.trace)
      o_.trace("round " + std::to_string(bars.round + 1) + " paused after seed " + std::to_string(r.looked - 1) +
               " of " + std::to_string(seeds.size()) + ": a line may cover nearly all of the part");
    const auto t_early = Clock::now();
    const bool done = grow_alone(bars, first);
    early_s += since(t_early);
    may_pause = false;
    if (done) {
      out.lines = std::move(first);
      out.covered_early = true;
      break;
    }
  }
  out.looked = r.looked;
  record(r);
  out_.times.candidates += since(t0) - early_s;
  out_.times.fit += early_s;
  return out;
}

// 3. Grow the best in batches of o.batch, concurrently within a batch. A candidate over area
// that a grown patch already covers is skipped: it would grow that patch again.
Decomposition::GrownBatch Decomposition::grow_batch(const RoundBars& bars, std::vector<const LineCandidate*> lines) {
  GrownBatch b;
  b.lines = std::move(lines);
  const std::size_t n = b.lines.size();
  b.grown.resize(n);
  b.known.resize(n);
  for (std::size_t k = 0; k < n; ++k) b.known[k] = o_.reuse_grown ? cache_.find(*b.lines[k]) : nullptr;
  // The batch is grown in rank order, concurrently, and is kept up to the first candidate
  // that grows a patch covering the target alone: a part one sweep covers grows one
  // candidate instead of a batch. Which candidate that is follows from what each grows,
  // never from which finished first, so the answer is the same at every thread count.
  // Tasks take candidates in rank order and start none past that one once it is known;
  // those already running finish and are dropped. Where no patch covers the target alone,
  // the whole batch is grown: a cover of several patches picks among all of them (the
  // first candidate with which the pool reached the target, as a stop, left freeform/6
  // of scripts/coverage_curves.py with 95.4% in 4 patches instead of 98.8% in 5).
  std::mutex kept_mutex;
  std::atomic<std::size_t> next_task{0};
  std::atomic<bool> enough{false};
  std::vector<char> done(n, 0);
  const auto grow_next = [&] {  // the next candidate in rank order
    const std::size_t k = next_task++;
    if (enough) return;
    if (b.known[k]) b.grown[k] = *b.known[k];
    else if (const Grown* g = early_.find(*b.lines[k])) b.grown[k] = *g;
    else b.grown[k] = grow_patch(work_, *b.lines[k], s_.grow);
    const std::lock_guard<std::mutex> lock(kept_mutex);
    done[k] = 1;
    while (!enough && b.kept < n && done[b.kept])
      if (bars.covers_alone(b.grown[b.kept++])) enough = true;
  };
  // Candidates whose probe sweep passed over the target's area may cover it alone: in rank
  // order, each is grown by itself, with both threads inside its fits and evaluations,
  // until one does or the next could not; the rest of the batch then grows concurrently.
  // Grown side by side instead, a candidate that covers the part alone took as long as on
  // one thread, while the next was grown for nothing (the 13k cone part, cone cutters: fit
  // 45 ms on 1 thread, 50 ms on 2). The same candidates are kept either way. Real faces,
  // whose best line passes over under half of the part, never grow this way.
  std::size_t first = 0;
  for (; first < n && !enough && b.lines[first]->estimate >= bars.target_area; ++first) grow_next();
  parallel_invoke_each(n - first, [&](std::size_t) { grow_next(); });
  b.enough = enough;
  return b;
}

int Decomposition::take_in(const RoundBars& bars, GrownBatch& b, int& grown_this_round) {
  const DecomposeOptions& o = o_;
  // The cache after the batch: b.known points into it.
  for (std::size_t k = 0; k < b.kept; ++k)
    if (o.reuse_grown && !b.known[k])
      cache_.entries.push_back({b.lines[k]->line, b.lines[k]->kind, b.lines[k]->sweep.rulings, b.grown[k]});
  if (o.on_grown) {
    std::vector<std::size_t> fitted;
    for (std::size_t k = 0; k < b.kept; ++k)
      if (!b.known[k]) fitted.push_back(k);
    parallel_invoke_each(fitted.size(), [&](std::size_t i) {
      o.on_grown(work_, *b.lines[fitted[i]], s_.grow, b.grown[fitted[i]]);
    });
  }
  int alone = -1;
  for (std::size_t k = 0; k < b.kept; ++k) {
    ++(b.known[k] ? out_.regrown : out_.grown);
    ++grown_this_round;
    for (Patch& p : b.grown[k].patches) {
      ++out_.candidates_valid;
      if (b.enough && k + 1 == b.kept && alone < 0 && p.covered_area >= bars.target_area)
        alone = static_cast<int>(pool_.size());
      claims_.push_back(claim_of(p, mesh_.vertex_count()));
      pool_.push_back(std::move(p));
    }
  }
  return alone;
}

void Decomposition::grow(const RoundBars& bars, const std::vector<LineCandidate>& lines) {
  const DecomposeOptions& o = o_;
  const auto t0 = Clock::now();
  const double finish_before = out_.times.finish;  // a patch finished here is counted there
  int grown_this_round = 0;
  std::size_t next = 0;
  double reached = cover_.fraction();  // by the greedy cover of the pool after the last batch
  while (grown_this_round < o.grow_per_round && next < lines.size()) {
    std::vector<const LineCandidate*> batch;
    while (static_cast<int>(batch.size()) < o.batch && grown_this_round + static_cast<int>(batch.size()) < o.grow_per_round &&
           next < lines.size()) {
      const LineCandidate& c = lines[next++];
      if (!already_claimed(work_, c, claims_)) batch.push_back(&c);
    }
    if (batch.empty()) break;
    grown_cover_.reset();  // the pool changes
    GrownBatch b = grow_batch(bars, std::move(batch));
    const int alone = take_in(bars, b, grown_this_round);
    say_("round " + std::to_string(bars.round + 1) + ": grown " + std::to_string(grown_this_round) + ", " +
         std::to_string(out_.candidates_valid) + " candidate patches so far");
    if (b.enough) {
      // The coarse grid judged that patch; the finish (step 5) judges it on the fine grid, on
      // which it may cover less, and with its simplest cutter kind. Finished now, it ends the
      // round only if it still covers the target alone; otherwise the candidates after it
      // are grown as if it had not (on a cone face tessellated from IGES, a free-form
      // cutter ranked first covered 95.7% coarse and 90.7% finished).
      if (alone < 0) break;
      finish_picks({alone});
      if (pool_[static_cast<std::size_t>(alone)].covered_area >= bars.target_area) break;
      if (b.kept < b.lines.size()) next = static_cast<std::size_t>(b.lines[b.kept] - lines.data());
    }
    // Enough in the pool to reach the target: the rest need not be grown.
    grown_cover_ = cover_;
    greedy_cover(pool_, area_, s_.cover, &*grown_cover_);
    const double trial = grown_cover_->fraction();
    if (trial >= o.coverage_target) break;
    // A batch that adds less than min_round_gain to the pool's greedy cover ends the
    // round's growth, as such a round ends the search: the next candidates rank below
    // those that added nothing worth a patch (on Rotor 67's lower face, the third round's
    // first batch added nothing, and its second, grown for nothing, took about a quarter
    // of the round). The round's cover still improves with its swaps (improve_cover).
    // min_round_gain = 0 grows every batch, as before.
    if (trial - reached < o.min_round_gain) break;
    reached = trial;
  }
  out_.times.fit += since(t0) - (out_.times.finish - finish_before);
}

void Decomposition::finish_picks(const std::vector<int>& picks) {
  const auto t = Clock::now();
  finished_.resize(pool_.size(), 0);
  std::vector<std::size_t> todo;
  for (const int k : picks)
    if (!finished_[static_cast<std::size_t>(k)]) todo.push_back(static_cast<std::size_t>(k));
  parallel_invoke_each(todo.size(), [&](std::size_t i) {
    Patch& p = pool_[todo[i]];
    if (std::optional<Patch> f = finish_patch(work_, p, s_.finish)) {
      p = std::move(*f);
    } else {
      p.covered_vertices.clear();
      p.covered_area = 0.0;
    }
  });
  for (const std::size_t k : todo) finished_[k] = 1;
  out_.times.finish += since(t);
}

Cover Decomposition::kept_of(const std::vector<int>& picks) const {
  Cover kept = empty_cover(area_);
  kept.used.assign(pool_.size(), 1);
  for (const int k : picks) kept.used[static_cast<std::size_t>(k)] = 0;
  CoverOptions fco = s_.cover;
  fco.coverage_target = 1.0;  // keep every chosen patch that still adds enough
  greedy_cover(pool_, area_, fco, &kept);
  return order_cover(pool_, area_, kept.picks);
}

Cover Decomposition::cover_again() const {
  Cover again = empty_cover(area_);
  extend_cover(pool_, area_, s_.cover, o_.max_swaps, &again);
  return again;
}

}  // namespace

DecomposeResult decompose(const SurfaceIndex& index, const DecomposeOptions& o, const ProgressFn& progress) {
  const ProgressFn say = [&](const std::string& s) {
    if (progress) progress(s);
  };
  DecomposeResult out;
  // A noisy Φ (a scan): the solver works on a smoothed copy and reports against Φ as given.
  // Beside the noise estimate, the first round's seeds over Φ as given, which the rounds
  // start from unless Φ is smoothed: the seeding is a millisecond of mostly serial passes
  // (Rotor 67's faces), done on the other thread while the estimate's threads are busy.
  const auto t_noise = Clock::now();
  std::unique_ptr<SeedTiler> tiler;
  std::optional<std::vector<Seed>> first_seeds;
  run_beside(
      [&] {
        tiler = std::make_unique<SeedTiler>(index.mesh());
        first_seeds = (*tiler)(seed_options(o, index.diagonal(), 0));
      },
      [&] { out.noise = estimate_noise(index.mesh()); });
  std::unique_ptr<SurfaceIndex> smoothed;
  if (out.noise.sigma > o.noise_fraction * o.tolerance) {
    smoothed = std::make_unique<SurfaceIndex>(smooth_surface(index.mesh(), o.smoothing_passes, o.smoothing_rings));
    out.smoothed = true;
    say("the surface is noisy (sigma " + std::to_string(out.noise.sigma) + " mm): fitting on a smoothed copy");
    tiler = std::make_unique<SeedTiler>(smoothed->mesh());
    first_seeds.reset();
  }
  const SurfaceIndex& work = smoothed ? *smoothed : index;
  out.times.seeds += since(t_noise);
  Decomposition d(work, smoothed ? &index : nullptr, index.diagonal(), o, by_generality(o.kinds), say, out,
                  std::move(tiler), std::move(first_seeds));

  // Rounds (steps 1-4), then the chosen patches with their simplest cutter kind, evaluated
  // finely and covered again in greedy order (step 5: the fine grid sees a little more or less
  // than the coarse one). Where the finish lost more than a round must gain (a pick with no
  // valid patch on the fine grid, or one cut back) and the target is missed, the pool is
  // covered again with the finished patches as they are. Where that cover promises a round's
  // gain over the finished one, its new picks are finished; otherwise, where the rounds ended
  // only because their coarse cover met the target, they go on over what is still uncovered.
  // A few passes at most; the best cover finished is kept. (A cylinder part tessellated from
  // IGES: two patches covered 98.1% coarse, and the finish kept one, at 60.8%.)
  constexpr int kFinishPasses = 4;
  Cover final_cover;
  bool seed_again = true;   // the rounds run in this pass
  bool met_target = false;  // the rounds last run ended as their (coarse) cover met the target
  bool lost = false;        // a finish lost more than a round must gain
  for (int pass = 0;; ++pass) {
    if (seed_again) met_target = d.rounds();
    d.finish_picks(d.cover().picks);
    const auto t0 = Clock::now();
    Cover kept = d.kept_of(d.cover().picks);
    lost = lost || kept.fraction() < d.cover().fraction() - o.min_round_gain;
    if (pass == 0 || kept.fraction() > final_cover.fraction()) final_cover = std::move(kept);
    out.times.finish += since(t0);
    if (final_cover.fraction() >= o.coverage_target || !lost || pass + 1 == kFinishPasses) break;
    const auto t_again = Clock::now();
    Cover again = d.cover_again();
    out.times.cover += since(t_again);
    const bool unfinished =
        std::any_of(again.picks.begin(), again.picks.end(), [&](int k) { return !d.finished(k); });
    if (unfinished && again.fraction() >= final_cover.fraction() + o.min_round_gain)
      seed_again = false;
    else if (met_target && out.rounds < o.max_rounds)
      seed_again = true;
    else
      break;
    say("the finish covered " + std::to_string(100.0 * final_cover.fraction()) + "% of the " +
        std::to_string(100.0 * d.cover().fraction()) + "% chosen: " +
        (seed_again ? "the rounds go on" : "covered again with the finished patches"));
    // The rounds go on from the best finished cover, every pick of it finished.
    d.set_cover(seed_again ? final_cover : std::move(again));
  }
  const auto t0 = Clock::now();
  for (std::size_t k = 0; k < final_cover.picks.size(); ++k) {
    Patch p = d.take(final_cover.picks[k]);
    p.id = static_cast<int>(k);
    out.patches.push_back(std::move(p));
  }
  out.times.finish += since(t0);
  out.vertex_patch = final_cover.vertex_patch;
  out.covered_area = final_cover.covered_area;
  out.coverage = final_cover.fraction();
  out.coverage_curve = final_cover.curve;
  out.uncovered = uncovered_regions(work.mesh(), out.vertex_patch, d.area());
  say(std::to_string(out.patches.size()) + " patches finished: " + std::to_string(100.0 * out.coverage) + "%");
  return out;
}

}  // namespace flank
