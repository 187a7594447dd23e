// Points of the envelope Ω of the two-parameter sphere family with centres R(t, s) and radii
// d(s) (DESIGN "Machined surface Ω"): unit n with n·∂R/∂t = 0 and n·∂R/∂s = −d′(s), point
// R + d n. Two solutions (the two sides of the motion); `side` picks one.
#pragma once

#include "kernels/types.h"

namespace flank {

struct EnvelopePoint {
  Vec3 point = Vec3::Zero();
  Vec3 normal = Vec3::Zero();  // unit, from the sphere centre to the point
  bool valid = false;          // false where |d′| ≥ L or the axis does not move across itself
};

// centre = R(t, s), rt = ∂R/∂t, rs = ∂R/∂s = b − a, d = d(s), dd = d′(s).
// side = +1 takes n with positive component along û × ê₁ (û = rs/|rs|, ê₁ the unit part of
// rt normal to û); side = −1 the other one.
EnvelopePoint envelope_point(const Vec3& centre, const Vec3& rt, const Vec3& rs, double d,
                             double dd, int side);

// The side (+1/−1) whose envelope normal points along `toward` (e.g. from the axis to Φ).
int envelope_side(const Vec3& rt, const Vec3& rs, const Vec3& toward);

}  // namespace flank
