#include "kernels/surface_index.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "kernels/parallel.h"

namespace flank {
namespace {

// nx × ny grid cells over [0, sx] × [0, sy], two triangles per cell, counter-clockwise seen
// from +z; `jitter` moves interior vertices in the plane (a fraction of the spacing).
template <class Height>
Mesh make_grid(int nx, int ny, double sx, double sy, Height height, double jitter = 0.0,
               unsigned seed = 1) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Mesh m;
  m.V.resize((nx + 1) * (ny + 1), 3);
  const double hx = sx / nx, hy = sy / ny;
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) {
      double x = i * hx, y = j * hy;
      if (jitter > 0 && i > 0 && i < nx && j > 0 && j < ny) {
        x += jitter * hx * u(rng);
        y += jitter * hy * u(rng);
      }
      m.V.row(j * (nx + 1) + i) << x, y, height(x, y);
    }
  m.F.resize(2 * nx * ny, 3);
  int f = 0;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const int v00 = j * (nx + 1) + i, v10 = v00 + 1, v01 = v00 + nx + 1, v11 = v01 + 1;
      m.F.row(f++) << v00, v10, v11;
      m.F.row(f++) << v00, v11, v01;
    }
  return m;
}

Mesh flat_square(int n, double size) {
  return make_grid(n, n, size, size, [](double, double) { return 0.0; });
}

Mesh perturbed_grid(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Mesh m = make_grid(
      39, 39, 10.0, 10.0, [](double x, double y) { return 0.8 * std::sin(x) * std::cos(0.7 * y); },
      0.3, seed);
  for (Eigen::Index v = 0; v < m.V.rows(); ++v) m.V(v, 2) += 0.05 * u(rng);
  return m;
}

Mesh triangle_soup(int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Mesh m;
  m.V.resize(3 * count, 3);
  m.F.resize(count, 3);
  for (int f = 0; f < count; ++f) {
    const Vec3 centre(u01(rng), u01(rng), u01(rng));
    const double size = 0.02 + 0.15 * u01(rng);
    for (int k = 0; k < 3; ++k) {
      m.V.row(3 * f + k) = (centre + size * Vec3(u(rng), u(rng), u(rng))).transpose();
      m.F(f, k) = 3 * f + k;
    }
  }
  return m;
}

// Brute force is slow in unoptimised (sanitizer) builds; Release runs the full counts.
#ifdef NDEBUG
constexpr int kQueryScale = 4;
#else
constexpr int kQueryScale = 1;
#endif

struct BruteForce {
  int face = -1;
  double d2 = std::numeric_limits<double>::infinity();
  Vec3 point = Vec3::Zero();
};

struct Corners {
  Vec3 a, b, c;
};

std::vector<Corners> corners(const Mesh& m) {
  std::vector<Corners> out;
  for (int f = 0; f < m.face_count(); ++f)
    out.push_back({m.V.row(m.F(f, 0)), m.V.row(m.F(f, 1)), m.V.row(m.F(f, 2))});
  return out;
}

// The lexicographic minimum of (distance², face) over all faces.
BruteForce brute_force(const std::vector<Corners>& triangles, const Vec3& p) {
  BruteForce best;
  for (std::size_t f = 0; f < triangles.size(); ++f) {
    const Corners& t = triangles[f];
    const Vec3 q = closest_point_on_triangle(p, t.a, t.b, t.c);
    const double d2 = (p - q).squaredNorm();
    if (d2 < best.d2) best = {static_cast<int>(f), d2, q};
  }
  return best;
}

// Random points around the mesh plus points within 1e-7 of random surface points (many
// triangles at nearly equal distance: the hard case for a float BVH).
Points make_queries(const Mesh& m, int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> face(0, m.face_count() - 1);
  const BoundingBox box = bounding_box(m);
  const Vec3 lo = box.min - 0.2 * Vec3::Constant(box.diagonal());
  const Vec3 hi = box.max + 0.2 * Vec3::Constant(box.diagonal());
  Points Q(count, 3);
  for (int i = 0; i < count; ++i) {
    Vec3 p;
    if (i % 4 == 3) {
      const int f = face(rng);
      double a = u01(rng), b = u01(rng);
      if (a + b > 1) a = 1 - a, b = 1 - b;
      const Vec3 v0 = m.V.row(m.F(f, 0)), v1 = m.V.row(m.F(f, 1)), v2 = m.V.row(m.F(f, 2));
      p = v0 + a * (v1 - v0) + b * (v2 - v0) + 1e-7 * Vec3(u(rng), u(rng), u(rng));
    } else {
      for (int k = 0; k < 3; ++k) p[k] = lo[k] + (hi[k] - lo[k]) * u01(rng);
    }
    Q.row(i) = p.transpose();
  }
  return Q;
}

void expect_same(const ClosestPoint& a, const ClosestPoint& b) {
  EXPECT_EQ(a.face, b.face);
  EXPECT_EQ(a.distance, b.distance);
  EXPECT_EQ(a.signed_distance, b.signed_distance);
  EXPECT_EQ(a.point, b.point);
  EXPECT_EQ(a.direction, b.direction);
  EXPECT_EQ(a.boundary, b.boundary);
  EXPECT_EQ(a.on_boundary, b.on_boundary);
}

