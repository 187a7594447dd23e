#include "solver/synth.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <vector>

#include "kernels/bspline.h"
#include "kernels/envelope.h"
#include "kernels/parallel.h"

namespace flank {

GuideCurves paper_guides() {
  GuideCurves g;
  g.top = {Vec3(75, 15, -5), Vec3(30, 30, -5), Vec3(0, 60, -5)};
  g.bottom = {Vec3(60, 0, -45), Vec3(30, 30, -45), Vec3(15, 75, -45)};
  return g;
}

Vec3 bezier2(const std::array<Vec3, 3>& p, double t, int order) {
  switch (order) {
    case 0: return (1 - t) * (1 - t) * p[0] + 2 * t * (1 - t) * p[1] + t * t * p[2];
    case 1: return 2 * ((1 - t) * (p[1] - p[0]) + t * (p[2] - p[1]));
    case 2: return 2 * (p[2] - 2 * p[1] + p[0]);
    default: return Vec3::Zero();
  }
}

AxisMotion guide_motion(const GuideCurves& guides, double length) {
  AxisMotion m;
  m.a = [bottom = guides.bottom](double t, int order) { return bezier2(bottom, t, order); };
  m.b = [guides, length](double t, int order) -> Vec3 {
    // b = B + L u, u = D/|D|, D = T − B. With N = |D|:
    // N′ = u·D′, u′ = (D′ − u N′)/N, N″ = u′·D′ + u·D″, u″ = (D″ − 2 u′ N′ − u N″)/N.
    const Vec3 B = bezier2(guides.bottom, t, order);
    const Vec3 D = bezier2(guides.top, t, 0) - bezier2(guides.bottom, t, 0);
    const double N = D.norm();
    const Vec3 u = D / N;
    if (order == 0) return B + length * u;
    const Vec3 D1 = bezier2(guides.top, t, 1) - bezier2(guides.bottom, t, 1);
    const double N1 = u.dot(D1);
    const Vec3 u1 = (D1 - u * N1) / N;
    if (order == 1) return B + length * u1;
    if (order != 2) return Vec3::Zero();
    const Vec3 D2 = bezier2(guides.top, t, 2) - bezier2(guides.bottom, t, 2);
    const double N2 = u1.dot(D1) + u.dot(D2);
    const Vec3 u2 = (D2 - 2 * u1 * N1 - u * N2) / N;
    return B + length * u2;
  };
  return m;
}

AxisMotion spline_motion(const Motion& motion) {
  auto shared = std::make_shared<const Motion>(motion);
  AxisMotion m;
  m.a = [shared](double t, int order) { return shared->a_at(t, order); };
  m.b = [shared](double t, int order) { return shared->b_at(t, order); };
  return m;
}

std::string ToolProfile::validate() const {
  std::ostringstream out;
  if (!(length > 0.0) || !std::isfinite(length)) {
    out << description << ": the axis length " << length << " must be positive";
    return out.str();
  }
  if (!radius || !slope) return description + ": no sphere radii";
  constexpr int kSamples = 1000;
  for (int i = 0; i <= kSamples; ++i) {
    const double s = static_cast<double>(i) / kSamples;
    const double d = radius(s), dd = slope(s);
    if (!std::isfinite(d) || !std::isfinite(dd)) {
      out << description << ": sphere radius not finite at s = " << s;
      return out.str();
    }
    if (d <= 0.0) {
      out << description << ": sphere radius d(" << s << ") = " << d << " is not positive";
      return out.str();
    }
    if (std::abs(dd) >= length) {
      out << description << ": radius slope |d'(" << s << ")| = " << std::abs(dd)
          << " reaches the axis length L = " << length
          << " (the cutter surface is undefined there)";
      return out.str();
    }
  }
  return {};
}

namespace {
std::string number(double v) {
  std::ostringstream out;
  out << v;
  return out.str();
}
}  // namespace

ToolProfile profile_from_cutter(const Cutter& cutter) {
  ToolProfile p;
  p.length = cutter.length;
  p.radius = [cutter](double s) { return cutter.radius(s); };
  p.slope = [cutter](double s) { return cutter.slope(s); };
  p.description = std::string(to_string(cutter.kind)) + " cutter (" +
                  std::to_string(cutter.coeffs.size()) + " coefficients), L = " +
                  number(cutter.length);
  return p;
}

ToolProfile cylinder_profile(double length, double radius) {
  ToolProfile p;
  p.length = length;
  p.radius = [radius](double) { return radius; };
  p.slope = [](double) { return 0.0; };
  p.description = "cylinder R = " + number(radius) + ", L = " + number(length);
  return p;
}

ToolProfile cone_profile(double length, double r_tip, double r_end) {
  ToolProfile p = profile_from_cutter(cone_from_end_radii(length, r_tip, r_end));
  p.description = "cone r_tip = " + number(r_tip) + ", r_end = " + number(r_end) +
                  ", L = " + number(length);
  return p;
}

ToolProfile barrel_profile(double length, double r0, double r_end) {
  ToolProfile p;
  p.length = length;
  p.description = "barrel R0 = " + number(r0) + ", r_end = " + number(r_end) + ", L = " +
                  number(length);
  const double half = 0.5 * length;
  if (!(r0 > half)) {
    // No arc of radius R0 spans the length: a profile that validate() rejects.
    p.description += " (impossible: R0 must exceed L/2)";
    p.radius = [](double) { return 0.0; };
    p.slope = [](double) { return 0.0; };
    return p;
  }
  const double sag = r0 - std::sqrt(r0 * r0 - half * half);
  const double rc = r_end + sag - r0;  // arc centre (L/2, rc), below the axis
  p.radius = [=](double s) {
    const double z = s * length - half;
    return r0 - std::sqrt(z * z + rc * rc);
  };
  p.slope = [=](double s) {
    const double z = s * length - half;
    return -length * z / std::sqrt(z * z + rc * rc);
  };
  return p;
}

std::string SynthOptions::validate() const {
  if (rows < 2 || cols < 2) return "the resolution needs at least 2 x 2 samples";
  if (static_cast<long long>(rows) * cols > 50'000'000LL)
    return "the resolution " + std::to_string(rows) + "x" + std::to_string(cols) +
           " exceeds 50 million samples";
  if (side != 1 && side != -1) return "side must be +1 or -1";
  return {};
}

namespace {

// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection §5.1.5).
Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + (d1 / (d1 - d3)) * ab;
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

double triangle_distance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  return (p - closest_on_triangle(p, a, b, c)).norm();
}

// a, a′, b, b′ at one t.
struct AxisState {
  Vec3 a, at, b, bt;
};

AxisState axis_state(const AxisMotion& m, double t) {
  return {m.a(t, 0), m.a(t, 1), m.b(t, 0), m.b(t, 1)};
}

EnvelopePoint envelope_at(const AxisState& x, double s, double d, double dd, int side) {
  const Vec3 centre = (1 - s) * x.a + s * x.b;
  const Vec3 rt = (1 - s) * x.at + s * x.bt;
  return envelope_point(centre, rt, x.b - x.a, d, dd, side);
}

}  // namespace

