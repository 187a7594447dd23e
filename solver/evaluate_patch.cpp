#include "solver/evaluate_patch.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>

#include "kernels/envelope.h"
#include "kernels/parallel.h"

namespace flank {

std::string EvaluateOptions::validate() const {
  if (!(tolerance > 0.0) || !std::isfinite(tolerance)) return "tolerance must be positive";
  if (rows < 2 || cols < 2) return "evaluation needs at least 2 by 2 samples";
  if (!(spacing >= 0) || !std::isfinite(spacing) || max_samples < 4) return "evaluation spacing out of range";
  if (!(omega_band >= 1.0) || !std::isfinite(omega_band)) return "the band of Ω that covers must be at least the tolerance";
  if (holder && !(holder_length > 0.0 && holder_radius > 0.0))
    return "holder length and radius must be positive";
  return {};
}

ErrorGrid sample_errors(const SurfaceIndex& index, const Motion& motion, const Cutter& cutter,
                        int rows, int cols, bool untrusted_edges) {
  ErrorGrid grid;
  grid.rows = rows, grid.cols = cols;
  const std::size_t n = static_cast<std::size_t>(rows) * cols;
  std::vector<double> d(static_cast<std::size_t>(cols)), dd(static_cast<std::size_t>(cols));
  for (int j = 0; j < cols; ++j) {
    const double s = static_cast<double>(j) / (cols - 1);
    d[j] = cutter.radius(s);
    dd[j] = cutter.slope(s);
  }
  std::vector<Line> rulings(static_cast<std::size_t>(rows));
  std::vector<Vec3> a_t(static_cast<std::size_t>(rows)), b_t(static_cast<std::size_t>(rows));
  grid.sphere_error.resize(static_cast<Eigen::Index>(n));
  grid.interior.resize(n);
  grid.faces.resize(n);
  grid.directions.resize(static_cast<Eigen::Index>(n), 3);
  grid.omega.resize(static_cast<Eigen::Index>(n), 3);
  grid.omega_valid.resize(n);
  grid.omega_interior.resize(n);
  grid.error.resize(static_cast<Eigen::Index>(n));
  if (untrusted_edges) grid.untrusted.resize(n);
  const Mesh& m = index.mesh();
  const auto at_edge = [&](int f) {
    return f >= 0 && (index.is_boundary_vertex(m.F(f, 0)) || index.is_boundary_vertex(m.F(f, 1)) ||
                      index.is_boundary_vertex(m.F(f, 2)));
  };
  // Row by row, each row whole in one task: its centres' closest points (each warm-started
  // from the one before it on the row), its envelope points, and theirs (warm-started from
  // the centre's footpoint face: Ω's points lie near Φ, next to it). A row's results go
  // straight into the grid: no batch of every sample's answer (72 bytes each, twice), whose
  // fresh pages cost more than the copy, and no serial pass over the samples.
  parallel_for(0, static_cast<std::size_t>(rows), [&](std::size_t b, std::size_t e) {
    Points centres(cols, 3);
    std::vector<ClosestPoint> cp(static_cast<std::size_t>(cols)), op(static_cast<std::size_t>(cols));
    for (std::size_t ii = b; ii < e; ++ii) {
      const int i = static_cast<int>(ii);
      const double t = static_cast<double>(i) / (rows - 1);
      rulings[ii] = motion.ruling(t);
      a_t[ii] = motion.a_at(t, 1);
      b_t[ii] = motion.b_at(t, 1);
      for (int j = 0; j < cols; ++j) centres.row(j) = rulings[ii].point(static_cast<double>(j) / (cols - 1)).transpose();
      index.closest_points_serial(centres, {}, cp);
      const Vec3 rs = rulings[ii].b - rulings[ii].a;
      const std::size_t k0 = grid.index(i, 0);
      for (int j = 0; j < cols; ++j) {
        const std::size_t k = k0 + static_cast<std::size_t>(j);
        const ClosestPoint& c = cp[static_cast<std::size_t>(j)];
        grid.directions.row(static_cast<Eigen::Index>(k)) = c.direction.transpose();
        grid.interior[k] = !c.boundary && c.face >= 0;
        // Beyond Φ's edge the sign of the face plane means nothing: there a sphere gouges
        // only if it reaches Φ at all.
        grid.sphere_error(static_cast<Eigen::Index>(k)) = (grid.interior[k] ? c.signed_distance : c.distance) - d[j];
        grid.faces[k] = c.face;
        // Ω's points: on Φ's side, the envelope normal points from the axis toward the footpoint.
        const double s = static_cast<double>(j) / (cols - 1);
        const Vec3 centre = centres.row(j).transpose();
        const Vec3 rt = (1 - s) * a_t[ii] + s * b_t[ii];
        const EnvelopePoint ep = envelope_point(centre, rt, rs, d[j], dd[j], envelope_side(rt, rs, -c.direction));
        grid.omega_valid[k] = ep.valid;
        grid.omega.row(static_cast<Eigen::Index>(k)) = (ep.valid ? ep.point : centre).transpose();
      }
      index.closest_points_serial(grid.omega.middleRows(static_cast<Eigen::Index>(k0), cols),
                                  std::span<const int>(grid.faces).subspan(k0, static_cast<std::size_t>(cols)), op);
      for (int j = 0; j < cols; ++j) {
        const std::size_t k = k0 + static_cast<std::size_t>(j);
        const ClosestPoint& o = op[static_cast<std::size_t>(j)];
        if (untrusted_edges) grid.untrusted[k] = at_edge(o.face) || at_edge(cp[static_cast<std::size_t>(j)].face);
        const bool over = grid.omega_valid[k] && o.face >= 0 && !o.boundary;
        grid.omega_interior[k] = over;
        grid.error(static_cast<Eigen::Index>(k)) = over ? o.signed_distance : 0.0;
      }
    }
  }, 1);
  // The sweep across the axis, at the axis midpoint: a row where it is slow (a fifth of the
  // median) or reverses against a neighbour row is where the motion stalls or turns back.
  {
    std::vector<Vec3> across(static_cast<std::size_t>(rows));
    std::vector<double> speed(static_cast<std::size_t>(rows));
    for (int i = 0; i < rows; ++i) {
      const Vec3 u = (rulings[i].b - rulings[i].a).normalized();
      const Vec3 v = 0.5 * (a_t[i] + b_t[i]);
      across[i] = v - v.dot(u) * u;
      speed[i] = across[i].norm();
    }
    std::vector<double> sorted = speed;
    std::nth_element(sorted.begin(), sorted.begin() + rows / 2, sorted.end());
    const double slow = 0.2 * sorted[static_cast<std::size_t>(rows / 2)];
    grid.sweeps.assign(static_cast<std::size_t>(rows), 1);
    for (int i = 0; i < rows; ++i) {
      const bool back = (i > 0 && across[i].dot(across[i - 1]) < 0) ||
                        (i + 1 < rows && across[i].dot(across[i + 1]) < 0);
      grid.sweeps[i] = !(speed[i] < slow || back);
    }
  }
  return grid;
}

std::vector<SampleClass> classify_samples(const ErrorGrid& grid, double tolerance) {
  std::vector<SampleClass> out(static_cast<std::size_t>(grid.rows) * grid.cols, SampleClass::overhang);
  for (std::size_t k = 0; k < out.size(); ++k) {
    const auto e = static_cast<Eigen::Index>(k);
    if (!grid.sweeps.empty() && !grid.sweeps[k / static_cast<std::size_t>(grid.cols)])
      out[k] = SampleClass::outside;  // the motion stalls or turns back: Ω folds
    else if (!grid.untrusted.empty() && grid.untrusted[k])
      out[k] = SampleClass::overhang;
    else if (grid.sphere_error(e) < -tolerance)
      out[k] = SampleClass::outside;  // the whole cutter: a sphere reaching into Φ gouges
    else if (grid.omega_interior[k])
      out[k] = std::abs(grid.error(e)) <= tolerance ? SampleClass::within : SampleClass::outside;
    else if (!grid.omega_valid[k] && grid.interior[k])
      out[k] = SampleClass::outside;  // over Φ, but this part of the cutter cuts no surface
  }
  return out;
}

namespace {

// Ω as a mesh over the grid: two triangles per cell whose corners all have an envelope point.
// `keep` (optional) further restricts the corners. The rows of cells in parallel: which of
// each cell's two triangles are faces, then, after counting, each row's faces at its place,
// in the order of one pass over the rows.
Mesh envelope_mesh(const ErrorGrid& grid, const std::vector<char>* keep) {
  const int rows = grid.rows, cols = grid.cols;
  const auto ok = [&](int k) {
    return grid.omega_valid[static_cast<std::size_t>(k)] && (!keep || (*keep)[static_cast<std::size_t>(k)]);
  };
  const auto is_face = [&](int p, int q, int r) {
    if (!ok(p) || !ok(q) || !ok(r)) return false;
    const Vec3 a = grid.omega.row(p).transpose();
    const Vec3 n = (Vec3(grid.omega.row(q).transpose()) - a).cross(Vec3(grid.omega.row(r).transpose()) - a);
    return n.norm() > 1e-20;
  };
  // Triangles per row of cells, and rows of cells.
  const auto strip = static_cast<std::size_t>(2 * std::max(0, cols - 1));
  const auto cell_rows = static_cast<std::size_t>(std::max(0, rows - 1));
  std::vector<char> made(cell_rows * strip);
  std::vector<Eigen::Index> first(cell_rows + 1, 0);  // row i's faces from first[i]
  parallel_for(0, cell_rows, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      Eigen::Index count = 0;
      const int row = static_cast<int>(i) * cols;
      for (int j = 0; j + 1 < cols; ++j) {
        const int v00 = row + j, v01 = v00 + 1, v10 = v00 + cols, v11 = v10 + 1;
        char* m = &made[i * strip + 2 * static_cast<std::size_t>(j)];
        m[0] = is_face(v00, v10, v11), m[1] = is_face(v00, v11, v01);
        count += m[0] + m[1];
      }
      first[i + 1] = count;
    }
  }, 8);
  for (std::size_t i = 0; i < cell_rows; ++i) first[i + 1] += first[i];
  Mesh m;
  m.V = grid.omega;
  m.F.resize(first[cell_rows], 3);
  parallel_for(0, cell_rows, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      Eigen::Index f = first[i];
      const int row = static_cast<int>(i) * cols;
      for (int j = 0; j + 1 < cols; ++j) {
        const int v00 = row + j, v01 = v00 + 1, v10 = v00 + cols, v11 = v10 + 1;
        const char* made_here = &made[i * strip + 2 * static_cast<std::size_t>(j)];
        if (made_here[0]) m.F.row(f++) << v00, v10, v11;
        if (made_here[1]) m.F.row(f++) << v00, v11, v01;
      }
    }
  }, 8);
  return m;
}

}  // namespace

