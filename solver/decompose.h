// Automatic decomposition (DESIGN "Automatic decomposition", the step the paper leaves to a
// person): orchestration only. Each round seeds the part of Φ still uncovered
// (solver/seed_tiles), lays candidate lines across it and ranks them by the area their probe
// sweep may cover (solver/candidate_lines), grows the best into fitted, trimmed candidate
// patches concurrently (solver/grow_patch), and extends a greedy cover (solver/greedy_cover).
// The chosen patches are then refitted at full resolution with their simplest cutter kind.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "kernels/cutter.h"
#include "kernels/surface_index.h"
#include "solver/greedy_cover.h"
#include "solver/grow_patch.h"
#include "solver/patch.h"
#include "solver/surface_noise.h"

namespace flank {

struct DecomposeOptions {
  double tolerance = 0.0;  // absolute, > 0
  // Cutter kinds allowed. Every one by default: the product designs the cutter. Candidates are
  // fitted with the most general kind allowed, and each chosen patch gets the simplest allowed
  // kind that cuts the same surface.
  std::vector<CutterKind> kinds{CutterKind::cylinder, CutterKind::cone, CutterKind::barrel,
                                CutterKind::spline};
  // Allowed sphere radii and cutter lengths (absolute; 0: the default fraction of the bbox
  // diagonal). Radii of 1%..10% and lengths of 3%..45% of the diagonal are tools a machinist
  // would accept on a part of that size.
  double radius_min = 0.0, radius_max = 0.0;
  double length_min = 0.0, length_max = 0.0;
  static constexpr double kDefaultRadiusMin = 0.01, kDefaultRadiusMax = 0.10;
  static constexpr double kDefaultLengthMin = 0.03, kDefaultLengthMax = 0.45;
  bool holder = false;
  double holder_length = 0.0, holder_radius = 0.0;
  double coverage_target = 0.95;
  int max_patches = 20;
  double min_gain = 0.005;  // a patch must add at least this fraction of Φ's area
  int max_swaps = 8;        // improvements of the greedy cover per round (greedy_cover.h)
  int max_rounds = 6;       // seeding rounds: all of Φ, then what is still uncovered
  // A round after the first that adds less than this fraction of Φ's area ends the search:
  // what is left is scattered slivers, cheaper to finish with a ball-end mill. Within every
  // round, a growth batch that adds less than this to the pool's greedy cover ends the
  // round's growth.
  double min_round_gain = 0.01;
  // Seed spacing of the first round as a fraction of the diagonal; later rounds seed the
  // uncovered regions at half of it.
  double seed_spacing = 0.12;
  int max_seeds = 24;       // per round

  // Candidate lines per seed (solver/candidate_lines).
  int directions = 24, tilts = 3, radii = 6;
  int directions_kept = 2, lengths = 3;
  double probe_step = 0.015;  // of the diagonal: the probe sweeps' step

  // Growth: candidates grown per round, concurrently in batches of a fixed size (so that the
  // result does not depend on the thread count); a batch is kept up to the first candidate,
  // in rank order, that grows a patch covering coverage_target alone. The fit's samples and
  // control points.
  int grow_per_round = 16;
  int batch = 8;
  // A later round that lays out exactly a line an earlier one grew reuses that growth's pieces
  // instead of fitting them again (growth is deterministic: the same pieces either way).
  bool reuse_grown = true;
  // A later round that seeds exactly where an earlier one did reuses that seed's candidate
  // lines when none of the faces whose cover the search read has changed since (the search is
  // deterministic and reads the cover nowhere else: the same lines either way).
  bool reuse_seeds = true;
  // Seeds are searched in order, and the search pauses at the first seed with a line whose
  // probe sweep passed over nearly all of Φ (all but min_round_gain of its area). The lines
  // found so far are then ranked and grown as growth would grow them (those that may cover
  // coverage_target alone, one at a time in rank order). If the first patch that covers the
  // target alone leaves less than min_round_gain of Φ uncovered, the round's search ends
  // there and the seeds after are never searched; otherwise it goes on without pausing again
  // in that round, and what was grown is reused. A part one sweep covers is searched at one or a few seeds instead of some twenty;
  // its patch may come from another line than the search of every seed would grow first, and
  // then covers at most min_round_gain less. No line of the four real faces passes over that
  // much: their search never pauses, and finds what it found before.
  bool grow_early = true;
  int control_points = 16, samples_t = 48, samples_s = 16, iterations = 10;
  // A fit that starts from a fitted motion (a trimmed sweep, the first trim's other pieces)
  // is near its optimum already. Against 10 on the same 422 candidates of the 17 coverage
  // cases (scripts/grow_pairs.py --refit-iterations 5), 5 grew the same best area in more
  // than 95% of them (1.0014 in sum) in 0.93 of the growth time (Rotor 67 lower 0.83).
  int refit_iterations = 5;
  // How far an accepted Gauss–Newton step may be extended (FitOptions::max_extrapolations:
  // up to 2^this steps): a candidate needs the patch's extent, not the last digit of its cutter
  // radius.
  int extrapolations = 2;
  // The chosen patches' final evaluation: at least final_rows × final_cols samples, and
  // neighbouring samples at most final_spacing × diagonal apart (candidates are evaluated at
  // twice that spacing).
  int final_rows = 200, final_cols = 60;
  double final_spacing = 0.0025;