// Brute force agreement, with no hint, random hints and the true face as hint.
void check_against_brute_force(const Mesh& m, const Points& Q, unsigned seed,
                               QueryEngine engine) {
  SCOPED_TRACE(engine == QueryEngine::kEmbree ? "Embree" : "box tree");
  const SurfaceIndex index(m, engine);
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> face(0, m.face_count() - 1);
  const double scale = index.diagonal();
  const std::vector<Corners> triangles = corners(m);
  int mismatches = 0;
  for (Eigen::Index i = 0; i < Q.rows(); ++i) {
    const Vec3 p = Q.row(i);
    const BruteForce bf = brute_force(triangles, p);
    const double d = std::sqrt(bf.d2);
    const ClosestPoint cp = index.closest_point(p);
    EXPECT_EQ(cp.face, bf.face) << "query " << i;
    EXPECT_NEAR(cp.distance, d, 1e-12 * d + 1e-300) << "query " << i;
    EXPECT_LE((cp.point - bf.point).norm(), 1e-12 * scale) << "query " << i;
    EXPECT_NEAR(std::abs(cp.signed_distance), cp.distance, 0.0);
    EXPECT_NEAR(cp.direction.norm(), 1.0, 1e-15);
    // Below ~1e-14 of the coordinates' magnitude p − p⊥ is rounding noise and g is the normal.
    if (cp.distance > 1e-13 * (scale + p.cwiseAbs().maxCoeff())) {
      EXPECT_LE((cp.direction - (p - cp.point) / cp.distance).norm(), 1e-12);
      const double side = (p - cp.point).dot(index.normals().row(cp.face));
      EXPECT_EQ(cp.signed_distance < 0, side < 0) << "query " << i;
    }
    const ClosestPoint random_hint = index.closest_point(p, face(rng));
    const ClosestPoint true_hint = index.closest_point(p, bf.face);
    if (random_hint.face != cp.face || true_hint.face != cp.face) ++mismatches;
    expect_same(random_hint, cp);
    expect_same(true_hint, cp);
  }
  EXPECT_EQ(mismatches, 0);
}

void check_against_brute_force(const Mesh& m, const Points& Q, unsigned seed) {
  for (const QueryEngine engine : {QueryEngine::kBoxTree, QueryEngine::kEmbree})
    check_against_brute_force(m, Q, seed, engine);
}

Vec3 unit_normal(const Vec3& a, const Vec3& b, const Vec3& c) {
  return (b - a).cross(c - a).normalized();
}

}  // namespace

TEST(SurfaceIndex, ClosestPointOnTriangleAnalyticRegions) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  struct Case {
    Vec3 p, expected;
    int region;
  };
  const Case cases[] = {
      {{0.2, 0.3, 0.7}, {0.2, 0.3, 0}, 0},
      {{0.2, 0.3, -0.4}, {0.2, 0.3, 0}, 0},
      {{0.5, -1, 0.5}, {0.5, 0, 0}, 1},
      {{1, 1, -0.3}, {0.5, 0.5, 0}, 2},
      {{-2, 0.4, 1}, {0, 0.4, 0}, 3},
      {{-1, -1, 0.2}, a, 4},
      {{2, -0.5, 0}, b, 5},
      {{-0.5, 2, 1}, c, 6},
      {{0.25, 0.25, 0}, {0.25, 0.25, 0}, 0},  // on the triangle
  };
  for (const Case& k : cases) {
    int region = -1;
    const Vec3 q = closest_point_on_triangle(k.p, a, b, c, &region);
    EXPECT_EQ(region, k.region) << k.p.transpose();
    EXPECT_LE((q - k.expected).norm(), 1e-15) << k.p.transpose();
  }
  EXPECT_EQ(closest_point_on_triangle(Vec3(3, 4, 5), a, b, c),
            closest_point_on_triangle(Vec3(3, 4, 5), a, b, c, nullptr));
}

// p built from a known footpoint q in each region: q + (outward in-plane cone) + normal.
TEST(SurfaceIndex, ClosestPointOnTriangleConstructedRegions) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_real_distribution<double> u01(0.05, 0.95);
  int checked = 0;
  for (int trial = 0; trial < 500; ++trial) {
    const Vec3 v[3] = {Vec3(u(rng), u(rng), u(rng)) * 3, Vec3(u(rng), u(rng), u(rng)) * 3,
                       Vec3(u(rng), u(rng), u(rng)) * 3};
    const Vec3 n = unit_normal(v[0], v[1], v[2]);
    // Skip slivers: the region test is ill-conditioned there and the mesh has none.
    const double area2 = (v[1] - v[0]).cross(v[2] - v[0]).norm();
    double longest = 0;
    for (int k = 0; k < 3; ++k) longest = std::max(longest, (v[(k + 1) % 3] - v[k]).norm());
    if (area2 < 0.1 * longest * longest) continue;
    Vec3 out[3];  // outward in-plane normal of edge k = (v[k], v[k+1])
    for (int k = 0; k < 3; ++k) out[k] = (v[(k + 1) % 3] - v[k]).cross(n).normalized();
    const double h = 2 * u(rng);
    // Interior.
    {
      double s = u01(rng), t = u01(rng);
      if (s + t > 0.95) s *= 0.5, t *= 0.5;
      const Vec3 q = v[0] + s * (v[1] - v[0]) + t * (v[2] - v[0]);
      int region = -1;
      EXPECT_LE((closest_point_on_triangle(q + h * n, v[0], v[1], v[2], &region) - q).norm(),
                1e-12);
      EXPECT_EQ(region, 0);
    }
    for (int k = 0; k < 3; ++k) {
      // Edge k.
      const Vec3 q = v[k] + u01(rng) * (v[(k + 1) % 3] - v[k]);
      int region = -1;
      const Vec3 pe = q + (0.1 + std::abs(u(rng))) * out[k] + h * n;
      EXPECT_LE((closest_point_on_triangle(pe, v[0], v[1], v[2], &region) - q).norm(), 1e-12);
      EXPECT_EQ(region, 1 + k);
      // Vertex k: a positive combination of the outward normals of its two edges.
      const Vec3 cone =
          (0.1 + std::abs(u(rng))) * out[k] + (0.1 + std::abs(u(rng))) * out[(k + 2) % 3];
      const Vec3 pv = v[k] + cone + h * n;
      EXPECT_LE((closest_point_on_triangle(pv, v[0], v[1], v[2], &region) - v[k]).norm(), 1e-12);
      EXPECT_EQ(region, 4 + k);
    }
    ++checked;
  }
  EXPECT_GT(checked, 100);
}