std::pair<int, int> evaluation_grid(const Motion& motion, const Cutter& cutter, const EvaluateOptions& o) {
  int rows = o.rows, cols = o.cols;
  if (o.spacing > 0) {
    // Rows as if the axis moved everywhere as fast as at its fastest (its ends or its middle,
    // over 64 chords, 2% to spare: a chord under-reads the fastest speed within it): uniform
    // rows in t are then at most `spacing` apart everywhere.
    double fastest = 0.0;
    for (double s : {0.0, 0.5, 1.0}) {
      Vec3 prev = motion.point(0.0, s);
      for (int i = 1; i <= 64; ++i) {
        const Vec3 q = motion.point(i / 64.0, s);
        fastest = std::max(fastest, (q - prev).norm());
        prev = q;
      }
    }
    rows = std::max(rows, static_cast<int>(std::ceil(1.02 * 64.0 * fastest / o.spacing)) + 1);
    cols = std::max(cols, static_cast<int>(std::ceil(cutter.length / o.spacing)) + 1);
    // Within the budget, the two counts shrink in proportion.
    const double excess = static_cast<double>(rows) * cols / std::max(1, o.max_samples);
    if (excess > 1.0) {
      const double f = 1.0 / std::sqrt(excess);
      rows = std::max(o.rows, static_cast<int>(rows * f));
      cols = std::max(o.cols, static_cast<int>(cols * f));
    }
  }
  return {rows, cols};
}

