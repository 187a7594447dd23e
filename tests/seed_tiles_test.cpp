// Seeds against analytic ground truth: a cylinder's principal curvatures are 0 along the
// axis and ∓1/R across, a sphere's ∓1/R everywhere, a plane's 0; the sampling is a
// spacing-cover equal to the plain O(#V · seeds) farthest-point loop.
#include "solver/seed_tiles.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <limits>
#include <numbers>
#include <tuple>

#include "kernels/parallel.h"

namespace flank {
namespace {

// (nu + 1) × (nv + 1) vertices at f(u, v), u, v ∈ [0, 1]; faces oriented like ∂u × ∂v, or
// the other way when `flip`.
Mesh grid_mesh(int nu, int nv, const std::function<Vec3(double, double)>& f, bool flip = false) {
  Mesh mesh;
  mesh.V.resize(static_cast<Eigen::Index>(nu + 1) * (nv + 1), 3);
  for (int i = 0; i <= nu; ++i)
    for (int j = 0; j <= nv; ++j)
      mesh.V.row(i * (nv + 1) + j) = f(double(i) / nu, double(j) / nv).transpose();
  mesh.F.resize(2 * static_cast<Eigen::Index>(nu) * nv, 3);
  Eigen::Index k = 0;
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const int a = i * (nv + 1) + j, b = a + nv + 1, c = b + 1, d = a + 1;
      if (flip) {
        mesh.F.row(k++) << a, c, b;
        mesh.F.row(k++) << a, d, c;
      } else {
        mesh.F.row(k++) << a, b, c;
        mesh.F.row(k++) << a, c, d;
      }
    }
  return mesh;
}

// A fixed pseudo-random value in [0, 1) per (i, salt): splitmix64, the same on every library.
double hash01(std::uint64_t i, std::uint64_t salt = 0) {
  std::uint64_t z = i * 0x9E3779B97F4A7C15ull + salt * 0xD1B54A32D192ED03ull + 0x632BE59BD9B4E5Bull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return double(z >> 11) * 0x1.0p-53;
}

// Moves every vertex by up to ±amount/2 in x and y.
void jitter(Mesh& mesh, double amount, std::uint64_t salt) {
  for (Eigen::Index v = 0; v < mesh.V.rows(); ++v) {
    mesh.V(v, 0) += amount * (hash01(std::uint64_t(v), salt) - 0.5);
    mesh.V(v, 1) += amount * (hash01(std::uint64_t(v), salt + 1) - 0.5);
  }
}

double distance(const Mesh& mesh, int a, int b) { return (mesh.V.row(a) - mesh.V.row(b)).norm(); }

// The definition, O(#V · seeds).
std::vector<int> reference_fps(const Mesh& mesh, const SeedOptions& options) {
  const int n = mesh.vertex_count();
  auto allowed = [&](int v) { return options.allowed.empty() || options.allowed[v]; };
  int first = -1;
  for (int v = 0; v < n; ++v) {
    if (!allowed(v)) continue;
    if (first < 0 || std::tie(mesh.V(v, 0), mesh.V(v, 1), mesh.V(v, 2)) <
                         std::tie(mesh.V(first, 0), mesh.V(first, 1), mesh.V(first, 2)))
      first = v;
  }
  std::vector<int> seeds;
  if (first < 0) return seeds;
  seeds.push_back(first);
  std::vector<double> d(n, std::numeric_limits<double>::infinity());
  while (static_cast<int>(seeds.size()) < options.max_seeds) {
    int far = -1;
    for (int v = 0; v < n; ++v) {
      if (!allowed(v)) continue;
      d[v] = std::min(d[v], distance(mesh, v, seeds.back()));
      if (far < 0 || d[v] > d[far]) far = v;
    }
    if (!(d[far] >= options.spacing)) break;
    seeds.push_back(far);
  }
  return seeds;
}

void expect_same(const std::vector<Seed>& a, const std::vector<Seed>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].vertex, b[i].vertex) << i;
    EXPECT_EQ(a[i].point, b[i].point) << i;
    EXPECT_EQ(a[i].normal, b[i].normal) << i;
    EXPECT_EQ(a[i].dir_min, b[i].dir_min) << i;
    EXPECT_EQ(a[i].dir_max, b[i].dir_max) << i;
    EXPECT_EQ(a[i].k_min, b[i].k_min) << i;
    EXPECT_EQ(a[i].k_max, b[i].k_max) << i;
  }
}