SynthResult synth_envelope(const AxisMotion& motion, const ToolProfile& tool,
                           const SynthOptions& options) {
  assert(options.validate().empty());
  const int rows = options.rows, cols = options.cols;
  const double ht = 1.0 / (rows - 1), hs = 1.0 / (cols - 1);
  auto t_of = [&](int i) { return i == rows - 1 ? 1.0 : i * ht; };
  auto s_of = [&](int j) { return j == cols - 1 ? 1.0 : j * hs; };

  // Sphere radii at the grid columns and at the column midpoints.
  std::vector<double> d(cols), dd(cols), dm(cols - 1), ddm(cols - 1);
  for (int j = 0; j < cols; ++j) d[j] = tool.radius(s_of(j)), dd[j] = tool.slope(s_of(j));
  for (int j = 0; j + 1 < cols; ++j) {
    const double s = (j + 0.5) * hs;
    dm[j] = tool.radius(s), ddm[j] = tool.slope(s);
  }

  SynthResult result;
  result.mesh.V.resize(static_cast<Eigen::Index>(rows) * cols, 3);
  Points normals(static_cast<Eigen::Index>(rows) * cols, 3);
  std::vector<int> row_invalid(rows, 0);
  std::vector<AxisState> state(rows);
  parallel_for(0, rows, [&](std::size_t begin, std::size_t end) {
    for (std::size_t ii = begin; ii < end; ++ii) {
      const int i = static_cast<int>(ii);
      state[i] = axis_state(motion, t_of(i));
      for (int j = 0; j < cols; ++j) {
        const EnvelopePoint e = envelope_at(state[i], s_of(j), d[j], dd[j], options.side);
        const Eigen::Index v = static_cast<Eigen::Index>(i) * cols + j;
        if (!e.valid) {
          ++row_invalid[i];
          result.mesh.V.row(v).setZero();
          normals.row(v).setZero();
          continue;
        }
        result.mesh.V.row(v) = e.point.transpose();
        normals.row(v) = e.normal.transpose();
      }
    }
  }, 8);
  for (int i = 0; i < rows; ++i) {
    if (row_invalid[i] > 0 && result.invalid == 0) {
      result.invalid_t = t_of(i);
      for (int j = 0; j < cols; ++j)
        if (normals.row(static_cast<Eigen::Index>(i) * cols + j).isZero()) {
          result.invalid_s = s_of(j);
          break;
        }
    }
    result.invalid += row_invalid[i];
  }
  if (result.invalid > 0) {
    result.mesh = Mesh{};
    return result;
  }

  const Points& V = result.mesh.V;
  auto vid = [cols](int i, int j) { return i * cols + j; };
  auto X = [&](int v) -> Vec3 { return V.row(v).transpose(); };

  // Orientation: the cell triangles (00, 10, 11), (00, 11, 01) have normals along X_t × X_s,
  // which is ±n. Vote over all cells, in a fixed order, for the sign that points along −n.
  std::vector<long long> row_vote(rows - 1, 0);
  parallel_for(0, rows - 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t ii = begin; ii < end; ++ii) {
      const int i = static_cast<int>(ii);
      for (int j = 0; j + 1 < cols; ++j) {
        const int v00 = vid(i, j), v10 = vid(i + 1, j), v11 = vid(i + 1, j + 1);
        const Vec3 fn = (X(v10) - X(v00)).cross(X(v11) - X(v00));
        const Vec3 n = (normals.row(v00) + normals.row(v10) + normals.row(v11)).transpose();
        row_vote[i] += fn.dot(n) < 0 ? 1 : -1;
      }
    }
  }, 8);
  long long vote = 0;
  for (long long v : row_vote) vote += v;
  const bool forward = vote >= 0;  // (00, 10, 11) already faces the tool

  Faces& F = result.mesh.F;
  F.resize(static_cast<Eigen::Index>(rows - 1) * (cols - 1) * 2, 3);
  for (int i = 0; i + 1 < rows; ++i)
    for (int j = 0; j + 1 < cols; ++j) {
      const int v00 = vid(i, j), v10 = vid(i + 1, j), v11 = vid(i + 1, j + 1),
                v01 = vid(i, j + 1);
      const Eigen::Index f = 2 * (static_cast<Eigen::Index>(i) * (cols - 1) + j);
      if (forward) {
        F.row(f) << v00, v10, v11;
        F.row(f + 1) << v00, v11, v01;
      } else {
        F.row(f) << v00, v11, v10;
        F.row(f + 1) << v00, v01, v11;
      }
    }

  // Chord error: the exact envelope at each cell's centre and edge midpoints against the
  // cell's two triangles.
  std::vector<double> row_error(rows - 1, 0.0);
  std::vector<int> row_bad(rows - 1, 0);
  parallel_for(0, rows - 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t ii = begin; ii < end; ++ii) {
      const int i = static_cast<int>(ii);
      const AxisState mid = axis_state(motion, (i + 0.5) * ht);
      double worst = 0.0;
      for (int j = 0; j + 1 < cols; ++j) {
        const Vec3 p00 = X(vid(i, j)), p10 = X(vid(i + 1, j)), p11 = X(vid(i + 1, j + 1)),
                   p01 = X(vid(i, j + 1));
        const EnvelopePoint samples[5] = {
            envelope_at(mid, (j + 0.5) * hs, dm[j], ddm[j], options.side),        // centre
            envelope_at(mid, s_of(j), d[j], dd[j], options.side),                 // t-edge at s_j
            envelope_at(mid, s_of(j + 1), d[j + 1], dd[j + 1], options.side),     // at s_{j+1}
            envelope_at(state[i], (j + 0.5) * hs, dm[j], ddm[j], options.side),   // s-edge at t_i
            envelope_at(state[i + 1], (j + 0.5) * hs, dm[j], ddm[j], options.side)};
        for (const EnvelopePoint& e : samples) {
          if (!e.valid) {
            ++row_bad[i];
            continue;
          }
          const double dist = std::min(triangle_distance(e.point, p00, p10, p11),
                                       triangle_distance(e.point, p00, p11, p01));
          worst = std::max(worst, dist);
        }
      }
      row_error[i] = worst;
    }
  }, 4);
  for (int i = 0; i + 1 < rows; ++i) {
    result.chord_error = std::max(result.chord_error, row_error[i]);
    if (row_bad[i] > 0 && result.invalid == 0) {
      result.invalid_t = (i + 0.5) * ht;
      result.invalid_s = 0.5;
    }
    result.invalid += row_bad[i];
  }
  return result;
}

}  // namespace flank
