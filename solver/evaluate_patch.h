// Patch evaluation (DESIGN "Machined surface Ω and error"): signed error of the sphere
// family against Φ, the machined surface Ω as a mesh, the Φ area it covers within
// tolerance, the whole-cutter gouge check and the holder clearance.
#pragma once

#include <string>
#include <vector>

#include "kernels/cutter.h"
#include "kernels/surface_index.h"
#include "solver/motion.h"
#include "solver/patch.h"

namespace flank {

// e(t_i, s_j) = dist(R(t_i, s_j), Φ) − d(s_j) on a uniform grid over [0, 1]².
struct ErrorGrid {
  int rows = 0, cols = 0;
  VecX error;                 // rows·cols, row-major over t; signed (negative: gouge)
  std::vector<char> interior; // footpoint inside Φ (not beyond its boundary)
  std::vector<int> faces;     // footpoint faces (warm starts for a finer pass)
  Points directions;          // unit g of every sample (from Φ toward the sphere centre)
  double at(int i, int j) const { return error(i * cols + j); }
  bool inside(int i, int j) const { return interior[static_cast<std::size_t>(i * cols + j)] != 0; }
};

ErrorGrid sample_errors(const SurfaceIndex& index, const Motion& motion, const Cutter& cutter,
                        int rows, int cols);

struct EvaluateOptions {
  double tolerance = 0.0;  // absolute, > 0
  int rows = 200;          // samples along t for errors and Ω
  int cols = 60;           // samples along s
  bool holder = false;
  double holder_length = 0.0;
  double holder_radius = 0.0;
  bool envelope = true;  // build Ω as a mesh
  bool coverage = true;  // measure the covered Φ area (needs Ω)

  std::string validate() const;
};

Patch evaluate_patch(const SurfaceIndex& index, const Motion& motion, const Cutter& cutter,
                     const EvaluateOptions& options);

}  // namespace flank
