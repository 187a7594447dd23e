#include "kernels/cell_grid.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "kernels/parallel.h"

namespace flank {
namespace {

// Every box that holds a point is among the items its cell lists, in increasing order: on
// boxes of very mixed sizes (most small, a few spanning much of the grid), for points inside,
// exactly on a box's faces and corners, and outside everything.
TEST(CellGrid, ListsEveryBoxHoldingThePoint) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const int n = 2000;
  std::vector<Vec3> lo(n), hi(n);
  for (int i = 0; i < n; ++i) {
    const Vec3 c(100.0 * u01(rng), 40.0 * u01(rng), 5.0 * u01(rng));
    const double size = i % 97 == 0 ? 60.0 * u01(rng) : 0.5 + u01(rng);
    const Vec3 half = 0.5 * size * Vec3(u01(rng), u01(rng), u01(rng));
    lo[i] = c - half, hi[i] = c + half;
  }
  const CellGrid grid(lo, hi);
  EXPECT_LE(static_cast<double>(grid.entries()), 16.0 * n + 64.0);
  EXPECT_GT(grid.cells(), 100u);  // a grid, not one cell holding everything
  // The table is sized by the cells, not by the (item, cell) pairs: neighbouring boxes share
  // most of their cells, and a table per pair was most of the cost of Ω's index.
  EXPECT_LE(grid.slots(), 4 * grid.cells() + 16);
  EXPECT_LT(grid.cells(), grid.entries());
  std::vector<Vec3> points;
  for (int k = 0; k < 3000; ++k) points.emplace_back(-10.0 + 120.0 * u01(rng), -10.0 + 60.0 * u01(rng), -3.0 + 11.0 * u01(rng));
  for (int i = 0; i < n; i += 7) {
    points.push_back(lo[i]), points.push_back(hi[i]);
    points.emplace_back(lo[i].x(), hi[i].y(), 0.5 * (lo[i].z() + hi[i].z()));
  }
  int held = 0;
  for (const Vec3& p : points) {
    const std::span<const std::int32_t> items = grid.items_at(p);
    EXPECT_TRUE(std::is_sorted(items.begin(), items.end()));
    for (int i = 0; i < n; ++i) {
      if (!((p.array() >= lo[i].array()).all() && (p.array() <= hi[i].array()).all())) continue;
      ++held;
      EXPECT_TRUE(std::binary_search(items.begin(), items.end(), i)) << "box " << i;
    }
  }
  EXPECT_GT(held, 3000);
}

// Built in chunks of items on two threads, the grid is the one a single pass builds: the same
// cells and table, and every point's list the same, in the same order. Boxes along a winding
// strip, as a mesh's faces come, so that the chunks share many cells, among scattered ones.
TEST(CellGrid, SameGridWhateverTheThreadCount) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const int n = 40000;  // several chunks
  std::vector<Vec3> lo(n), hi(n);
  for (int i = 0; i < n; ++i) {
    const double t = 0.002 * i;
    const Vec3 strip(30.0 + 25.0 * std::cos(t), 30.0 + 25.0 * std::sin(3.0 * t), 5.0 + u01(rng));
    const Vec3 c = i % 13 == 0 ? Vec3(60.0 * u01(rng), 60.0 * u01(rng), 10.0 * u01(rng)) : strip;
    const double size = i % 211 == 0 ? 20.0 * u01(rng) : 0.3 + 0.5 * u01(rng);
    lo[i] = c - 0.5 * size * Vec3(u01(rng), u01(rng), u01(rng));
    hi[i] = c + 0.5 * size * Vec3(u01(rng), u01(rng), u01(rng));
  }
  const auto built = [&](int threads) {
    const ThreadLimit limit(threads);
    return CellGrid(lo, hi);
  };
  const CellGrid one = built(1), two = built(2);
  EXPECT_EQ(one.cells(), two.cells());
  EXPECT_EQ(one.entries(), two.entries());
  EXPECT_EQ(one.slots(), two.slots());
  std::vector<Vec3> points;
  for (int k = 0; k < 20000; ++k)
    points.emplace_back(-5.0 + 70.0 * u01(rng), -5.0 + 70.0 * u01(rng), -1.0 + 12.0 * u01(rng));
  for (int i = 0; i < n; i += 3) points.push_back(0.5 * (lo[i] + hi[i]));
  std::size_t listed = 0;
  for (const Vec3& p : points) {
    const std::span<const std::int32_t> a = one.items_at(p), b = two.items_at(p);
    ASSERT_TRUE(std::equal(a.begin(), a.end(), b.begin(), b.end()));
    listed += a.size();
  }
  EXPECT_GT(listed, points.size());
}

TEST(CellGrid, EmptyAndDegenerate) {
  const CellGrid empty;
  EXPECT_TRUE(empty.items_at(Vec3::Zero()).empty());
  const CellGrid none(std::vector<Vec3>{}, std::vector<Vec3>{});
  EXPECT_TRUE(none.items_at(Vec3::Zero()).empty());
  // Every box the same point: one cell, which lists them all, and nothing beside it.
  const std::vector<Vec3> at(5, Vec3(1.0, 2.0, 3.0));
  const CellGrid point(at, at);
  EXPECT_EQ(point.items_at(Vec3(1.0, 2.0, 3.0)).size(), 5u);
  EXPECT_TRUE(point.items_at(Vec3(1.0, 2.0, 4.5)).empty());
  EXPECT_TRUE(point.items_at(Vec3(0.0, 0.0, 0.0)).empty());
}

}  // namespace
}  // namespace flank