TEST(SurfaceIndex, ClosestPointOnTriangleMatchesDenseSampling) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  constexpr int kSamples = 300;  // per side of the barycentric grid
  int seen[7] = {};
  for (int trial = 0; trial < 20; ++trial) {
    const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), c(u(rng), u(rng), u(rng));
    double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    std::vector<Vec3> samples;
    for (int i = 0; i <= kSamples; ++i)
      for (int j = 0; i + j <= kSamples; ++j)
        samples.push_back(a + (double(i) / kSamples) * (b - a) + (double(j) / kSamples) * (c - a));
    for (int k = 0; k < 40; ++k) {
      const Vec3 p = 2.0 * Vec3(u(rng), u(rng), u(rng));
      int region = -1;
      const Vec3 q = closest_point_on_triangle(p, a, b, c, &region);
      ASSERT_GE(region, 0);
      ASSERT_LE(region, 6);
      ++seen[region];
      const double exact = (p - q).norm();
      double sampled = std::numeric_limits<double>::infinity();
      for (const Vec3& s : samples) sampled = std::min(sampled, (p - s).norm());
      EXPECT_LE(exact, sampled + 1e-12);                       // nothing on Φ is closer
      EXPECT_LE(sampled - exact, longest / kSamples + 1e-12);  // and q is on the triangle
      // q is on the triangle: non-negative barycentrics.
      const Vec3 n = (b - a).cross(c - a);
      const double area = n.squaredNorm();
      const double wa = (c - b).cross(q - b).dot(n) / area;
      const double wb = (a - c).cross(q - c).dot(n) / area;
      EXPECT_GE(wa, -1e-12);
      EXPECT_GE(wb, -1e-12);
      EXPECT_GE(1 - wa - wb, -1e-12);
    }
  }
  for (int region = 0; region < 7; ++region) EXPECT_GT(seen[region], 0) << region;
}

TEST(SurfaceIndex, MatchesBruteForceOnPerturbedGrid) {
  const Mesh m = perturbed_grid(3);
  ASSERT_EQ(m.face_count(), 2 * 39 * 39);
  check_against_brute_force(m, make_queries(m, 500 * kQueryScale, 5), 9);
}

// record_queries logs what a replay needs: every unbounded query's point and the hint it
// searched from (its own, or the previous answer's face in a chained batch), nothing of bounded
// queries, and nothing once it is cleared.
TEST(SurfaceIndex, RecordsUnboundedQueriesWithTheHintsTheySearchedFrom) {
  SurfaceIndex index(perturbed_grid(3));
  std::vector<SurfaceIndex::RecordedQuery> log;
  index.record_queries(&log);
  const Vec3 p0(0.3, 0.4, 0.5), p1(0.6, 0.2, 0.4), p2(0.1, 0.9, -0.3);
  const ClosestPoint a = index.closest_point(p0, 7);
  Points batch(2, 3);
  batch.row(0) = p1.transpose();
  batch.row(1) = p2.transpose();
  std::vector<ClosestPoint> serial(2);
  index.closest_points_serial(batch, {}, serial);
  (void)index.closest_points_within(batch, 1.0);  // bounded: not logged
  index.record_queries(nullptr);
  (void)index.closest_point(p0);
  ASSERT_EQ(log.size(), 3u);
  EXPECT_EQ(log[0].point, p0);
  EXPECT_EQ(log[0].hint, 7);
  EXPECT_EQ(log[1].point, p1);
  EXPECT_EQ(log[1].hint, -1);
  EXPECT_EQ(log[2].point, p2);
  EXPECT_EQ(log[2].hint, serial[0].face);  // chained: the previous answer's face
  // Replayed with its hints, the stream gives the same answers.
  EXPECT_EQ(index.closest_point(log[0].point, log[0].hint).face, a.face);
  EXPECT_EQ(index.closest_point(log[2].point, log[2].hint).face, serial[1].face);
}

