#include "report/write_step.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <deque>
#include <exception>
#include <limits>
#include <optional>

#include "io/read_mesh.h"
#include <Eigen/Dense>
#include <Eigen/Sparse>

#include "kernels/bspline.h"
#include "kernels/envelope.h"
#include "kernels/parallel.h"

namespace flank::report {

namespace {
constexpr int kProfileSamples = 101;  // the meridian samples of patches.json's tool.profile
// The face fit's parallel blocks: curves of the grid whose knots are laid together, rows of the
// fine grid whose deviation is measured together. Fixed sizes, so that the work and its
// result do not depend on the thread count; large enough that a block outweighs its task.
constexpr int kCurveBlock = 32;
constexpr int kFineRowBlock = 32;
}  // namespace

namespace {

// The n × count basis matrix of the cubic B-spline on `knots` (clamped, over [lo, hi]) at the n
// uniform parameters lo + (hi − lo) k / (n − 1): 4 entries a row.
Eigen::SparseMatrix<double> basis_matrix(int n, const std::vector<double>& knots) {
  const int count = static_cast<int>(knots.size()) - kSplineDegree - 1;
  const double lo = knots.front(), hi = knots.back();
  std::vector<Eigen::Triplet<double>> entries;
  for (int k = 0; k < n; ++k) {
    const double x = k + 1 == n ? hi : lo + (hi - lo) * (k / static_cast<double>(n - 1));
    const BasisRow row = cubic_basis(knots, count, x);
    for (int c = 0; c <= kSplineDegree; ++c) entries.emplace_back(k, row.first + c, row.value[static_cast<std::size_t>(c)]);
  }
  Eigen::SparseMatrix<double> B(n, count);
  B.setFromTriplets(entries.begin(), entries.end());
  return B;
}

// Clamped uniform knots for `count` poles over [lo, hi].
std::vector<double> knots_over(int count, double lo, double hi) {
  std::vector<double> k = clamped_uniform_knots(count);
  if (lo != 0.0 || hi != 1.0)
    for (double& x : k) x = lo + (hi - lo) * x;
  return k;
}

// Clamped cubic knots over [lo, hi] ⊂ [0, 1] at the exact surface's `breaks` (sorted, inside
// (0, 1)), each of multiplicity two. At a break the surface changes polynomial piece (the
// motion's along t, a spline cutter's profile along s) and its curvature may jump: a double
// knot (a C¹ join) follows that, where simple knots converge slowly around it. Breaks nearer
// to lo or hi than half the shortest piece are left out (a sliver span holds no sample).
std::vector<double> piece_knots(const std::vector<double>& breaks, double lo, double hi) {
  double shortest = 1.0, last = 0.0;
  for (const double b : breaks) shortest = std::min(shortest, b - last), last = b;
  shortest = std::min(shortest, 1.0 - last);
  std::vector<double> k(kSplineDegree + 1, lo);
  for (const double b : breaks)
    if (b - lo >= 0.5 * shortest && hi - b >= 0.5 * shortest) k.insert(k.end(), 2, b);
  k.insert(k.end(), kSplineDegree + 1, hi);
  return k;
}

using PoleGrid = FacePoles;  // a face's poles, knots and deviation (report/write_step.h)

int pole_count(const std::vector<double>& knots) { return static_cast<int>(knots.size()) - kSplineDegree - 1; }

// The banded normal equations of one direction's least squares: B and a factorisation of BᵀB.
struct Direction {
  Eigen::SparseMatrix<double> B;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> normal;
  Direction(int n, const std::vector<double>& knots) : B(basis_matrix(n, knots)) {
    normal.compute(Eigen::SparseMatrix<double>(B.transpose() * B));
  }
  bool ok() const { return normal.info() == Eigen::Success; }
  // The poles (count × m) whose curves fit the columns of P (n × m) in least squares.
  Eigen::MatrixXd solve(const Eigen::MatrixXd& P) const { return normal.solve(Eigen::MatrixXd(B.transpose() * P)); }
};

// The tensor-product least-squares surface: on a full grid it separates, poles = Bu⁺ P Bv⁺ᵀ
// per coordinate, each factor from banded normal equations.
PoleGrid least_squares(const std::string& name, const Points& grid, int rows, int cols, std::vector<double> knots_u,
                       std::vector<double> knots_v) {
  const int nu = pole_count(knots_u), nv = pole_count(knots_v);
  const Direction u(rows, knots_u), v(cols, knots_v);
  if (!u.ok() || !v.ok()) throw io::Error(name + ": the B-spline fit is singular");
  PoleGrid g{Points(static_cast<Eigen::Index>(nu) * nv, 3), nu, nv, std::move(knots_u), std::move(knots_v), 0.0};
  for (int c = 0; c < 3; ++c) {
    Eigen::MatrixXd P(rows, cols);
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j < cols; ++j) P(i, j) = grid(static_cast<Eigen::Index>(i) * cols + j, c);
    const Eigen::MatrixXd along_u = u.solve(P);                                // nu × cols
    const Eigen::MatrixXd both = v.solve(along_u.transpose()).transpose();     // nu × nv
    for (int i = 0; i < nu; ++i)
      for (int j = 0; j < nv; ++j) g.poles(static_cast<Eigen::Index>(i) * nv + j, c) = both(i, j);
  }
  return g;
}

// The largest distance between the surface and `fine` at the fine grid's parameters. The
// surface is evaluated as the tensor product it is, Bu · P · Bvᵀ per coordinate with the basis
// tabulated once per fine row and column: the same values as OCCT's evaluation of the written
// face (CadIo.FaceDeviationIsTheWrittenFaces checks), without locating each parameter among
// the knots again, which made measuring 80% of the fit on large faces.
double deviation(const PoleGrid& g, const Points& fine, int rows, int cols) {
  const int fine_rows = 2 * rows - 1, fine_cols = 2 * cols - 1;
  const Eigen::SparseMatrix<double> Bu = basis_matrix(fine_rows, g.knots_u), Bv = basis_matrix(fine_cols, g.knots_v);
  std::array<Eigen::MatrixXd, 3> on_u;  // per coordinate, fine_rows × nv
  for (int c = 0; c < 3; ++c) {
    Eigen::MatrixXd P(g.nu, g.nv);
    for (int i = 0; i < g.nu; ++i)
      for (int j = 0; j < g.nv; ++j) P(i, j) = g.poles(static_cast<Eigen::Index>(i) * g.nv + j, c);
    on_u[static_cast<std::size_t>(c)] = Bu * P;
  }
  // The fine rows in blocks of a fixed size, in parallel; a maximum is the same in any order.
  const int block = kFineRowBlock, blocks = (fine_rows + block - 1) / block;
  std::vector<double> worst(static_cast<std::size_t>(blocks), 0.0);
  parallel_for(0, static_cast<std::size_t>(blocks), [&](std::size_t b0, std::size_t b1) {
    for (std::size_t b = b0; b < b1; ++b) {
      const int i0 = static_cast<int>(b) * block, h = std::min(block, fine_rows - i0);
      Eigen::MatrixXd squared = Eigen::MatrixXd::Zero(fine_cols, h);
      for (int c = 0; c < 3; ++c) {
        const Eigen::MatrixXd on = Bv * on_u[static_cast<std::size_t>(c)].middleRows(i0, h).transpose();  // fine_cols × h
        for (int i = 0; i < h; ++i)
          for (int j = 0; j < fine_cols; ++j) {
            const double e = on(j, i) - fine(static_cast<Eigen::Index>(i0 + i) * fine_cols + j, c);
            squared(j, i) += e * e;
          }
      }
      worst[b] = squared.maxCoeff();
    }
  }, 1);
  return std::sqrt(*std::max_element(worst.begin(), worst.end()));
}

// Knots along one direction with which every curve of the grid along it (the columns when
// `along_rows` is false: curves along u through the coarse columns) is fitted within `target`
// at every fine parameter: the surface's pieces (piece_knots) first, then each span where
// some curve misses split in two, until none misses. nullopt when a span that misses can no
// longer be split, or the poles would outnumber four fifths of the points (as the densest
// uniform fit below): beyond, least squares loses its hold on the points. Where the error is
// (near Ω's ends, where the envelope turns fast) is where the knots go: Rotor 67 lower's
// twelve faces took 9k poles this way where uniform knots took 226k. On nullopt, `miss` (if
// given) receives the worst distance of the last knots tried (infinity if none were).
std::optional<std::vector<double>> direction_knots(const Points& fine, int rows, int cols, bool along_rows,
                                                   const std::vector<double>& breaks, double lo, double hi,
                                                   double target, double* miss = nullptr) {
  const int fine_cols = 2 * cols - 1;
  const int n = along_rows ? cols : rows, m = along_rows ? rows : cols;  // points along, curves
  const auto at = [&](int fine_along, int curve, int c) {
    const int i = along_rows ? 2 * curve : fine_along, j = along_rows ? fine_along : 2 * curve;
    return fine(static_cast<Eigen::Index>(i) * fine_cols + j, c);
  };
  const double spacing = (hi - lo) / (n - 1);
  std::vector<double> knots = piece_knots(breaks, lo, hi);
  double last = std::numeric_limits<double>::infinity();
  const auto give_up = [&] {
    if (miss) *miss = last;
    return std::nullopt;
  };
  for (;;) {
    if (pole_count(knots) > std::max(4, (4 * n) / 5)) return give_up();
    const Direction d(n, knots);
    if (!d.ok()) return give_up();
    const Eigen::SparseMatrix<double> fine_basis = basis_matrix(2 * n - 1, knots);
    // The curves in blocks of a fixed size, in parallel; each block's worst squared error at
    // every fine parameter, then the largest over the blocks (the same in any order).
    const int block = kCurveBlock, blocks = (m + block - 1) / block;
    Eigen::MatrixXd block_worst(2 * n - 1, blocks);
    parallel_for(0, static_cast<std::size_t>(blocks), [&](std::size_t k0, std::size_t k1) {
      for (std::size_t k = k0; k < k1; ++k) {
        const int b0 = static_cast<int>(k) * block, w = std::min(block, m - b0);
        Eigen::MatrixXd squared = Eigen::MatrixXd::Zero(2 * n - 1, w);
        for (int c = 0; c < 3; ++c) {
          Eigen::MatrixXd P(n, w);
          for (int a = 0; a < n; ++a)
            for (int b = 0; b < w; ++b) P(a, b) = at(2 * a, b0 + b, c);
          const Eigen::MatrixXd on = fine_basis * d.solve(P);  // (2n − 1) × w
          for (int a = 0; a < 2 * n - 1; ++a)
            for (int b = 0; b < w; ++b) {
              const double e = on(a, b) - at(a, b0 + b, c);
              squared(a, b) += e * e;
            }
        }
        block_worst.col(static_cast<Eigen::Index>(k)) = squared.rowwise().maxCoeff();
      }
    }, 1);
    const Eigen::VectorXd worst = block_worst.rowwise().maxCoeff();
    last = std::sqrt(worst.maxCoeff());
    if (last <= target) return knots;
    // Split every span holding a fine parameter that misses (a parameter on a knot: both sides).
    std::vector<double> split;
    for (std::size_t k = kSplineDegree; k + kSplineDegree + 1 < knots.size(); ++k) {
      const double k0 = knots[k], k1 = knots[k + 1];
      if (!(k1 > k0)) continue;
      const int a0 = static_cast<int>(std::floor((k0 - lo) / (hi - lo) * (2 * n - 2)));
      const int a1 = static_cast<int>(std::ceil((k1 - lo) / (hi - lo) * (2 * n - 2)));
      bool misses = false;
      for (int a = std::max(0, a0); a <= std::min(2 * n - 2, a1) && !misses; ++a) misses = worst(a) > target * target;
      if (!misses) continue;
      if (k1 - k0 < 2.0 * spacing) return give_up();
      split.push_back(0.5 * (k0 + k1));
    }
    knots.insert(knots.end(), split.begin(), split.end());
    std::sort(knots.begin(), knots.end());
  }
}

// First knots that follow the exact surface's pieces and its error (direction_knots, half of
// `target` along each direction); then, if that surface misses `target`, half as many poles
// as grid points on uniform knots, then more. The first that meets `target` at every fine point,
// else the most accurate. The uniform fit with one pole per point interpolates only up to 24
// points: at uniform parameters the collocation matrix of a cubic with uniform knots and as
// many poles as points has a condition number that grows about 1.17 times a point (66 at 24
// points, 1e13 at 200, exactly singular in double at 324, which a Rotor 67 patch hit); beyond,
// four fifths as many poles as points, whose condition stays under 9 for every count up to 420
// tried (half: under 5). `following` and `uniform` choose which of the two are tried; the result
// is nothing when none was. `unlaid` (if given) receives the direction along which the knots
// that follow Ω could not be laid, their miss there and the target they had, else direction 0.
struct Unlaid {
  int direction = 0;  // 1: t, 2: s
  double miss = std::numeric_limits<double>::infinity();  // infinity: no knots were tried
  double target = 0.0;
};
std::optional<PoleGrid> fit_poles(const std::string& name, const Points& fine, int rows, int cols, double target,
                                  const FaceDomain& domain, const FaceBreaks& breaks, bool following = true,
                                  bool uniform = true, Unlaid* unlaid = nullptr) {
  if (unlaid) *unlaid = {};
  const int fine_cols = 2 * cols - 1;
  Points grid(static_cast<Eigen::Index>(rows) * cols, 3);
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < cols; ++j)
      grid.row(static_cast<Eigen::Index>(i) * cols + j) = fine.row(static_cast<Eigen::Index>(2 * i) * fine_cols + 2 * j);
  std::optional<PoleGrid> best;
  const auto consider = [&](PoleGrid g) {
    g.deviation = deviation(g, fine, rows, cols);
    if (!best || g.deviation < best->deviation) best = std::move(g);
    return best->deviation <= target;
  };
  if (following) {
    double miss = std::numeric_limits<double>::infinity();
    const std::optional<std::vector<double>> ku =
        direction_knots(fine, rows, cols, false, breaks.t, domain.t0, domain.t1, 0.5 * target, &miss);
    const std::optional<std::vector<double>> kv =
        ku ? direction_knots(fine, rows, cols, true, breaks.s, domain.s0, domain.s1, 0.5 * target, &miss)
           : std::nullopt;
    if (ku && kv && consider(least_squares(name, grid, rows, cols, *ku, *kv))) return best;
    if (unlaid && !(ku && kv)) *unlaid = {ku ? 2 : 1, miss, 0.5 * target};
  }
  if (!uniform) return best;
  const auto poles = [](int points, bool more) {
    const int half = std::max(4, (points + 1) / 2);
    return more ? std::min(points, std::max({half, 24, static_cast<int>(std::ceil(0.8 * points))})) : half;
  };
  for (const bool more : {false, true})
    if (consider(least_squares(name, grid, rows, cols, knots_over(poles(rows, more), domain.t0, domain.t1),
                               knots_over(poles(cols, more), domain.s0, domain.s1))))
      break;
  return best;
}

