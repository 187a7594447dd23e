// subdivide_midpoint: the finer re-mesh of the scaling ladder keeps the surface exactly.
#include "kernels/mesh.h"

#include <gtest/gtest.h>

#include <set>
#include <utility>

#include "io/read_mesh.h"
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

}  // namespace
}  // namespace flank