// Unit, orthogonal, right-handed (dir_min, dir_max, normal).
void expect_frame(const Seed& s) {
  EXPECT_NEAR(s.normal.norm(), 1.0, 1e-12);
  EXPECT_NEAR(s.dir_min.norm(), 1.0, 1e-12);
  EXPECT_NEAR(s.dir_max.norm(), 1.0, 1e-12);
  EXPECT_NEAR(s.dir_min.dot(s.normal), 0.0, 1e-12);
  EXPECT_NEAR(s.dir_max.dot(s.normal), 0.0, 1e-12);
  EXPECT_NEAR(s.dir_min.cross(s.dir_max).dot(s.normal), 1.0, 1e-12);
}

// A wavy, jittered sheet: curvature varies, nothing is on a lattice.
Mesh wavy_sheet(int n, std::uint64_t salt) {
  Mesh mesh = grid_mesh(n, n, [](double u, double v) {
    return Vec3(10 * u, 10 * v, 0.6 * std::sin(2.1 * u + 0.3) * std::cos(1.7 * v));
  });
  jitter(mesh, 0.3 * 10.0 / n, salt);
  return mesh;
}

TEST(SeedTiles, ValidateRejectsBadOptions) {
  SeedOptions o;
  EXPECT_FALSE(o.validate().empty());  // spacing defaults to 0
  o.spacing = -1;
  EXPECT_FALSE(o.validate().empty());
  o.spacing = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(o.validate().empty());
  o.spacing = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(o.validate().empty());
  o.spacing = 1;
  EXPECT_TRUE(o.validate().empty());
  o.max_seeds = 0;
  EXPECT_FALSE(o.validate().empty());
  o.max_seeds = 1;
  o.allowed = {0, 1, 2};
  EXPECT_FALSE(o.validate().empty());
  o.allowed = {0, 1, 1};
  EXPECT_TRUE(o.validate().empty());
}

TEST(SeedTiles, CylinderCurvatureAndAxis) {
  const double R = 20, L = 20;
  // Half cylinder about the z axis, 200 × 60 quads, normals outward (∂θ × ∂z).
  const Mesh mesh = grid_mesh(200, 60, [&](double u, double v) {
    const double t = std::numbers::pi * u;
    return Vec3(R * std::cos(t), R * std::sin(t), L * v);
  });
  SeedOptions o;
  o.spacing = 6;
  const std::vector<Seed> seeds = seed_tiles(mesh, o);
  ASSERT_GT(seeds.size(), 20u);
  const Vec3 axis = Vec3::UnitZ();
  double worst_along = 0, worst_across = 0, worst_dir = 1;
  for (const Seed& s : seeds) {
    expect_frame(s);
    const Vec3 radial = Vec3(s.point.x(), s.point.y(), 0).normalized();
    EXPECT_GT(s.normal.dot(radial), 0.9999) << s.vertex;
    // Outward normals: Φ bends away from them, so the curvature across is −1/R.
    EXPECT_LT(std::abs(s.k_min), 1e-3 / R) << s.vertex;
    EXPECT_NEAR(s.k_max, -1 / R, 0.02 / R) << s.vertex;
    EXPECT_GT(std::abs(s.dir_min.dot(axis)), 0.999) << s.vertex;
    worst_along = std::max(worst_along, std::abs(s.k_min) * R);
    worst_across = std::max(worst_across, std::abs(s.k_max * R + 1));
    worst_dir = std::min(worst_dir, std::abs(s.dir_min.dot(axis)));
  }
  std::printf(
      "[ cylinder ] %zu seeds: max |k_axis|·R %.2e, max |k_across·R + 1| %.2e, "
      "min |dir_min·axis| %.8f\n",
      seeds.size(), worst_along, worst_across, worst_dir);
}