FittedSurface to_surface(const std::string& name, const PoleGrid& g) {
  return {io::SplineSurface::from_poles(name, g.poles, g.nu, g.nv, g.knots_u, g.knots_v), g.deviation};
}

}  // namespace

bool denser_grids_may_help(double before, std::optional<double> now) { return now && *now <= 0.5 * before; }

bool knots_within_reach(double miss, double target, int more, int most) {
  double reach = target;
  for (int m = more; m < most; m *= 2) reach *= 16.0;
  return !std::isfinite(miss) || miss <= reach;
}

FaceBreaks face_breaks(const Patch& p) {
  FaceBreaks b;
  for (const double k : p.motion.knots)
    if (k > 0.0 && k < 1.0 && (b.t.empty() || k > b.t.back())) b.t.push_back(k);
  b.s = profile_breaks(p.cutter.kind);
  return b;
}

FittedSurface fit_exact_grid(const std::string& name, const Points& fine, int rows, int cols, double target,
                             const FaceDomain& domain, const FaceBreaks& breaks) {
  return to_surface(name, *fit_poles(name, fine, rows, cols, target, domain, breaks));
}

namespace {

// Ω of a patch at the (2·rows − 1) × (2·cols − 1) fine parameters over [0, 1]², before
// exact_omega_grid cuts it: the same for every margin, so sampled once per density.
struct OmegaSamples {
  int rows = 0, cols = 0;  // of the coarse grid
  Points all;              // fine row-major; rows where `valid` is 0 unset
  std::vector<char> valid;
};

std::optional<OmegaSamples> sample_omega(const Patch& p, int rows, int cols) {
  const EnvelopeMesh& env = p.envelope;
  if (env.rows < 2 || env.cols < 2 || env.V.rows() != static_cast<Eigen::Index>(env.rows) * env.cols)
    return std::nullopt;
  const int fr = 2 * rows - 1, fc = 2 * cols - 1;
  OmegaSamples out{rows, cols, Points(static_cast<Eigen::Index>(fr) * fc, 3),
                   std::vector<char>(static_cast<std::size_t>(fr) * fc, 0)};
  auto V = [&](int a, int b) -> Vec3 { return env.V.row(static_cast<Eigen::Index>(a) * env.cols + b).transpose(); };
  // The cutter's radius and slope depend on the column only.
  std::vector<double> radius(static_cast<std::size_t>(fc)), slope(static_cast<std::size_t>(fc));
  for (int j = 0; j < fc; ++j) {
    const double s = j / static_cast<double>(fc - 1);
    radius[static_cast<std::size_t>(j)] = p.cutter.radius(s);
    slope[static_cast<std::size_t>(j)] = p.cutter.slope(s);
  }
  // Each fine row on its own (the cone part's one face: 645 rows of 333 points, 15 ms on one
  // thread).
  parallel_for(0, static_cast<std::size_t>(fr), [&](std::size_t r0, std::size_t r1) {
    for (int i = static_cast<int>(r0); i < static_cast<int>(r1); ++i) {
      const double t = i / static_cast<double>(fr - 1);
      const Line l = p.motion.ruling(t);
      const Vec3 at = p.motion.a_at(t, 1), bt = p.motion.b_at(t, 1);
      const double ti = t * (env.rows - 1);
      const int i0 = std::min(static_cast<int>(ti), env.rows - 2);
      const double wu = ti - i0;
      for (int j = 0; j < fc; ++j) {
        const double s = j / static_cast<double>(fc - 1);
        // The side the envelope grid took: the candidate nearer to it (bilinear between samples).
        const double sj = s * (env.cols - 1);
        const int j0 = std::min(static_cast<int>(sj), env.cols - 2);
        const double wv = sj - j0;
        const Vec3 near = (1 - wu) * ((1 - wv) * V(i0, j0) + wv * V(i0, j0 + 1)) +
                          wu * ((1 - wv) * V(i0 + 1, j0) + wv * V(i0 + 1, j0 + 1));
        const Vec3 centre = l.point(s), rs = l.b - l.a, rt = (1 - s) * at + s * bt;
        const double d = radius[static_cast<std::size_t>(j)], dd = slope[static_cast<std::size_t>(j)];
        const EnvelopePoint plus = envelope_point(centre, rt, rs, d, dd, +1);
        const EnvelopePoint minus = envelope_point(centre, rt, rs, d, dd, -1);
        const std::size_t k = static_cast<std::size_t>(i) * fc + j;
        out.valid[k] = plus.valid && minus.valid && plus.point.allFinite() && minus.point.allFinite();
        if (!out.valid[k]) continue;
        const Vec3 q = (plus.point - near).norm() <= (minus.point - near).norm() ? plus.point : minus.point;
        out.all.row(static_cast<Eigen::Index>(k)) = q.transpose();
      }
    }
  }, 8);
  return out;
}

bool cut_omega_grid(const Patch& p, const OmegaSamples& samples, int& rows, int& cols, Points& fine,
                    FaceDomain* domain, int margin) {
  const EnvelopeMesh& env = p.envelope;
  rows = samples.rows, cols = samples.cols;
  const int fc = 2 * cols - 1;
  const Points& all = samples.all;
  const std::vector<char>& valid = samples.valid;
  // Rows and columns of the rows × cols grid, cut from the ends while the band of fine samples
  // beside the kept rectangle's edge lacks Ω somewhere.
  int r0 = 0, r1 = rows - 1, c0 = 0, c1 = cols - 1;
  const auto band_has_gap = [&](int fi0, int fi1, int fj0, int fj1) {
    for (int i = fi0; i <= fi1; ++i)
      for (int j = fj0; j <= fj1; ++j)
        if (!valid[static_cast<std::size_t>(i) * fc + j]) return true;
    return false;
  };
  for (;;) {
    if (r1 - r0 < 3 || c1 - c0 < 3) return false;
    const int i0 = 2 * r0, i1 = 2 * r1, j0 = 2 * c0, j1 = 2 * c1;
    if (!band_has_gap(i0, i1, j0, j1)) break;
    if (band_has_gap(i0, i0 + 1, j0, j1)) ++r0;
    else if (band_has_gap(i1 - 1, i1, j0, j1)) --r1;
    else if (band_has_gap(i0, i1, j0, j0 + 1)) ++c0;
    else if (band_has_gap(i0, i1, j1 - 1, j1)) --c1;
    else return false;  // Ω is missing inside, not at an edge
  }
  // Next to where Ω ends it folds (its points race toward the edge) and no spline follows it:
  // the caller may ask to keep `margin` rows or columns of the envelope grid farther off.
  if (margin > 0) {
    const int mr = margin * (rows - 1) / std::max(1, env.rows - 1), mc = margin * (cols - 1) / std::max(1, env.cols - 1);
    if (r0 > 0) r0 += mr;
    if (r1 < rows - 1) r1 -= mr;
    if (c0 > 0) c0 += mc;
    if (c1 < cols - 1) c1 -= mc;
    if (r1 - r0 < 3 || c1 - c0 < 3) return false;
  }
  const int kr = r1 - r0 + 1, kc = c1 - c0 + 1, kfr = 2 * kr - 1, kfc = 2 * kc - 1;
  fine.resize(static_cast<Eigen::Index>(kfr) * kfc, 3);
  for (int i = 0; i < kfr; ++i)
    for (int j = 0; j < kfc; ++j)
      fine.row(static_cast<Eigen::Index>(i) * kfc + j) =
          all.row(static_cast<Eigen::Index>(2 * r0 + i) * fc + 2 * c0 + j);
  domain->t0 = r0 / static_cast<double>(rows - 1), domain->t1 = r1 / static_cast<double>(rows - 1);
  domain->s0 = c0 / static_cast<double>(cols - 1), domain->s1 = c1 / static_cast<double>(cols - 1);
  rows = kr, cols = kc;
  return fine.allFinite();
}

}  // namespace

