#include "solver/seed_tiles.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <tuple>
#include <utility>

#include "kernels/parallel.h"

namespace flank {

std::string SeedOptions::validate() const {
  // isfinite first: an ordered comparison with NaN would trap in Debug builds.
  if (!std::isfinite(spacing) || spacing <= 0.0) return "seed spacing must be positive";
  if (max_seeds < 1) return "max seeds must be at least 1";
  for (char a : allowed)
    if (a != 0 && a != 1) return "the seed mask must hold only 0 and 1";
  return {};
}

namespace {

// The squared distance of every comparison in this file, always in this one order of
// operations, so that a box bound and a point distance round alike.
inline double dist2(double ax, double ay, double az, double bx, double by, double bz) {
  const double dx = ax - bx, dy = ay - by, dz = az - bz;
  return dx * dx + dy * dy + dz * dz;
}

}  // namespace

// What SeedTiler keeps over its calls: in a named namespace, not an anonymous one, as its Impl
// (a member of a class with linkage) holds them.
namespace seed_tiling {

struct MeshScale {
  double mean_edge = 0.0;
  double area = 0.0;
};

// Mean edge length (each face's three edges; interior edges count twice) and total area.
// Partial sums over fixed blocks of faces, added in block order: thread-count independent.
MeshScale mesh_scale(const Mesh& mesh) {
  constexpr std::size_t kBlock = 1 << 14;
  const std::size_t faces = static_cast<std::size_t>(mesh.face_count());
  const std::size_t blocks = (faces + kBlock - 1) / kBlock;
  std::vector<double> edge(blocks, 0.0), area(blocks, 0.0);
  parallel_for(
      0, blocks,
      [&](std::size_t b0, std::size_t b1) {
        for (std::size_t b = b0; b < b1; ++b) {
          double e = 0.0, a = 0.0;
          for (std::size_t f = b * kBlock; f < std::min(faces, (b + 1) * kBlock); ++f) {
            const auto i = static_cast<Eigen::Index>(f);
            const Vec3 p0 = mesh.V.row(mesh.F(i, 0)), p1 = mesh.V.row(mesh.F(i, 1)),
                       p2 = mesh.V.row(mesh.F(i, 2));
            e += (p1 - p0).norm() + (p2 - p1).norm() + (p0 - p2).norm();
            a += 0.5 * (p1 - p0).cross(p2 - p0).norm();
          }
          edge[b] = e, area[b] = a;
        }
      },
      1);
  MeshScale s;
  for (std::size_t b = 0; b < blocks; ++b) s.mean_edge += edge[b], s.area += area[b];
  if (faces > 0) s.mean_edge /= 3.0 * static_cast<double>(faces);
  return s;
}

// Φ's vertices bucketed in a dense uniform grid (counting sort: within a cell, vertices keep
// increasing index order). The cell count is capped near #V by growing the cell.
class VertexGrid {
 public:
  VertexGrid(const Points& V, double cell) {
    const Eigen::Index n = V.rows();
    origin_ = V.colwise().minCoeff().transpose();
    const Vec3 extent = V.colwise().maxCoeff().transpose() - origin_;
    const double cap = 2.0 * static_cast<double>(n) + 1024.0;
    auto cells_for = [&](double c) {
      return (extent.x() / c + 1) * (extent.y() / c + 1) * (extent.z() / c + 1);
    };
    while (cells_for(cell) > cap) cell *= 1.25;
    h_ = cell;
    for (int k = 0; k < 3; ++k) dims_[k] = static_cast<int>(extent[k] / h_) + 1;
    const std::size_t total = static_cast<std::size_t>(dims_[0]) * dims_[1] * dims_[2];

    std::vector<int> cell_of(static_cast<std::size_t>(n));
    parallel_for(
        0, cell_of.size(),
        [&](std::size_t i0, std::size_t i1) {
          for (std::size_t i = i0; i < i1; ++i) {
            const auto v = static_cast<Eigen::Index>(i);
            cell_of[i] = flat(coord(V(v, 0), 0), coord(V(v, 1), 1), coord(V(v, 2), 2));
          }
        },
        4096);
    start_.assign(total + 1, 0);
    for (int c : cell_of) ++start_[static_cast<std::size_t>(c) + 1];
    for (std::size_t c = 0; c < total; ++c) start_[c + 1] += start_[c];
    order_.resize(cell_of.size());
    std::vector<int> fill(start_.begin(), start_.end() - 1);
    for (std::size_t i = 0; i < cell_of.size(); ++i)
      order_[static_cast<std::size_t>(fill[static_cast<std::size_t>(cell_of[i])]++)] =
          static_cast<int>(i);
    for (std::size_t c = 0; c < total; ++c)
      if (start_[c + 1] > start_[c]) occupied_.push_back(static_cast<int>(c));
  }

