// Closest points on the design surface Φ (DESIGN "Closest points"): a tree of oriented boxes
// (or Embree's BVH) searched with an exact point–triangle test in double precision.
#pragma once

#include <memory>
#include <span>
#include <vector>

#include "kernels/mesh.h"
#include "kernels/types.h"

namespace flank {

struct ClosestPoint {
  Vec3 point = Vec3::Zero();      // footpoint p⊥ on Φ
  Vec3 direction = Vec3::Zero();  // g = (p − p⊥)/|p − p⊥|; the face normal when p lies on Φ
  double distance = 0.0;          // |p − p⊥| ≥ 0
  double signed_distance = 0.0;   // distance, negative when p is behind the footpoint face
  int face = -1;                  // face of the footpoint, -1 if the query failed
  // The footpoint lies on a boundary edge or vertex of Φ and p is beyond it (g is not the
  // face normal): the query point has left the surface.
  bool boundary = false;
  // The footpoint lies on a boundary edge or vertex of Φ, beyond it or not.
  bool on_boundary = false;
};

// How queries search Φ. Both give the same answers, bit for bit (the exact minimum of
// (distance², face) over all faces).
enum class QueryEngine {
  // Our tree of oriented boxes (kernels/obb_tree.h): a query's cost grows with
  // log(triangles), and a hint face leaves little to visit. The default.
  kBoxTree,
  // Embree's BVH of axis-aligned boxes with rtcPointQuery: the reference, kept for the
  // tests and benchmarks that compare with it.
  kEmbree,
  // A uniform grid of cells, each listing the faces within a fixed reach of it
  // (kernels/cell_grid.h): built in linear time, for an index that lives for a few bounded
  // queries (Ω's in evaluate_patch, where building the box tree cost more than all its
  // queries). Made by SurfaceIndex::within_reach; answers closest_points_within up to that
  // reach only.
  kCells,
};

class SurfaceIndex {
 public:
  // Builds the search structure over a copy of `mesh` (which must be valid: see
  // io::read_mesh).
  explicit SurfaceIndex(const Mesh& mesh, QueryEngine engine = QueryEngine::kBoxTree);
  // An index for closest_points_within with max_distance ≤ reach (> 0, finite) only
  // (QueryEngine::kCells), with the same answers as the box tree's; any other query throws
  // std::logic_error. The index keeps `mesh` (moved in, where the caller is done with it).
  // `queries`: about how many queries it is for (0: few). Where that many would cost more on
  // the cells than a box tree's build and queries (a reach many faces wide, so that a cell
  // lists hundreds of faces, and queries several times the faces), it searches a box tree
  // instead (engine() says which): the same answers, and still bounded queries only.
  static SurfaceIndex within_reach(Mesh mesh, double reach, std::size_t queries = 0);
  ~SurfaceIndex();
  SurfaceIndex(SurfaceIndex&&) noexcept;
  SurfaceIndex& operator=(SurfaceIndex&&) noexcept;
  SurfaceIndex(const SurfaceIndex&) = delete;
  SurfaceIndex& operator=(const SurfaceIndex&) = delete;

  const Mesh& mesh() const;
  double diagonal() const;          // bounding-box diagonal of Φ
  const Points& normals() const;    // #F by 3 unit face normals
  bool is_boundary_vertex(int v) const;
  QueryEngine engine() const;

  // One query. `hint_face` (a previous footpoint's face, or -1) bounds the search radius
  // by the exact distance to that face: the warm start for coherent queries.
  ClosestPoint closest_point(const Vec3& p, int hint_face = -1) const;

  // #Q queries in parallel; `hints` is empty or #Q faces (-1 for none). With no hints, each
  // query starts from the previous one's face (queries in a batch are usually coherent: along
  // a line, a row of a grid). Hints never change an answer. Deterministic.
  std::vector<ClosestPoint> closest_points(PointsRef queries,
                                           std::span<const int> hints = {}) const;
  // #Q queries in parallel that look no farther than max_distance: face −1 (and nothing else
  // set) where no face of Φ is that near; otherwise the same answer as closest_points. Far
  // queries then cost little. `face_mask` (empty, or #F 0/1): only the faces marked 1 count,
  // and the answer (face, boundary flags) is the one an index built over those faces alone,
  // in the same order, would give: one index serves several subsets of one surface.
  std::vector<ClosestPoint> closest_points_within(PointsRef queries, double max_distance,
                                                  std::span<const char> face_mask = {}) const;
  // Same into caller storage, on the calling thread only (for use inside parallel tasks), with
  // the same chaining when `hints` is empty.
  void closest_points_serial(PointsRef queries, std::span<const int> hints,
                             std::span<ClosestPoint> out) const;

  // While `log` is set (not null), every unbounded query (closest_point, closest_points,
  // closest_points_serial) appends its point and the hint face it searched from (its own, or
  // the previous answer's in a chained batch), under a lock: a workload's stream of queries,
  // for a benchmark to replay on its own (bench/decompose_benchmark.cpp, BM_ReplayQueries). Set
  // it while no query runs; run the workload on one thread to keep the stream in its order.
  struct RecordedQuery {
    Vec3 point;
    int hint = -1;
  };
  void record_queries(std::vector<RecordedQuery>* log);

 private:
  SurfaceIndex(Mesh mesh, QueryEngine engine, double reach, std::size_t queries);
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Exact closest point on triangle (a, b, c) to p. `region` receives 0 for the interior,
// 1..3 for edges ab, bc, ca, 4..6 for vertices a, b, c.
Vec3 closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                               int* region = nullptr);

}  // namespace flank