bool exact_omega_grid(const Patch& p, int& rows, int& cols, Points& fine, FaceDomain* domain, int margin) {
  const std::optional<OmegaSamples> samples = sample_omega(p, rows, cols);
  return samples && cut_omega_grid(p, *samples, rows, cols, fine, domain, margin);
}

std::vector<Vec2> solid_profile(const Cutter& c) {
  std::vector<Vec2> m;
  bool simple = true;
  for (int k = 0; k < kProfileSamples; ++k) {
    m.push_back(c.meridian(k / (kProfileSamples - 1.0)));
    simple = simple && m.back().allFinite() && m.back().y() > 0 && (k == 0 || m[k].x() > m[k - 1].x());
  }
  if (simple) return m;
  // The contact circles fold back along the axis (|d d″ + d′²| > L² somewhere): the tool is
  // then the outline of the union of its spheres over the axial span of the meridian.
  double z0 = std::numeric_limits<double>::infinity(), z1 = -z0;
  for (const Vec2& q : m)
    if (std::isfinite(q.x())) z0 = std::min(z0, q.x()), z1 = std::max(z1, q.x());
  constexpr int kOutline = 201, kSpheres = 2001;
  std::vector<Vec2> outline;
  for (int k = 0; k < kOutline; ++k) {
    const double z = z0 + (z1 - z0) * k / (kOutline - 1.0);
    double r = 0.0;
    for (int i = 0; i < kSpheres; ++i) {
      const double s = i / (kSpheres - 1.0), d = c.radius(s), dz = z - s * c.length;
      r = std::max(r, std::sqrt(std::max(0.0, d * d - dz * dz)));
    }
    outline.push_back({z, r});
  }
  return outline;
}