  // Scan noise (solver/surface_noise.h): when Φ's vertices scatter off a smooth surface by
  // more than this fraction of the tolerance, the solver fits on a smoothed copy of Φ (this
  // many local quadric projections) and reports against Φ as given. Measured on the test blades
  // the scatter is ~1e-4 of the tolerance; a scan at 2e-4 of the diagonal is 0.7 of a 3e-4 one.
  double noise_fraction = 0.1;
  // Local quadric projections over 4-rings (about 60 vertices), 4 times: on a barrel envelope
  // with noise of 2e-4 of the diagonal that leaves 0.18 of the noise (2-rings 8 times: 0.28).
  int smoothing_passes = 4, smoothing_rings = 4;

  // Diagnostics: one line per candidate line kept, per grown piece and per round.
  std::function<void(const std::string&)> trace;
  // Diagnostics: every candidate fitted and kept (not one reused from an earlier round, nor
  // one dropped because a candidate ranked before it covered the coverage target alone),
  // with the index it was grown on (Φ's smoothed copy for a noisy scan), the options it was
  // grown with and what it grew; called concurrently after each batch. bench/grow_pairs
  // grows the same candidates with other fit settings.
  std::function<void(const SurfaceIndex&, const LineCandidate&, const GrowOptions&, const Grown&)> on_grown;

  std::string validate() const;
};

struct StageTimes {
  double seeds = 0, candidates = 0, fit = 0, cover = 0, finish = 0;
};

struct DecomposeResult {
  NoiseEstimate noise;                 // of Φ as given
  bool smoothed = false;               // the solver fitted on a smoothed copy of Φ
  std::vector<Patch> patches;          // in cover order; ids 0..k-1
  std::vector<int> vertex_patch;       // per Φ vertex: the patch that covers it, −1 if none
  double total_area = 0.0;
  double covered_area = 0.0;
  double coverage = 0.0;               // covered fraction of Φ's area
  std::vector<double> coverage_curve;  // covered fraction after 1, 2, …, k patches
  std::vector<UncoveredRegion> uncovered;  // edge-connected uncovered regions, largest first
  StageTimes times;
  int rounds = 0;
  int seeds = 0;
  long long lines_scored = 0;          // candidate lines whose footpoints were queried
  int seeds_reused = 0;                // seeds whose lines an earlier round had found: reused
  int candidates = 0;                  // candidate lines laid out and swept
  int grown = 0;                       // candidates fitted
  int regrown = 0;                     // candidates an earlier round had grown: reused, not fitted
  int candidates_valid = 0;            // candidate patches (pieces) valid as tools
};

using ProgressFn = std::function<void(const std::string&)>;

DecomposeResult decompose(const SurfaceIndex& index, const DecomposeOptions& options,
                          const ProgressFn& progress = {});

// The radius and length ranges in effect (absolute), defaults resolved against the diagonal.
struct ToolRanges {
  double radius_min, radius_max, length_min, length_max;
};
ToolRanges tool_ranges(const DecomposeOptions& options, double diagonal);

}  // namespace flank
