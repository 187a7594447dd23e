#include "solver/fit_motion.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <span>
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
  if (!(radius_min >= 0) || !(radius_max >= 0) || !std::isfinite(radius_min) || !std::isfinite(radius_max))
    return "cutter radius bounds must be finite and not negative";
  if (radius_max > 0 && radius_min > radius_max) {
    std::ostringstream s;
    s << "the cutter radius range is empty: radius_min " << radius_min << " > radius_max " << radius_max;
    return s.str();
  }
  if (!(max_slope_fraction >= 0 && max_slope_fraction < 1))
    return "max_slope_fraction must be in [0, 1): |d'| must stay below the cutter length";
  if (active_set_iterations < 1) return "active_set_iterations must be at least 1";
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
  if (radius_at_min) s << ", radius at its lower bound";
  if (radius_at_max) s << ", radius at its upper bound";
  if (slope_at_limit) s << ", slope at its limit";
  return s.str();
}

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Levenberg–Marquardt damping: λ starts small (the fit starts near a sweep), shrinks 3 times
// after an accepted step and grows 4 times after a rejected one. (Nielsen's gain-ratio update
// was tried: a fifth fewer passes, but in 10 iterations the fits reached less, and the cover of
// three of the eight real-face cases fell by 1.5–3 points.)
constexpr double kInitialDamping = 1e-4;
constexpr double kDampingShrink = 3.0;
constexpr double kDampingGrowth = 4.0;
constexpr double kMinDamping = 1e-9;
// A step extension is tried when the parabola's minimum lies at least this many steps out.
constexpr double kExtendBeyond = 1.5;

// The profile parts have at most kSplineProfileCoefficients columns: fixed-capacity storage,
// so that a row block (and each sample's terms) costs no heap allocation. Allocations in the
// parallel row loop, 3000 per evaluation, held the two threads up on the allocator.
using ProfileRow3 = Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::ColMajor, 3, kSplineProfileCoefficients>;
using ProfileSquare = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor,
                                    kSplineProfileCoefficients, kSplineProfileCoefficients>;
using ProfileVec = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kSplineProfileCoefficients, 1>;

// Unknowns: per control point k the six coordinates [A_k, B_k], then the profile c.
struct Layout {
  int K = 0;
  int nc = 0;
  int n() const { return 6 * K + nc; }
  int a(int k) const { return 6 * k; }
  int b(int k) const { return 6 * k + 3; }
  int c(int q) const { return 6 * K + q; }
};

// JᵀJ's upper triangle, stored by columns (what CHOLMOD factors, see build_pattern): the rows
// of each column run without gaps from first[col] down to the diagonal, its last entry.
struct UpperPattern {
  std::vector<int> col_ptr, row_idx, first;
  std::size_t size() const { return row_idx.size(); }
  // The entry (row, col), for first[col] <= row <= col.
  std::size_t at(int row, int col) const {
    return static_cast<std::size_t>(col_ptr[col] + row - first[col]);
  }
  std::size_t diagonal(int col) const { return static_cast<std::size_t>(col_ptr[col + 1] - 1); }
};

// Per-t_i contribution to JᵀJ and Jᵀr in local coordinates [A_f..A_f+3, B_f..B_f+3] (24)
// and the profile (nc).
struct RowBlock {
  Eigen::Matrix3d Maa, Mab, Mbb;
  ProfileRow3 Ca, Cb;  // 3 by nc
  ProfileSquare Hcc;   // nc by nc
  Vec3 ga, gb;
  ProfileVec gc;
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
  std::vector<double> H_fair;  // constant: W2 DᵀD, in the pattern
  bool fair_active = true;
  UpperPattern pattern;
  // Σ_j (W1 + W3) P_jᵀ P_j over all s_j, summed as a row's own loop sums it: the profile block
  // of every row whose samples all lie inside Φ (most rows), bit for bit.
  ProfileSquare Hcc_all;
  std::vector<RowBlock> blocks;  // assemble()'s, kept from one assembly to the next

  int m() const { return options.samples_t; }
  int n() const { return options.samples_s; }
};

