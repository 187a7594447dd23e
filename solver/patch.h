// A flank-millable patch: a cutter, its motion, and the proof of error and collisions.
#pragma once

#include <limits>
#include <vector>

#include "kernels/cutter.h"
#include "kernels/types.h"
#include "solver/motion.h"

namespace flank {

// Against Φ as given: e is Ω's signed deviation where Ω lies over Φ; the gouge also counts
// every sphere of the whole cutter (every s, every t).
struct PatchError {
  double max = 0.0;           // max |e| over the evaluated samples of Ω
  double rms = 0.0;           // rms of e
  double max_gouge = 0.0;     // max(−e, 0) over Ω and the whole cutter
  double max_relative = 0.0;  // max / bbox diagonal of Φ
  // The gouge the patch was judged on: against the smoothed Φ the solver worked on when Φ is
  // noisy (see solver/surface_noise.h), else max_gouge. A scan's noise puts single vertices
  // above any surface the cutter could leave; they are not what the cutter gouges.
  double judged_gouge = 0.0;
};

struct Collision {
  bool checked = false;       // a holder was given
  bool holder_clear = true;   // holder cylinder keeps clear of Φ
  double min_clearance = std::numeric_limits<double>::infinity();  // min dist − holder radius
  double holder_length = 0.0;
  double holder_radius = 0.0;
};

// Ω sampled on a grid in (t, s): #rows·#cols vertices, row-major over t, with the signed
// error e of each vertex (e > 0 material left, e < 0 gouge).
struct EnvelopeMesh {
  Points V;
  Faces F;
  VecX error;
  int rows = 0;
  int cols = 0;
};

struct Patch {
  int id = 0;
  Motion motion;
  Cutter cutter;
  char tip = 'a';  // the cutter tip is at a(t); the spindle is beyond b(t)
  PatchError error;
  double covered_area = 0.0;
  double coverage_fraction = 0.0;  // covered area / area of Φ
  Collision collision;
  std::vector<int> covered_vertices;  // Φ vertices within tolerance of Ω's interior
  EnvelopeMesh envelope;
};

}  // namespace flank
