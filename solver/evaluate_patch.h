// Patch evaluation (DESIGN "Machined surface Ω and error"): the machined surface Ω of a cutter
// and its motion, sampled on a (t, s) grid, its signed deviation from Φ, the Φ area it covers
// within tolerance, the whole-cutter gouge check and the holder clearance.
#pragma once

#include <string>
#include <vector>

#include "kernels/cutter.h"
#include "kernels/surface_index.h"
#include "solver/motion.h"
#include "solver/patch.h"

namespace flank {

// One uniform (t, s) grid over [0, 1]², row-major over t, measured two ways:
// - the sphere of every sample (centre R(t, s), radius d(s)): e_sphere = dist(R, Φ) − d, the
//   paper's ε (eq. 13); negative anywhere along the whole cutter means the cutter gouges;
// - the machined surface itself: Ω's point of every sample (the envelope point, R + d n) and
//   its signed distance to Φ, e = ±dist(Ω, Φ) (+: material left, −: gouge). This is the error
//   of what is really cut: where the envelope's contact point is not the sphere's nearest point
//   to Φ, e_sphere says nothing of Ω.
struct ErrorGrid {
  int rows = 0, cols = 0;
  // Spheres.
  VecX sphere_error;           // e_sphere; beyond Φ's boundary the unsigned distance − d
  std::vector<char> interior;  // the centre's footpoint is inside Φ (not beyond its boundary)
  std::vector<int> faces;      // footpoint faces of the centres (warm starts)
  Points directions;           // unit g of every centre (from Φ toward the centre)
  // Ω.
  Points omega;                      // envelope points (the centre where there is none)
  std::vector<char> omega_valid;     // the envelope point exists (|d′| < L, the axis moves across itself)
  std::vector<char> omega_interior;  // valid and its footpoint is inside Φ
  VecX error;                        // signed deviation e of Ω from Φ where omega_interior, else 0
  // Per row: the axis sweeps on across itself there. Where the motion stalls or turns back,
  // the envelope folds: its points there lie inside what the sweep cuts away, or swing off Φ
  // between samples.
  std::vector<char> sweeps;
  // Per sample: its verdict is not to be trusted, so it counts as overhang (empty: all are).
  // On a smoothed scan, next to Φ's edges: a one-sided neighbourhood averages little of the
  // noise out, and what is left there is the scan's, not the cutter's.
  std::vector<char> untrusted;

  std::size_t index(int i, int j) const { return static_cast<std::size_t>(i) * cols + j; }
  double at(int i, int j) const { return error(static_cast<Eigen::Index>(index(i, j))); }
  // Ω's sample counts toward the error: it exists and lies over Φ.
  bool inside(int i, int j) const { return omega_interior[index(i, j)] != 0; }
};

// `untrusted_edges`: samples whose footpoint (of Ω or of the centre) lies on a face touching
// Φ's boundary are marked untrusted (see ErrorGrid::untrusted).
ErrorGrid sample_errors(const SurfaceIndex& index, const Motion& motion, const Cutter& cutter,
                        int rows, int cols, bool untrusted_edges = false);

// What a sample of the grid is worth against a tolerance.
enum class SampleClass : char {
  within,    // Ω lies over Φ within tolerance
  overhang,  // beyond Φ's edge (the cutter overhangs the part): no error, no gain
  outside,   // out of tolerance, the sphere reaches into Φ, Ω has no point over Φ here, or the
             // motion stalls or turns back
};
std::vector<SampleClass> classify_samples(const ErrorGrid& grid, double tolerance);

struct EvaluateOptions {
  double tolerance = 0.0;  // absolute, > 0
  int rows = 200;          // samples along t for errors and Ω (at least, with `spacing`)
  int cols = 60;           // samples along s (at least, with `spacing`)
  // When > 0: more rows and columns where needed so that neighbouring axis samples are at most
  // this far apart (absolute), up to max_samples in all. Ω's mesh must follow Φ's curvature
  // within a fraction of the tolerance, and the error be seen between samples: a fixed count
  // is too coarse on a long sweep and wasted on a short one.
  double spacing = 0.0;
  int max_samples = 60000;
  bool holder = false;
  double holder_length = 0.0;
  double holder_radius = 0.0;
  bool envelope = true;  // keep Ω as a mesh in the patch (for envelopes.ply)
  bool coverage = true;  // measure the covered Φ area
  // Coverage counts a Φ vertex within tolerance of Ω only where Ω itself lies within this
  // multiple of the tolerance of Φ (or beyond Φ's edge): Ω's false parts, folds where the
  // motion reverses or a surface crossing Φ at an angle, pass near some vertices without
  // cutting them. Twice, not once: on a scanned Φ the distance from Ω to Φ's nearest vertex
  // carries that vertex's noise, and a vertex within tolerance would count as uncovered
  // because a noisy neighbour is not. tests/check_patches.py applies the same rule.
  double omega_band = 2.0;
  // The reported errors also count Φ's vertices under Ω: within this many tolerances of it,
  // their nearest point on Ω inside it (not on its edge) and within 30° of Φ's normal (their
  // signed distance to Ω; Ω taken where it lies over Φ). On a scan the largest deviation sits
  // at the vertices, between Ω's samples.
  double vertex_band = 10.0;
  bool vertex_side = true;  // false: grid samples only (cheaper, for screening candidates)
  // The reported max |e| is searched on finer sub-grids around this many of the largest
  // samples (0: the grid alone), so that it does not depend on where the samples fell.
  int refine_max = 8;
  // The surface evaluated against is a smoothed scan: see sample_errors.
  bool untrusted_edges = false;

  std::string validate() const;
};

// `index` is the surface the solver works on. `given` (optional) is Φ as given when `index` is
// a smoothed copy of it (same vertices and faces): the trim decisions, the good parts of Ω and
// judged_gouge then come from `index`, while the reported errors and the coverage (Φ's vertices
// within tolerance of Ω) are measured against `given`.
// `grid` (optional): the grid of this motion and cutter on `index` at evaluation_grid's size,
// when the caller has it already.
Patch evaluate_patch(const SurfaceIndex& index, const Motion& motion, const Cutter& cutter,
                     const EvaluateOptions& options, const SurfaceIndex* given = nullptr,
                     const ErrorGrid* grid = nullptr);

// The rows and columns evaluate_patch samples (see EvaluateOptions::spacing).
std::pair<int, int> evaluation_grid(const Motion& motion, const Cutter& cutter, const EvaluateOptions& options);

}  // namespace flank
