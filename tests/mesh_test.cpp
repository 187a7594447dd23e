// subdivide_midpoint: the finer re-mesh of the scaling ladder keeps the surface exactly.
// sorted_edge_slots: the edges' order the index's boundary and adjacency are read from.
// radix_sort_by_key: a stable sort, whatever the keys' width and the thread count.
#include "kernels/mesh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "io/read_mesh.h"
#include "kernels/parallel.h"
#include "kernels/surface_index.h"

namespace flank {
namespace {

int edge_count(const Mesh& m) {
  std::set<std::pair<int, int>> edges;
  for (int f = 0; f < m.face_count(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = m.F(f, k), b = m.F(f, (k + 1) % 3);
      edges.emplace(std::min(a, b), std::max(a, b));
    }
  return static_cast<int>(edges.size());
}

TEST(SubdivideMidpoint, SameSurfaceFourTimesTheFaces) {
  const Mesh blade = io::read_mesh(FLANK_TEST_DATA_DIR "/../../data/propeller_blade_upper.stl").mesh;
  const Mesh fine = subdivide_midpoint(blade);
  // One new vertex per edge, shared by the faces on both sides; four faces per face.
  EXPECT_EQ(fine.vertex_count(), blade.vertex_count() + edge_count(blade));
  EXPECT_EQ(fine.face_count(), 4 * blade.face_count());
  EXPECT_NEAR(total_area(fine), total_area(blade), 1e-9 * total_area(blade));
  EXPECT_TRUE(fine.V.topRows(blade.vertex_count()).isApprox(blade.V, 0.0));
  const BoundingBox a = bounding_box(blade), b = bounding_box(fine);
  EXPECT_TRUE(a.min.isApprox(b.min) && a.max.isApprox(b.max));

  // Each child face lies in its parent's plane, with its orientation.
  const Points parent = face_normals(blade), child = face_normals(fine);
  for (int f = 0; f < fine.face_count(); ++f)
    ASSERT_GT(child.row(f).dot(parent.row(f / 4)), 1.0 - 1e-9) << "face " << f;

  // Every new vertex is on the old surface.
  const SurfaceIndex index(blade);
  for (int v = blade.vertex_count(); v < fine.vertex_count(); ++v)
    ASSERT_LT(index.closest_point(fine.V.row(v)).distance, 1e-9 * index.diagonal()) << "vertex " << v;
}

TEST(SubdivideMidpoint, EmptyMeshStaysEmpty) {
  const Mesh fine = subdivide_midpoint(Mesh{});
  EXPECT_EQ(fine.vertex_count(), 0);
  EXPECT_EQ(fine.face_count(), 0);
}

// The edge slots come out in exactly std::sort's order of (vertex pair, slot), at any thread
// count: on a real part, on random faces over few vertices (edges shared by many faces, so
// equal keys) or many (faces and vertices in several chunks), with a fan whose centre has
// hundreds of edges (a bucket sorted by std::sort, not by insertion), with faces repeated
// (the same key in many slots), and with none.
TEST(SortedEdgeSlots, EqualStdSortOfTheKeyedSlots) {
  const auto expected = [](const Mesh& m) {
    std::vector<KeyedIndex> e;
    for (int f = 0; f < m.face_count(); ++f)
      for (int k = 0; k < 3; ++k) {
        const auto u = static_cast<std::uint64_t>(m.F(f, k)), v = static_cast<std::uint64_t>(m.F(f, (k + 1) % 3));
        e.push_back({(std::min(u, v) << 32) | std::max(u, v), 3 * f + k});
      }
    std::sort(e.begin(), e.end());
    return e;
  };
  std::vector<Mesh> meshes{io::read_mesh(FLANK_TEST_DATA_DIR "/../../data/propeller_blade_upper.stl").mesh};
  std::mt19937 rng(11);
  for (const int nv : {3, 40, 5000, 40000}) {
    Mesh m;
    m.V = Points::Random(nv, 3);
    m.F.resize(3 * nv, 3);
    for (int f = 0; f < m.face_count(); ++f) {
      std::vector<int> pick;
      while (pick.size() < 3) {  // three distinct vertices
        const int v = static_cast<int>(rng() % static_cast<unsigned>(nv));
        if (std::find(pick.begin(), pick.end(), v) == pick.end()) pick.push_back(v);
      }
      m.F.row(f) << pick[0], pick[1], pick[2];
    }
    meshes.push_back(m);
  }
  Mesh fan;  // vertex 0 at the centre of 600 faces, every one given twice
  fan.V = Points::Random(601, 3);
  fan.F.resize(1200, 3);
  for (int i = 0; i < 600; ++i) fan.F.row(2 * i) = fan.F.row(2 * i + 1) = Eigen::RowVector3i(0, 1 + i, 1 + (i + 1) % 600);
  meshes.push_back(fan);
  meshes.emplace_back();
  for (const Mesh& m : meshes) {
    const std::vector<KeyedIndex> want = expected(m);
    for (const int threads : {1, 2, 3}) {
      const ThreadLimit limit(threads);
      const Buffer<KeyedIndex> got = sorted_edge_slots(m);
      ASSERT_EQ(got.size(), want.size());
      EXPECT_TRUE(std::equal(got.begin(), got.end(), want.begin()))
          << m.face_count() << " faces, " << threads << " threads";
    }
  }
}

// Against std::stable_sort by key alone: random keys of several widths (an 11-bit pass, a
// pass that is one digit throughout and skipped, all 64 bits; the weld's 22 and all 32 of a
// narrow key), few keys or many, items in index order or not, sizes around the chunk (16384
// items), at 1 to 3 threads.
template <class Item>
void expect_stable_sort_by_key(std::initializer_list<int> widths) {
  std::mt19937_64 rng(11);
  for (const int bits : widths)
    for (const std::size_t n : std::vector<std::size_t>{0, 1, 100, 16384, 2 * 16384 + 5, 100000})
      for (const bool shuffled : {false, true}) {
        std::vector<Item> items(n);
        for (std::size_t i = 0; i < n; ++i) {
          std::uint64_t key = bits == 64 ? rng() : rng() & ((std::uint64_t{1} << bits) - 1);
          if (bits == 33) key &= ~(std::uint64_t{0x7ff} << 11);  // the second digit: all zero
          items[i] = {static_cast<decltype(Item::key)>(key), static_cast<std::int32_t>(i)};
        }
        if (shuffled) std::shuffle(items.begin(), items.end(), rng);
        std::vector<Item> want = items;
        std::stable_sort(want.begin(), want.end(),
                         [](const Item& a, const Item& b) { return a.key < b.key; });
        for (const int threads : {1, 2, 3}) {
          const ThreadLimit limit(threads);
          std::vector<Item> got = items;
          radix_sort_by_key(got, bits);
          EXPECT_TRUE(got == want) << bits << " bits, " << n << " items, shuffled " << shuffled
                                   << ", " << threads << " threads, " << sizeof(Item)
                                   << "-byte items";
        }
      }
}

TEST(RadixSortByKey, IsTheStableSortByKey) {
  expect_stable_sort_by_key<KeyedIndex>({1, 11, 12, 32, 33, 64});
  expect_stable_sort_by_key<NarrowKeyedIndex>({1, 11, 12, 22, 32});
}

}  // namespace
}  // namespace flank