  // Non-empty cells in increasing order, and the vertices of one of them.
  const std::vector<int>& occupied() const { return occupied_; }
  int begin(int cell) const { return start_[static_cast<std::size_t>(cell)]; }
  int end(int cell) const { return start_[static_cast<std::size_t>(cell) + 1]; }
  int vertex(int slot) const { return order_[static_cast<std::size_t>(slot)]; }

  // Calls f(v) for every vertex whose cell meets the box of radius r about p (a superset of
  // the ball; the caller tests the distance), in a fixed order.
  template <class F>
  void for_each_near(const Vec3& p, double r, F&& f) const {
    int lo[3], hi[3];
    for (int k = 0; k < 3; ++k) lo[k] = coord(p[k] - r, k), hi[k] = coord(p[k] + r, k);
    for (int z = lo[2]; z <= hi[2]; ++z)
      for (int y = lo[1]; y <= hi[1]; ++y)
        for (int x = lo[0]; x <= hi[0]; ++x) {
          const int c = flat(x, y, z);
          for (int s = begin(c); s < end(c); ++s) f(vertex(s));
        }
  }

 private:
  int coord(double value, int axis) const {
    const double u = std::floor((value - origin_[axis]) / h_);
    if (!(u > 0)) return 0;
    return u >= dims_[axis] - 1 ? dims_[axis] - 1 : static_cast<int>(u);
  }
  int flat(int x, int y, int z) const { return (z * dims_[1] + y) * dims_[0] + x; }