namespace {
struct GridStats {
  double max_abs = 0.0, rms = 0.0, max_gouge = 0.0;
};
GridStats stats(const ErrorGrid& grid) {
  GridStats st;
  double sum_sq = 0.0;
  int count = 0;
  for (Eigen::Index k = 0; k < grid.error.size(); ++k) {
    if (!grid.untrusted.empty() && grid.untrusted[static_cast<std::size_t>(k)]) continue;
    st.max_gouge = std::max(st.max_gouge, -grid.sphere_error(k));  // the whole cutter, every s and t
    if (!grid.omega_interior[static_cast<std::size_t>(k)]) continue;
    const double e = grid.error(k);
    st.max_gouge = std::max(st.max_gouge, -e);
    st.max_abs = std::max(st.max_abs, std::abs(e));
    sum_sq += e * e;
    ++count;
  }
  st.rms = count ? std::sqrt(sum_sq / count) : 0.0;
  return st;
}
// Ω's signed deviation from Φ at (t, s), with Φ's side taken as at a nearby sample (`g`, the
// unit direction from Φ toward the sphere centre there); NaN where Ω has no point over Φ.
double omega_error_at(const SurfaceIndex& index, const Motion& motion, const Cutter& cutter, double t,
                      double s, const Vec3& g, int hint) {
  const Line l = motion.ruling(t);
  const Vec3 centre = l.point(s), rs = l.b - l.a;
  const Vec3 rt = (1 - s) * motion.a_at(t, 1) + s * motion.b_at(t, 1);
  const EnvelopePoint ep = envelope_point(centre, rt, rs, cutter.radius(s), cutter.slope(s), envelope_side(rt, rs, -g));
  if (!ep.valid) return std::numeric_limits<double>::quiet_NaN();
  const ClosestPoint cp = index.closest_point(ep.point, hint);
  if (cp.face < 0 || cp.boundary) return std::numeric_limits<double>::quiet_NaN();
  return cp.signed_distance;
}

// The largest |e| (signed) on 5 × 5 sub-grids of quarter-sample steps around each of the
// `count` samples of largest |e| (over Φ, on rows where the axis sweeps).
double refined_max(const SurfaceIndex& index, const Motion& motion, const Cutter& cutter, const ErrorGrid& grid,
                   int count) {
  // The `count` largest, the first of equals by sample: each block of samples' own, then
  // the largest of those. The order is total, so they are the ones one sort of all finds.
  using Ranked = std::pair<double, std::size_t>;
  const auto before = [](const Ranked& a, const Ranked& b) {
    return a.first > b.first || (a.first == b.first && a.second < b.second);
  };
  const auto largest = [&](std::vector<Ranked>& v) {
    const auto m = std::min<std::size_t>(v.size(), static_cast<std::size_t>(std::max(0, count)));
    std::partial_sort(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(m), v.end(), before);
    v.resize(m);
  };
  constexpr std::size_t kBlock = 8192;
  const std::size_t samples = grid.omega_interior.size();
  std::vector<std::vector<Ranked>> tops((samples + kBlock - 1) / kBlock);
  parallel_for(0, tops.size(), [&](std::size_t b0, std::size_t b1) {
    for (std::size_t b = b0; b < b1; ++b) {
      for (std::size_t k = b * kBlock; k < std::min(samples, (b + 1) * kBlock); ++k)
        if (grid.omega_interior[k] &&
            (grid.sweeps.empty() || grid.sweeps[k / static_cast<std::size_t>(grid.cols)]))
          tops[b].emplace_back(std::abs(grid.error(static_cast<Eigen::Index>(k))), k);
      largest(tops[b]);
    }
  }, 1);
  std::vector<Ranked> top;
  for (const std::vector<Ranked>& t : tops) top.insert(top.end(), t.begin(), t.end());
  largest(top);
  const std::size_t n = top.size();
  // Each sample's neighbourhood on its own (25 queries), then the largest in sample order,
  // the first of equals kept: the value one pass over them all finds.
  const double dt = 1.0 / (grid.rows - 1), ds = 1.0 / (grid.cols - 1);
  std::vector<double> near_best(n, 0.0);
  parallel_for(0, n, [&](std::size_t q0, std::size_t q1) {
    for (std::size_t q = q0; q < q1; ++q) {
      const std::size_t k = top[q].second;
      const auto cols = static_cast<std::size_t>(grid.cols);
      const int i = static_cast<int>(k / cols), j = static_cast<int>(k % cols);
      const Vec3 g = grid.directions.row(static_cast<Eigen::Index>(k)).transpose();
      double& best = near_best[q];
      for (int a = -2; a <= 2; ++a)
        for (int b = -2; b <= 2; ++b) {
          const double t = std::clamp((i + 0.25 * a) * dt, 0.0, 1.0);
          const double s = std::clamp((j + 0.25 * b) * ds, 0.0, 1.0);
          const double e = omega_error_at(index, motion, cutter, t, s, g, grid.faces[k]);
          if (std::isfinite(e) && std::abs(e) > std::abs(best)) best = e;
        }
    }
  }, 1);
  double best = 0.0;
  for (const double e : near_best)
    if (std::abs(e) > std::abs(best)) best = e;
  return best;
}

// cos 30°: how nearly along Φ's normal Ω's nearest point must lie for a vertex to be under Ω.
constexpr double kUnderCosine = 0.8660254037844386;

// Ω over a grid as one mesh (two triangles per cell whose corners all have an envelope point)
// and, made on first use, its index. The error seen from Φ's vertices and the coverage each
// look at a part of it (over Φ; within the band of Φ) through a face mask: one index instead
// of one per part, with the answers of each part's own index. Both look no farther than
// `reach` (a few tolerances), so the index is a grid of cells (QueryEngine::kCells): a box
// tree took longer to build than all its queries took to answer. Not on a fine Φ, where the
// final evaluation asks as many queries as Φ has vertices near Ω: SurfaceIndex::within_reach
// then searches a box tree (on the 1M-triangle cone at one thread, the finish's 8.5 s became
// 0.9 s).
class OmegaSurface {
 public:
  OmegaSurface(const ErrorGrid& grid, double reach) : mesh_(envelope_mesh(grid, nullptr)), reach_(reach) {}
  const Mesh& mesh() const { return index_ ? index_->mesh() : mesh_; }
  // Made on first use, for about `queries` queries (the first use's).
  const SurfaceIndex& index(std::size_t queries) {
    // The index keeps the mesh: a copy of Ω's (a few MB on a fine grid) was a serial pass.
    if (!index_)
      index_ = std::make_unique<SurfaceIndex>(SurfaceIndex::within_reach(std::move(mesh_), reach_, queries));
    return *index_;
  }
  // The faces whose three corners `keep` holds: the faces envelope_mesh(grid, &keep) has.
  std::vector<char> mask(const std::vector<char>& keep) const {
    const Faces& F = mesh().F;
    std::vector<char> m(static_cast<std::size_t>(F.rows()));
    parallel_for(0, m.size(), [&](std::size_t begin, std::size_t end) {
      for (std::size_t f = begin; f < end; ++f) {
        const auto i = static_cast<Eigen::Index>(f);
        m[f] = keep[static_cast<std::size_t>(F(i, 0))] && keep[static_cast<std::size_t>(F(i, 1))] &&
               keep[static_cast<std::size_t>(F(i, 2))];
      }
    }, 8192);
    return m;
  }