// The cost at an iterate, and what JᵀJ and Jᵀr are made from there: they are assembled
// (assemble()) only for an iterate the fit moves to. A trial step the fit rejects, or an
// extension it does not take, needs its cost alone: about half of all evaluations.
struct Evaluation {
  double cost = 0.0;
  int interior = 0;
  // The samples' points and footpoints (row-major over t_i, s_j), the axis ends at the t_i and
  // the sphere radii at the s_j.
  Points q;
  std::vector<ClosestPoint> cp;
  std::vector<Vec3> a_i, b_i;
  VecX d;
  bool assembled = false;
  std::vector<double> H;  // JᵀJ's upper triangle in the pattern, once assembled
  VecX g;                 // N, once assembled
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


// Sample (p, its footpoint f, sphere radius d)'s residuals: ρ = ⟨p − p⊥, n⟩ − d (F_plane) and
// q = p − (p⊥ + d n) (F_point).
struct Residual {
  double rho;
  Vec3 q;
};
Residual residual(const Vec3& p, const ClosestPoint& f, double d) {
  return {f.direction.dot(p - f.point) - d, p - f.point - d * f.direction};
}

// `reuse`: an evaluation the fit is done with, whose buffers (the footpoints alone are 216 KB
// at the default sampling) are written again in place rather than allocated afresh.
Evaluation evaluate(Problem& pb, const VecX& x, std::vector<int>& hints, FitTiming& timing,
                    Evaluation reuse = {}) {
  const Layout& lay = pb.layout;
  const int m = pb.m(), n = pb.n();
  assert(lay.nc <= kSplineProfileCoefficients);
  Points A, B;
  VecX c;
  unpack(lay, x, &A, &B, &c);
  Evaluation ev = std::move(reuse);
  ev.cost = 0.0, ev.interior = 0, ev.assembled = false;
  ev.d = pb.P * c;
  const VecX& d = ev.d;

  // Row by row in one parallel pass: the axis at t_i, its samples, their closest points (from
  // the hints, the footpoint faces of the iterate before) and the row's cost. The passes were
  // three (the samples serially, the batch of queries, the cost), and between them the
  // second thread idled. The time counts as queries: the cost adds about 1% to it.
  const auto t0 = Clock::now();
  ev.a_i.resize(static_cast<std::size_t>(m)), ev.b_i.resize(static_cast<std::size_t>(m));
  ev.q.resize(static_cast<Eigen::Index>(m) * n, 3);
  ev.cp.resize(static_cast<std::size_t>(m) * n);
  std::vector<double> row_cost(static_cast<std::size_t>(m));
  std::vector<int> row_interior(static_cast<std::size_t>(m));
  parallel_for(0, static_cast<std::size_t>(m), [&](std::size_t begin, std::size_t end) {
    for (std::size_t ii = begin; ii < end; ++ii) {
      const int i = static_cast<int>(ii);
      const BasisRow& br = pb.rows[ii];
      Vec3 ai = Vec3::Zero(), bi = Vec3::Zero();
      for (int k = 0; k <= kSplineDegree; ++k) {
        ai += br.value[k] * A.row(br.first + k).transpose();
        bi += br.value[k] * B.row(br.first + k).transpose();
      }
      ev.a_i[ii] = ai, ev.b_i[ii] = bi;
      for (int j = 0; j < n; ++j) ev.q.row(i * n + j) = ((1.0 - pb.s[j]) * ai + pb.s[j] * bi).transpose();
      const std::size_t first = ii * static_cast<std::size_t>(n);
      const std::span<ClosestPoint> row_cp(ev.cp.data() + first, static_cast<std::size_t>(n));
      pb.index.closest_points_serial(ev.q.middleRows(i * n, n),
                                     std::span<const int>(hints.data() + first, static_cast<std::size_t>(n)), row_cp);
      double cost = 0.0;
      int interior = 0;
      for (int j = 0; j < n; ++j) {
        const ClosestPoint& f = row_cp[static_cast<std::size_t>(j)];
        hints[first + static_cast<std::size_t>(j)] = f.face;
        if (f.boundary || f.face < 0) continue;  // beyond Φ: no proximity information
        ++interior;
        const Residual r = residual(ev.q.row(i * n + j).transpose(), f, d(j));
        cost += pb.W1 * r.rho * r.rho + pb.W3 * r.q.squaredNorm();
      }
      // Rigidity (eq. 9) as a soft constraint at t_i.
      const double r = (ai - bi).squaredNorm() - pb.L * pb.L;
      cost += pb.W4 * r * r;
      row_cost[ii] = cost, row_interior[ii] = interior;
    }
  }, 1);  // rows differ in cost (their queries, samples beyond Φ): small chunks balance them
  // The cost summed in row order.
  for (int i = 0; i < m; ++i) ev.cost += row_cost[static_cast<std::size_t>(i)], ev.interior += row_interior[static_cast<std::size_t>(i)];
  timing.query_s += seconds_since(t0);
  timing.queries += static_cast<long long>(ev.cp.size());
  return ev;
}

// JᵀJ and Jᵀr of an evaluation, once.
void assemble(Problem& pb, Evaluation& ev, FitTiming& timing) {
  if (ev.assembled) return;
  const Layout& lay = pb.layout;
  const int m = pb.m(), n = pb.n(), nc = lay.nc;
  const VecX& d = ev.d;
  const auto t0 = Clock::now();
  std::vector<RowBlock>& blocks = pb.blocks;
  blocks.resize(static_cast<std::size_t>(m));  // every block is written in full below
  parallel_for(0, static_cast<std::size_t>(m), [&](std::size_t begin, std::size_t end) {
    for (std::size_t ii = begin; ii < end; ++ii) {
      const int i = static_cast<int>(ii);
      RowBlock& rb = blocks[ii];
      rb.Maa.setZero(), rb.Mab.setZero(), rb.Mbb.setZero();
      rb.Ca = ProfileRow3::Zero(3, nc), rb.Cb = ProfileRow3::Zero(3, nc), rb.Hcc = ProfileSquare::Zero(nc, nc);
      rb.ga.setZero(), rb.gb.setZero();
      rb.gc = ProfileVec::Zero(nc);
      bool all_inside = true;
      for (int j = 0; j < n && all_inside; ++j) {
        const ClosestPoint& f = ev.cp[static_cast<std::size_t>(i * n + j)];
        all_inside = !f.boundary && f.face >= 0;
      }
      if (all_inside) rb.Hcc = pb.Hcc_all;
      for (int j = 0; j < n; ++j) {
        const ClosestPoint& f = ev.cp[static_cast<std::size_t>(i * n + j)];
        if (f.boundary || f.face < 0) continue;  // beyond Φ: no proximity information
        const Vec3& nn = f.direction;
        const auto [rho, qv] = residual(ev.q.row(i * n + j).transpose(), f, d(j));
        // At a true footpoint p − p⊥ = dist·n, so q = (dist − d)·n and its exact derivative is
        // n nᵀ up to a term that vanishes with the residual. The frozen-footpoint model (I)
        // would pin the samples tangentially, like point-to-point ICP, and crawl along the
        // near-degenerate valleys (radius ↔ offset, reparametrisation) of the problem.
        const Eigen::Matrix3d M = (pb.W1 + pb.W3) * nn * nn.transpose();
        const double sa = 1.0 - pb.s[j], sb = pb.s[j];
        rb.Maa += sa * sa * M, rb.Mab += sa * sb * M, rb.Mbb += sb * sb * M;
        const auto Pj = pb.P.row(j);
        // noalias: the outer products are written in place, with the same roundings.
        ProfileRow3 Hpc(3, nc);
        Hpc.noalias() = -(pb.W1 + pb.W3) * nn * Pj;
        rb.Ca += sa * Hpc, rb.Cb += sb * Hpc;
        if (!all_inside) rb.Hcc.noalias() += (pb.W1 + pb.W3) * Pj.transpose() * Pj;
        const Vec3 gp = (pb.W1 * rho + pb.W3 * nn.dot(qv)) * nn;
        rb.ga += sa * gp, rb.gb += sb * gp;
        rb.gc -= (pb.W1 * rho + pb.W3 * nn.dot(qv)) * Pj.transpose();
      }
      const Vec3 e = ev.a_i[ii] - ev.b_i[ii];
      const double r = e.squaredNorm() - pb.L * pb.L;
      const Eigen::Matrix3d E = 4.0 * pb.W4 * e * e.transpose();
      rb.Maa += E, rb.Mab -= E, rb.Mbb += E;
      rb.ga += 2.0 * pb.W4 * r * e, rb.gb -= 2.0 * pb.W4 * r * e;
    }
  }, 4);  // rows differ in cost (samples beyond Φ are skipped): small chunks balance them

  const int N = lay.n();
  const UpperPattern& up = pb.pattern;
  // Fairness acts on the update δ (W2 |D δ|², see FitOptions): it adds to JᵀJ only.
  if (pb.fair_active) ev.H = pb.H_fair;
  else ev.H.assign(up.size(), 0.0);
  ev.g.setZero(N);
  // H(r0 + r, c0 + c) += w B(r, c) for the block's entries on or above the diagonal.
  const auto add_block = [&](int r0, int c0, double w, const Eigen::Matrix3d& B) {
    for (int c = 0; c < 3; ++c) {
      const std::size_t base = up.at(r0, c0 + c);
      const int rows = r0 == c0 ? c + 1 : 3;
      for (int r = 0; r < rows; ++r) ev.H[base + static_cast<std::size_t>(r)] += w * B(r, c);
    }
  };
  // The blocks summed into JᵀJ and Jᵀr concurrently, each task owning columns (contiguous in
  // the pattern): control point l's six (its a and b, with g's entries there), or one profile
  // column. Every element still receives its terms in i order, as one loop over i would add
  // them: the sums are the same bits whatever the thread count.
  const int K = lay.K;
  parallel_for(0, static_cast<std::size_t>(K + nc), [&](std::size_t begin, std::size_t end) {
    for (std::size_t task = begin; task < end; ++task) {
      if (task < static_cast<std::size_t>(K)) {
        const int l = static_cast<int>(task);
        const int la = lay.a(l), lb = lay.b(l);
        for (int i = 0; i < m; ++i) {
          const BasisRow& br = pb.rows[i];
          const int ll = l - br.first;
          if (ll < 0 || ll > kSplineDegree) continue;
          const RowBlock& rb = blocks[static_cast<std::size_t>(i)];
          for (int kk = 0; kk <= ll; ++kk) {  // the control points k <= l: rows above
            const int ka = lay.a(br.first + kk), kb = lay.b(br.first + kk);
            const double NkNl = br.value[kk] * br.value[ll];
            add_block(ka, la, NkNl, rb.Maa);
            add_block(ka, lb, NkNl, rb.Mab);
            if (kk < ll) add_block(kb, la, NkNl, rb.Mab.transpose());
            add_block(kb, lb, NkNl, rb.Mbb);
          }
          const double Nl = br.value[ll];
          ev.g.segment<3>(la) += Nl * rb.ga;
          ev.g.segment<3>(lb) += Nl * rb.gb;
        }
      } else {
        const int q = static_cast<int>(task) - K, col = lay.c(q);
        for (int i = 0; i < m; ++i) {
          const BasisRow& br = pb.rows[i];
          const RowBlock& rb = blocks[static_cast<std::size_t>(i)];
          for (int k = 0; k <= kSplineDegree; ++k) {
            const double Nk = br.value[k];
            const std::size_t at_a = up.at(lay.a(br.first + k), col), at_b = up.at(lay.b(br.first + k), col);
            for (int r = 0; r < 3; ++r) {
              ev.H[at_a + static_cast<std::size_t>(r)] += Nk * rb.Ca(r, q);
              ev.H[at_b + static_cast<std::size_t>(r)] += Nk * rb.Cb(r, q);
            }
          }
          const std::size_t at_c = up.at(lay.c(0), col);
          for (int r = 0; r <= q; ++r) ev.H[at_c + static_cast<std::size_t>(r)] += rb.Hcc(r, q);
          ev.g(col) += rb.gc(q);
        }
      }
    }
  }, 1);
  timing.assembly_s += seconds_since(t0);
  ev.assembled = true;
}

// The cutter constraints of FitOptions as linear inequalities G c ≤ h on the profile
// coefficients. Both profile bases are non-negative and sum to one (Bernstein; clamped
// B-spline), so d(s) is a convex combination of the c_k and lo ≤ c_k ≤ hi bounds d(s) for
// every s. d′ is again such a spline, of one degree less, whose coefficients are scaled
// differences: p (c_{k+1} − c_k) for Bernstein degree p, 3 (c_{k+1} − c_k)/(t_{k+4} − t_{k+1})
// for the clamped cubic B-spline; |c_{k+1} − c_k| ≤ max_step[k] bounds |d′| for every s.
struct ProfileBounds {
  enum class Kind { radius_min, radius_max, slope };
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  std::vector<double> max_step;  // nc − 1 entries, or none
  MatX G;                        // the same as rows: #constraints by nc
  VecX h;
  std::vector<Kind> kind;
  // Violations below it are rounding (the projection removes them) and slacks below it count
  // as active in the report: the KKT solves leave errors of ~1e-16 of the radii times the
  // conditioning of the normal matrix along the profile.
  double tolerance = 0.0;