TEST(SurfaceIndex, MatchesBruteForceOnTriangleSoup) {
  const Mesh m = triangle_soup(2000, 13);
  check_against_brute_force(m, make_queries(m, 500 * kQueryScale, 17), 19);
}

// Far from the origin the float BVH coordinates are coarse; the index works relative to the
// bounding-box centre.
TEST(SurfaceIndex, MatchesBruteForceFarFromOrigin) {
  Mesh m = perturbed_grid(23);
  m.V.rowwise() += Eigen::RowVector3d(1e4, -2e4, 5e3);
  check_against_brute_force(m, make_queries(m, 250 * kQueryScale, 29), 31);
}

// The box tree passes over a triangle when its single-precision distance is farther than the
// best by a margin: exact ties and near-ties must still reach the exact test. Above a flat grid,
// points over a vertex are equidistant from up to six triangles and points over an edge from
// two, at every height; brute force keeps the lowest face.
TEST(SurfaceIndex, MatchesBruteForceOnExactTies) {
  const Mesh m = make_grid(24, 24, 12.0, 12.0, [](double, double) { return 0.0; });
  Points Q(0, 3);
  std::vector<Vec3> points;
  for (double height : {0.0, 1e-9, 0.37, 5.0, 60.0})
    for (int j = 1; j < 24; j += 5)
      for (int i = 1; i < 24; i += 4) {
        const Vec3 vertex(0.5 * i, 0.5 * j, height);
        points.push_back(vertex);
        points.push_back(vertex + Vec3(0.25, 0.0, 0.0));   // over a grid edge
        points.push_back(vertex + Vec3(0.25, 0.25, 0.0));  // over a diagonal
        points.push_back(vertex + Vec3(0.25, 0.25 + 1e-12, 0.0));  // just off it
      }
  Q.resize(static_cast<Eigen::Index>(points.size()), 3);
  for (std::size_t k = 0; k < points.size(); ++k) Q.row(static_cast<Eigen::Index>(k)) = points[k].transpose();
  check_against_brute_force(m, Q, 41);
}

// Slivers (angles down to 1e-7 rad) far from the origin: their frames in single precision are
// the coarsest; brute force decides.
TEST(SurfaceIndex, MatchesBruteForceOnSliversFarFromOrigin) {
  std::mt19937 rng(43);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Mesh m;
  const int count = 600;
  m.V.resize(3 * count, 3);
  m.F.resize(count, 3);
  const Vec3 far(3e4, -1e4, 2e4);
  for (int f = 0; f < count; ++f) {
    const Vec3 a = far + 5.0 * Vec3(u(rng), u(rng), u(rng));
    const Vec3 dir = Vec3(u(rng), u(rng), u(rng)).normalized();
    const Vec3 side = dir.unitOrthogonal();
    const double length = 0.5 + std::abs(u(rng));
    const double thin = std::pow(10.0, -7.0 + 6.0 * std::abs(u(rng)));  // 1e-7 .. 1e-1
    const Vec3 b = a + length * dir, c = a + 0.5 * length * dir + thin * length * side;
    m.V.row(3 * f) = a.transpose(), m.V.row(3 * f + 1) = b.transpose(), m.V.row(3 * f + 2) = c.transpose();
    m.F.row(f) << 3 * f, 3 * f + 1, 3 * f + 2;
  }
  check_against_brute_force(m, make_queries(m, 250 * kQueryScale, 47), 53);
}

// A bounded query answers exactly as an unbounded one where Φ is within the bound (a face at
// exactly the bound included) and says "none" beyond it, with both engines.
TEST(SurfaceIndex, BoundedQueriesAnswerWithinTheBound) {
  const Mesh m = perturbed_grid(61);
  const Points Q = make_queries(m, 400, 67);
  for (const QueryEngine engine : {QueryEngine::kBoxTree, QueryEngine::kEmbree}) {
    SCOPED_TRACE(engine == QueryEngine::kEmbree ? "Embree" : "box tree");
    const SurfaceIndex index(m, engine);
    const std::vector<ClosestPoint> all = index.closest_points(Q);
    std::vector<double> d;
    for (const ClosestPoint& c : all) d.push_back(c.distance);
    std::sort(d.begin(), d.end());
    for (const double bound : {0.0, d[d.size() / 4], d[d.size() / 2], d.back() * 2.0}) {
      const std::vector<ClosestPoint> within = index.closest_points_within(Q, bound);
      int inside = 0;
      for (std::size_t i = 0; i < all.size(); ++i) {
        if (all[i].distance <= bound) {
          ++inside;
          expect_same(within[i], all[i]);
        } else {
          EXPECT_EQ(within[i].face, -1) << i;
        }
      }
      if (bound > 0.0) {
        EXPECT_GT(inside, 0);
      }
    }
  }
}

