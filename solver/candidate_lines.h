// Candidate lines of the automatic decomposition (DESIGN "Automatic decomposition"): at a
// seed, lines in many directions, tilts and offsets are scored by movability and by how well a
// cutter fits their footpoint distances; the best directions are laid across the free part of
// Φ (inside it and not yet covered) at a few lengths, refined by the paper's local search
// (Fig. 8) and swept along Φ. What they sweep before their cutter stops fitting estimates the
// area they can cover: that, not an exact-envelope threshold, ranks them.
#pragma once

#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include "kernels/cutter.h"
#include "kernels/movability.h"
#include "kernels/surface_index.h"
#include "solver/motion.h"
#include "solver/propagate.h"
#include "solver/seed_tiles.h"
#include "solver/thresholds.h"

namespace flank {

struct CandidateLineOptions {
  // The cutter kinds allowed, simplest first. Directions are scored with the most general
  // profile. Each kept direction is refined twice, steered by the barrel profile (where
  // allowed) and by the most general one: a free-form profile fits almost any line's
  // distances, so its misfit cannot lead the search into the narrow hole of F_l around a
  // ruling, while a quadratic one does and still follows a curved profile; but on a free-form
  // cutter's envelope only the free-form profile finds the axis. Each laid-out line then gets
  // the simplest allowed kind that fits its footpoint distances (Thresholds::kind_misfit).
  std::vector<CutterKind> kinds{CutterKind::spline};
  double radius_min = 0.0, radius_max = 0.0;  // allowed sphere radii (absolute, > 0)
  double length_min = 0.0, length_max = 0.0;  // allowed cutter lengths (absolute, > 0)

  // Scoring at a seed: directions × tilts × radii, at one reference length (the geometric
  // mean of the allowed lengths): the direction and the offset, not the length, decide
  // movability.
  int directions = 24;        // over 180° in the tangent plane
  int tilts = 3;              // toward the normal, symmetric, up to max_tilt_deg
  double max_tilt_deg = 8.0;
  int radii = 6;              // geometric over the allowed radii
  int coarse_samples = 16;    // n of the first scoring (5 unknowns: fewer is noise)
  int fine_samples = 30;      // n of the rescoring of the best
  int fine_candidates = 6;    // aimed at their laid length per seed
  double aim_turn_deg = 4.0;  // the small turns tried when aiming
  int directions_kept = 2;    // distinct directions laid out per seed
  double distinct_deg = 25.0; // directions closer than this are the same
  // Lengths laid out per direction: the free run's (within the allowed lengths), then halved.
  int lengths = 3;
  // How far a line reaches past the free run's ends (beyond Φ's edge, or back into covered
  // area), as a fraction of its length: no gap is left at the boundary.
  double overhang = 0.03;
  // Local search (Fig. 8) of each laid-out line.
  int refine_rounds = 4;
  int refine_candidates = 7;  // per end and round
  int refine_samples = 20;    // n of the local search's lines
  // The probe sweep that estimates what a line covers.
  double step = 0.0;          // absolute, > 0
  int probe_samples = 16;     // along the line: the sweep only needs its distance profile
  double max_travel = 0.0;    // each way, absolute, > 0
  // Diagnostics: one line per kept direction and per refined line; empty: silent.
  std::function<void(const std::string&)> trace;

  std::string validate() const;
};

struct LineCandidate {
  Line line;
  CutterKind kind = CutterKind::spline;
  int seed = -1;
  Movability movability;   // at n = fine_samples, with the profile of `kind`
  double score = 0.0;      // F_l + w (profile misfit / L)²
  Propagation sweep;       // the probe sweep: its rulings start the fit
  double inside = 0.0;     // length of the line over Φ
  double swept = 0.0;      // how far its midpoint travels across it in the probe sweep
  double estimate = 0.0;   // the area of Φ the probe sweep passed over: what it may cover
  int order = 0;           // in the seed's search: among equal estimates the first found leads
};

// Faces of Φ already covered (#F 0/1) or empty when nothing is.
using CoveredFaces = std::vector<char>;

// Along the line through `mid` with unit direction u: how far (≥ 0, each way, up to `reach`)
// its footpoints stay inside Φ and off covered faces. The run through mid is searched in steps
// of reach/64 and its ends bisected to 1/64 of a step.
struct FreeRun {
  double low = 0.0, high = 0.0;  // distances from mid toward −u and +u
  bool low_open = false, high_open = false;  // the run goes on past `reach` that way
  bool operator==(const FreeRun&) const = default;
};
FreeRun free_run(const SurfaceIndex& index, const Vec3& mid, const Vec3& u, double reach,
                 const CoveredFaces& covered);

// One free_run and what it found.
struct FreeRunRecord {
  Vec3 mid = Vec3::Zero(), u = Vec3::Zero();
  double reach = 0.0;
  FreeRun run;
};
// Whether every recorded free_run finds exactly the same run under `covered`.
bool free_runs_hold(const SurfaceIndex& index, const std::vector<FreeRunRecord>& runs, const CoveredFaces& covered);

// The candidate lines at one seed, best estimate first. Deterministic, at every thread count:
// each stage's lines are searched concurrently where threads are free (called from concurrent
// tasks, each mostly stays on its own), and joined in a fixed order. `scored` counts the lines whose footpoints were queried (a line judged with several
// cutter kinds counts once). `runs`, when given, receives every free_run the search made
// through the cover, with what it found: which lines the search finds depends on the cover
// through these alone, so at the same seed, under a cover where each gives the same again
// (free_runs_hold), it finds the same lines, ranked for that cover by rank_candidates.
//
// `stop`, when given, lets another thread end the search part-way: its flag is read at the
// start of each stage and of each stage's tasks, and once it is set the search returns early
// with `stopped` set. A stopped search's lines, count and records are incomplete: discard
// them (decompose stops the seeds still searched beside one whose lines end its search).
struct SearchStop {
  const std::atomic<bool>* flag = nullptr;
  bool stopped = false;
};
std::vector<LineCandidate> seed_candidates(const SurfaceIndex& index, const Seed& seed, int seed_id,
                                           const CoveredFaces& covered,
                                           const CandidateLineOptions& options,
                                           const Thresholds& thresholds, long long* scored,
                                           std::vector<FreeRunRecord>* runs = nullptr,
                                           SearchStop* stop = nullptr);

// Each line's `sweep.fresh`, `swept` and `estimate` for the cover `covered` (empty: none), and
// the lines in the order seed_candidates returns them: best estimate first, then `order`.
// Moves no line and queries nothing: a seed's lines found under one cover are ranked so under
// another.
void rank_candidates(std::vector<LineCandidate>& lines, const CoveredFaces& covered);

// The line of length L along u laid over a free run around `mid`: where the run is shorter
// than L, centred on it; otherwise against the run's end nearer to mid when that end is
// within 3/4 L (so that strips tile from Φ's edges and from covered area inward), else
// centred on mid. It reaches `overhang`·L past a run end it is laid against.
Line lay_line(const Vec3& mid, const Vec3& u, double L, const FreeRun& run, double overhang);

}  // namespace flank