// Appended, not "P" + …: GCC 12 warns falsely (-Wrestrict, its bug 105329) on the latter.
std::string face_name(const Patch& p) {
  std::string name = "P";
  name += std::to_string(p.id);
  return name;
}
std::string tool_name(const Patch& p) { return face_name(p) + "-tool"; }

std::vector<PatchFace> fit_patch_faces(const std::string& file, const std::vector<Patch>& patches, double tolerance) {
  // Each patch's face is fitted on its own, concurrently. An error of a patch's fit is
  // rethrown after all have run, the first in patch order, whatever the thread count.
  struct Fitted {
    std::optional<PoleGrid> best;
    FaceDomain domain;
    std::exception_ptr error;
  };
  std::vector<Fitted> fitted(patches.size());
  parallel_invoke_each(patches.size(), [&](std::size_t k) {
    const Patch& p = patches[k];
    Fitted& out = fitted[k];
    const FaceBreaks breaks = face_breaks(p);
    try {
      // Ω's grid in the evaluation's (t, s) samples, then up to eight times as many rows and
      // columns (more points to hold more knots, where the face needs more poles than four
      // fifths of the grid's points), until the face is within 1/150 of the tolerance (a
      // margin under the 1% promised), while denser grids still help (denser_grids_may_help);
      // else the closest. Where Ω ends inside the grid, a face that misses the target is first
      // tried again at the same density kept 1, 2, 4, 8 envelope rows (columns) farther from
      // that end: the kink where Ω ends is what a denser grid then fits slowly (the noisy
      // barrel's second patch went to 3001 × 1257 points, 1/75 of the tolerance, where one row
      // off its end met the target at 376 × 158; 28 of its command's 35 s).
      // Knots that follow Ω are tried first on grids denser along the direction where they
      // could not be laid (up to 8×, while the target is within their reach:
      // knots_within_reach), before uniform knots on any: where Ω turns faster than
      // the grid's rows near an end (HECC side a at 1e-4, patch 1; a made-up blade's face whose
      // first span missed by 18× the target on the grid and 2× on twice the rows), a span
      // cannot be split finer than the rows, and uniform knots met the target there with up to
      // 320 × 144 poles.
      bool met = false;
      // Ω's samples at the densities both passes below may try (1 × 1, 2 × 1), kept for the
      // second (a deque: what it holds stays where it is).
      std::deque<std::pair<std::pair<int, int>, std::optional<OmegaSamples>>> kept;
      const auto attempt = [&](int more_rows, int more_cols, bool following, bool uniform, Unlaid* unlaid) {
        const std::pair density{more_rows, more_cols};
        const std::optional<OmegaSamples>* samples = nullptr;
        for (const auto& [d, s] : kept)
          if (d == density) samples = &s;
        std::optional<OmegaSamples> fresh;
        if (!samples) {
          fresh = sample_omega(p, (p.envelope.rows - 1) * more_rows + 1, (p.envelope.cols - 1) * more_cols + 1);
          samples = &fresh;
          if (more_cols == 1 && more_rows <= 2) samples = &kept.emplace_back(density, std::move(fresh)).second;
        }
        for (const int margin : {0, 1, 2, 4, 8}) {
          int rows = 0, cols = 0;
          Points fine;
          FaceDomain domain;
          if (!*samples || !cut_omega_grid(p, **samples, rows, cols, fine, &domain, margin)) break;
          const bool trimmed = domain.t0 > 0.0 || domain.t1 < 1.0 || domain.s0 > 0.0 || domain.s1 < 1.0;
          std::optional<PoleGrid> g = fit_poles(file + ": patch " + std::to_string(p.id), fine, rows, cols,
                                                tolerance / 150.0, domain, breaks, following, uniform,
                                                margin == 0 ? unlaid : nullptr);
          if (g && (!out.best || g->deviation < out.best->deviation)) out.best = std::move(*g), out.domain = domain;
          met = out.best && out.best->deviation <= tolerance / 150.0;
          if (met || !trimmed) break;
        }
        return met;
      };
      // Denser along the direction where the knots could not be laid only while the target
      // is within reach there (knots_within_reach).
      std::vector<std::pair<int, int>> followed;  // densities where the first pass tried them
      for (int more_rows = 1, more_cols = 1; more_rows <= 8 && more_cols <= 8;) {
        Unlaid unlaid;
        followed.emplace_back(more_rows, more_cols);
        if (attempt(more_rows, more_cols, true, false, &unlaid)) break;
        if (unlaid.direction == 0) break;  // laid, and the surface misses: the densities below take it on
        int& more = unlaid.direction == 1 ? more_rows : more_cols;
        if (!knots_within_reach(unlaid.miss, unlaid.target, more, 8)) break;
        more *= 2;
      }
      // Denser grids only while they pay: each time the points have doubled both ways, the
      // best face must have halved its miss (denser_grids_may_help).
      double before = std::numeric_limits<double>::infinity();
      for (const auto& [more_rows, more_cols] : {std::pair{1, 1}, {2, 1}, {2, 2}, {4, 2}, {4, 4}, {8, 4}, {8, 8}}) {
        if (met) break;
        const bool tried = std::find(followed.begin(), followed.end(), std::pair{more_rows, more_cols}) != followed.end();
        attempt(more_rows, more_cols, !tried, true, nullptr);
        if (more_rows != more_cols) continue;
        const std::optional<double> now = out.best ? std::optional(out.best->deviation) : std::nullopt;
        if (more_rows > 1 && !met && !denser_grids_may_help(before, now)) break;
        before = now.value_or(std::numeric_limits<double>::infinity());
      }
    } catch (...) {
      out.error = std::current_exception();
    }
  });
  for (const Fitted& f : fitted)
    if (f.error) std::rethrow_exception(f.error);
  std::vector<PatchFace> faces(patches.size());
  for (std::size_t k = 0; k < patches.size(); ++k)
    if (fitted[k].best) faces[k] = FittedFace{std::move(*fitted[k].best), fitted[k].domain};
  return faces;
}