// Queries over a subset of the faces answer as an index built over that subset alone (the
// same vertices, the kept faces in their order): the same face, point and distance, and the
// subset's own boundary (holes punched in the middle of the surface have edges too).
TEST(SurfaceIndex, MaskedQueriesAnswerAsTheSubsetsOwnIndex) {
  const Mesh m = perturbed_grid(71);
  std::mt19937 rng(73);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<char> mask(static_cast<std::size_t>(m.face_count()), 1);
  // A few holes of neighbouring faces and scattered single faces left out.
  for (int hole = 0; hole < 6; ++hole) {
    const int f0 = static_cast<int>(u01(rng) * (m.face_count() - 200));
    for (int f = f0; f < f0 + 40; ++f) mask[static_cast<std::size_t>(f)] = 0;
  }
  for (auto& c : mask)
    if (u01(rng) < 0.05) c = 0;
  Mesh sub;
  sub.V = m.V;
  std::vector<int> full_face;
  for (int f = 0; f < m.face_count(); ++f)
    if (mask[static_cast<std::size_t>(f)]) full_face.push_back(f);
  sub.F.resize(static_cast<Eigen::Index>(full_face.size()), 3);
  for (std::size_t i = 0; i < full_face.size(); ++i) sub.F.row(static_cast<Eigen::Index>(i)) = m.F.row(full_face[i]);
  // Points near the surface (over holes and their edges too) and farther away.
  const Points Q = make_queries(m, 600, 79);
  for (const QueryEngine engine : {QueryEngine::kBoxTree, QueryEngine::kEmbree}) {
    SCOPED_TRACE(engine == QueryEngine::kEmbree ? "Embree" : "box tree");
    const SurfaceIndex whole(m, engine), own(sub, engine);
    for (const double bound : {0.05, 1e9}) {
      const std::vector<ClosestPoint> masked = whole.closest_points_within(Q, bound, mask);
      const std::vector<ClosestPoint> alone = own.closest_points_within(Q, bound);
      int boundary = 0;
      for (std::size_t i = 0; i < masked.size(); ++i) {
        SCOPED_TRACE(i);
        ClosestPoint b = alone[i];
        ASSERT_EQ(masked[i].face < 0, b.face < 0);
        if (b.face < 0) continue;
        b.face = full_face[static_cast<std::size_t>(b.face)];  // the subset's numbering
        expect_same(masked[i], b);
        boundary += b.on_boundary;
      }
      if (bound > 1.0) {
        EXPECT_GT(boundary, 10);  // the holes' edges are met
      }
    }
  }
}

// A box tree's first masked queries build what masks need (once, whichever thread asks
// first): two threads asking at once on a fresh index get the answers one thread gets.
TEST(SurfaceIndex, FirstMaskedQueriesFromTwoThreadsAtOnce) {
  const Mesh m = perturbed_grid(87);
  std::vector<char> mask(static_cast<std::size_t>(m.face_count()), 1);
  for (std::size_t f = 0; f < mask.size(); f += 7) mask[f] = 0;
  const Points Q = make_queries(m, 400, 89);
  const SurfaceIndex reference(m);
  const std::vector<ClosestPoint> expected = reference.closest_points_within(Q, 1e9, mask);
  const SurfaceIndex fresh(m);
  std::vector<ClosestPoint> got[2];
  parallel_invoke_each(2, [&](std::size_t t) { got[t] = fresh.closest_points_within(Q, 1e9, mask); });
  for (const auto& g : got) {
    ASSERT_EQ(g.size(), expected.size());
    for (std::size_t i = 0; i < g.size(); ++i) expect_same(g[i], expected[i]);
  }
}

// The grid of cells answers a bounded query as the box tree does, bit for bit: at the reach
// it was built for (a face at exactly that distance included), nearer, with and without a face
// mask, on surfaces, soups, slivers far from the origin and exact ties.
TEST(SurfaceIndex, CellsAnswerBoundedQueriesAsTheBoxTree) {
  Mesh far_slivers = triangle_soup(300, 83);
  for (Eigen::Index v = 0; v < far_slivers.V.rows(); v += 3)  // squash every third corner onto its edge
    far_slivers.V.row(v + 2) = 0.5 * (far_slivers.V.row(v) + far_slivers.V.row(v + 1)) +
                               1e-6 * (far_slivers.V.row(v + 2) - far_slivers.V.row(v));
  far_slivers.V.rowwise() += Eigen::RowVector3d(3e4, -1e4, 2e4);
  const Mesh ties = make_grid(24, 24, 12.0, 12.0, [](double, double) { return 0.0; });
  const std::vector<std::pair<const char*, Mesh>> meshes{
      {"perturbed grid", perturbed_grid(89)}, {"soup", triangle_soup(500, 97)}, {"far slivers", far_slivers}, {"flat grid", ties}};
  for (const auto& [name, m] : meshes) {
    SCOPED_TRACE(name);
    Points Q = make_queries(m, 300 * kQueryScale, 101);
    if (std::string(name) == "flat grid")  // over vertices, edges and diagonals: exact ties
      for (Eigen::Index i = 0; i < Q.rows(); ++i)
        Q.row(i) << 0.5 * static_cast<double>(i % 23 + 1) + 0.25 * static_cast<double>(i % 3),
            0.5 * static_cast<double>(i / 23 % 23 + 1) + 0.25 * static_cast<double>(i % 2), 0.1 * static_cast<double>(i % 5);
    const SurfaceIndex tree(m);
    std::vector<double> d;
    for (const ClosestPoint& c : tree.closest_points(Q))
      if (c.distance > 0.0) d.push_back(c.distance);
    std::sort(d.begin(), d.end());
    std::vector<char> mask(static_cast<std::size_t>(m.face_count()));
    for (std::size_t f = 0; f < mask.size(); ++f) mask[f] = (f * 7919) % 5 != 0;
    for (const double reach : {d[d.size() / 8], d[d.size() / 2], 2.0 * d.back()}) {
      const SurfaceIndex cells = SurfaceIndex::within_reach(m, reach);
      EXPECT_EQ(cells.engine(), QueryEngine::kCells);
      int found = 0;
      for (const double bound : {reach, 0.5 * reach, 0.0})
        for (const bool masked : {false, true}) {
          const std::span<const char> fm = masked ? std::span<const char>(mask) : std::span<const char>{};
          const std::vector<ClosestPoint> a = cells.closest_points_within(Q, bound, fm);
          const std::vector<ClosestPoint> b = tree.closest_points_within(Q, bound, fm);
          for (std::size_t i = 0; i < a.size(); ++i) {
            SCOPED_TRACE(i);
            expect_same(a[i], b[i]);
            found += a[i].face >= 0;
          }
        }
      EXPECT_GT(found, 0);
    }
  }
}

