// The oriented-box tree (kernels/obb_tree.h) and the query engine built on it: every box holds
// its triangles, the tree is the same whatever the thread count, and on real parts and on
// coherent queries a cutter radius above them the box tree answers exactly as Embree and brute
// force do, bit for bit.
#include "kernels/obb_tree.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "io/read_mesh.h"
#include "kernels/parallel.h"
#include "kernels/surface_index.h"

namespace flank {
namespace {

std::vector<std::array<Vec3, 3>> corners_of(const Mesh& m) {
  std::vector<std::array<Vec3, 3>> out(static_cast<std::size_t>(m.face_count()));
  for (int f = 0; f < m.face_count(); ++f)
    out[static_cast<std::size_t>(f)] = {Vec3(m.V.row(m.F(f, 0))), Vec3(m.V.row(m.F(f, 1))),
                                        Vec3(m.V.row(m.F(f, 2)))};
  return out;
}

// A wavy sheet rolled a little: curved in both directions, n × n cells.
Mesh wavy_sheet(int n) {
  Mesh m;
  m.V.resize((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = 100.0 * i / n, y = 60.0 * j / n;
      m.V.row(j * (n + 1) + i) << x, 40.0 * std::sin(y / 40.0),
          3.0 * std::sin(x / 9.0) * std::cos(y / 7.0) + 40.0 * (1.0 - std::cos(y / 40.0));
    }
  m.F.resize(2 * n * n, 3);
  int f = 0;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int v00 = j * (n + 1) + i, v10 = v00 + 1, v01 = v00 + n + 1, v11 = v01 + 1;
      m.F.row(f++) << v00, v10, v11;
      m.F.row(f++) << v00, v11, v01;
    }
  return m;
}

// The items below node `n` (pre-order subtree), as positions into order().
void collect(const ObbTree& tree, int n, std::vector<int>& out) {
  const ObbNode& node = tree.nodes()[static_cast<std::size_t>(n)];
  if (node.leaf()) {
    for (int i = node.first; i < node.first + node.count; ++i) out.push_back(i);
    return;
  }
  collect(tree, n + 1, out);
  collect(tree, n + node.right, out);
}

int depth(const ObbTree& tree, int n) {
  const ObbNode& node = tree.nodes()[static_cast<std::size_t>(n)];
  if (node.leaf()) return 1;
  return 1 + std::max(depth(tree, n + 1), depth(tree, n + node.right));
}

TEST(ObbTree, EveryBoxHoldsItsTrianglesAndEveryTriangleIsOnce) {
  Mesh m = wavy_sheet(60);
  m.V.rowwise() += Eigen::RowVector3d(3e4, -1e4, 2e3);
  const auto tri = corners_of(m);
  const ObbTree tree(tri, 1e-12 * m.V.cwiseAbs().maxCoeff());
  ASSERT_FALSE(tree.nodes().empty());
  std::vector<int> seen(tri.size(), 0);
  for (const int pos : tree.order()) ++seen[static_cast<std::size_t>(pos)];
  EXPECT_TRUE(std::all_of(seen.begin(), seen.end(), [](int c) { return c == 1; }));
  for (std::size_t n = 0; n < tree.nodes().size(); ++n) {
    const ObbNode& node = tree.nodes()[n];
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(node.axes[static_cast<std::size_t>(k)].norm(), 1.0, 1e-12);
      for (int l = k + 1; l < 3; ++l)
        EXPECT_NEAR(node.axes[static_cast<std::size_t>(k)].dot(node.axes[static_cast<std::size_t>(l)]),
                    0.0, 1e-12);
    }
    std::vector<int> items;
    collect(tree, static_cast<int>(n), items);
    for (const int pos : items)
      for (const Vec3& v : tri[static_cast<std::size_t>(tree.order()[static_cast<std::size_t>(pos)])]) {
        EXPECT_LE(node.lower_bound2(v), 1e-24) << "node " << n;
      }
  }
  // Median splits: depth ⌈log2(items / 4)⌉ + 1 at most.
  EXPECT_LE(depth(tree, 0), static_cast<int>(std::ceil(std::log2(tri.size() / 4.0))) + 2);
}

// The float boxes the queries test hold every corner below them, evaluated in double
// precision (the float evaluation's own error is covered by the pruning margin).
void expect_lane_holds(const ObbTree& tree, const std::vector<std::array<Vec3, 3>>& tri,
                       const ObbWideNode& w, int lane, std::int32_t child, int& checked) {
  std::vector<ObbLeaf> leaves;
  std::vector<std::int32_t> pending{child};
  while (!pending.empty()) {
    const std::int32_t c = pending.back();
    pending.pop_back();
    if (c < 0) {
      leaves.push_back(tree.leaves()[static_cast<std::size_t>(-1 - c)]);
      continue;
    }
    const ObbWideNode& n = tree.wide_nodes()[static_cast<std::size_t>(c)];
    for (int l = 0; l < n.count; ++l) pending.push_back(n.child[l]);
  }
  for (const ObbLeaf& leaf : leaves)
    for (int i = leaf.first; i < leaf.first + leaf.count; ++i)
      for (const Vec3& v : tri[static_cast<std::size_t>(tree.order()[static_cast<std::size_t>(i)])]) {
        const Vec3 rel = v - tree.origin();
        for (int k = 0; k < 3; ++k) {
          double x = 0.0;
          for (int j = 0; j < 3; ++j)
            x += static_cast<double>(w.axes[3 * k + j][lane]) * (rel[j] - static_cast<double>(w.centre[j][lane]));
          EXPECT_LE(std::abs(x), static_cast<double>(w.half[k][lane]));
        }
        ++checked;
      }
}

TEST(ObbTree, WideFloatBoxesHoldTheirTriangles) {
  Mesh m = wavy_sheet(40);
  m.V.rowwise() += Eigen::RowVector3d(3e4, -1e4, 2e3);  // far from the origin: coarse floats
  const auto tri = corners_of(m);
  // The pad SurfaceIndex gives: 1e-12 of the coordinates' magnitude.
  const ObbTree tree(tri, 1e-12 * m.V.cwiseAbs().maxCoeff());
  ASSERT_FALSE(tree.wide_nodes().empty());
  int checked = 0;
  for (const ObbWideNode& w : tree.wide_nodes()) {
    EXPECT_GE(w.count, 2);
    EXPECT_LE(w.count, ObbWideNode::kLanes);
    for (int l = 0; l < w.count; ++l) expect_lane_holds(tree, tri, w, l, w.child[l], checked);
  }
  EXPECT_GT(checked, 3 * static_cast<int>(tri.size()));  // every corner, at every level
  int items = 0;
  for (const ObbLeaf& leaf : tree.leaves()) items += leaf.count;
  EXPECT_EQ(items, static_cast<int>(tri.size()));
}

// On a curved sheet the boxes hug the surface: a leaf box is far thinner across the surface
// than along it (what makes queries from above cheap), unlike an axis-aligned box.
TEST(ObbTree, LeafBoxesAreThinAcrossTheSurface) {
  const Mesh m = wavy_sheet(120);
  const ObbTree tree(corners_of(m), 0.0);
  double thin = 0.0, leaves = 0.0;
  for (const ObbNode& node : tree.nodes()) {
    if (!node.leaf()) continue;
    leaves += 1.0;
    if (node.half[0] < 0.05 * node.half[2]) thin += 1.0;
  }
  EXPECT_GT(thin / leaves, 0.9);
}

TEST(ObbTree, SameTreeWhateverTheThreadCount) {
  const Mesh m = wavy_sheet(150);  // 45,000 triangles: the top levels build in parallel
  const auto tri = corners_of(m);
  std::vector<ObbNode> one;
  std::vector<int> one_order;
  std::vector<ObbWideNode> one_wide;
  std::vector<ObbLeaf> one_leaves;
  {
    const ThreadLimit limit(1);
    const ObbTree tree(tri, 1e-12);
    one.assign(tree.nodes().begin(), tree.nodes().end());
    one_order = tree.order();
    one_wide.assign(tree.wide_nodes().begin(), tree.wide_nodes().end());
    one_leaves.assign(tree.leaves().begin(), tree.leaves().end());
  }
  const ObbTree two(tri, 1e-12);
  ASSERT_EQ(two.nodes().size(), one.size());
  EXPECT_EQ(two.order(), one_order);
  for (std::size_t n = 0; n < one.size(); ++n) {
    EXPECT_EQ(two.nodes()[n].centre, one[n].centre);
    EXPECT_EQ(two.nodes()[n].half, one[n].half);
    EXPECT_EQ(two.nodes()[n].right, one[n].right);
    EXPECT_EQ(two.nodes()[n].first, one[n].first);
  }
  // The wide nodes (collapsed concurrently above 1024 items) and leaves, byte for byte.
  ASSERT_EQ(two.wide_nodes().size(), one_wide.size());
  ASSERT_EQ(two.leaves().size(), one_leaves.size());
  EXPECT_EQ(std::memcmp(two.wide_nodes().data(), one_wide.data(), one_wide.size() * sizeof(ObbWideNode)), 0);
  for (std::size_t k = 0; k < one_leaves.size(); ++k) {
    EXPECT_EQ(two.leaves()[k].first, one_leaves[k].first);
    EXPECT_EQ(two.leaves()[k].count, one_leaves[k].count);
  }
}

// The wide tree is in pre-order: a node's first inner lane is the next node, every node but
// the root is some lane's child exactly once, and the leaves, met left to right, cover the
// item order without gap or overlap.
TEST(ObbTree, WideNodesAndLeavesInPreOrder) {
  for (const int n : {40, 150}) {  // 3,200 and 45,000 triangles
    const ObbTree tree(corners_of(wavy_sheet(n)), 1e-12);
    const std::span<const ObbWideNode> wide = tree.wide_nodes();
    std::vector<int> parents(wide.size(), 0), leaf_parents(tree.leaves().size(), 0);
    for (std::size_t i = 0; i < wide.size(); ++i) {
      bool first_inner = true;
      for (int l = 0; l < wide[i].count; ++l) {
        const std::int32_t c = wide[i].child[l];
        if (c < 0) {
          ++leaf_parents[static_cast<std::size_t>(-1 - c)];
          continue;
        }
        ASSERT_LT(static_cast<std::size_t>(c), wide.size());
        EXPECT_GT(static_cast<std::size_t>(c), i);
        if (first_inner) {
          EXPECT_EQ(static_cast<std::size_t>(c), i + 1);
        }
        first_inner = false;
        ++parents[static_cast<std::size_t>(c)];
      }
    }
    EXPECT_EQ(parents[0], 0);
    for (std::size_t i = 1; i < parents.size(); ++i) EXPECT_EQ(parents[i], 1) << "wide node " << i;
    for (std::size_t k = 0; k < leaf_parents.size(); ++k) EXPECT_EQ(leaf_parents[k], 1) << "leaf " << k;
    std::int32_t next = 0;
    for (const ObbLeaf& leaf : tree.leaves()) {
      EXPECT_EQ(leaf.first, next);
      EXPECT_GE(leaf.count, 1);
      EXPECT_LE(leaf.count, ObbTree::kMaxLeafItems);
      next = leaf.first + leaf.count;
    }
    EXPECT_EQ(static_cast<std::size_t>(next), tree.order().size());
  }
}

TEST(ObbTree, EmptyAndSingleTriangle) {
  const ObbTree empty(std::span<const std::array<Vec3, 3>>{}, 0.0);
  double best = std::numeric_limits<double>::infinity();
  int visits = 0;
  empty.nearest(Vec3::Zero(), best, [&](int) { ++visits; });
  EXPECT_EQ(visits, 0);
  const std::array<Vec3, 3> one[1] = {{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}};
  const ObbTree single(one, 0.0);
  single.nearest(Vec3(5, 5, 5), best, [&](int leaf) {
    EXPECT_EQ(leaf, 0);
    EXPECT_EQ(single.leaves()[0].first, 0);
    EXPECT_EQ(single.leaves()[0].count, 1);
    ++visits;
  });
  EXPECT_EQ(visits, 1);
}

void expect_identical(const ClosestPoint& a, const ClosestPoint& b, const std::string& what) {
  EXPECT_EQ(a.face, b.face) << what;
  EXPECT_EQ(a.point, b.point) << what;
  EXPECT_EQ(a.distance, b.distance) << what;
  EXPECT_EQ(a.signed_distance, b.signed_distance) << what;
  EXPECT_EQ(a.direction, b.direction) << what;
  EXPECT_EQ(a.boundary, b.boundary) << what;
  EXPECT_EQ(a.on_boundary, b.on_boundary) << what;
}

// Lines of 30 points at a cutter-like height above the part (on both sides, and beyond its
// edges), each point warm-started from the previous one's footpoint face, as movability and
// the fit ask; then random points in the box around the part, cold. Both engines must give
// the same answer bit for bit, and every 7th query equals brute force.
void check_part(const Mesh& m, unsigned seed) {
  const SurfaceIndex tree(m, QueryEngine::kBoxTree);
  const SurfaceIndex embree(m, QueryEngine::kEmbree);
  const double diag = tree.diagonal();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::uniform_int_distribution<int> face(0, m.face_count() - 1);
  const auto brute = [&](const Vec3& p) {
    int best = -1;
    double best_d2 = std::numeric_limits<double>::infinity();
    for (int f = 0; f < m.face_count(); ++f) {
      const Vec3 q = closest_point_on_triangle(p, m.V.row(m.F(f, 0)), m.V.row(m.F(f, 1)),
                                               m.V.row(m.F(f, 2)));
      const double d2 = (p - q).squaredNorm();
      if (d2 < best_d2) best_d2 = d2, best = f;
    }
    return best;
  };
  int queries = 0;
  for (int line = 0; line < 40; ++line) {
    const int f = face(rng);
    const Vec3 a = m.V.row(m.F(f, 0));
    const Vec3 n = tree.normals().row(f);
    const double height = (line % 2 ? 1.0 : -1.0) * (0.01 + 0.1 * u01(rng)) * diag;
    const Vec3 dir = n.cross(Vec3(u01(rng) - 0.5, u01(rng) - 0.5, u01(rng) - 0.5)).normalized();
    int hint_tree = -1, hint_embree = -1;
    for (int i = 0; i < 30; ++i, ++queries) {
      const Vec3 p = a + height * n + (0.3 * diag * i / 29.0) * dir;
      const ClosestPoint ct = tree.closest_point(p, hint_tree);
      const ClosestPoint ce = embree.closest_point(p, hint_embree);
      expect_identical(ct, ce, "line " + std::to_string(line) + " point " + std::to_string(i));
      expect_identical(tree.closest_point(p), ct, "cold, line " + std::to_string(line));
      if (queries % 7 == 0) {
        EXPECT_EQ(ct.face, brute(p));
      }
      hint_tree = ct.face;
      hint_embree = ce.face;
    }
  }
  const BoundingBox box = bounding_box(m);
  for (int i = 0; i < 300; ++i) {
    Vec3 p;
    for (int k = 0; k < 3; ++k)
      p[k] = box.min[k] - 0.2 * diag + (box.max[k] - box.min[k] + 0.4 * diag) * u01(rng);
    const ClosestPoint ct = tree.closest_point(p);
    expect_identical(ct, embree.closest_point(p), "random " + std::to_string(i));
    if (i % 7 == 0) {
      EXPECT_EQ(ct.face, brute(p));
    }
  }
}

TEST(ObbTree, SameAnswersAsEmbreeAndBruteForceOnRealParts) {
  for (const char* name : {"rotor67_blade_upper.stl", "hecc_splitter_blade_side_a.stl"}) {
    SCOPED_TRACE(name);
    check_part(io::read_mesh(std::string(FLANK_TEST_DATA_DIR "/") + name).mesh, 11);
  }
  SCOPED_TRACE("propeller");
  check_part(io::read_mesh(FLANK_TEST_DATA_DIR "/../../data/propeller_blade_upper.stl").mesh, 12);
}

TEST(ObbTree, SameAnswersAsEmbreeAndBruteForceOnACurvedSheet) {
  check_part(wavy_sheet(90), 13);
}

}  // namespace
}  // namespace flank
