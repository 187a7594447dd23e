// Initial ruled surfaces (paper §4.2–4.4): refine a user's line by local search of its
// endpoints' neighbourhoods (Fig. 8), propagate it as-tangentially-as-possible both ways
// (§4.3), or take a user's ordered lines as control polygons (§4.4).
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "kernels/movability.h"
#include "solver/motion.h"

namespace flank {

struct RefineLineOptions {
  MovabilityOptions movability;
  int candidates_per_end = 15;  // 15 × 15 endpoint pairs per round, as Fig. 8
  double radius = 0.0;          // search radius in the normal planes; 0: 5% of the line length
  int rounds = 4;               // each round searches around the best so far, radius halved
  // The cutter the line must suit: candidates are scored F_l + profile_weight·(rms/L)², the
  // misfit of their footpoint distances to this kind. Without it any line that slides
  // along itself while its distances vary could look perfectly movable on an envelope.
  std::optional<CutterKind> kind;
  double profile_weight = 1.0;
  // With `kind`: candidates whose profile leaves these sphere radii (absolute; 0: no bound)
  // are no candidates. On a part near an exact envelope, a whole family of tilted lines has
  // F_l ≈ 0 and a profile of the kind (the radius ↔ offset valley), some with radii no tool has.
  double radius_min = 0.0, radius_max = 0.0;
};

struct RefinedLine {
  Line line;
  Movability movability;
  double score = 0.0;
  int evaluated = 0;
};

// Deterministic (sunflower pattern in the discs, no RNG). Candidates are scored in parallel.
RefinedLine refine_line(const SurfaceIndex& index, const Line& start,
                        const RefineLineOptions& options = {});

// Where the run of footpoints inside Φ (not beyond its boundary) along the line's extension
// ends, in the line's parameter s (0 at a, 1 at b): searched from `from` toward the low
// (s < from) or the high end, at most `reach` past the line's end, to 1/4096 of its length.
// NaN when Φ goes on past the reach, or when there is nothing inside Φ between `from` and the
// middle. `hint` is a face to start the closest-point search from (updated; -1 for none).
double interior_edge(const SurfaceIndex& index, const Line& line, bool low, double from,
                     double reach, int* hint);

struct PropagateOptions {
  MovabilityOptions movability;
  double step = 0.0;              // midpoint step; 0: 1e-3 × bbox diagonal (DESIGN)
  double max_movability = 1e-3;   // ε_move: stop when F_l exceeds it
  double max_travel = 0.0;        // midpoint path cap each way; 0: 4 × bbox diagonal
  // Stop when the corrected line's footpoint distances differ from the start line's by more
  // than this anywhere (absolute; 0: never): the start's cutter can no longer follow Φ. On a
  // real surface this, not F_l, is what ends a sweep: F_l is a rate, and the corrector undoes
  // most of the drift it predicts.
  double max_profile_error = 0.0;
  // The corrector restores the distance profile mostly by moving the line toward or away from
  // Φ and along its axis, not back along the sweep: where the profile cannot be kept exactly
  // (any real surface), a free sweep component lets the least-squares step pull the line back
  // onto itself and the sweep stalls (15 of 20 lines across a Rotor 67 face; 0 with the hold).
  // A spring on each end against moving along the sweep, of this fraction of the corrector's
  // own stiffness (0: none). Soft, because the rulings of a twisted part do turn along the
  // sweep: at full stiffness the profile drifted 2.5 tolerances off an exact envelope and the
  // sweep stopped early; at 0.01 it stays within 0.8 and sweeps the whole part.
  double hold_sweep = 0.01;
  // Faces that count as covered already (#F 0/1, not owned; null: none): Propagation::fresh
  // counts only samples whose footpoint is on another face.
  const std::vector<char>* covered_faces = nullptr;
  // One line per step when set (F_l, the other sweep, sliding, Φ's edges): diagnostics.
  std::function<void(const std::string&)> trace;
};

enum class PropagateStop { max_movability, left_surface, jump, max_travel, stalled, degenerate, profile_error };
const char* to_string(PropagateStop stop);

struct Propagation {
  std::vector<Line> rulings;  // in motion order, the start line among them
  // Per ruling: the fraction of its samples whose footpoint is inside Φ and not on a covered
  // face (PropagateOptions::covered_faces): what the sweep passes over that is still to cut.
  std::vector<double> fresh;
  // Per ruling, its `samples` footpoints' faces (−1 outside Φ), ruling after ruling: `fresh`
  // again for another cover without a query (fresh_fractions).
  std::vector<int> faces;
  int samples = 0;
  int start_index = 0;
  PropagateStop stop_backward = PropagateStop::degenerate;
  PropagateStop stop_forward = PropagateStop::degenerate;
  double max_movability = 0.0;  // worst F_l along the kept rulings
};

// Per ruling of `p`: the fraction of its samples whose footpoint is inside Φ and not on a face
// that `covered` (#F 0/1; null or empty: none) marks. propagate fills Propagation::fresh so.
std::vector<double> fresh_fractions(const Propagation& p, const std::vector<char>* covered);

// RK2 integration of (ȧ, ḃ) = (v(0), v(1)) with |b − a| = L kept and the sweep direction
// kept continuous, both ways from `start`, on the calling thread.
Propagation propagate(const SurfaceIndex& index, const Line& start,
                      const PropagateOptions& options = {});

// Line-driven start (§4.2–4.3) in one call: refine the line for a cutter of `kind`,
// propagate it both ways, and fit the swept rulings with `control_points` per curve.
struct LineStart {
  RefinedLine refined;
  Propagation propagation;
  Motion motion;
  bool ok = false;
  std::string message;  // why not, when !ok
};
LineStart line_driven_start(const SurfaceIndex& index, const Line& line,
                            std::optional<CutterKind> kind, int control_points,
                            const PropagateOptions& propagate_options = {});

// Surface-driven start (§4.4): the endpoints of ordered lines are the control polygons of
// a(t) and b(t); the result is resampled to `control_points` per curve.
Motion motion_from_lines(const std::vector<Line>& lines, int control_points);

}  // namespace flank
