#include "solver/evaluate_patch.h"

#include <algorithm>
#include <cmath>

#include "kernels/envelope.h"
#include "kernels/parallel.h"

namespace flank {

std::string EvaluateOptions::validate() const {
  if (!(tolerance > 0.0) || !std::isfinite(tolerance)) return "tolerance must be positive";
  if (rows < 2 || cols < 2) return "evaluation needs at least 2 by 2 samples";
  if (holder && !(holder_length > 0.0 && holder_radius > 0.0))
    return "holder length and radius must be positive";
  return {};
}

ErrorGrid sample_errors(const SurfaceIndex& index, const Motion& motion, const Cutter& cutter,
                        int rows, int cols) {
  ErrorGrid grid;
  grid.rows = rows, grid.cols = cols;
  Points q(static_cast<Eigen::Index>(rows) * cols, 3);
  std::vector<double> d(static_cast<std::size_t>(cols));
  for (int j = 0; j < cols; ++j) d[j] = cutter.radius(static_cast<double>(j) / (cols - 1));
  for (int i = 0; i < rows; ++i) {
    const Line l = motion.ruling(static_cast<double>(i) / (rows - 1));
    for (int j = 0; j < cols; ++j) q.row(i * cols + j) = l.point(static_cast<double>(j) / (cols - 1)).transpose();
  }
  const std::vector<ClosestPoint> cp = index.closest_points(q);
  grid.error.resize(q.rows());
  grid.interior.resize(cp.size());
  grid.faces.resize(cp.size());
  grid.directions.resize(static_cast<Eigen::Index>(cp.size()), 3);
  for (std::size_t k = 0; k < cp.size(); ++k) {
    grid.directions.row(static_cast<Eigen::Index>(k)) = cp[k].direction.transpose();
    const double dk = d[k % static_cast<std::size_t>(cols)];
    grid.interior[k] = !cp[k].boundary && cp[k].face >= 0;
    // Beyond Φ's edge the sign of the face plane means nothing: there a sphere gouges only
    // if it reaches Φ at all.
    grid.error(static_cast<Eigen::Index>(k)) =
        (grid.interior[k] ? cp[k].signed_distance : cp[k].distance) - dk;
    grid.faces[k] = cp[k].face;
  }
  return grid;
}

namespace {

Mesh envelope_mesh(const Motion& motion, const Cutter& cutter,
                   const ErrorGrid& grid, EnvelopeMesh* out) {
  const int rows = grid.rows, cols = grid.cols;
  Points V(static_cast<Eigen::Index>(rows) * cols, 3);
  std::vector<char> valid(static_cast<std::size_t>(rows) * cols, 0);
  VecX err(V.rows());
  parallel_for(0, static_cast<std::size_t>(rows), [&](std::size_t b, std::size_t e) {
    for (std::size_t ii = b; ii < e; ++ii) {
      const int i = static_cast<int>(ii);
      const double t = static_cast<double>(i) / (rows - 1);
      const Vec3 a = motion.a_at(t), bb = motion.b_at(t);
      const Vec3 at = motion.a_at(t, 1), bt = motion.b_at(t, 1);
      for (int j = 0; j < cols; ++j) {
        const double s = static_cast<double>(j) / (cols - 1);
        const Vec3 centre = (1 - s) * a + s * bb;
        const Vec3 rt = (1 - s) * at + s * bt;
        // Φ's side: the envelope normal points from the axis toward the footpoint.
        const Vec3 g = grid.directions.row(i * cols + j).transpose();
        const int side = envelope_side(rt, bb - a, -g);
        const EnvelopePoint ep = envelope_point(centre, rt, bb - a, cutter.radius(s), cutter.slope(s), side);
        const std::size_t k = static_cast<std::size_t>(i * cols + j);
        valid[k] = ep.valid;
        V.row(static_cast<Eigen::Index>(k)) = (ep.valid ? ep.point : centre).transpose();
        err(static_cast<Eigen::Index>(k)) = grid.error(static_cast<Eigen::Index>(k));
      }
    }
  });
  std::vector<Eigen::Vector3i> faces;
  auto add = [&](int p, int q, int r) {
    if (!valid[p] || !valid[q] || !valid[r]) return;
    const Vec3 n = (Vec3(V.row(q)) - Vec3(V.row(p))).cross(Vec3(V.row(r)) - Vec3(V.row(p)));
    if (n.norm() > 1e-20) faces.emplace_back(p, q, r);
  };
  for (int i = 0; i + 1 < rows; ++i)
    for (int j = 0; j + 1 < cols; ++j) {
      const int v00 = i * cols + j, v01 = v00 + 1, v10 = v00 + cols, v11 = v10 + 1;
      add(v00, v10, v11);
      add(v00, v11, v01);
    }
  Mesh m;
  m.V = V;
  m.F.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (std::size_t f = 0; f < faces.size(); ++f) m.F.row(static_cast<Eigen::Index>(f)) = faces[f].transpose();
  out->V = V;
  out->F = m.F;
  out->error = err;
  out->rows = rows;
  out->cols = cols;
  return m;
}

}  // namespace

Patch evaluate_patch(const SurfaceIndex& index, const Motion& motion, const Cutter& cutter,
                     const EvaluateOptions& options) {
  Patch patch;
  patch.motion = motion;
  patch.cutter = cutter;
  const ErrorGrid grid = sample_errors(index, motion, cutter, options.rows, options.cols);

  double max_abs = 0.0, sum_sq = 0.0, max_gouge = 0.0;
  int count = 0;
  for (Eigen::Index k = 0; k < grid.error.size(); ++k) {
    const double e = grid.error(k);
    max_gouge = std::max(max_gouge, -e);  // the whole cutter, every s and t
    if (!grid.interior[static_cast<std::size_t>(k)]) continue;
    max_abs = std::max(max_abs, std::abs(e));
    sum_sq += e * e;
    ++count;
  }
  patch.error.max = max_abs;
  patch.error.rms = count ? std::sqrt(sum_sq / count) : 0.0;
  patch.error.max_gouge = max_gouge;
  patch.error.max_relative = max_abs / index.diagonal();

  if (options.holder) {
    // The holder: a cylinder of the given radius on the half-axis beyond the spindle end b.
    const int steps_t = options.rows, steps_h = 24;
    Points q(static_cast<Eigen::Index>(steps_t) * steps_h, 3);
    for (int i = 0; i < steps_t; ++i) {
      const Line l = motion.ruling(static_cast<double>(i) / (steps_t - 1));
      const Vec3 u = (l.b - l.a).normalized();
      for (int h = 0; h < steps_h; ++h)
        q.row(i * steps_h + h) = (l.b + (options.holder_length * h / (steps_h - 1)) * u).transpose();
    }
    const std::vector<ClosestPoint> cp = index.closest_points(q);
    double clearance = std::numeric_limits<double>::infinity();
    for (const ClosestPoint& f : cp) {
      const double dist = f.boundary ? f.distance : f.signed_distance;
      clearance = std::min(clearance, dist - options.holder_radius);
    }
    patch.collision.checked = true;
    patch.collision.holder_length = options.holder_length;
    patch.collision.holder_radius = options.holder_radius;
    patch.collision.min_clearance = clearance;
    patch.collision.holder_clear = clearance >= 0.0;
  }

  if (options.envelope || options.coverage) {
    const Mesh omega = envelope_mesh(motion, cutter, grid, &patch.envelope);
    if (options.coverage && omega.F.rows() > 0) {
      const SurfaceIndex omega_index(omega);
      const Mesh& phi = index.mesh();
      const std::vector<ClosestPoint> cp = omega_index.closest_points(phi.V);
      const VecX area = vertex_areas(phi);
      double covered = 0.0;
      for (int v = 0; v < phi.vertex_count(); ++v) {
        const ClosestPoint& f = cp[static_cast<std::size_t>(v)];
        if (f.face >= 0 && !f.boundary && f.distance <= options.tolerance) {
          patch.covered_vertices.push_back(v);
          covered += area(v);
        }
      }
      patch.covered_area = covered;
      patch.coverage_fraction = covered / std::max(1e-300, area.sum());
    }
    if (!options.envelope) patch.envelope = {};
  }
  return patch;
}

}  // namespace flank
