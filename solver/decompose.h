// Automatic decomposition (DESIGN "Automatic decomposition", the step the paper leaves to a
// person): seeds over Φ, thousands of candidate lines per seed scored by movability, the
// best grown and fitted concurrently into candidate patches, then a greedy cover; uncovered
// regions are seeded again for a bounded number of rounds.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "kernels/cutter.h"
#include "kernels/surface_index.h"
#include "solver/patch.h"

namespace flank {

struct DecomposeOptions {
  double tolerance = 0.0;                         // absolute, > 0
  std::vector<CutterKind> kinds{CutterKind::cone};
  double radius_min = 0.0, radius_max = 0.0;      // allowed cutter (sphere) radii; 0: 1%..10% of diagonal
  double length_min = 0.0, length_max = 0.0;      // allowed cutter lengths; 0: 10%..45% of diagonal
  bool holder = false;
  double holder_length = 0.0, holder_radius = 0.0;
  double coverage_target = 0.95;
  int max_patches = 20;
  int max_rounds = 3;          // seeding rounds (the first, then re-seeding of uncovered regions)
  double min_gain = 0.005;     // a patch must add at least this fraction of Φ's area

  // Candidate lines per seed: directions × tilts × radii × lengths.
  int directions = 24;         // over 180° in the tangent plane
  int tilts = 5;               // toward the normal, symmetric, up to `max_tilt_deg`
  double max_tilt_deg = 8.0;
  int radii = 6;
  int lengths = 3;
  int coarse_samples = 16;     // n for the first scoring (5 unknowns: fewer is noise)
  int fine_samples = 30;       // n for the rescoring of the best
  int fine_candidates = 16;    // per seed and kind, rescored at fine_samples
  int lines_per_seed = 3;      // kept per seed (distinct directions or radii)
  int max_grown_per_round = 12;
  double good_movability = 1e-5;  // F_l at or below this (and a profile within tolerance): "sweeps"

  // Fit of each grown candidate.
  int control_points = 20;
  int fit_iterations = 12;

  std::string validate() const;
};

struct StageTimes {
  double seeds = 0, candidates = 0, fit = 0, cover = 0;
};

struct UncoveredRegion {
  double area = 0.0;
  Vec3 centroid = Vec3::Zero();
  int vertices = 0;
};

struct DecomposeResult {
  std::vector<Patch> patches;          // in the order chosen; ids 0..k-1
  std::vector<int> vertex_patch;       // per Φ vertex: the patch that covers it, −1 if none
  double total_area = 0.0;
  double covered_area = 0.0;
  double coverage = 0.0;               // covered fraction of Φ's area
  std::vector<UncoveredRegion> uncovered;  // edge-connected uncovered regions, largest first
  StageTimes times;
  int rounds = 0;
  int seeds = 0;
  long long lines_scored = 0;
  int grown = 0;                       // candidates propagated and fitted
  int candidates_valid = 0;            // of those, patches without gouge or holder collision
};

using ProgressFn = std::function<void(const std::string&)>;

DecomposeResult decompose(const SurfaceIndex& index, const DecomposeOptions& options,
                          const ProgressFn& progress = {});

}  // namespace flank
