#include "kernels/envelope.h"

#include <cmath>

namespace flank {

namespace {
struct Frame {
  Vec3 u, e1, e2;
  double rt_along = 0.0;  // û·rt
  double rt_normal = 0.0; // |rt − (û·rt) û|
};

bool make_frame(const Vec3& rt, const Vec3& rs, Frame* f) {
  const double L = rs.norm();
  if (!(L > 0.0)) return false;
  f->u = rs / L;
  f->rt_along = f->u.dot(rt);
  const Vec3 perp = rt - f->rt_along * f->u;
  f->rt_normal = perp.norm();
  if (!(f->rt_normal > 1e-14 * (1.0 + rt.norm()))) return false;
  f->e1 = perp / f->rt_normal;
  f->e2 = f->u.cross(f->e1);
  return true;
}
}  // namespace

EnvelopePoint envelope_point(const Vec3& centre, const Vec3& rt, const Vec3& rs, double d,
                             double dd, int side) {
  EnvelopePoint out;
  Frame f;
  if (!make_frame(rt, rs, &f)) return out;
  const double q = dd / rs.norm();  // n·û = −q
  if (!(std::abs(q) < 1.0)) return out;
  const double c = std::sqrt(1.0 - q * q);  // |n − (n·û) û|
  // n = −q û + c (cos θ ê₁ + sin θ ê₂) with n·rt = 0:
  // −q (û·rt) + c cos θ |rt⊥| = 0.
  const double cos_theta = q * f.rt_along / (c * f.rt_normal);
  if (!(std::abs(cos_theta) <= 1.0)) return out;
  const double sin_theta = (side >= 0 ? 1.0 : -1.0) * std::sqrt(1.0 - cos_theta * cos_theta);
  out.normal = -q * f.u + c * (cos_theta * f.e1 + sin_theta * f.e2);
  out.point = centre + d * out.normal;
  out.valid = true;
  return out;
}

int envelope_side(const Vec3& rt, const Vec3& rs, const Vec3& toward) {
  Frame f;
  if (!make_frame(rt, rs, &f)) return 1;
  return toward.dot(f.e2) >= 0.0 ? 1 : -1;
}

}  // namespace flank