// within_reach told of many queries over faces far smaller than the reach (a cell would list
// hundreds of faces) searches a box tree instead, with the cells' answers bit for bit, and
// still answers bounded queries only; told of few queries, or of a reach a tenth of a face
// wide, it keeps the cells. A 120 × 120 grid (28,800 faces, 0.05 wide): the reach of 0.5 (a
// vertex band's ten tolerances over a fine Ω) against 0.005.
TEST(SurfaceIndex, WithinReachSearchesATreeWhereCellsWouldListHundredsOfFaces) {
  const Mesh m = make_grid(
      120, 120, 6.0, 6.0, [](double x, double y) { return 0.3 * std::sin(x) * std::cos(0.8 * y); }, 0.3, 5);
  const std::size_t F = static_cast<std::size_t>(m.face_count());
  // Points near the surface, in the order of its vertices (as Φ's vertices are asked), and
  // points around it.
  Points Q(static_cast<Eigen::Index>(m.V.rows()) + 200, 3);
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (Eigen::Index v = 0; v < m.V.rows(); ++v) Q.row(v) = m.V.row(v) + 0.02 * Eigen::RowVector3d(u(rng), u(rng), u(rng));
  Q.bottomRows(200) = make_queries(m, 200, 13);
  std::vector<char> mask(F);
  for (std::size_t f = 0; f < F; ++f) mask[f] = (f * 7919) % 5 != 0;
  const SurfaceIndex few = SurfaceIndex::within_reach(m, 0.5, 100);
  const SurfaceIndex many = SurfaceIndex::within_reach(m, 0.5, 4 * F);
  const SurfaceIndex narrow = SurfaceIndex::within_reach(m, 0.005, 4 * F);
  EXPECT_EQ(few.engine(), QueryEngine::kCells);
  EXPECT_EQ(many.engine(), QueryEngine::kBoxTree);
  EXPECT_EQ(narrow.engine(), QueryEngine::kCells);
  int found = 0;
  for (const double bound : {0.5, 0.005, 0.0})
    for (const bool masked : {false, true}) {
      SCOPED_TRACE(::testing::Message() << "bound " << bound << (masked ? ", masked" : ""));
      const std::span<const char> fm = masked ? std::span<const char>(mask) : std::span<const char>{};
      const std::vector<ClosestPoint> a = few.closest_points_within(Q, bound, fm);
      const std::vector<ClosestPoint> b = many.closest_points_within(Q, bound, fm);
      ASSERT_EQ(a.size(), b.size());
      for (std::size_t i = 0; i < a.size(); ++i) {
        SCOPED_TRACE(i);
        expect_same(a[i], b[i]);
        found += a[i].face >= 0;
      }
      if (bound <= 0.005) {
        const std::vector<ClosestPoint> c = narrow.closest_points_within(Q, bound, fm);
        for (std::size_t i = 0; i < a.size(); ++i) expect_same(c[i], a[i]);
      }
    }
  EXPECT_GT(found, 2 * m.V.rows());  // every point near the surface, within 0.5
  EXPECT_THROW(many.closest_point(Vec3::Zero()), std::logic_error);
  EXPECT_THROW(many.closest_points(Q.topRows(8)), std::logic_error);
  std::vector<ClosestPoint> out(8);
  EXPECT_THROW(many.closest_points_serial(Q.topRows(8), {}, out), std::logic_error);
  EXPECT_THROW(many.closest_points_within(Q, 0.6), std::logic_error);
}

TEST(SurfaceIndex, CellsRefuseQueriesBeyondTheirReach) {
  const Mesh m = perturbed_grid(103);
  const SurfaceIndex cells = SurfaceIndex::within_reach(m, 0.1);
  const Points Q = make_queries(m, 8, 107);
  EXPECT_THROW(cells.closest_point(Vec3::Zero()), std::logic_error);
  EXPECT_THROW(cells.closest_points(Q), std::logic_error);
  std::vector<ClosestPoint> out(8);
  EXPECT_THROW(cells.closest_points_serial(Q, {}, out), std::logic_error);
  EXPECT_THROW(cells.closest_points_within(Q, 0.2), std::logic_error);
  EXPECT_NO_THROW(cells.closest_points_within(Q, 0.1));
  EXPECT_THROW(SurfaceIndex::within_reach(m, 0.0), std::invalid_argument);
  EXPECT_THROW(SurfaceIndex::within_reach(m, std::numeric_limits<double>::infinity()), std::invalid_argument);
}