  Vec3 origin_;
  double h_ = 1.0;
  int dims_[3] = {1, 1, 1};
  std::vector<int> start_;  // per dense cell, into order_
  std::vector<int> order_;  // vertex indices by cell
  std::vector<int> occupied_;
};

}  // namespace seed_tiling

namespace {

using seed_tiling::MeshScale;
using seed_tiling::VertexGrid;

// Farthest-point sampling with per-cell pruning: a cell is revisited only when the new seed
// is nearer to its bounding box than the cell's current farthest vertex, which cannot change
// any distance, so the result is that of the plain O(#V · seeds) loop. Distances are exact
// per vertex and the argmax is a serial scan: no dependence on the thread count.
std::vector<int> farthest_points(const Mesh& mesh, const VertexGrid& grid,
                                 const SeedOptions& options) {
  const bool masked = !options.allowed.empty();
  struct Cell {
    int begin = 0, end = 0;  // slots of allowed vertices
    double lo[3], hi[3];     // bounding box of those vertices
    double max_d2 = std::numeric_limits<double>::infinity();
    int arg = -1;  // lowest-index vertex at max_d2
  };
  std::vector<Cell> cells;
  std::vector<double> x, y, z, d2;
  std::vector<int> id;
  for (int c : grid.occupied()) {
    Cell cell;
    cell.begin = static_cast<int>(id.size());
    for (int s = grid.begin(c); s < grid.end(c); ++s) {
      const int v = grid.vertex(s);
      if (masked && !options.allowed[static_cast<std::size_t>(v)]) continue;
      id.push_back(v);
      x.push_back(mesh.V(v, 0)), y.push_back(mesh.V(v, 1)), z.push_back(mesh.V(v, 2));
    }
    cell.end = static_cast<int>(id.size());
    if (cell.end == cell.begin) continue;
    for (int k = 0; k < 3; ++k)
      cell.lo[k] = std::numeric_limits<double>::infinity(), cell.hi[k] = -cell.lo[k];
    for (int s = cell.begin; s < cell.end; ++s) {
      const double q[3] = {x[s], y[s], z[s]};
      for (int k = 0; k < 3; ++k)
        cell.lo[k] = std::min(cell.lo[k], q[k]), cell.hi[k] = std::max(cell.hi[k], q[k]);
    }
    cell.arg = id[static_cast<std::size_t>(cell.begin)];
    cells.push_back(cell);
  }
  std::vector<int> seeds;
  if (id.empty()) return seeds;
  d2.assign(id.size(), std::numeric_limits<double>::infinity());

  // First seed: smallest (x, y, z), then smallest index.
  int first = 0;
  for (std::size_t s = 1; s < id.size(); ++s) {
    const auto f = static_cast<std::size_t>(first);
    const bool less = std::tie(x[s], y[s], z[s], id[s]) < std::tie(x[f], y[f], z[f], id[f]);
    if (less) first = static_cast<int>(s);
  }
  seeds.push_back(id[static_cast<std::size_t>(first)]);

  const std::size_t mean_cell = std::max<std::size_t>(1, id.size() / cells.size());
  const std::size_t grain = std::max<std::size_t>(1, 8192 / mean_cell);
  std::vector<int> touched;
  while (static_cast<int>(seeds.size()) < options.max_seeds) {
    const double px = mesh.V(seeds.back(), 0), py = mesh.V(seeds.back(), 1),
                 pz = mesh.V(seeds.back(), 2);
    touched.clear();
    for (std::size_t c = 0; c < cells.size(); ++c) {
      const Cell& cell = cells[c];
      const double bx = std::clamp(px, cell.lo[0], cell.hi[0]);
      const double by = std::clamp(py, cell.lo[1], cell.hi[1]);
      const double bz = std::clamp(pz, cell.lo[2], cell.hi[2]);
      // The margin keeps the bound a bound whatever the rounding.
      if (dist2(px, py, pz, bx, by, bz) * (1.0 - 1e-12) >= cell.max_d2) continue;
      touched.push_back(static_cast<int>(c));
    }
    parallel_for(
        0, touched.size(),
        [&](std::size_t t0, std::size_t t1) {
          for (std::size_t t = t0; t < t1; ++t) {
            Cell& cell = cells[static_cast<std::size_t>(touched[t])];
            // Three simple loops (update, max, first at max) that the compiler can vectorise.
            double best = -1.0;
            for (int s = cell.begin; s < cell.end; ++s)
              d2[s] = std::min(d2[s], dist2(x[s], y[s], z[s], px, py, pz));
            for (int s = cell.begin; s < cell.end; ++s) best = std::max(best, d2[s]);
            int s = cell.begin;
            while (d2[s] != best) ++s;
            cell.max_d2 = best, cell.arg = id[s];
          }
        },
        grain);
    const Cell* far = &cells.front();
    for (const Cell& cell : cells)
      if (cell.max_d2 > far->max_d2 || (cell.max_d2 == far->max_d2 && cell.arg < far->arg))
        far = &cell;
    if (!(std::sqrt(far->max_d2) >= options.spacing)) break;
    seeds.push_back(far->arg);
  }
  return seeds;
}

// Area-weighted vertex normals of the seeds: the sum of the incident faces' cross products
// (each |·| = 2 × area), in face order.
std::vector<Vec3> seed_normals(const Mesh& mesh, const std::vector<int>& seeds) {
  std::vector<int> slot(static_cast<std::size_t>(mesh.vertex_count()), -1);
  for (std::size_t i = 0; i < seeds.size(); ++i)
    slot[static_cast<std::size_t>(seeds[i])] = static_cast<int>(i);
  std::vector<Vec3> sum(seeds.size(), Vec3::Zero());
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    const int s0 = slot[static_cast<std::size_t>(mesh.F(f, 0))];
    const int s1 = slot[static_cast<std::size_t>(mesh.F(f, 1))];
    const int s2 = slot[static_cast<std::size_t>(mesh.F(f, 2))];
    if (s0 < 0 && s1 < 0 && s2 < 0) continue;
    const Vec3 p0 = mesh.V.row(mesh.F(f, 0));
    const Vec3 n = (Vec3(mesh.V.row(mesh.F(f, 1))) - p0).cross(Vec3(mesh.V.row(mesh.F(f, 2))) - p0);
    for (int s : {s0, s1, s2})
      if (s >= 0) sum[static_cast<std::size_t>(s)] += n;
  }
  for (Vec3& n : sum) {
    const double len = n.norm();
    n = len > 0 ? Vec3(n / len) : Vec3::UnitZ();
  }
  return sum;
}

// Some unit vector orthogonal to n: n's smallest component's axis, made orthogonal.
Vec3 any_tangent(const Vec3& n) {
  int axis = 0;
  for (int k = 1; k < 3; ++k)
    if (std::abs(n[k]) < std::abs(n[axis])) axis = k;
  return (Vec3::Unit(axis) - n[axis] * n).normalized();
}

// Principal curvatures and directions from the least-squares height field over the ball
// of `radius` about the seed; x, y are scaled by the radius to keep the 5 × 5 system sane.
void fit_curvature(const Mesh& mesh, const VertexGrid& grid, double radius, Seed& seed) {
  const Vec3& n = seed.normal;
  const Vec3 t1 = any_tangent(n), t2 = n.cross(t1);
  seed.dir_min = t1, seed.dir_max = n.cross(t1), seed.k_min = seed.k_max = 0.0;

  using Vec5 = Eigen::Matrix<double, 5, 1>;
  Eigen::Matrix<double, 5, 5> normal_matrix = Eigen::Matrix<double, 5, 5>::Zero();
  Vec5 rhs = Vec5::Zero();
  int count = 0;
  const double r2 = radius * radius;
  const Vec3 p = seed.point;
  grid.for_each_near(p, radius, [&](int v) {
    if (v == seed.vertex) return;
    const double vx = mesh.V(v, 0), vy = mesh.V(v, 1), vz = mesh.V(v, 2);
    if (dist2(vx, vy, vz, p.x(), p.y(), p.z()) > r2) return;
    const Vec3 d(vx - p.x(), vy - p.y(), vz - p.z());
    const double u = d.dot(t1) / radius, w = d.dot(t2) / radius, h = d.dot(n);
    const Vec5 phi(u * u, u * w, w * w, u, w);
    normal_matrix.selfadjointView<Eigen::Lower>().rankUpdate(phi);
    rhs += h * phi;
    ++count;
  });
  if (count < 6) return;
  const Eigen::LDLT<Eigen::Matrix<double, 5, 5>, Eigen::Lower> ldlt(normal_matrix);
  // Collinear or otherwise degenerate neighbourhoods leave the quadric undetermined.
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive() || !(ldlt.rcond() > 1e-10)) return;
  const Vec5 coef = ldlt.solve(rhs);
  const double a = coef(0) / r2, b = coef(1) / r2, c = coef(2) / r2;
  Eigen::Matrix2d shape;
  shape << 2 * a, b, b, 2 * c;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(shape);
  const Eigen::Vector2d k = eigen.eigenvalues();
  const int i_min = std::abs(k(0)) <= std::abs(k(1)) ? 0 : 1;
  const Eigen::Vector2d e = eigen.eigenvectors().col(i_min);
  Vec3 dir = (e(0) * t1 + e(1) * t2).normalized();
  // A fixed sign: the largest component positive.
  Eigen::Index big = 0;
  dir.cwiseAbs().maxCoeff(&big);
  if (dir(big) < 0) dir = -dir;
  seed.dir_min = dir;
  seed.dir_max = n.cross(dir);
  seed.k_min = k(i_min);
  seed.k_max = k(1 - i_min);
}

}  // namespace

