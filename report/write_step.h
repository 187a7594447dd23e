// The machined surfaces and the cutters as CAD: patches.step (each patch's Ω as a B-spline
// surface, the second paper's flank-millable NURBS surface) and tools.step (each cutter as a
// solid of revolution at the start of its motion).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "io/cad.h"
#include "kernels/types.h"
#include "solver/patch.h"

namespace flank::report {

struct FittedSurface {
  io::SplineSurface surface;
  double deviation = 0.0;  // max distance from the exact surface at grid points and cell midpoints, mm
};

// Fits a B-spline surface to the even points of `fine`, a (2·rows − 1) × (2·cols − 1) grid of
// exact surface points (row-major), within `fit_tolerance`, and measures its deviation from
// every fine point (grid points, edge midpoints and cell centres) at the same parameters:
// an upper bound on the distance between the two surfaces there. Throws io::Error(name: …).
FittedSurface fit_exact_grid(const std::string& name, const Points& fine, int rows, int cols,
                             double fit_tolerance);

// Ω of patch `p` sampled exactly (forward model) on a (2·rows − 1) × (2·cols − 1) grid over its
// (t, s) ∈ [0, 1]², rows × cols being its envelope grid; false if some point has no envelope.
bool exact_omega_grid(const Patch& p, Points& fine);

// The name of a patch's face in patches.step and of its cutter in tools.step.
std::string face_name(const Patch& p);
std::string tool_name(const Patch& p);

// patches.step: one named B-spline face per patch, fitted within tolerance / 200. Returns each
// patch's measured deviation (NaN where Ω could not be sampled; that patch is left out).
std::vector<double> write_patches_step(const std::filesystem::path& path, const std::vector<Patch>& patches,
                                       double tolerance);
// tools.step: each cutter's meridian (patches.json's tool.profile), closed by flat ends and
// revolved about its axis, placed at t = 0 of its motion.
void write_tools_step(const std::filesystem::path& path, const std::vector<Patch>& patches);

}  // namespace flank::report