TEST(SurfaceIndex, BatchedParallelEqualsSerial) {
  const Mesh m = perturbed_grid(37);
  const SurfaceIndex index(m);
  const Points Q = make_queries(m, 1250 * kQueryScale, 41);
  std::mt19937 rng(43);
  std::uniform_int_distribution<int> face(-1, m.face_count() - 1);
  std::vector<int> hints(static_cast<std::size_t>(Q.rows()));
  for (int& h : hints) h = face(rng);

  const std::vector<ClosestPoint> parallel = index.closest_points(Q);
  const std::vector<ClosestPoint> parallel_hinted = index.closest_points(Q, hints);
  std::vector<ClosestPoint> serial(static_cast<std::size_t>(Q.rows()));
  index.closest_points_serial(Q, {}, serial);
  std::vector<ClosestPoint> one_thread;
  {
    const ThreadLimit limit(1);
    one_thread = index.closest_points(Q, hints);
  }
  ASSERT_EQ(parallel.size(), serial.size());
  for (std::size_t i = 0; i < serial.size(); ++i) {
    expect_same(parallel[i], serial[i]);
    expect_same(parallel_hinted[i], serial[i]);
    expect_same(one_thread[i], serial[i]);
    expect_same(index.closest_point(Q.row(static_cast<Eigen::Index>(i))), serial[i]);
  }
  EXPECT_TRUE(index.closest_points(Points(0, 3)).empty());
}

TEST(SurfaceIndex, BoundaryFlagAndSignOnFlatSquare) {
  const Mesh m = flat_square(10, 10.0);  // z = 0 over [0, 10]², normals +z
  const SurfaceIndex index(m);
  EXPECT_NEAR(index.diagonal(), std::sqrt(200.0), 1e-12);
  for (int f = 0; f < m.face_count(); ++f)
    EXPECT_LE((Vec3(index.normals().row(f)) - Vec3::UnitZ()).norm(), 1e-15);

  // Above and below the interior.
  ClosestPoint cp = index.closest_point(Vec3(5.3, 4.6, 2.0));
  EXPECT_FALSE(cp.boundary);
  EXPECT_NEAR(cp.distance, 2.0, 1e-15);
  EXPECT_NEAR(cp.signed_distance, 2.0, 1e-15);
  EXPECT_LE((cp.direction - Vec3::UnitZ()).norm(), 1e-15);
  cp = index.closest_point(Vec3(5.3, 4.6, -2.0));
  EXPECT_FALSE(cp.boundary);
  EXPECT_NEAR(cp.signed_distance, -2.0, 1e-15);
  EXPECT_LE((cp.direction + Vec3::UnitZ()).norm(), 1e-15);

  // Above a boundary edge and a corner: g is the normal, the point has not left Φ.
  EXPECT_FALSE(index.closest_point(Vec3(10.0, 5.5, 3.0)).boundary);
  EXPECT_FALSE(index.closest_point(Vec3(0.0, 0.0, 3.0)).boundary);
  EXPECT_FALSE(index.closest_point(Vec3(4.5, 0.0, -1.0)).boundary);

  // Beyond an edge, on both sides of the plane.
  cp = index.closest_point(Vec3(12.0, 5.5, 1.0));
  EXPECT_TRUE(cp.boundary);
  EXPECT_LE((cp.point - Vec3(10.0, 5.5, 0.0)).norm(), 1e-14);
  EXPECT_NEAR(cp.distance, std::sqrt(5.0), 1e-14);
  EXPECT_GT(cp.signed_distance, 0.0);
  cp = index.closest_point(Vec3(12.0, 5.5, -1.0));
  EXPECT_TRUE(cp.boundary);
  EXPECT_NEAR(cp.signed_distance, -std::sqrt(5.0), 1e-14);
  // In the plane beyond the edge: dot(g, N) = 0 counts as the positive side.
  cp = index.closest_point(Vec3(4.5, -3.0, 0.0));
  EXPECT_TRUE(cp.boundary);
  EXPECT_NEAR(cp.signed_distance, 3.0, 1e-14);
  // Beyond a corner.
  cp = index.closest_point(Vec3(11.0, 12.0, 0.5));
  EXPECT_TRUE(cp.boundary);
  EXPECT_LE((cp.point - Vec3(10.0, 10.0, 0.0)).norm(), 1e-14);

  // Vertex classification: corners and edge vertices are boundary, inner ones are not.
  EXPECT_TRUE(index.is_boundary_vertex(0));
  EXPECT_TRUE(index.is_boundary_vertex(5));       // on y = 0
  EXPECT_TRUE(index.is_boundary_vertex(11 * 5));  // on x = 0
  EXPECT_TRUE(index.is_boundary_vertex(11 * 11 - 1));
  EXPECT_FALSE(index.is_boundary_vertex(11 * 5 + 5));
  int boundary_vertices = 0;
  for (int v = 0; v < m.vertex_count(); ++v) boundary_vertices += index.is_boundary_vertex(v);
  EXPECT_EQ(boundary_vertices, 40);

  // Sign flips exactly across the plane along a vertical line.
  for (double z : {-1.0, -1e-9, 1e-9, 1.0}) {
    cp = index.closest_point(Vec3(3.3, 7.7, z));
    EXPECT_EQ(cp.signed_distance > 0, z > 0) << z;
    EXPECT_FALSE(cp.boundary);
  }
}