 private:
  Mesh mesh_;  // until the index takes it
  double reach_;
  std::unique_ptr<SurfaceIndex> index_;
};

// Φ's vertices inside the bounding box of Ω's faces (those `mask` marks) grown by `margin`
// (the only ones within `margin` of them), in increasing order. Empty when no face is marked.
// Both passes in blocks on every thread, combined in block order.
std::vector<int> vertices_near(const Mesh& phi, const Mesh& omega, const std::vector<char>& mask, double margin) {
  constexpr std::size_t kBlock = 8192;
  const auto nf = static_cast<std::size_t>(omega.F.rows());
  const std::size_t face_blocks = (nf + kBlock - 1) / kBlock;
  const Vec3 none = Vec3::Constant(std::numeric_limits<double>::infinity());
  std::vector<Vec3> block_lo(face_blocks, none), block_hi(face_blocks, -none);
  parallel_for(0, face_blocks, [&](std::size_t b0, std::size_t b1) {
    for (std::size_t b = b0; b < b1; ++b) {
      Vec3 lo = none, hi = -none;
      for (std::size_t f = b * kBlock; f < std::min(nf, (b + 1) * kBlock); ++f) {
        if (!mask[f]) continue;
        for (int c = 0; c < 3; ++c) {
          const Vec3 p = omega.V.row(omega.F(static_cast<Eigen::Index>(f), c)).transpose();
          lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
        }
      }
      block_lo[b] = lo, block_hi[b] = hi;
    }
  }, 1);
  Vec3 lo = none, hi = -none;
  for (std::size_t b = 0; b < face_blocks; ++b)
    lo = lo.cwiseMin(block_lo[b]), hi = hi.cwiseMax(block_hi[b]);
  std::vector<int> near;
  if (!(lo.array() <= hi.array()).all()) return near;  // no face marked
  lo.array() -= margin, hi.array() += margin;
  const auto nv = static_cast<std::size_t>(phi.vertex_count());
  std::vector<std::vector<int>> found((nv + kBlock - 1) / kBlock);
  parallel_for(0, found.size(), [&](std::size_t b0, std::size_t b1) {
    for (std::size_t b = b0; b < b1; ++b)
      for (std::size_t v = b * kBlock; v < std::min(nv, (b + 1) * kBlock); ++v) {
        const Vec3 p = phi.V.row(static_cast<Eigen::Index>(v)).transpose();
        if ((p.array() >= lo.array()).all() && (p.array() <= hi.array()).all())
          found[b].push_back(static_cast<int>(v));
      }
  }, 1);
  for (const std::vector<int>& f : found) near.insert(near.end(), f.begin(), f.end());
  return near;
}

}  // namespace