std::vector<WrittenFace> write_patches_step(const std::filesystem::path& path, const std::vector<Patch>& patches,
                                            const std::vector<PatchFace>& fitted) {
  assert(fitted.size() == patches.size());
  const std::string file = path.string();
  std::vector<WrittenFace> written(patches.size(), {std::numeric_limits<double>::quiet_NaN(), {}});
  std::vector<io::NamedSurface> faces;
  for (std::size_t k = 0; k < patches.size(); ++k) {
    if (!fitted[k]) continue;
    const std::string name = face_name(patches[k]);
    written[k] = {fitted[k]->poles.deviation, fitted[k]->domain};
    faces.push_back({name, to_surface(file + ": patch " + std::to_string(patches[k].id), fitted[k]->poles).surface});
  }
  io::write_surfaces(path, faces);
  return written;
}

std::vector<WrittenFace> write_patches_step(const std::filesystem::path& path, const std::vector<Patch>& patches,
                                            double tolerance) {
  return write_patches_step(path, patches, fit_patch_faces(path.string(), patches, tolerance));
}

void write_tools_step(const std::filesystem::path& path, const std::vector<Patch>& patches) {
  std::vector<io::RevolvedSolid> solids;
  for (const Patch& p : patches) {
    io::RevolvedSolid s;
    s.name = tool_name(p);
    const Line l = p.motion.ruling(0.0);
    s.origin = l.a;
    s.axis = (l.b - l.a).normalized();
    s.meridian = solid_profile(p.cutter);
    solids.push_back(std::move(s));
  }
  io::write_solids(path, solids);
}

}  // namespace flank::report