  bool empty() const { return G.rows() == 0; }
  double violation(const VecX& c) const {
    return empty() ? 0.0 : (G * c - h).maxCoeff();
  }
  // Clamp into [lo, hi], then walk along the coefficients pulling each to within max_step of
  // its predecessor: stays inside [lo, hi] (each move is toward a value inside) and leaves a
  // feasible c unchanged, bit for bit.
  void project(VecX* c) const {
    for (Eigen::Index k = 0; k < c->size(); ++k) (*c)(k) = std::min(std::max((*c)(k), lo), hi);
    for (std::size_t k = 0; k < max_step.size(); ++k) {
      const double prev = (*c)(static_cast<Eigen::Index>(k));
      double& next = (*c)(static_cast<Eigen::Index>(k + 1));
      next = std::min(std::max(next, prev - max_step[k]), prev + max_step[k]);
    }
  }
};

ProfileBounds profile_bounds(CutterKind kind, double L, const FitOptions& o) {
  ProfileBounds pb;
  const int nc = coefficient_count(kind);
  if (o.radius_min > 0) pb.lo = o.radius_min;
  if (o.radius_max > 0) pb.hi = o.radius_max;
  if (o.max_slope_fraction > 0 && nc > 1) {
    const double limit = o.max_slope_fraction * L;  // on |d′|
    pb.max_step.resize(static_cast<std::size_t>(nc - 1));
    if (kind == CutterKind::spline) {
      const std::vector<double> t = clamped_uniform_knots(nc);
      for (int k = 0; k + 1 < nc; ++k)
        pb.max_step[k] = limit * (t[k + kSplineDegree + 1] - t[k + 1]) / kSplineDegree;
    } else {
      const int degree = nc - 1;  // Bernstein
      for (int k = 0; k + 1 < nc; ++k) pb.max_step[k] = limit / degree;
    }
  }
  std::vector<std::pair<VecX, double>> rows;
  for (int k = 0; k < nc; ++k) {
    if (o.radius_min > 0) {
      rows.emplace_back(-VecX::Unit(nc, k), -pb.lo);
      pb.kind.push_back(ProfileBounds::Kind::radius_min);
    }
    if (o.radius_max > 0) {
      rows.emplace_back(VecX::Unit(nc, k), pb.hi);
      pb.kind.push_back(ProfileBounds::Kind::radius_max);
    }
  }
  for (std::size_t k = 0; k < pb.max_step.size(); ++k)
    for (double sign : {1.0, -1.0}) {
      VecX g = VecX::Zero(nc);
      g(static_cast<Eigen::Index>(k) + 1) = sign, g(static_cast<Eigen::Index>(k)) = -sign;
      rows.emplace_back(g, pb.max_step[k]);
      pb.kind.push_back(ProfileBounds::Kind::slope);
    }
  pb.G.resize(static_cast<Eigen::Index>(rows.size()), nc);
  pb.h.resize(static_cast<Eigen::Index>(rows.size()));
  for (std::size_t r = 0; r < rows.size(); ++r) {
    pb.G.row(static_cast<Eigen::Index>(r)) = rows[r].first.transpose();
    pb.h(static_cast<Eigen::Index>(r)) = rows[r].second;
  }
  pb.tolerance = 1e-10 * std::max({L, o.radius_max, o.radius_min});
  return pb;
}

// x's profile part projected onto the cutter constraints (a no-op when it satisfies them).
void project_profile(const ProfileBounds& bounds, int nc, VecX* x) {
  if (bounds.empty()) return;
  VecX c = x->tail(nc);
  bounds.project(&c);
  x->tail(nc) = c;
}

// Upper-triangular pattern of JᵀJ: control points couple within the cubic support, the
// profile couples with everything.
UpperPattern build_pattern(const Layout& lay) {
  const int N = lay.n();
  auto block = [&](int v) { return v < 6 * lay.K ? v / 6 : -1; };
  UpperPattern up;
  up.col_ptr.assign(1, 0);
  for (int col = 0; col < N; ++col) {
    for (int row = 0; row <= col; ++row) {
      const int bc = block(col), br = block(row);
      if (bc < 0 || br < 0 || std::abs(bc - br) <= kSplineDegree) up.row_idx.push_back(row);
    }
    up.first.push_back(up.row_idx[static_cast<std::size_t>(up.col_ptr.back())]);
    up.col_ptr.push_back(static_cast<int>(up.row_idx.size()));
    assert(up.row_idx.back() == col && col - up.first.back() + 1 == up.col_ptr.back() - up.col_ptr[col]);
  }
  return up;
}

// δᵀ H δ for H's upper triangle in the pattern.
double quadratic_form(const UpperPattern& up, const std::vector<double>& H, const VecX& delta) {
  double sum = 0.0;
  for (int col = 0; col + 1 < static_cast<int>(up.col_ptr.size()); ++col)
    for (int k = up.col_ptr[col]; k < up.col_ptr[col + 1]; ++k) {
      const int row = up.row_idx[static_cast<std::size_t>(k)];
      sum += (row == col ? 1.0 : 2.0) * H[static_cast<std::size_t>(k)] * delta(row) * delta(col);
    }
  return sum;
}

}  // namespace