// The boundary flag agrees with an independent edge count on a jittered grid.
TEST(SurfaceIndex, BoundaryFlagMatchesEdgeCount) {
  const Mesh m = perturbed_grid(47);
  const SurfaceIndex index(m);
  std::map<std::pair<int, int>, int> edge_count;
  for (int f = 0; f < m.face_count(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = m.F(f, k), b = m.F(f, (k + 1) % 3);
      ++edge_count[{std::min(a, b), std::max(a, b)}];
    }
  std::vector<bool> boundary_vertex(static_cast<std::size_t>(m.vertex_count()), false);
  for (const auto& [edge, count] : edge_count)
    if (count == 1) boundary_vertex[edge.first] = boundary_vertex[edge.second] = true;
  for (int v = 0; v < m.vertex_count(); ++v)
    EXPECT_EQ(index.is_boundary_vertex(v), boundary_vertex[static_cast<std::size_t>(v)]) << v;

  const Points Q = make_queries(m, 2000, 53);
  int flagged = 0;
  for (Eigen::Index i = 0; i < Q.rows(); ++i) {
    const Vec3 p = Q.row(i);
    const ClosestPoint cp = index.closest_point(p);
    int region = -1;
    closest_point_on_triangle(p, m.V.row(m.F(cp.face, 0)), m.V.row(m.F(cp.face, 1)),
                              m.V.row(m.F(cp.face, 2)), &region);
    bool on_boundary = false;
    if (region >= 1 && region <= 3) {
      const int a = m.F(cp.face, region - 1), b = m.F(cp.face, region % 3);
      on_boundary = edge_count[{std::min(a, b), std::max(a, b)}] == 1;
    } else if (region >= 4) {
      on_boundary = boundary_vertex[static_cast<std::size_t>(m.F(cp.face, region - 4))];
    }
    const Vec3 n = index.normals().row(cp.face);
    const bool expected =
        cp.distance > 0 && on_boundary && std::abs(cp.direction.dot(n)) < 1 - 1e-9;
    EXPECT_EQ(cp.boundary, expected) << i;
    flagged += cp.boundary;
  }
  EXPECT_GT(flagged, 100);  // queries reach 20% of the diagonal beyond the grid
}

TEST(SurfaceIndex, QueryExactlyOnVertex) {
  const Mesh m = flat_square(4, 4.0);
  const SurfaceIndex index(m);
  for (int v : {0, 2, 12, 24}) {  // corner, edge, inner, corner
    const Vec3 p = m.V.row(v);
    for (int hint : {-1, 0, m.face_count() - 1}) {
      const ClosestPoint cp = index.closest_point(p, hint);
      EXPECT_EQ(cp.distance, 0.0);
      EXPECT_EQ(cp.signed_distance, 0.0);
      EXPECT_EQ(cp.point, p);
      EXPECT_FALSE(cp.boundary);
      EXPECT_EQ(cp.direction, Vec3(index.normals().row(cp.face)));
      // Every incident face is at distance 0: the lowest index wins.
      int lowest = m.face_count();
      for (int f = 0; f < m.face_count(); ++f)
        if ((m.F.row(f).array() == v).any()) lowest = std::min(lowest, f);
      EXPECT_EQ(cp.face, lowest) << "vertex " << v << " hint " << hint;
    }
  }
}

TEST(SurfaceIndex, SingleTriangleAndEdgeCases) {
  Mesh m;
  m.V.resize(3, 3);
  m.V << 0, 0, 0, 1, 0, 0, 0, 1, 0;
  m.F.resize(1, 3);
  m.F << 0, 1, 2;
  SurfaceIndex index(m);
  for (int v = 0; v < 3; ++v) EXPECT_TRUE(index.is_boundary_vertex(v));
  // Out-of-range hints are ignored.
  const ClosestPoint ref = index.closest_point(Vec3(0.2, 0.2, 1.0));
  expect_same(index.closest_point(Vec3(0.2, 0.2, 1.0), 5), ref);
  expect_same(index.closest_point(Vec3(0.2, 0.2, 1.0), -7), ref);
  EXPECT_EQ(ref.face, 0);
  EXPECT_FALSE(ref.boundary);
  // On the edge itself: distance 0, not boundary.
  const ClosestPoint on_edge = index.closest_point(Vec3(0.5, 0.0, 0.0));
  EXPECT_EQ(on_edge.distance, 0.0);
  EXPECT_FALSE(on_edge.boundary);
  EXPECT_EQ(on_edge.direction, Vec3::UnitZ());

  // Moving keeps the index usable.
  SurfaceIndex moved(std::move(index));
  expect_same(moved.closest_point(Vec3(0.2, 0.2, 1.0)), ref);
  EXPECT_EQ(moved.mesh().face_count(), 1);

  // No faces: every query fails with face -1.
  Mesh empty;
  empty.V.resize(0, 3);
  empty.F.resize(0, 3);
  const SurfaceIndex none(empty);
  EXPECT_EQ(none.closest_point(Vec3(1, 2, 3)).face, -1);
}

}  // namespace flank