struct SeedTiler::Impl {
  explicit Impl(const Mesh& m) : mesh(m), scale(seed_tiling::mesh_scale(m)) {}

  const Mesh& mesh;
  const seed_tiling::MeshScale scale;
  std::vector<std::pair<double, std::unique_ptr<seed_tiling::VertexGrid>>> grids;  // by cell size

  const seed_tiling::VertexGrid& grid(double cell) {
    for (const auto& [size, g] : grids)
      if (size == cell) return *g;
    grids.emplace_back(cell, std::make_unique<seed_tiling::VertexGrid>(mesh.V, cell));
    return *grids.back().second;
  }
};

SeedTiler::SeedTiler(const Mesh& mesh) : impl_(std::make_unique<Impl>(mesh)) {}
SeedTiler::~SeedTiler() = default;

std::vector<Seed> SeedTiler::operator()(const SeedOptions& options) {
  const Mesh& mesh = impl_->mesh;
  assert(options.validate().empty());
  assert(options.allowed.empty() ||
         options.allowed.size() == static_cast<std::size_t>(mesh.vertex_count()));
  if (!options.validate().empty() || mesh.vertex_count() == 0) return {};
  if (!options.allowed.empty() &&
      options.allowed.size() != static_cast<std::size_t>(mesh.vertex_count()))
    return {};

  const seed_tiling::MeshScale& scale = impl_->scale;
  // Cells of about √#V vertices balance the per-seed scan over cells against the vertices
  // of the cells a seed touches; never much below the spacing, the scale of the late seeds.
  const double density_cell =
      std::sqrt(scale.area / std::sqrt(static_cast<double>(mesh.vertex_count())));
  const seed_tiling::VertexGrid& grid = impl_->grid(std::max(options.spacing / 2, density_cell));

  const std::vector<int> chosen = farthest_points(mesh, grid, options);
  const std::vector<Vec3> normals = seed_normals(mesh, chosen);
  std::vector<Seed> seeds(chosen.size());
  const double radius = std::max(options.spacing / 4, 3 * scale.mean_edge);
  parallel_for(
      0, seeds.size(),
      [&](std::size_t i0, std::size_t i1) {
        for (std::size_t i = i0; i < i1; ++i) {
          Seed& seed = seeds[i];
          seed.vertex = chosen[i];
          seed.point = mesh.V.row(seed.vertex).transpose();
          seed.normal = normals[i];
          fit_curvature(mesh, grid, radius, seed);
        }
      },
      4);
  return seeds;
}

std::vector<Seed> seed_tiles(const Mesh& mesh, const SeedOptions& options) {
  return SeedTiler(mesh)(options);
}

}  // namespace flank
