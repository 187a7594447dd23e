#include "solver/fit_motion.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <vector>

#include "kernels/bspline.h"
#include "kernels/parallel.h"
#include "solver/sparse_cholesky.h"

namespace flank {

std::string FitOptions::validate() const {
  if (samples_t < 8) return "fit needs at least 8 samples along the motion";
  if (samples_s < 4) return "fit needs at least 4 samples along the axis";
  if (control_points != 0 && control_points < 4) return "a motion needs at least 4 control points";
  if (weight_plane < 0 || weight_fair < 0 || weight_point < 0 || weight_rigid < 0)
    return "fit weights must not be negative";
  if (weight_plane + weight_point <= 0) return "one of the proximity weights must be positive";
  if (max_iterations < 1) return "fit needs at least one iteration";
  if (fair_iterations < 0) return "fair_iterations must not be negative";
  if (length < 0 || scale < 0) return "length and scale must not be negative";
  return {};
}

const char* to_string(FitStatus status) {
  switch (status) {
    case FitStatus::converged: return "converged";
    case FitStatus::max_iterations: return "max_iterations";
    case FitStatus::not_positive_definite: return "not_positive_definite";
    case FitStatus::left_surface: return "left_surface";
    case FitStatus::invalid_cutter: return "invalid_cutter";
  }
  return "unknown";
}

std::string FitResult::brief_report() const {
  std::ostringstream s;
  s << to_string(status) << " after " << iterations << " iterations, cost " << initial_cost
    << " -> " << final_cost << ", " << to_string(cutter.kind) << " L=" << length;
  return s.str();
}

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Unknowns: per control point k the six coordinates [A_k, B_k], then the profile c.
struct Layout {
  int K = 0;
  int nc = 0;
  int n() const { return 6 * K + nc; }
  int a(int k) const { return 6 * k; }
  int b(int k) const { return 6 * k + 3; }
  int c(int q) const { return 6 * K + q; }
};

struct Problem {
  const SurfaceIndex& index;
  const FitOptions& options;
  Layout layout;
  std::vector<double> knots;
  std::vector<BasisRow> rows;  // basis at t_i
  std::vector<double> s;       // s_j
  MatX P;                      // n by nc profile basis
  double L = 0.0;
  double W1 = 0, W2 = 0, W3 = 0, W4 = 0;
  MatX H_fair;  // constant: W2 DᵀD
  bool fair_active = true;

