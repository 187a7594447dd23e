#include "kernels/movability.h"

#include <Eigen/Eigenvalues>
#include <array>
#include <atomic>
#include <cmath>
#include <memory>
#include <mutex>
#include <vector>

namespace flank {

double movability_sample(int i, int n) { return (i + 0.5) / n; }

namespace {

// The radius range of a line's profile is checked at s = k / kRangeChecks, k = 0..kRangeChecks.
constexpr int kRangeChecks = 20;

// The profile basis of `kind` at the n samples of a line (rows 0..n−1) and at the range checks
// (rows n..n + kRangeChecks), made once: every line of a search has the same ones, and a run
// uses a few (kind, n). Shared by the threads and kept for the process, read without a lock.
// Not a thread_local: a thread's first use of a thread_local with a destructor registers it
// under the dynamic loader's lock (__cxa_thread_atexit), which waits out a dlopen in progress,
// the CAD module's that decompose opens meanwhile (50 ms of the 13k cone part's candidates).
const ProfileTable& sample_table(CutterKind kind, int n) {
  static std::array<std::atomic<const ProfileTable*>, 64> published{};
  static std::mutex mutex;
  static std::vector<std::unique_ptr<const ProfileTable>> tables;  // under `mutex`; beyond 64 too
  const std::size_t rows = static_cast<std::size_t>(n) + kRangeChecks + 1;
  const auto fits = [&](const ProfileTable& t) { return t.kind == kind && t.s.size() == rows; };
  for (const auto& slot : published) {
    const ProfileTable* t = slot.load(std::memory_order_acquire);
    if (!t) break;
    if (fits(*t)) return *t;
  }
  const std::lock_guard lock(mutex);
  for (const auto& t : tables)
    if (fits(*t)) return *t;
  std::vector<double> s;
  for (int i = 0; i < n; ++i) s.push_back(movability_sample(i, n));
  for (int k = 0; k <= kRangeChecks; ++k) s.push_back(k / static_cast<double>(kRangeChecks));
  tables.push_back(std::make_unique<const ProfileTable>(profile_table(kind, s)));
  if (tables.size() <= published.size()) published[tables.size() - 1].store(tables.back().get(), std::memory_order_release);
  return *tables.back();
}

}  // namespace

Movability movability_from_directions(const Vec3& a, const Vec3& b, std::span<const double> s,
                                      PointsRef g, std::span<const double> weights,
                                      double null_cutoff, const Vec3* tangent,
                                      double tangent_below) {
  Movability out;
  out.samples = static_cast<int>(s.size());
  const Vec3 ab = b - a;
  const double L = ab.norm();
  if (!(L > 0.0) || s.size() < 3) return out;
  out.u = ab / L;
  // Any orthonormal frame normal to u: the velocity field in world space does not depend on it.
  out.n1 = out.u.unitOrthogonal();
  out.n2 = out.u.cross(out.n1);

  // A = (1/Σw) Σ w_i k_i k_iᵀ with r_i = ⟨g_i, v(s_i)⟩ = k_iᵀ x (eq. 5).
  Eigen::Matrix<double, 5, 5> A = Eigen::Matrix<double, 5, 5>::Zero();
  double wsum = 0.0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const double w = weights.empty() ? 1.0 : weights[i];
    if (w <= 0.0) continue;
    const Vec3 gi = g.row(static_cast<Eigen::Index>(i)).transpose();
    const double g1 = gi.dot(out.n1), g2 = gi.dot(out.n2), gu = gi.dot(out.u);
    const double h = s[i] - 0.5;
    Eigen::Matrix<double, 5, 1> k;
    k << g1, g2, gu, h * g1, h * g2;
    A.noalias() += w * k * k.transpose();
    wsum += w;
  }
  if (wsum < 3.0) return out;
  A /= wsum;

