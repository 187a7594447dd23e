#include "report/write_step.h"

#include <cmath>
#include <limits>

#include "io/read_mesh.h"
#include "kernels/envelope.h"

namespace flank::report {

namespace {
constexpr int kProfileSamples = 101;  // the meridian samples of patches.json's tool.profile
}  // namespace

FittedSurface fit_exact_grid(const std::string& name, const Points& fine, int rows, int cols,
                             double fit_tolerance) {
  const int fine_cols = 2 * cols - 1;
  Points grid(static_cast<Eigen::Index>(rows) * cols, 3);
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < cols; ++j)
      grid.row(static_cast<Eigen::Index>(i) * cols + j) = fine.row(static_cast<Eigen::Index>(2 * i) * fine_cols + 2 * j);
  FittedSurface out{io::SplineSurface::fit(name, grid, rows, cols, fit_tolerance), 0.0};
  for (int i = 0; i < 2 * rows - 1; ++i)
    for (int j = 0; j < fine_cols; ++j) {
      const Vec3 on = out.surface.point(i / (2.0 * (rows - 1)), j / (2.0 * (cols - 1)));
      const Vec3 exact = fine.row(static_cast<Eigen::Index>(i) * fine_cols + j).transpose();
      out.deviation = std::max(out.deviation, (on - exact).norm());
    }
  return out;
}

bool exact_omega_grid(const Patch& p, Points& fine) {
  const EnvelopeMesh& env = p.envelope;
  const int rows = env.rows, cols = env.cols;
  if (rows < 2 || cols < 2 || env.V.rows() != static_cast<Eigen::Index>(rows) * cols) return false;
  const int fr = 2 * rows - 1, fc = 2 * cols - 1;
  fine.resize(static_cast<Eigen::Index>(fr) * fc, 3);
  for (int i = 0; i < fr; ++i) {
    const double t = i / static_cast<double>(fr - 1);
    const Line l = p.motion.ruling(t);
    const Vec3 at = p.motion.a_at(t, 1), bt = p.motion.b_at(t, 1);
    for (int j = 0; j < fc; ++j) {
      const double s = j / static_cast<double>(fc - 1);
      // The side the envelope grid took: the candidate nearer to it (bilinear between samples).
      const int i0 = std::min(i / 2, rows - 2), j0 = std::min(j / 2, cols - 2);
      const double wu = 0.5 * (i - 2 * i0), wv = 0.5 * (j - 2 * j0);
      auto V = [&](int a, int b) -> Vec3 { return env.V.row(static_cast<Eigen::Index>(a) * cols + b).transpose(); };
      const Vec3 near = (1 - wu) * ((1 - wv) * V(i0, j0) + wv * V(i0, j0 + 1)) +
                        wu * ((1 - wv) * V(i0 + 1, j0) + wv * V(i0 + 1, j0 + 1));
      const Vec3 centre = l.point(s), rs = l.b - l.a, rt = (1 - s) * at + s * bt;
      const double d = p.cutter.radius(s), dd = p.cutter.slope(s);
      const EnvelopePoint plus = envelope_point(centre, rt, rs, d, dd, +1);
      const EnvelopePoint minus = envelope_point(centre, rt, rs, d, dd, -1);
      if (!plus.valid || !minus.valid) return false;
      const Vec3 q = (plus.point - near).norm() <= (minus.point - near).norm() ? plus.point : minus.point;
      fine.row(static_cast<Eigen::Index>(i) * fc + j) = q.transpose();
    }
  }
  return fine.allFinite();
}

// Appended, not "P" + …: GCC 12 warns falsely (-Wrestrict, its bug 105329) on the latter.
std::string face_name(const Patch& p) {
  std::string name = "P";
  name += std::to_string(p.id);
  return name;
}
std::string tool_name(const Patch& p) { return face_name(p) + "-tool"; }

std::vector<double> write_patches_step(const std::filesystem::path& path, const std::vector<Patch>& patches,
                                       double tolerance) {
  std::vector<double> deviation(patches.size(), std::numeric_limits<double>::quiet_NaN());
  std::vector<io::NamedSurface> faces;
  for (std::size_t k = 0; k < patches.size(); ++k) {
    const Patch& p = patches[k];
    Points fine;
    if (!exact_omega_grid(p, fine)) continue;
    FittedSurface f = fit_exact_grid(path.string() + ": patch " + std::to_string(p.id), fine, p.envelope.rows,
                                     p.envelope.cols, tolerance / 200.0);
    deviation[k] = f.deviation;
    faces.push_back({face_name(p), std::move(f.surface)});
  }
  io::write_surfaces(path, faces);
  return deviation;
}

void write_tools_step(const std::filesystem::path& path, const std::vector<Patch>& patches) {
  std::vector<io::RevolvedSolid> solids;
  for (const Patch& p : patches) {
    io::RevolvedSolid s;
    s.name = tool_name(p);
    const Line l = p.motion.ruling(0.0);
    s.origin = l.a;
    s.axis = (l.b - l.a).normalized();
    for (int k = 0; k < kProfileSamples; ++k) s.meridian.push_back(p.cutter.meridian(k / (kProfileSamples - 1.0)));
    solids.push_back(std::move(s));
  }
  io::write_solids(path, solids);
}

}  // namespace flank::report