ActiveSetStep active_set_step(const std::function<bool(const VecX& rhs, VecX* x)>& solve,
                              const VecX& free_step, const MatX& A, const VecX& b,
                              double tolerance, int max_iterations) {
  ActiveSetStep out;
  const Eigen::Index n = free_step.size();
  const int m = static_cast<int>(A.rows());
  assert(A.cols() == n && b.size() == m);
  VecX delta = VecX::Zero(n);
  std::vector<VecX> u(static_cast<std::size_t>(m));  // H⁻¹ aᵢ, once i has been a candidate
  std::vector<char> in_set(static_cast<std::size_t>(m), 0);
  // Rows found dependent on the working set; forgotten when a row leaves it.
  std::vector<char> dependent(static_cast<std::size_t>(m), 0);
  std::vector<int> W;  // working set, in the order the constraints entered
  VecX lambda;
  const VecX a_free = A * free_step;
  for (int it = 0; it < max_iterations; ++it) {
    out.iterations = it + 1;
    // Minimiser of q on the equalities of W: δ* = δ_free − Σ λ_w H⁻¹a_w with
    // (A_W H⁻¹ A_Wᵀ) λ = A_W δ_free − b_W; KKT gives H δ* + g + A_Wᵀ λ = 0.
    const int w = static_cast<int>(W.size());
    MatX M(w, w);
    VecX rhs(w);
    for (int r = 0; r < w; ++r) {
      for (int c = 0; c < w; ++c) M(r, c) = A.row(W[r]).dot(u[W[c]]);
      rhs(r) = a_free(W[r]) - b(W[r]);
    }
    // A_W H⁻¹ A_Wᵀ is positive definite for a positive definite H and independent rows; when
    // rounding makes it otherwise, H is too ill-conditioned along the constrained directions
    // for an exact step (e.g. a profile coefficient almost free of data): fail, so that the
    // caller damps more.
    const Eigen::LLT<MatX> llt(M);
    if (llt.info() != Eigen::Success) return out;
    lambda = llt.solve(rhs);
    if (!lambda.allFinite()) return out;
    VecX target = free_step;
    for (int r = 0; r < w; ++r) target -= lambda(r) * u[W[r]];

    // The first constraint outside W that the segment δ → δ* crosses (ties: the lowest row).
    // One that δ* violates by rounding only does not block: after a multiplier at rounding
    // level is dropped, it would come straight back and cycle.
    const VecX p = target - delta;
    int blocking = -1;
    for (;;) {
      double alpha = 1.0;
      blocking = -1;
      for (int i = 0; i < m; ++i) {
        if (in_set[i] || dependent[i] || !(A.row(i).dot(target) > b(i) + tolerance)) continue;
        const double ap = A.row(i).dot(p);
        if (!(ap > 0.0)) continue;
        const double slack = std::max(0.0, b(i) - A.row(i).dot(delta));
        if (slack < alpha * ap) alpha = slack / ap, blocking = i;
      }
      if (blocking < 0) break;
      if (u[blocking].size() == 0 && !solve(A.row(blocking).transpose(), &u[blocking])) return out;
      // A row in the span of W's rows cannot block in exact arithmetic (aᵢᵀp = 0 for every
      // step that keeps W), and would make A_W H⁻¹ A_Wᵀ singular: its H⁻¹-norm left after
      // projecting out W's rows, aᵢᵀH⁻¹aᵢ − vᵀ M⁻¹ v with v = A_W H⁻¹ aᵢ, is at rounding level.
      const double own = A.row(blocking).dot(u[blocking]);
      if (!(own > 0.0)) return out;  // H is not numerically positive definite along aᵢ
      double left = own;
      if (w > 0) {
        VecX v(w);
        for (int r = 0; r < w; ++r) v(r) = A.row(W[r]).dot(u[blocking]);
        left -= v.dot(llt.solve(v));
      }
      if (left > 1e-10 * own) {
        delta += alpha * p;
        break;
      }
      dependent[blocking] = 1;
    }
    if (blocking >= 0) {
      W.push_back(blocking);
      in_set[blocking] = 1;
      continue;
    }
    delta = target;
    // Optimal when no multiplier is negative beyond rounding; else drop the most negative.
    const double scale = w > 0 ? lambda.cwiseAbs().maxCoeff() : 0.0;
    int drop = -1;
    for (int r = 0; r < w; ++r)
      if (lambda(r) < -1e-12 * scale && (drop < 0 || lambda(r) < lambda(drop))) drop = r;
    if (drop < 0) {
      out.optimal = true;
      break;
    }
    in_set[W[drop]] = 0;
    W.erase(W.begin() + drop);
    std::fill(dependent.begin(), dependent.end(), 0);
  }
  out.ok = true;
  out.step = std::move(delta);
  std::vector<int> order(W.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int x, int y) { return W[x] < W[y]; });
  for (int r : order) out.active.push_back(W[r]);
  if (out.optimal) {
    out.multipliers.resize(static_cast<Eigen::Index>(W.size()));
    for (std::size_t k = 0; k < order.size(); ++k)
      out.multipliers(static_cast<Eigen::Index>(k)) = lambda(order[k]);
  }
  return out;
}