TEST(SeedTiles, SpherePatchBothCurvatures) {
  const double R = 10;
  auto sphere = [&](double u, double v) {
    const double lon = -0.6 + 1.2 * u, lat = -0.6 + 1.2 * v;
    return Vec3(R * std::cos(lat) * std::cos(lon), R * std::cos(lat) * std::sin(lon),
                R * std::sin(lat));
  };
  for (bool flip : {false, true}) {
    // ∂lon × ∂lat points outward; flipped faces turn the normal inward, toward which the
    // sphere bends: the sign of both curvatures follows.
    const Mesh mesh = grid_mesh(120, 120, sphere, flip);
    SeedOptions o;
    o.spacing = 2;
    const std::vector<Seed> seeds = seed_tiles(mesh, o);
    ASSERT_GT(seeds.size(), 10u);
    const double k = flip ? 1 / R : -1 / R;
    double worst = 0;
    for (const Seed& s : seeds) {
      expect_frame(s);
      EXPECT_GT(s.normal.dot(s.point.normalized()) * (flip ? -1 : 1), 0.9999) << s.vertex;
      EXPECT_NEAR(s.k_min, k, 0.02 / R) << s.vertex;
      EXPECT_NEAR(s.k_max, k, 0.02 / R) << s.vertex;
      worst = std::max({worst, std::abs(s.k_min / k - 1), std::abs(s.k_max / k - 1)});
    }
    std::printf("[ sphere ] %s normals, %zu seeds: max |k·R ∓ 1| %.2e\n",
                flip ? "inward" : "outward", seeds.size(), worst);
  }
}

TEST(SeedTiles, PlaneIsASpacingCover) {
  Mesh mesh = grid_mesh(80, 50, [](double u, double v) { return Vec3(8 * u, 5 * v, 1.5); });
  jitter(mesh, 0.03, 7);
  SeedOptions o;
  o.spacing = 0.7;
  const std::vector<Seed> seeds = seed_tiles(mesh, o);
  ASSERT_GT(seeds.size(), 30u);
  for (const Seed& s : seeds) {
    expect_frame(s);
    EXPECT_NEAR(s.normal.z(), 1.0, 1e-12);
    EXPECT_NEAR(s.k_min, 0.0, 1e-9);
    EXPECT_NEAR(s.k_max, 0.0, 1e-9);
  }
  for (std::size_t i = 0; i < seeds.size(); ++i)
    for (std::size_t j = i + 1; j < seeds.size(); ++j)
      EXPECT_GE(distance(mesh, seeds[i].vertex, seeds[j].vertex), o.spacing) << i << " " << j;
  for (int v = 0; v < mesh.vertex_count(); ++v) {
    double nearest = std::numeric_limits<double>::infinity();
    for (const Seed& s : seeds) nearest = std::min(nearest, distance(mesh, v, s.vertex));
    EXPECT_LT(nearest, o.spacing) << v;
  }
  // The first seed is the lexicographically smallest vertex: the corner (0, 0) moved by jitter
  // is not necessarily it, so compare with the definition.
  EXPECT_EQ(seeds.front().vertex, reference_fps(mesh, o).front());
}

TEST(SeedTiles, EqualsTheDefinition) {
  const Mesh mesh = wavy_sheet(70, 3);
  for (double spacing : {0.4, 1.3, 4.0}) {
    SeedOptions o;
    o.spacing = spacing;
    std::vector<int> got;
    for (const Seed& s : seed_tiles(mesh, o)) got.push_back(s.vertex);
    EXPECT_EQ(got, reference_fps(mesh, o)) << spacing;
    const std::size_t all = got.size();
    o.max_seeds = 7;
    got.clear();
    for (const Seed& s : seed_tiles(mesh, o)) got.push_back(s.vertex);
    EXPECT_EQ(got.size(), std::min<std::size_t>(all, 7));
    EXPECT_EQ(got, reference_fps(mesh, o)) << spacing;
  }
}