  // Eliminate y = (α, λ1, λ2): S = A_μμ − A_μy A_yy⁺ A_yμ, the pseudo-inverse because α is
  // unconstrained on cylinder-like lines (g ⟂ u everywhere).
  const Eigen::Matrix2d Amm = A.topLeftCorner<2, 2>();
  const Eigen::Matrix<double, 2, 3> Amy = A.topRightCorner<2, 3>();
  const Eigen::Matrix3d Ayy = A.bottomRightCorner<3, 3>();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> ey(Ayy);
  // Directions of y that the footpoints barely see are free: set to zero, not amplified.
  const double cutoff = null_cutoff * std::max(1e-300, A.trace());
  Eigen::Matrix3d Ayy_pinv = Eigen::Matrix3d::Zero();
  for (int k = 0; k < 3; ++k) {
    const double lam = ey.eigenvalues()(k);
    if (lam > cutoff)
      Ayy_pinv += (1.0 / lam) * ey.eigenvectors().col(k) * ey.eigenvectors().col(k).transpose();
  }
  Eigen::Matrix2d S = Amm - Amy * Ayy_pinv * Amy.transpose();
  S = 0.5 * (S + S.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(S);
  Eigen::Vector2d mu = es.eigenvectors().col(0);
  double value = es.eigenvalues()(0), value_other = es.eigenvalues()(1);
  if (tangent && es.eigenvalues()(1) <= tangent_below) {
    // Both sweeps are (nearly) free: take the one tangent to Φ. Its cost is μᵀSμ.
    const Eigen::Vector2d t(tangent->dot(out.n1), tangent->dot(out.n2));
    if (t.norm() > 0) {
      mu = t.normalized();
      value = mu.dot(S * mu);
      value_other = S.trace() - value;
    }
  }
  const Eigen::Vector3d y = -Ayy_pinv * Amy.transpose() * mu;
  out.value = std::max(0.0, value);
  out.value_other = std::max(0.0, value_other);
  out.mu1 = mu(0), out.mu2 = mu(1);
  out.alpha = y(0), out.lambda1 = y(1), out.lambda2 = y(2);
  out.status = MovabilityStatus::ok;
  return out;
}

std::vector<ClosestPoint> line_footpoints(const SurfaceIndex& index, const Vec3& a, const Vec3& b, int n,
                                          std::span<int> hints) {
  Points q(n, 3);
  for (int i = 0; i < n; ++i) {
    const double s = movability_sample(i, n);
    q.row(i) = ((1.0 - s) * a + s * b).transpose();
  }
  std::vector<ClosestPoint> cp(static_cast<std::size_t>(n));
  const bool hinted = static_cast<int>(hints.size()) == n;
  index.closest_points_serial(q, hinted ? std::span<const int>(hints) : std::span<const int>{}, cp);
  if (hinted)
    for (int i = 0; i < n; ++i) hints[i] = cp[i].face;
  return cp;
}

Movability movability(const SurfaceIndex& index, const Vec3& a, const Vec3& b,
                      const MovabilityOptions& options, std::span<int> hints) {
  const std::vector<ClosestPoint> cp = line_footpoints(index, a, b, options.samples, hints);
  return movability_from_footpoints(a, b, cp, options);
}

Movability movability_from_footpoints(const Vec3& a, const Vec3& b, std::span<const ClosestPoint> cp,
                                      const MovabilityOptions& options) {
  const int n = static_cast<int>(cp.size());
  std::vector<double> s(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) s[i] = movability_sample(i, n);
  Points g(n, 3);
  std::vector<double> w(static_cast<std::size_t>(n), 1.0);
  int boundary = 0;
  bool jump = false;
  const double step = (b - a).norm() / n;
  for (int i = 0; i < n; ++i) {
    g.row(i) = cp[i].direction.transpose();
    if (cp[i].boundary || cp[i].face < 0) {
      w[i] = 0.0;
      ++boundary;
    }
    // Two branches of the characteristic (paper Remark 1) show as interior footpoints that
    // jump; footpoints on Φ's boundary jump across a hole or along an edge, which is no branch.
    const bool interior_pair = i > 0 && !cp[i].boundary && !cp[i - 1].boundary && cp[i].face >= 0 && cp[i - 1].face >= 0;
    if (interior_pair && (cp[i].point - cp[i - 1].point).norm() > options.jump_factor * step + 1e-12)
      jump = true;
  }
  Vec3 tangent = Vec3::Zero();
  if (options.tangent_sweep_below > 0) {
    Vec3 mean_g = Vec3::Zero();
    for (int i = 0; i < n; ++i) mean_g += w[i] * g.row(i).transpose();
    tangent = (b - a).cross(mean_g);
  }
  Movability out = movability_from_directions(a, b, s, g, w, options.null_cutoff,
                                              options.tangent_sweep_below > 0 ? &tangent : nullptr,
                                              options.tangent_sweep_below);
  out.boundary_samples = boundary;
  if (options.profile && out.status == MovabilityStatus::ok) {
    // The basis at the samples and at the 21 checks of the radius range, tabulated once.
    const ProfileTable& table = sample_table(*options.profile, n);
    std::vector<int> rows;
    std::vector<double> dd;
    for (int i = 0; i < n; ++i)
      if (w[i] > 0) rows.push_back(i), dd.push_back(cp[i].distance);
    out.cutter = Cutter::fit(table, (b - a).norm(), rows, dd);
    double sq = 0.0;
    out.radius_min = std::numeric_limits<double>::infinity();
    out.radius_max = -out.radius_min;
    for (std::size_t k = 0; k < rows.size(); ++k) {
      const double r = out.cutter.radius_at(table, rows[k]) - dd[k];
      sq += r * r;
    }
    for (int k = 0; k <= kRangeChecks; ++k) {
      const double radius = out.cutter.radius_at(table, n + k);
      out.radius_min = std::min(out.radius_min, radius);
      out.radius_max = std::max(out.radius_max, radius);
      out.max_slope = std::max(out.max_slope, std::abs(out.cutter.slope_at(table, n + k)));
    }
    out.profile_rms = rows.empty() ? 0.0 : std::sqrt(sq / static_cast<double>(rows.size()));
    if (options.second_profile && !rows.empty()) {
      const ProfileTable& second_table = sample_table(*options.second_profile, n);
      const Cutter second = Cutter::fit(second_table, (b - a).norm(), rows, dd);
      double sq2 = 0.0;
      for (std::size_t k = 0; k < rows.size(); ++k) {
        const double r = second.radius_at(second_table, rows[k]) - dd[k];
        sq2 += r * r;
      }
      out.second_profile_rms = std::sqrt(sq2 / static_cast<double>(rows.size()));
    }
  }
  if (boundary > options.max_boundary_fraction * n)
    out.status = MovabilityStatus::left_surface;
  else if (out.status == MovabilityStatus::ok && jump)
    out.status = MovabilityStatus::jump;
  return out;
}

}  // namespace flank
