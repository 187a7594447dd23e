// The machined surfaces and the cutters as CAD: patches.step (each patch's Ω as a B-spline
// surface, the second paper's flank-millable NURBS surface) and tools.step (each cutter as a
// solid of revolution at the start of its motion).
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "io/cad.h"
#include "kernels/types.h"
#include "kernels/cutter.h"
#include "solver/patch.h"

namespace flank::report {

struct FittedSurface {
  io::SplineSurface surface;
  double deviation = 0.0;  // max distance from the exact surface at grid points and cell midpoints, mm
};

// The (t, s) rectangle of a patch that its face in patches.step covers: its parameter domain.
struct FaceDomain {
  double t0 = 0.0, t1 = 1.0, s0 = 0.0, s1 = 1.0;
};

// Where the exact surface changes polynomial piece, along t (the motion's interior knots) and
// along s (a spline cutter's): sorted, inside (0, 1).
struct FaceBreaks {
  std::vector<double> t, s;
};
FaceBreaks face_breaks(const Patch& p);

// Fits a clamped cubic B-spline surface (least squares, tensor product, over `domain`) to the
// even points of `fine`, a (2·rows − 1) × (2·cols − 1) grid of exact surface points (row-major)
// uniform over the domain, and measures its deviation from every fine point (grid points, edge
// midpoints and cell centres) at the same parameters: an upper bound on the distance between
// the two surfaces there. Knots first follow the surface's pieces (`breaks`, each a double
// knot), as few as meet `target`; else half as many poles as grid points on uniform knots,
// else more. Throws io::Error(name: …).
FittedSurface fit_exact_grid(const std::string& name, const Points& fine, int rows, int cols,
                             double target, const FaceDomain& domain = {}, const FaceBreaks& breaks = {});

// patches.step's search for a face within tolerance/150 tries denser grids of Ω (2 × 1, 2 × 2,
// 4 × 2, ... up to 8 × 8 times the points) while they may help: after a square density (2k × 2k
// times the points) it goes on only if a face exists (`now`) and misses by at most half what
// the best did after k × k (`before`; +∞ when there was none). A cubic's miss on a smooth Ω
// falls about 16× when the points double both ways; one that does not even halve means Ω is
// not smooth at the grid's scale (it folds, or the grid jumps between its two sides), and
// denser grids then cost time without a face: the ladder's 2k blade rung spent 8.4 of its 8.7 s
// of search on three such faces. No face of the coverage cases met the target after a step
// that failed this test (none needed uniform knots at all).
bool denser_grids_may_help(double before, std::optional<double> now);

// The search's first pass lays knots that follow Ω; where a span that misses cannot be split
// finer than the grid's rows (columns), it tries twice as many, up to `most` times the
// envelope's. Each doubling lets the knots halve their spans once more, by which a cubic's
// miss falls about 16× at best: a miss of the knots (at `more` times the rows) above 16^k
// times their target, with k doublings left, is out of reach, and the pass stops there. The
// ladder's 2k blade rung had a face that missed by 24000× its target on the envelope's rows
// and 15000× on 8×, each time unlaid: 0.35 of its 0.78 s of writing; the faces the pass is
// for missed by 1.1× (Rotor 67 upper at 3e-4, met on 4×) to 18×. An infinite miss (no knots
// could be tried: more poles than the grid holds) is not judged.
bool knots_within_reach(double miss, double target, int more, int most);

// Ω of patch `p` sampled exactly (forward model), on the side its envelope grid took, on a
// (2·rows − 1) × (2·cols − 1) grid uniform over (t, s) ∈ [0, 1]², cut down to the rows and
// columns (of the rows × cols grid) where Ω exists everywhere: a motion that starts or ends
// with a stall, or a cutter whose end has no contact circle, leaves no Ω there. `domain` and
// the reduced rows and cols say what was kept. False when what lacks Ω is not at the
// rectangle's edges or fewer than 4 × 4 grid points are left.
// Where it cut, `margin` more rows or columns of the patch's envelope grid are left out.
bool exact_omega_grid(const Patch& p, int& rows, int& cols, Points& fine, FaceDomain* domain, int margin = 0);

// The meridian tools.step revolves: patches.json's tool.profile (101 points of
// Cutter::meridian), or, where that folds back along the axis, the outline of the union of the
// cutter's spheres (201 points).
std::vector<Vec2> solid_profile(const Cutter& c);

// The name of a patch's face in patches.step and of its cutter in tools.step.
std::string face_name(const Patch& p);
std::string tool_name(const Patch& p);

// A patch's face as written: its measured deviation from the exact Ω (NaN where Ω could not
// be sampled; that patch is left out) and the (t, s) domain it covers.
struct WrittenFace {
  double deviation = 0.0;
  FaceDomain domain;
};

// A face before it becomes Open CASCADE's: its poles (nu × nv, row-major, rows along u) on
// clamped cubic knots over its domain, and its deviation from the exact Ω, mm.
struct FacePoles {
  Points poles;
  int nu = 0, nv = 0;
  std::vector<double> knots_u, knots_v;
  double deviation = 0.0;
};
struct FittedFace {
  FacePoles poles;
  FaceDomain domain;
};
// Empty where Ω could not be sampled (that patch is left out of patches.step).
using PatchFace = std::optional<FittedFace>;

// patches.step: one named B-spline face per patch, fitted within tolerance/150 where it can be
// (a margin under the 1% promised), else as close as the search came.
std::vector<WrittenFace> write_patches_step(const std::filesystem::path& path, const std::vector<Patch>& patches,
                                            double tolerance);
// The same in two steps: the faces fitted (flank's own work, no Open CASCADE; `file` names the
// output in errors), then written. A caller overlaps the fit with the CAD module's opening
// or with other Open CASCADE work (tools.step).
std::vector<PatchFace> fit_patch_faces(const std::string& file, const std::vector<Patch>& patches, double tolerance);
std::vector<WrittenFace> write_patches_step(const std::filesystem::path& path, const std::vector<Patch>& patches,
                                            const std::vector<PatchFace>& faces);
// tools.step: each cutter's meridian (solid_profile), closed by flat ends and
// revolved about its axis, placed at t = 0 of its motion.
void write_tools_step(const std::filesystem::path& path, const std::vector<Patch>& patches);

}  // namespace flank::report
