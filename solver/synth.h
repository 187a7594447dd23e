// The forward problem (paper 2, Li–Mann–Bedi): a cutter Ψ given by its sphere radii d(s) and
// a motion of its axis give the exact machined surface Ω, sampled on a (t, s) grid and
// written as a triangle mesh. These envelopes are the ground truth of the recovery tests:
// a part machined by a known tool and motion must be found again by fit/decompose.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

#include "kernels/cutter.h"
#include "kernels/mesh.h"
#include "kernels/types.h"
#include "solver/motion.h"

namespace flank {

// The two axis end curves, t ∈ [0, 1]: a(t) the tip, b(t) toward the spindle. `order` is the
// derivative order, 0 (position), 1 or 2.
struct AxisMotion {
  std::function<Vec3(double t, int order)> a, b;
};

// Two quadratic Bézier guiding curves (knots [0,0,0,1,1,1]), paper 2 §4.
struct GuideCurves {
  std::array<Vec3, 3> bottom, top;
};

// Table 1 of paper 2 (mm): top T0 (75,15,−5), T1 (30,30,−5), T2 (0,60,−5);
// bottom B0 (60,0,−45), B1 (30,30,−45), B2 (15,75,−45).
GuideCurves paper_guides();

// Point (order 0), first or second derivative of a quadratic Bézier curve.
Vec3 bezier2(const std::array<Vec3, 3>& control, double t, int order = 0);

// The tool positioned on the guiding curves: tip a(t) = B(t) on the bottom curve, axis
// through B toward T, b(t) = B(t) + length · (T − B)/|T − B|. Derivatives are analytic.
AxisMotion guide_motion(const GuideCurves& guides, double length);

// The clamped cubic B-spline motion of flank's own patches.
AxisMotion spline_motion(const Motion& motion);

// The cutter as sphere radii on its axis: d(s) and d′(s) = dd/ds for s ∈ [0, 1] from the tip
// (s = 0, at a) to the spindle end (s = 1, at b). `length` is the axis length L = |b − a|.
struct ToolProfile {
  double length = 0.0;
  std::function<double(double s)> radius, slope;
  std::string description;

  // Empty if usable: d(s) finite and positive, |d′(s)| < L over [0, 1] (sampled);
  // otherwise one line naming the problem.
  std::string validate() const;
};

ToolProfile profile_from_cutter(const Cutter& cutter);
// Cylinder of radius R: d(s) = R.
ToolProfile cylinder_profile(double length, double radius);
// Cone whose meridian runs from r_tip at z = 0 (the tip, at a) to r_end at z = L.
ToolProfile cone_profile(double length, double r_tip, double r_end);
// Barrel: meridian a circular arc of radius R0 through (z = 0, r_end) and (z = L, r_end),
// bulging outward by sag = R0 − √(R0² − (L/2)²) at the middle. The sphere centred at z = sL
// and tangent inside the arc (arc centre (L/2, rc), rc = r_end + sag − R0) has radius
// d(z) = R0 − √((z − L/2)² + rc²). Needs R0 > L/2.
// Note: the end spheres (s = 0, 1) touch the arc slightly beyond the axis ends (at z ≈ ∓0.30
// for the default barrel, radius ≈ 4.98), because their contact normal points at the
// off-axis arc centre; the cutter's working meridian therefore spans z ∈ [−0.30, L + 0.30].
ToolProfile barrel_profile(double length, double r0, double r_end);

// Fig. 6 of paper 2 gives only the arc radius R0 = 418.17 mm and h = 50 mm of its barrel; the
// end radius is not stated. flank's default barrel takes r_end = 5 mm (the cylinder's radius),
// which gives a sag of 0.748 mm and a middle radius of 5.748 mm.
constexpr double kPaperBarrelR0 = 418.17;
constexpr double kPaperBarrelEndRadius = 5.0;
constexpr double kPaperToolLength = 50.0;

struct SynthOptions {
  int rows = 241;  // samples in t (along the motion)
  int cols = 61;   // samples in s (along the axis)
  int side = +1;   // which side of the motion the envelope is taken on (see envelope_point)

  std::string validate() const;  // empty if usable
};

struct SynthResult {
  Mesh mesh;             // rows × cols vertices, vertex (i, j) at index i·cols + j
  int invalid = 0;       // grid points without an envelope point (mesh left empty if > 0)
  double invalid_t = 0;  // parameters of the first invalid grid point
  double invalid_s = 0;
  // Largest distance from the exact envelope at each cell's centre and edge midpoints to the
  // cell's triangles: how well the mesh represents Ω at this resolution.
  double chord_error = 0;
};

// Ω on the uniform grid (t_i, s_j) over [0, 1]²: vertex = R + d n with R(t, s) =
// (1 − s) a(t) + s b(t). Each grid cell becomes two triangles split along its (i, j)–(i+1, j+1)
// diagonal, oriented so that face normals point toward the tool (the sphere centres).
SynthResult synth_envelope(const AxisMotion& motion, const ToolProfile& tool,
                           const SynthOptions& options = {});


}  // namespace flank