FitResult fit_motion(const SurfaceIndex& index, const Motion& init_motion,
                     const FitOptions& options, const Cutter* init_cutter) {
  const auto t_start = Clock::now();
  FitResult result;
  const int K = options.control_points > 0 ? options.control_points : init_motion.count();
  const Motion init =
      K == init_motion.count() ? init_motion : init_motion.restricted(0, 1, 0, 1, K);

  Problem pb{index, options, {}, {}, {}, {}, {}, 0, 0, 0, 0, 0, {}, options.fair_iterations > 0, {}, {}, {}};
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
  pb.pattern = build_pattern(pb.layout);
  pb.Hcc_all = ProfileSquare::Zero(nc, nc);
  for (int j = 0; j < n; ++j) {
    const auto Pj = pb.P.row(j);
    pb.Hcc_all.noalias() += (pb.W1 + pb.W3) * Pj.transpose() * Pj;  // as assemble() sums it
  }
  MatX H_fair = MatX::Zero(N, N);
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
          H_fair(pb.layout.a(k) + e, pb.layout.a(l) + e) += pb.W2 * ck * cl;
          H_fair(pb.layout.b(k) + e, pb.layout.b(l) + e) += pb.W2 * ck * cl;
        }
  }
  pb.H_fair.resize(pb.pattern.size());
  for (int col = 0; col < N; ++col)
    for (int k = pb.pattern.col_ptr[col]; k < pb.pattern.col_ptr[col + 1]; ++k)
      pb.H_fair[static_cast<std::size_t>(k)] = H_fair(pb.pattern.row_idx[static_cast<std::size_t>(k)], col);

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
  // Every iterate stays a real tool: start from a feasible profile.
  const ProfileBounds bounds = profile_bounds(options.kind, pb.L, options);
  project_profile(bounds, nc, &x);

  const UpperPattern& up = pb.pattern;
  // Two factorisations: the one this step is solved with, and the next damping's, made ahead
  // on a second thread when one is free (see the loop below).
  SparseCholesky factors[2];
  int current = 0;
  const bool look_ahead = max_threads() > 1;
  auto t0 = Clock::now();
  for (int f = 0; f < (look_ahead ? 2 : 1); ++f)
    if (factors[f].analyze(N, up.col_ptr, up.row_idx) != SparseCholesky::Status::ok) {
      result.status = FitStatus::not_positive_definite;
      return result;
    }
  result.timing.factor_s += seconds_since(t0);

  Evaluation ev = evaluate(pb, x, hints, result.timing);
  Evaluation spare;                // the buffers of an evaluation the fit is done with
  std::vector<int> trial_hints;
  assemble(pb, ev, result.timing);
  result.initial_cost = ev.cost;
  double lambda = kInitialDamping;
  int iter = 0;
  bool converged = false;
  std::vector<double> values(up.size()), values_ahead;
  const auto solve = [&](const VecX& rhs, VecX* out) {
    return factors[current].solve(rhs, out) == SparseCholesky::Status::ok;
  };
  // The factorisation of JᵀJ + damping made ahead, for this iterate's JᵀJ.
  struct Ahead {
    bool ready = false;
    double lambda = 0.0;
    SparseCholesky::Status status = SparseCholesky::Status::failed;
  } ahead;
  // A = [0 | G]: the constraints act on c only.
  MatX A_bounds = MatX::Zero(bounds.G.rows(), N);
  A_bounds.rightCols(nc) = bounds.G;
  for (; iter < options.max_iterations && !converged; ++iter) {
    if (ev.interior < std::max(nc, n)) {
      result.status = FitStatus::left_surface;
      break;
    }
    if (iter == options.fair_iterations && pb.fair_active) {
      for (std::size_t k = 0; k < up.size(); ++k) ev.H[k] -= pb.H_fair[k];
      pb.fair_active = false;
    }
    double diag_max = -std::numeric_limits<double>::infinity();
    for (int col = 0; col < N; ++col) diag_max = std::max(diag_max, ev.H[up.diagonal(col)]);
    const double diag_floor = 1e-12 * diag_max;
    // JᵀJ + damping, in the pattern.
    const auto damped = [&](double damping, std::vector<double>* out) {
      *out = ev.H;
      for (int col = 0; col < N; ++col) {
        const std::size_t k = up.diagonal(col);
        (*out)[k] += damping * (ev.H[k] + diag_floor) + diag_floor;
      }
    };
    ahead.ready = false;  // a new iterate, or the fairness gone: another JᵀJ
    bool accepted = false;
    while (!accepted && lambda < 1e12) {
      t0 = Clock::now();
      VecX delta;
      SparseCholesky::Status fs = SparseCholesky::Status::failed;
      ++result.timing.factorisations;
      if (ahead.ready && ahead.lambda == lambda) {
        current = 1 - current;
        fs = ahead.status;
        ahead.ready = false;
        ++result.timing.made_ahead;
      } else if (look_ahead) {
        // A third to a half of a fit's factorisations are retries of a rejected step, with
        // kDampingGrowth times the damping on the same JᵀJ: a second thread that is free
        // factors that one meanwhile, into the other factorisation. It is the very
        // factorisation the retry would make, so the fit takes the same steps whether it was
        // made ahead or not. A thread that is busy (fits run side by side in decompose) is
        // not waited for: the offer is withdrawn when this factorisation is done.
        const double next = lambda * kDampingGrowth;
        SparseCholesky::Status next_status = SparseCholesky::Status::failed;
        SparseCholesky& other = factors[1 - current];
        const bool made = run_if_idle(
            [&] {
              damped(next, &values_ahead);
              next_status = other.factorize(values_ahead);
            },
            [&] {
              damped(lambda, &values);
              fs = factors[current].factorize(values);
            });
        ahead = {made, next, next_status};
      } else {
        damped(lambda, &values);
        fs = factors[current].factorize(values);
      }
      bool solved = fs == SparseCholesky::Status::ok && solve(-ev.g, &delta);
      // The damped Gauss–Newton model under the cutter constraints, solved exactly: only when
      // the free step leaves them, so an unconstrained fit takes the very same steps.
      int active = 0;
      bool cut_short = false;
      const VecX c_now = x.tail(nc);
      const char* failed = solved ? nullptr : "factorisation failed";
      if (solved && bounds.violation(c_now + delta.tail(nc)) > bounds.tolerance) {
        const VecX slack = (bounds.h - bounds.G * c_now).cwiseMax(0.0);
        ActiveSetStep qp = active_set_step(solve, delta, A_bounds, slack, bounds.tolerance,
                                           options.active_set_iterations);
        solved = qp.ok;
        if (!solved) failed = "constrained step failed";
        delta = std::move(qp.step);
        active = static_cast<int>(qp.active.size());
        cut_short = !qp.optimal;
      }
      result.timing.factor_s += seconds_since(t0);
      if (!solved) {
        if (options.trace) {
          char line[128];
          std::snprintf(line, sizeof line, "iter %d lambda %.3g: %s", iter, lambda, failed);
          options.trace(line);
        }
        lambda *= 10.0;
        continue;
      }
      VecX x_new = x + delta;
      project_profile(bounds, nc, &x_new);  // violations below the tolerance, or rounding
      trial_hints = hints;
      Evaluation trial = evaluate(pb, x_new, trial_hints, result.timing, std::move(spare));
      if (options.trace) {
        char line[256];
        std::snprintf(line, sizeof line,
                      "iter %d lambda %.3g cost %.6g -> %.6g (fair %.3g) interior %d |step| %.3g active %d%s",
                      iter, lambda, ev.cost, trial.cost, quadratic_form(up, pb.H_fair, delta), trial.interior,
                      delta.head(6 * K).cwiseAbs().maxCoeff(), active, cut_short ? " (cut short)" : "");
        options.trace(line);
      }
      if (trial.cost <= ev.cost && trial.interior >= std::max(nc, n)) {
        const double decrease = ev.cost - trial.cost;
        // The cost along δ from c0 and its slope (the Gauss–Newton model's, 2 gᵀδ) to c(1).
        const double slope = 2.0 * ev.g.dot(delta);
        const VecX x_before = x;
        const double cost_before = ev.cost;
        x = x_new;
        hints.swap(trial_hints);
        const double step = delta.head(6 * K).cwiseAbs().maxCoeff();
        converged = decrease <= 1e-10 * ev.cost || step <= 1e-9 * scale || trial.cost < 1e-30;
        std::swap(ev, trial);
        lambda = std::max(lambda / kDampingShrink, kMinDamping);
        accepted = true;
        // Near the optimum the footpoints slide with the axis and successive GN steps line up
        // (linear convergence along the radius ↔ offset valley): the damped step falls short.
        // The parabola through c0, its slope and the cost reached says how far the minimum
        // along δ lies; one batch of closest points tries it when it is well past the step
        // (at most 2^max_extrapolations steps), instead of doubling blindly. A profile that
        // the extension pushes past a cutter constraint is projected back.
        if (options.max_extrapolations > 0 && !converged && !pb.fair_active) {
          const double bend = ev.cost - cost_before - slope;  // the parabola's α² term, from c(1)
          const double cap = static_cast<double>(1 << options.max_extrapolations);
          const double alpha = bend > 0.0 ? std::min(cap, -slope / (2.0 * bend)) : cap;
          // Where the minimum lies far out (or the parabola has none), the footpoints may not
          // follow that far: a miss there falls back once to twice the step.
          for (const double a : {alpha, 2.0}) {
            if (a < kExtendBeyond || (a == 2.0 && alpha <= 2.0)) break;
            VecX x_far = x_before + a * delta;
            project_profile(bounds, nc, &x_far);
            trial_hints = hints;
            Evaluation far = evaluate(pb, x_far, trial_hints, result.timing, std::move(trial));
            const bool further = far.cost < ev.cost && far.interior >= std::max(nc, n);
            if (further) {
              x = x_far;
              hints.swap(trial_hints);
              std::swap(ev, far);
            }
            trial = std::move(far);  // the evaluation left over
            if (further) break;
          }
        }
        // The iterate moved to: its JᵀJ and Jᵀr are the next step's.
        assemble(pb, ev, result.timing);
      } else {
        lambda *= kDampingGrowth;
      }
      spare = std::move(trial);
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
  if (!bounds.empty()) {
    const VecX slack = bounds.h - bounds.G * c;
    for (Eigen::Index r = 0; r < slack.size(); ++r) {
      if (slack(r) > bounds.tolerance) continue;
      switch (bounds.kind[static_cast<std::size_t>(r)]) {
        case ProfileBounds::Kind::radius_min: result.radius_at_min = true; break;
        case ProfileBounds::Kind::radius_max: result.radius_at_max = true; break;
        case ProfileBounds::Kind::slope: result.slope_at_limit = true; break;
      }
    }
  }
  if (result.status != FitStatus::left_surface) {
    result.status = converged ? FitStatus::converged : FitStatus::max_iterations;
    if (!result.cutter.valid()) result.status = FitStatus::invalid_cutter;
  }
  result.timing.total_s = seconds_since(t_start);
  return result;
}

}  // namespace flank