TEST(SeedTiles, MaskKeepsSeedsOnAllowedVertices) {
  const Mesh mesh = wavy_sheet(60, 11);
  SeedOptions o;
  o.spacing = 0.8;
  o.allowed.assign(static_cast<std::size_t>(mesh.vertex_count()), 0);
  for (int v = 0; v < mesh.vertex_count(); ++v)
    // A disc and a sprinkling elsewhere: re-seeding leaves ragged regions.
    o.allowed[v] = (mesh.V.row(v).head<2>() - Eigen::RowVector2d(6, 4)).norm() < 2.5 ||
                   hash01(std::uint64_t(v), 99) < 0.02;
  const std::vector<Seed> seeds = seed_tiles(mesh, o);
  ASSERT_FALSE(seeds.empty());
  for (const Seed& s : seeds) EXPECT_TRUE(o.allowed[s.vertex]) << s.vertex;
  for (int v = 0; v < mesh.vertex_count(); ++v) {
    if (!o.allowed[v]) continue;
    double nearest = std::numeric_limits<double>::infinity();
    for (const Seed& s : seeds) nearest = std::min(nearest, distance(mesh, v, s.vertex));
    EXPECT_LT(nearest, o.spacing) << v;
  }
  std::vector<int> got;
  for (const Seed& s : seeds) got.push_back(s.vertex);
  EXPECT_EQ(got, reference_fps(mesh, o));

  o.allowed.assign(o.allowed.size(), 0);
  EXPECT_TRUE(seed_tiles(mesh, o).empty());
}

TEST(SeedTiles, TooFewNeighboursGiveAnArbitraryFrame) {
  Mesh mesh;
  mesh.V.resize(4, 3);
  mesh.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0.2;
  mesh.F.resize(2, 3);
  mesh.F << 0, 1, 3, 0, 3, 2;
  SeedOptions o;
  o.spacing = 0.5;
  const std::vector<Seed> seeds = seed_tiles(mesh, o);
  ASSERT_EQ(seeds.size(), 4u);
  EXPECT_EQ(seeds.front().vertex, 0);
  for (const Seed& s : seeds) {
    expect_frame(s);
    EXPECT_EQ(s.k_min, 0.0);
    EXPECT_EQ(s.k_max, 0.0);
  }
}

TEST(SeedTiles, DeterministicAcrossCallsAndThreads) {
  const Mesh mesh = wavy_sheet(300, 5);
  SeedOptions o;
  o.spacing = 0.9;
  const std::vector<Seed> a = seed_tiles(mesh, o);
  ASSERT_GT(a.size(), 50u);
  expect_same(a, seed_tiles(mesh, o));
  std::vector<Seed> one;
  {
    const ThreadLimit limit(1);
    one = seed_tiles(mesh, o);
  }
  expect_same(a, one);
}

// A tiler kept over calls (as a decomposition's rounds call it: the whole sheet, then what a
// mask leaves, at half the spacing, then the first spacing again) gives what a fresh
// seed_tiles gives for each call.
TEST(SeedTiles, TilerKeptOverCallsGivesTheSameSeeds) {
  const Mesh mesh = wavy_sheet(120, 8);
  SeedTiler tiler(mesh);
  SeedOptions whole;
  whole.spacing = 2.0;
  SeedOptions masked;
  masked.spacing = 1.0;
  masked.allowed.assign(static_cast<std::size_t>(mesh.vertex_count()), 0);
  for (int v = 0; v < mesh.vertex_count(); ++v) masked.allowed[static_cast<std::size_t>(v)] = mesh.V(v, 0) > 5.0;
  SeedOptions fine;
  fine.spacing = 0.3;
  for (const SeedOptions* o : {&whole, &masked, &fine, &whole, &masked}) {
    const std::vector<Seed> kept = tiler(*o);
    ASSERT_FALSE(kept.empty());
    expect_same(kept, seed_tiles(mesh, *o));
  }
}

// Not asserted: the time for a 1M-vertex sheet at ~200 seeds.
TEST(SeedTiles, TimingOneMillionVertices) {
  const Mesh mesh = grid_mesh(999, 999, [](double u, double v) {
    return Vec3(100 * u, 141 * v, 3 * std::sin(5 * u) * std::cos(5.6 * v));
  });
  SeedOptions o;
  o.spacing = 7;
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<Seed> seeds = seed_tiles(mesh, o);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("[ timing ] %d vertices, %zu seeds, %d threads: %.3f s\n", mesh.vertex_count(),
              seeds.size(), max_threads(), s);
  EXPECT_FALSE(seeds.empty());
}

}  // namespace
}  // namespace flank