  int m() const { return options.samples_t; }
  int n() const { return options.samples_s; }
};

struct Evaluation {
  double cost = 0.0;
  MatX H;  // N by N (full, symmetric)
  VecX g;  // N
  int interior = 0;
};

void unpack(const Layout& lay, const VecX& x, Points* A, Points* B, VecX* c) {
  A->resize(lay.K, 3);
  B->resize(lay.K, 3);
  for (int k = 0; k < lay.K; ++k) {
    A->row(k) = x.segment<3>(lay.a(k)).transpose();
    B->row(k) = x.segment<3>(lay.b(k)).transpose();
  }
  *c = x.tail(lay.nc);
}

// Per-t_i contribution to JᵀJ and Jᵀr in local coordinates [A_f..A_f+3, B_f..B_f+3] (24)
// and the profile (nc).
struct RowBlock {
  Eigen::Matrix3d Maa, Mab, Mbb;
  MatX Ca, Cb;  // 3 by nc
  MatX Hcc;     // nc by nc
  Vec3 ga, gb;
  VecX gc;
  double cost = 0.0;
  int interior = 0;
};

Evaluation evaluate(Problem& pb, const VecX& x, std::vector<int>& hints, FitTiming& timing) {
  const Layout& lay = pb.layout;
  const int m = pb.m(), n = pb.n(), nc = lay.nc;
  Points A, B;
  VecX c;
  unpack(lay, x, &A, &B, &c);
  const VecX d = pb.P * c;

  auto t0 = Clock::now();
  std::vector<Vec3> a_i(m), b_i(m);
  Points q(static_cast<Eigen::Index>(m) * n, 3);
  for (int i = 0; i < m; ++i) {
    const BasisRow& r = pb.rows[i];
    Vec3 ai = Vec3::Zero(), bi = Vec3::Zero();
    for (int k = 0; k <= kSplineDegree; ++k) {
      ai += r.value[k] * A.row(r.first + k).transpose();
      bi += r.value[k] * B.row(r.first + k).transpose();
    }
    a_i[i] = ai, b_i[i] = bi;
    for (int j = 0; j < n; ++j) q.row(i * n + j) = ((1.0 - pb.s[j]) * ai + pb.s[j] * bi).transpose();
  }
  std::vector<ClosestPoint> cp = pb.index.closest_points(q, hints);
  for (std::size_t k = 0; k < cp.size(); ++k) hints[k] = cp[k].face;
  timing.query_s += seconds_since(t0);
  timing.queries += static_cast<long long>(cp.size());

  t0 = Clock::now();
  std::vector<RowBlock> blocks(static_cast<std::size_t>(m));
  parallel_for(0, static_cast<std::size_t>(m), [&](std::size_t begin, std::size_t end) {
    for (std::size_t ii = begin; ii < end; ++ii) {
      const int i = static_cast<int>(ii);
      RowBlock& rb = blocks[ii];
      rb.Maa.setZero(), rb.Mab.setZero(), rb.Mbb.setZero();
      rb.Ca = MatX::Zero(3, nc), rb.Cb = MatX::Zero(3, nc), rb.Hcc = MatX::Zero(nc, nc);
      rb.ga.setZero(), rb.gb.setZero();
      rb.gc = VecX::Zero(nc);
      for (int j = 0; j < n; ++j) {
        const ClosestPoint& f = cp[static_cast<std::size_t>(i * n + j)];
        if (f.boundary || f.face < 0) continue;  // beyond Φ: no proximity information
        ++rb.interior;
        const Vec3 p = q.row(i * n + j).transpose();
        const Vec3& nn = f.direction;
        const double rho = nn.dot(p - f.point) - d(j);
        const Vec3 qv = p - f.point - d(j) * nn;
        rb.cost += pb.W1 * rho * rho + pb.W3 * qv.squaredNorm();
        // At a true footpoint p − p⊥ = dist·n, so q = (dist − d)·n and its exact derivative is
        // n nᵀ up to a term that vanishes with the residual. The frozen-footpoint model (I)
        // would pin the samples tangentially, like point-to-point ICP, and crawl along the
        // near-degenerate valleys (radius ↔ offset, reparametrisation) of the problem.
        const Eigen::Matrix3d M = (pb.W1 + pb.W3) * nn * nn.transpose();
        const double sa = 1.0 - pb.s[j], sb = pb.s[j];
        rb.Maa += sa * sa * M, rb.Mab += sa * sb * M, rb.Mbb += sb * sb * M;
        const auto Pj = pb.P.row(j);
        const MatX Hpc = -(pb.W1 + pb.W3) * nn * Pj;
        rb.Ca += sa * Hpc, rb.Cb += sb * Hpc;
        rb.Hcc += (pb.W1 + pb.W3) * Pj.transpose() * Pj;
        const Vec3 gp = (pb.W1 * rho + pb.W3 * nn.dot(qv)) * nn;
        rb.ga += sa * gp, rb.gb += sb * gp;
        rb.gc -= (pb.W1 * rho + pb.W3 * nn.dot(qv)) * Pj.transpose();
      }
      // Rigidity (eq. 9) as a soft constraint at t_i.
      const Vec3 e = a_i[i] - b_i[i];
      const double r = e.squaredNorm() - pb.L * pb.L;
      const Eigen::Matrix3d E = 4.0 * pb.W4 * e * e.transpose();
      rb.Maa += E, rb.Mab -= E, rb.Mbb += E;
      rb.ga += 2.0 * pb.W4 * r * e, rb.gb -= 2.0 * pb.W4 * r * e;
      rb.cost += pb.W4 * r * r;
    }
  });

  Evaluation ev;
  const int N = lay.n();
  // Fairness acts on the update δ (W2 |D δ|², see FitOptions): it adds to JᵀJ only.
  ev.H = pb.fair_active ? pb.H_fair : MatX::Zero(N, N);
  ev.g = VecX::Zero(N);
  // Serial reduction in i order: the result does not depend on the thread count.
  for (int i = 0; i < m; ++i) {
    const RowBlock& rb = blocks[static_cast<std::size_t>(i)];
    const BasisRow& br = pb.rows[i];
    ev.cost += rb.cost;
    ev.interior += rb.interior;
    for (int k = 0; k <= kSplineDegree; ++k) {
      const int ka = lay.a(br.first + k), kb = lay.b(br.first + k);
      const double Nk = br.value[k];
      for (int l = 0; l <= kSplineDegree; ++l) {
        const int la = lay.a(br.first + l), lb = lay.b(br.first + l);
        const double NkNl = Nk * br.value[l];
        ev.H.block<3, 3>(ka, la) += NkNl * rb.Maa;
        ev.H.block<3, 3>(ka, lb) += NkNl * rb.Mab;
        ev.H.block<3, 3>(kb, la) += NkNl * rb.Mab.transpose();
        ev.H.block<3, 3>(kb, lb) += NkNl * rb.Mbb;
      }
      ev.H.block(ka, lay.c(0), 3, nc) += Nk * rb.Ca;
      ev.H.block(kb, lay.c(0), 3, nc) += Nk * rb.Cb;
      ev.H.block(lay.c(0), ka, nc, 3) += Nk * rb.Ca.transpose();
      ev.H.block(lay.c(0), kb, nc, 3) += Nk * rb.Cb.transpose();
      ev.g.segment<3>(ka) += Nk * rb.ga;
      ev.g.segment<3>(kb) += Nk * rb.gb;
    }
    ev.H.block(lay.c(0), lay.c(0), nc, nc) += rb.Hcc;
    ev.g.segment(lay.c(0), nc) += rb.gc;
  }
  timing.assembly_s += seconds_since(t0);
  return ev;
}

// Upper-triangular pattern of JᵀJ: control points couple within the cubic support, the
// profile couples with everything.
void build_pattern(const Layout& lay, std::vector<int>* col_ptr, std::vector<int>* row_idx) {
  const int N = lay.n();
  auto block = [&](int v) { return v < 6 * lay.K ? v / 6 : -1; };
  col_ptr->assign(1, 0);
  row_idx->clear();
  for (int col = 0; col < N; ++col) {
    for (int row = 0; row <= col; ++row) {
      const int bc = block(col), br = block(row);
      if (bc < 0 || br < 0 || std::abs(bc - br) <= kSplineDegree) row_idx->push_back(row);
    }
    col_ptr->push_back(static_cast<int>(row_idx->size()));
  }
}

}  // namespace