Patch evaluate_patch(const SurfaceIndex& index, const Motion& motion, const Cutter& cutter,
                     const EvaluateOptions& options, const SurfaceIndex* given, const ErrorGrid* known) {
  Patch patch;
  patch.motion = motion;
  patch.cutter = cutter;
  const auto [rows, cols] = evaluation_grid(motion, cutter, options);
  const bool reuse = known && known->rows == rows && known->cols == cols;
  ErrorGrid sampled;
  if (!reuse) sampled = sample_errors(index, motion, cutter, rows, cols, options.untrusted_edges);
  const ErrorGrid& grid = reuse ? *known : sampled;
  const GridStats judged = stats(grid);
  ErrorGrid given_grid;
  if (given) given_grid = sample_errors(*given, motion, cutter, rows, cols);
  const ErrorGrid& reported = given ? given_grid : grid;
  const GridStats st = given ? stats(given_grid) : judged;
  patch.error.max = st.max_abs;
  patch.error.rms = st.rms;
  patch.error.max_gouge = st.max_gouge;
  patch.error.judged_gouge = judged.max_gouge;
  patch.error.max_relative = st.max_abs / (given ? given : &index)->diagonal();
  if (options.refine_max > 0) {
    // The largest deviations are where the grid sampled them, give or take a sample: search a
    // finer grid around each of the largest, so that the figure does not depend on where the
    // samples fell (another sampling of the same Ω, as an independent check makes, finds more
    // between them otherwise).
    const double e = refined_max(given ? *given : index, motion, cutter, reported, options.refine_max);
    patch.error.max = std::max(patch.error.max, std::abs(e));
    if (e < 0) patch.error.max_gouge = std::max(patch.error.max_gouge, -e);
    patch.error.max_relative = patch.error.max / (given ? given : &index)->diagonal();
  }

  // The deviation seen from Φ's vertices under Ω as well: samples of Ω fall between the peaks
  // of a scanned Φ (its noise sits at the vertices), so its largest deviation depends on the
  // sampling; at the vertices it does not. tests/check_patches.py measures the same union.
  // Ω's mesh and index, one per grid: on a smoothed scan the reported grid is another one.
  std::optional<OmegaSurface> omega_grid, omega_reported;
  const auto omega_of = [&](const ErrorGrid& g) -> OmegaSurface& {
    std::optional<OmegaSurface>& o = &g == &grid ? omega_grid : omega_reported;
    if (!o) o.emplace(g, (options.vertex_side ? std::max(options.vertex_band, 1.0) : 1.0) * options.tolerance);
    return *o;
  };
  if (options.vertex_side) {
    // Over the part of Ω whose points lie over Φ, as the grid's errors.
    OmegaSurface& omega = omega_of(reported);
    const std::vector<char> over = omega.mask(reported.omega_interior);
    const SurfaceIndex* phi_index = given ? given : &index;
    const double band = options.vertex_band * options.tolerance;
    const std::vector<int> near = vertices_near(phi_index->mesh(), omega.mesh(), over, band);
    if (!near.empty()) {
      const Mesh& phi = phi_index->mesh();
      Points queries(static_cast<Eigen::Index>(near.size()), 3);
      for (std::size_t k = 0; k < near.size(); ++k) queries.row(static_cast<Eigen::Index>(k)) = phi.V.row(near[k]);
      const std::vector<ClosestPoint> cp = omega.index(near.size()).closest_points_within(queries, band, over);
      const Points normals = vertex_normals(phi);
      for (std::size_t k = 0; k < near.size(); ++k) {
        const ClosestPoint& f = cp[k];
        // At Ω's edges (the ends of the sweep and of the cutter) a vertex of Φ is not under Ω.
        if (f.face < 0 || f.on_boundary || f.distance > band) continue;
        // Under Ω: Ω's nearest point lies along Φ's normal (within 30°), not off to the side,
        // as it does for a vertex beyond the end of a sweep whose last rows bend.
        const double along =
            (f.point - Vec3(phi.V.row(near[k]).transpose())).dot(Vec3(normals.row(near[k]).transpose()));
        if (std::abs(along) < kUnderCosine * f.distance) continue;
        // Ω above Φ (on the tool side): material left; below: gouge.
        const double e = along >= 0 ? f.distance : -f.distance;
        patch.error.max = std::max(patch.error.max, std::abs(e));
        patch.error.max_gouge = std::max(patch.error.max_gouge, -e);
      }
      patch.error.max_relative = patch.error.max / phi_index->diagonal();
    }
  }
  // Without a smoothed copy the patch is judged on everything reported.
  if (!given) patch.error.judged_gouge = patch.error.max_gouge;

  if (options.holder) {
    // The holder: a cylinder of the given radius on the half-axis beyond the spindle end b.
    const int steps_t = rows, steps_h = 24;
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

  if (options.envelope) {
    const Mesh& omega = omega_of(grid).mesh();
    patch.envelope.V = omega.V;
    patch.envelope.F = omega.F;
    patch.envelope.rows = grid.rows;
    patch.envelope.cols = grid.cols;
    patch.envelope.error.resize(reported.error.size());
    for (Eigen::Index k = 0; k < reported.error.size(); ++k)
      patch.envelope.error(k) = reported.omega_interior[static_cast<std::size_t>(k)]
                                    ? reported.error(k)
                                    : std::numeric_limits<double>::quiet_NaN();
  }
  if (options.coverage) {
    // Covered: the Φ vertices whose nearest point on Ω is inside Ω, within tolerance, and on
    // a part of Ω that is itself within omega_band tolerances of Φ (or beyond Φ's edge).
    std::vector<char> good(reported.omega_valid.size());
    for (std::size_t k = 0; k < good.size(); ++k)
      good[k] = reported.omega_valid[k] &&
                (!reported.omega_interior[k] ||
                 std::abs(reported.error(static_cast<Eigen::Index>(k))) <= options.omega_band * options.tolerance);
    OmegaSurface& omega = omega_of(grid);
    const std::vector<char> cuts = omega.mask(good);
    // Only the Φ vertices near Ω can be covered: query those.
    const Mesh& phi = (given ? given : &index)->mesh();
    const std::vector<int> near = vertices_near(phi, omega.mesh(), cuts, options.tolerance);
    if (!near.empty()) {
      Points queries(static_cast<Eigen::Index>(near.size()), 3);
      for (std::size_t k = 0; k < near.size(); ++k) queries.row(static_cast<Eigen::Index>(k)) = phi.V.row(near[k]);
      const std::vector<ClosestPoint> cp = omega.index(near.size()).closest_points_within(queries, options.tolerance, cuts);
      const VecX area = vertex_areas(phi);
      double covered = 0.0;
      for (std::size_t k = 0; k < near.size(); ++k) {
        const ClosestPoint& f = cp[k];
        if (f.face >= 0 && !f.boundary && f.distance <= options.tolerance) {
          patch.covered_vertices.push_back(near[k]);
          covered += area(near[k]);
        }
      }
      patch.covered_area = covered;
      patch.coverage_fraction = covered / std::max(1e-300, area.sum());
    }
  }
  return patch;
}

}  // namespace flank