FitResult fit_motion(const SurfaceIndex& index, const Motion& init_motion,
                     const FitOptions& options, const Cutter* init_cutter) {
  const auto t_start = Clock::now();
  FitResult result;
  const int K = options.control_points > 0 ? options.control_points : init_motion.count();
  const Motion init =
      K == init_motion.count() ? init_motion : init_motion.restricted(0, 1, 0, 1, K);

  Problem pb{index, options, {}, {}, {}, {}, {}, 0, 0, 0, 0, 0, {}, options.fair_iterations > 0};
  pb.layout.K = K;
  pb.layout.nc = coefficient_count(options.kind);
  pb.knots = init.knots;
  const int m = options.samples_t, n = options.samples_s, nc = pb.layout.nc;
  pb.rows.resize(static_cast<std::size_t>(m));
  for (int i = 0; i < m; ++i) pb.rows[i] = cubic_basis(pb.knots, K, static_cast<double>(i) / (m - 1));
  pb.s.resize(static_cast<std::size_t>(n));
  for (int j = 0; j < n; ++j) pb.s[j] = static_cast<double>(j) / (n - 1);
  pb.P.resize(n, nc);
  {
    double v[kSplineProfileCoefficients], dv[kSplineProfileCoefficients];
    for (int j = 0; j < n; ++j) {
      profile_basis(options.kind, pb.s[j], v, dv);
      for (int k = 0; k < nc; ++k) pb.P(j, k) = v[k];
    }
  }
  pb.L = options.length > 0 ? options.length : init.mean_length();
  const double scale = options.scale > 0 ? options.scale : index.diagonal();
  const double sigma = 1.0 / scale;
  pb.W1 = sigma * sigma * options.weight_plane / (m * n);
  pb.W3 = sigma * sigma * options.weight_point / (m * n);
  pb.W2 = sigma * sigma * options.weight_fair / m;
  pb.W4 = std::pow(sigma, 4) * options.weight_rigid;

  // Fairness (eq. 11): second differences of a and b at consecutive t_i, linear in x.
  const int N = pb.layout.n();
  pb.H_fair = MatX::Zero(N, N);
  for (int i = 1; i + 1 < m; ++i) {
    std::vector<std::pair<int, double>> coef;  // control point → weight
    const double w[3] = {1.0, -2.0, 1.0};
    for (int o = 0; o < 3; ++o) {
      const BasisRow& br = pb.rows[i - 1 + o];
      for (int k = 0; k <= kSplineDegree; ++k) coef.emplace_back(br.first + k, w[o] * br.value[k]);
    }
    for (auto [k, ck] : coef)
      for (auto [l, cl] : coef)
        for (int e = 0; e < 3; ++e) {
          pb.H_fair(pb.layout.a(k) + e, pb.layout.a(l) + e) += pb.W2 * ck * cl;
          pb.H_fair(pb.layout.b(k) + e, pb.layout.b(l) + e) += pb.W2 * ck * cl;
        }
  }

  VecX x(N);
  for (int k = 0; k < K; ++k) {
    x.segment<3>(pb.layout.a(k)) = init.a.row(k).transpose();
    x.segment<3>(pb.layout.b(k)) = init.b.row(k).transpose();
  }
  std::vector<int> hints(static_cast<std::size_t>(m) * n, -1);

  // Initial profile: least squares to the footpoint distances of each axis sample.
  if (init_cutter && init_cutter->kind == options.kind && init_cutter->coeffs.size() == nc) {
    x.tail(nc) = init_cutter->coeffs;
  } else {
    Points q(static_cast<Eigen::Index>(m) * n, 3);
    for (int i = 0; i < m; ++i) {
      const double t = static_cast<double>(i) / (m - 1);
      for (int j = 0; j < n; ++j) q.row(i * n + j) = init.point(t, pb.s[j]).transpose();
    }
    const auto t0 = Clock::now();
    const std::vector<ClosestPoint> cp = index.closest_points(q);
    result.timing.query_s += seconds_since(t0);
    result.timing.queries += static_cast<long long>(cp.size());
    std::vector<double> ss, dd;
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < n; ++j) {
        const ClosestPoint& f = cp[static_cast<std::size_t>(i * n + j)];
        hints[static_cast<std::size_t>(i * n + j)] = f.face;
        if (f.boundary || f.face < 0) continue;
        ss.push_back(pb.s[j]);
        dd.push_back(f.distance);
      }
    if (ss.size() < static_cast<std::size_t>(std::max(nc, n))) {
      result.status = FitStatus::left_surface;
      result.motion = init;
      result.length = pb.L;
      result.timing.total_s = seconds_since(t_start);
      return result;
    }
    x.tail(nc) = Cutter::fit(options.kind, pb.L, ss, dd).coeffs;
  }

  std::vector<int> col_ptr, row_idx;
  build_pattern(pb.layout, &col_ptr, &row_idx);
  SparseCholesky chol;
  auto t0 = Clock::now();
  if (chol.analyze(N, col_ptr, row_idx) != SparseCholesky::Status::ok) {
    result.status = FitStatus::not_positive_definite;
    return result;
  }
  result.timing.factor_s += seconds_since(t0);

  Evaluation ev = evaluate(pb, x, hints, result.timing);
  result.initial_cost = ev.cost;
  double lambda = 1e-4;
  int iter = 0;
  bool converged = false;
  std::vector<double> values(row_idx.size());
  const bool trace = std::getenv("FLANK_TRACE_FIT") != nullptr;
  for (; iter < options.max_iterations && !converged; ++iter) {
    if (ev.interior < std::max(nc, n)) {
      result.status = FitStatus::left_surface;
      break;
    }
    if (iter == options.fair_iterations && pb.fair_active) {
      ev.H -= pb.H_fair;
      pb.fair_active = false;
    }
    const double diag_floor = 1e-12 * ev.H.diagonal().maxCoeff();
    bool accepted = false;
    while (!accepted && lambda < 1e12) {
      t0 = Clock::now();
      for (int col = 0; col < N; ++col)
        for (int k = col_ptr[col]; k < col_ptr[col + 1]; ++k) {
          const int row = row_idx[k];
          values[k] = ev.H(row, col);
          if (row == col) values[k] += lambda * (ev.H(col, col) + diag_floor) + diag_floor;
        }
      VecX delta;
      const auto fs = chol.factorize(values);
      const bool solved = fs == SparseCholesky::Status::ok &&
                          chol.solve(-ev.g, &delta) == SparseCholesky::Status::ok;
      result.timing.factor_s += seconds_since(t0);
      if (!solved) {
        lambda *= 10.0;
        continue;
      }
      const VecX x_new = x + delta;
      std::vector<int> trial_hints = hints;
      Evaluation trial = evaluate(pb, x_new, trial_hints, result.timing);
      if (trace)
        std::fprintf(stderr, "iter %d lambda %.3g cost %.6g -> %.6g (fair %.3g) interior %d |step| %.3g\n", iter, lambda,
                     ev.cost, trial.cost, delta.dot(pb.H_fair * delta), trial.interior, delta.head(6 * K).cwiseAbs().maxCoeff());
      if (trial.cost <= ev.cost && trial.interior >= std::max(nc, n)) {
        const double decrease = ev.cost - trial.cost;
        x = x_new;
        hints.swap(trial_hints);
        const double step = delta.head(6 * K).cwiseAbs().maxCoeff();
        converged = decrease <= 1e-10 * ev.cost || step <= 1e-9 * scale || trial.cost < 1e-30;
        ev = std::move(trial);
        lambda = std::max(lambda / 3.0, 1e-9);
        accepted = true;
        // Near the optimum the footpoints slide with the axis and successive GN steps line up
        // (linear convergence along the radius ↔ offset valley): extend the step while the
        // cost keeps falling, each extension one batch of closest points.
        for (int e = 0; e < options.max_extrapolations && !converged && !pb.fair_active; ++e) {
          const VecX x_far = x + delta * static_cast<double>(1 << e);
          std::vector<int> far_hints = hints;
          Evaluation far = evaluate(pb, x_far, far_hints, result.timing);
          if (!(far.cost < ev.cost) || far.interior < std::max(nc, n)) break;
          x = x_far;
          hints.swap(far_hints);
          ev = std::move(far);
        }
      } else {
        lambda *= 4.0;
      }
    }
    if (!accepted) {  // no step decreases the cost any more: a (local) minimum
      converged = true;
      break;
    }
  }

  Points A, B;
  VecX c;
  unpack(pb.layout, x, &A, &B, &c);
  result.motion.knots = pb.knots;
  result.motion.a = A;
  result.motion.b = B;
  result.cutter.kind = options.kind;
  result.cutter.length = pb.L;
  result.cutter.coeffs = c;
  result.length = pb.L;
  result.iterations = iter;
  result.final_cost = ev.cost;
  result.interior_fraction = static_cast<double>(ev.interior) / (static_cast<double>(m) * n);
  if (result.status != FitStatus::left_surface) {
    result.status = converged ? FitStatus::converged : FitStatus::max_iterations;
    if (!result.cutter.valid()) result.status = FitStatus::invalid_cutter;
  }
  result.timing.total_s = seconds_since(t_start);
  return result;
}

}  // namespace flank
