#include "kernels/surface_index.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cassert>
#include <cfenv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>

#include "kernels/cell_grid.h"
#include "kernels/lanes.h"
#include "kernels/obb_tree.h"
#include "kernels/parallel.h"

namespace flank {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr int kNoFace = std::numeric_limits<int>::max();

// Ericson, Real-Time Collision Detection §5.1.5: classify p against the Voronoi regions of
// the vertices, then the edges, then the interior. In the edge and interior branches the
// denominators are sums of non-negative terms, so a degenerate triangle (excluded by
// io::read_mesh) yields an endpoint instead of a division by zero.
inline Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                                int& region) {
  const Vec3 ab = b - a;
  const Vec3 ac = c - a;
  const Vec3 ap = p - a;
  const double d1 = ab.dot(ap);
  const double d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) {
    region = 4;
    return a;
  }
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp);
  const double d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) {
    region = 5;
    return b;
  }
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double den = d1 - d3;  // = |ab|² ≥ d1 ≥ 0
    region = 1;
    return den > 0.0 ? Vec3(a + (d1 / den) * ab) : a;
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp);
  const double d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) {
    region = 6;
    return c;
  }
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double den = d2 - d6;  // = |ac|² ≥ d2 ≥ 0
    region = 3;
    return den > 0.0 ? Vec3(a + (d2 / den) * ac) : a;
  }
  const double va = d3 * d6 - d5 * d4;
  const double e43 = d4 - d3;
  const double e56 = d5 - d6;
  if (va <= 0.0 && e43 >= 0.0 && e56 >= 0.0) {
    const double den = e43 + e56;  // = |bc|²
    region = 2;
    return den > 0.0 ? Vec3(b + (e43 / den) * (c - b)) : b;
  }
  const double sum = va + vb + vc;  // = |ab × ac|² > 0 for a proper triangle
  if (!(sum > 0.0)) {
    // Collinear vertices: the nearest of the three segments.
    const auto on_segment = [&p](const Vec3& s, const Vec3& t) -> Vec3 {
      const Vec3 st = t - s;
      const double len2 = st.squaredNorm();
      const double u = len2 > 0.0 ? std::clamp((p - s).dot(st) / len2, 0.0, 1.0) : 0.0;
      return s + u * st;
    };
    const Vec3 q[3] = {on_segment(a, b), on_segment(b, c), on_segment(c, a)};
    int best = 0;
    for (int k = 1; k < 3; ++k)
      if ((p - q[k]).squaredNorm() < (p - q[best]).squaredNorm()) best = k;
    region = best + 1;
    return q[best];
  }
  const double inv = 1.0 / sum;
  region = 0;
  return a + (vb * inv) * ab + (vc * inv) * ac;
}

// A triangle's corners, in the form the box tree reads.
using Corners = std::array<Vec3, 3>;

struct Triangle {
  Vec3 a, b, c;
  // A disc around the triangle in its own plane (a slab `thickness` thick, for the rounding
  // of the corners): the distance to the disc is a lower bound of the distance, a cheap test
  // that spares the exact one for most triangles a query visits. Query points sit a cutter
  // radius above Φ: the neighbours of the footpoint triangle are nearly as far as it is from
  // their plane, and it is the in-plane gap that tells them apart, which a ball around the
  // triangle does not see.
  Vec3 centre;
  Vec3 normal;  // unit, or zero for a degenerate triangle (the disc is then a ball)
  double radius;
  double thickness;

  // A lower bound of |p − x|² over the triangle, safe against rounding (see consider()).
  double lower_bound2(const Vec3& p) const {
    const Vec3 d = p - centre;
    const double h = normal.dot(d);
    const double rho = (d - h * normal).norm();
    const double across = std::max(std::abs(h) - thickness, 0.0);
    const double along = std::max(rho - radius, 0.0);
    return across * across + along * along;
  }
};

// The box tree's leaves for the query: a leaf's triangles side by side in single precision
// (lane l is item first + l), relative to the leaf's own origin, each in its own frame (e1
// along ab, e2 in the plane, n the normal) with its corners at (0, 0), (bx, 0) and (cx, cy),
// cy > 0. From these a query gets every triangle's distance in a few vector operations, and
// only the triangles that may be nearest get the exact test in double precision.
struct alignas(16) LeafPack {
  static constexpr int kLanes = ObbTree::kMaxLeafItems;
  float ax[kLanes], ay[kLanes], az[kLanes];     // corner a − origin
  float e1x[kLanes], e1y[kLanes], e1z[kLanes];  // unit, along ab
  float e2x[kLanes], e2y[kLanes], e2z[kLanes];  // unit, in the plane, toward c
  float nx[kLanes], ny[kLanes], nz[kLanes];     // unit normal
  float bx[kLanes], cx[kLanes], cy[kLanes];     // b and c in the frame
  float inv_ab[kLanes], inv_ac[kLanes], inv_bc[kLanes];  // 1/|ab|², 1/|ac|², 1/|bc|²
  // No default member initialisers: a Buffer of packs is first written by the parallel loop
  // that fills it, not on one thread before.
  Vec3 origin;                                  // the mean of the leaf's corners
  double radius;                                // of the leaf's corners about the origin
  std::int32_t first, count;                    // positions in the leaf order
  // Lanes whose frame single precision cannot hold (a sliver): always tested exactly.
  std::uint32_t always;
};

// Squared distances from q (relative to the pack's origin) to the pack's triangles in single
// precision: the distance in the plane to the triangle (0 inside it) and the height above the
// plane. Every lane is computed, unused ones on copies of lane 0, so that no lane meets an
// infinity or a NaN (Debug tests trap them).
void lane_distances(const LeafPack& k, float qx, float qy, float qz, float* out) {
  using V = Float4;
  constexpr int W = sizeof(V) / sizeof(float);
  static_assert(LeafPack::kLanes % W == 0);
  const V zero = splat<V>(0.0f), one = splat<V>(1.0f);
  for (int o = 0; o < LeafPack::kLanes; o += W) {
    const auto ld = [o](const float* p) { return load_lanes<V>(p + o); };
    const V dx = splat<V>(qx) - ld(k.ax), dy = splat<V>(qy) - ld(k.ay), dz = splat<V>(qz) - ld(k.az);
    const V x = ld(k.e1x) * dx + ld(k.e1y) * dy + ld(k.e1z) * dz;
    const V y = ld(k.e2x) * dx + ld(k.e2y) * dy + ld(k.e2z) * dz;
    const V h = ld(k.nx) * dx + ld(k.ny) * dy + ld(k.nz) * dz;
    const V bx = ld(k.bx), cx = ld(k.cx), cy = ld(k.cy);
    // The three edges as segments: the nearest point of each, clamped to its ends.
    const V t1 = lane_min(lane_max(x * bx * ld(k.inv_ab), zero), one);
    const V u1 = x - t1 * bx;
    const V d1 = u1 * u1 + y * y;
    const V t2 = lane_min(lane_max((x * cx + y * cy) * ld(k.inv_ac), zero), one);
    const V u2 = x - t2 * cx, v2 = y - t2 * cy;
    const V d2 = u2 * u2 + v2 * v2;
    const V ex = cx - bx, xb = x - bx;
    const V t3 = lane_min(lane_max((xb * ex + y * cy) * ld(k.inv_bc), zero), one);
    const V u3 = xb - t3 * ex, v3 = y - t3 * cy;
    const V d3 = u3 * u3 + v3 * v3;
    // Inside the triangle (all three edge functions ≥ 0): no distance in the plane.
    const auto inside = (y >= zero) & (ex * y - cy * xb >= zero) & (cy * x - cx * y >= zero);
    const V rho2 = inside ? zero : lane_min(lane_min(d1, d2), d3);
    store_lanes(h * h + rho2, out + o);
  }
}

// Embree reports errors through this sink; it never throws (it runs inside Embree). The
// first error wins; the constructor turns it into an exception, queries ignore it.
struct DeviceErrors {
  std::atomic<int> code{RTC_ERROR_NONE};
  char message[256] = {};
};

void on_device_error(void* user, RTCError code, const char* str) noexcept {
  auto* errors = static_cast<DeviceErrors*>(user);
  int expected = RTC_ERROR_NONE;
  if (errors->code.compare_exchange_strong(expected, static_cast<int>(code)))
    std::snprintf(errors->message, sizeof(errors->message), "%s", str ? str : "");
}

const char* error_name(int code) {
  switch (code) {
    case RTC_ERROR_NONE:
      return "no error";
    case RTC_ERROR_UNKNOWN:
      return "unknown error";
    case RTC_ERROR_INVALID_ARGUMENT:
      return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION:
      return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY:
      return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU:
      return "unsupported CPU";
    case RTC_ERROR_CANCELLED:
      return "cancelled";
    default:
      return "unrecognised error";
  }
}

// Embree works in float: a BVH box may look farther than the double triangle inside it by
// the rounding of vertices (≤ 1e-7 of the half diagonal, relative to the bbox centre), of
// the query point (≤ 1e-7 of its distance to the centre) and of the box distance. The
// relative 1e-5 and absolute `slack` = 1e-6 · diagonal margins cover that a hundredfold.
inline float search_radius(double distance, double slack) {
  return static_cast<float>(distance * (1.0 + 1e-5) + slack);
}

// Embree's SIMD kernels compute with inf and NaN in unused lanes by design; a caller that
// traps floating-point exceptions (Debug tests: tests/main.cpp) must not see them, so the
// trap mask is lifted around Embree calls and the caller's environment restored after.
class FloatingPointTrapsOff {
 public:
  FloatingPointTrapsOff() {
#if defined(__GLIBC__)
    active_ = fegetexcept() != 0;
#endif
    if (active_) feholdexcept(&saved_);
  }
  ~FloatingPointTrapsOff() {
    if (active_) fesetenv(&saved_);
  }
  FloatingPointTrapsOff(const FloatingPointTrapsOff&) = delete;
  FloatingPointTrapsOff& operator=(const FloatingPointTrapsOff&) = delete;

 private:
  fenv_t saved_{};
  bool active_ = true;
};

struct GeometryGuard {
  RTCGeometry geometry = nullptr;
  ~GeometryGuard() {
    if (geometry) rtcReleaseGeometry(geometry);
  }
};

}  // namespace

Vec3 closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                               int* region) {
  int r = 0;
  const Vec3 q = closest_on_triangle(p, a, b, c, r);
  if (region) *region = r;
  return q;
}

namespace {

// Each face's three corners, contiguous.
Buffer<Corners> corner_table(const Mesh& mesh) {
  Buffer<Corners> corners(static_cast<std::size_t>(mesh.face_count()));
  parallel_for(0, corners.size(), [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f) {
      const auto fi = static_cast<Eigen::Index>(f);
      corners[f] = {mesh.V.row(mesh.F(fi, 0)), mesh.V.row(mesh.F(fi, 1)), mesh.V.row(mesh.F(fi, 2))};
    }
  }, 1024);
  return corners;
}

}  // namespace

struct SurfaceIndex::Impl {
  Mesh mesh;
  Points normals;
  QueryEngine engine = QueryEngine::kBoxTree;
  std::vector<Triangle> triangles;          // kEmbree: per face, for the exact callback
  ObbTree tree;                             // kBoxTree
  Buffer<Corners> leaf_corners;             // kBoxTree: per position of the leaf order, contiguous
  Buffer<std::int32_t> face_position;       // kBoxTree: face → position (tree.order() inverts it)
  Buffer<LeafPack> packs;                   // kBoxTree: per leaf of tree.leaves()
  double reach = kInf;                      // within_reach's: the farthest a query may look
  CellGrid cells;                           // kCells: over the faces' boxes grown by reach
  Buffer<std::uint8_t> edge_boundary;       // per face, bit k: edge (k, k+1 mod 3) is a boundary
  std::vector<std::uint8_t> vertex_boundary;
  // For queries over a subset of the faces: the faces' edge slots (3 f + k) grouped by edge
  // (slots of group g: edge_slots[edge_start[g] .. edge_start[g + 1])), each slot's group, and
  // each vertex's faces (vertex_faces[vertex_start[v] .. vertex_start[v + 1])).
  std::vector<std::int32_t> edge_start, edge_slots, slot_edge;
  std::vector<std::int32_t> vertex_start, vertex_faces;
  mutable std::once_flag subset_once;
  std::vector<RecordedQuery>* log = nullptr;  // record_queries
  mutable std::mutex log_mutex;
  Vec3 origin = Vec3::Zero();  // bbox centre; Embree gets coordinates relative to it
  double diagonal = 0.0;
  double slack = 0.0;       // absolute part of the conservative float radius
  double on_surface = 0.0;  // below this distance g is rounding noise: use the normal
  DeviceErrors errors;
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;

  Impl() = default;
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }

  void check(const char* step) const {
    const int code = errors.code.load();
    if (code == RTC_ERROR_NONE) return;
    throw std::runtime_error(std::string("SurfaceIndex: Embree failed to ") + step + " (" +
                             error_name(code) + (errors.message[0] ? ": " : "") + errors.message +
                             ")");
  }

  // edge_boundary and vertex_boundary, from sorted_edge_slots(mesh).
  void build_boundary(std::span<const KeyedIndex> edges);
  // What masked queries need beyond them (edge_start … vertex_faces), and with_boundary the
  // boundary flags too, in the same serial pass: for the index made by within_reach, small
  // and built for every patch judged, whose queries are masked; otherwise built on the first
  // masked query.
  void build_subset_adjacency(std::span<const KeyedIndex> edges, bool with_boundary);
  // Both ends of edge k of face f are on the boundary.
  void mark_boundary_vertices(int f, int k) {
    vertex_boundary[static_cast<std::size_t>(mesh.F(f, k))] = 1;
    vertex_boundary[static_cast<std::size_t>(mesh.F(f, (k + 1) % 3))] = 1;
  }
  void need_subset_adjacency() const {
    std::call_once(subset_once,
                   [this] { const_cast<Impl*>(this)->build_subset_adjacency(sorted_edge_slots(mesh), false); });
  }
  bool masked_edge_boundary(int group, const char* mask) const;
  bool masked_on_boundary(int f, int region, const char* mask) const;
  // The normals, origin, diagonal and roundings from the mesh; returns the coordinates'
  // magnitude (the largest of the diagonal and the box's coordinates).
  double set_frame();
  void build_scene();
  void build_tree(std::span<const Corners> corners, double pad);
  // The Embree scene or the box tree, whichever the engine queries (after the corners).
  void build_search(std::span<const Corners> corners, double pad);

  // Only faces within max_distance count (infinity: all), and only those with mask[f] != 0
  // (null: all), as if the index held those alone.
  ClosestPoint query(const Vec3& p, int hint_face, double max_distance = kInf, const char* mask = nullptr) const;
  ClosestPoint query_once(const Vec3& p, int hint_face, double max_distance, const char* mask) const;
  // #Q queries in parallel (see closest_points and closest_points_within).
  std::vector<ClosestPoint> batch(PointsRef queries, std::span<const int> hints, double max_distance,
                                  const char* mask) const;
};

void SurfaceIndex::Impl::build_boundary(std::span<const KeyedIndex> edges) {
  const int nf = mesh.face_count();
  // A slot whose key neither neighbour shares is an edge of exactly one face.
  Buffer<std::uint8_t> alone(edges.size());
  parallel_for(0, edges.size(), [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const bool same_before = i > 0 && edges[i - 1].key == edges[i].key;
      const bool same_after = i + 1 < edges.size() && edges[i + 1].key == edges[i].key;
      alone[static_cast<std::size_t>(edges[i].index)] = !same_before && !same_after;
    }
  }, 4096);
  edge_boundary = Buffer<std::uint8_t>(static_cast<std::size_t>(nf));
  parallel_for(0, static_cast<std::size_t>(nf), [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f)
      edge_boundary[f] = static_cast<std::uint8_t>(alone[3 * f] | (alone[3 * f + 1] << 1) | (alone[3 * f + 2] << 2));
  }, 4096);
  // The boundary's vertices: few faces have a boundary edge, so one pass on this thread.
  vertex_boundary.assign(static_cast<std::size_t>(mesh.vertex_count()), 0);
  for (int f = 0; f < nf; ++f) {
    const std::uint8_t bits = edge_boundary[static_cast<std::size_t>(f)];
    if (!bits) continue;
    for (int k = 0; k < 3; ++k)
      if ((bits >> k) & 1u) mark_boundary_vertices(f, k);
  }
}

void SurfaceIndex::Impl::build_subset_adjacency(std::span<const KeyedIndex> edges, bool with_boundary) {
  const int nf = mesh.face_count();
  if (with_boundary) {
    edge_boundary = Buffer<std::uint8_t>(static_cast<std::size_t>(nf));
    std::fill(edge_boundary.begin(), edge_boundary.end(), std::uint8_t{0});
    vertex_boundary.assign(static_cast<std::size_t>(mesh.vertex_count()), 0);
  }
  edge_start.clear();
  edge_slots.resize(edges.size());
  slot_edge.resize(edges.size());
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i + 1;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    const auto group = static_cast<std::int32_t>(edge_start.size());
    edge_start.push_back(static_cast<std::int32_t>(i));
    for (std::size_t k = i; k < j; ++k) {
      edge_slots[k] = edges[k].index;
      slot_edge[static_cast<std::size_t>(edges[k].index)] = group;
    }
    if (with_boundary && j - i == 1) {  // an edge of exactly one face
      const int f = edges[i].index / 3;
      const int k = edges[i].index % 3;
      edge_boundary[static_cast<std::size_t>(f)] |= static_cast<std::uint8_t>(1u << k);
      mark_boundary_vertices(f, k);
    }
    i = j;
  }
  edge_start.push_back(static_cast<std::int32_t>(edges.size()));
  const int nv = mesh.vertex_count();
  vertex_start.assign(static_cast<std::size_t>(nv) + 1, 0);
  for (int f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) ++vertex_start[static_cast<std::size_t>(mesh.F(f, k)) + 1];
  for (int v = 0; v < nv; ++v) vertex_start[static_cast<std::size_t>(v) + 1] += vertex_start[static_cast<std::size_t>(v)];
  vertex_faces.resize(static_cast<std::size_t>(3) * nf);
  std::vector<std::int32_t> fill(vertex_start.begin(), vertex_start.end() - 1);
  for (int f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) vertex_faces[static_cast<std::size_t>(fill[static_cast<std::size_t>(mesh.F(f, k))]++)] = f;
}

bool SurfaceIndex::Impl::masked_edge_boundary(int group, const char* mask) const {
  int in = 0;
  for (std::int32_t i = edge_start[static_cast<std::size_t>(group)]; i < edge_start[static_cast<std::size_t>(group) + 1]; ++i)
    in += mask[edge_slots[static_cast<std::size_t>(i)] / 3] != 0;
  return in == 1;
}

bool SurfaceIndex::Impl::masked_on_boundary(int f, int region, const char* mask) const {
  if (region >= 1 && region <= 3) return masked_edge_boundary(slot_edge[static_cast<std::size_t>(3 * f + region - 1)], mask);
  if (region < 4) return false;
  // A vertex on an edge that exactly one face of the subset has.
  const int v = mesh.F(f, region - 4);
  for (std::int32_t i = vertex_start[static_cast<std::size_t>(v)]; i < vertex_start[static_cast<std::size_t>(v) + 1]; ++i) {
    const int g = vertex_faces[static_cast<std::size_t>(i)];
    if (!mask[g]) continue;
    for (int k = 0; k < 3; ++k)
      if ((mesh.F(g, k) == v || mesh.F(g, (k + 1) % 3) == v) && masked_edge_boundary(slot_edge[static_cast<std::size_t>(3 * g + k)], mask))
        return true;
  }
  return false;
}

void SurfaceIndex::Impl::build_scene() {
  serialize_library_threads();  // the ThreadSanitizer build only (kernels/parallel.h)
  device = rtcNewDevice(nullptr);
  if (!device)
    throw std::runtime_error(std::string("SurfaceIndex: cannot create the Embree device (") +
                             error_name(static_cast<int>(rtcGetDeviceError(nullptr))) + ")");
  rtcSetDeviceErrorFunction(device, &on_device_error, &errors);

  scene = rtcNewScene(device);
  check("create a scene");
  if (!scene) throw std::runtime_error("SurfaceIndex: Embree returned no scene");
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);

  const int nv = mesh.vertex_count();
  const int nf = mesh.face_count();
  if (nf > 0) {
    GeometryGuard geom{rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE)};
    check("create the triangle geometry");
    auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom.geometry, RTC_BUFFER_TYPE_VERTEX, 0,
                                                           RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                                           static_cast<std::size_t>(nv)));
    check("allocate the vertex buffer");
    auto* ib = static_cast<unsigned*>(
        rtcSetNewGeometryBuffer(geom.geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                3 * sizeof(unsigned), static_cast<std::size_t>(nf)));
    check("allocate the index buffer");
    if (!vb || !ib) throw std::runtime_error("SurfaceIndex: Embree returned no buffer");
    for (int v = 0; v < nv; ++v)
      for (int k = 0; k < 3; ++k) vb[3 * v + k] = static_cast<float>(mesh.V(v, k) - origin[k]);
    for (int f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) ib[3 * f + k] = static_cast<unsigned>(mesh.F(f, k));
    rtcSetGeometryBuildQuality(geom.geometry, RTC_BUILD_QUALITY_HIGH);
    rtcCommitGeometry(geom.geometry);
    rtcAttachGeometry(scene, geom.geometry);
    check("attach the triangle geometry");
  }
  {
    const FloatingPointTrapsOff traps_off;
    rtcCommitScene(scene);
  }
  check("build the BVH");
}

namespace {

struct QueryState {
  const Triangle* triangles;  // kEmbree: per face
  Vec3 p;
  Vec3 best_point = Vec3::Zero();
  double best_d2 = kInf;
  int best_face = kNoFace;
  int best_region = 0;
  double slack = 0.0;
  const char* mask = nullptr;  // faces that count (null: all)

  // Exact distance to face f with corners a, b, c; keeps the lexicographic minimum of
  // (distance², face), so the answer does not depend on the visiting order (hint or not,
  // tree order).
  bool exact(int f, const Vec3& a, const Vec3& b, const Vec3& c) {
    int region = 0;
    const Vec3 q = closest_on_triangle(p, a, b, c, region);
    const double d2 = (p - q).squaredNorm();
    if (d2 < best_d2 || (d2 == best_d2 && f < best_face)) {
      best_d2 = d2;
      best_face = f;
      best_region = region;
      best_point = q;
      return true;
    }
    return false;
  }
  // The same behind the triangle's disc bound (Embree's path).
  bool consider(int f) {
    if (mask && !mask[f]) return false;
    const Triangle& t = triangles[f];
    // d² ≥ lb² > best_d2: the triangle can neither win nor tie. The bound's own rounding is
    // under 1e-15 of (lb² + |p − centre|²); the margin is a thousandfold.
    const double lb2 = t.lower_bound2(p);
    if (lb2 > best_d2 && lb2 - best_d2 > 1e-12 * (lb2 + (p - t.centre).squaredNorm())) return false;
    return exact(f, t.a, t.b, t.c);
  }
};

// Beyond this magnitude (query distance plus leaf size) single precision is not used: squares
// would overflow.
constexpr double kFloatReach = 1e18;

// A leaf of the box tree: single-precision distances to all its triangles, then the exact test
// for those that may be nearest, nearest first, against the best so far. The float distance of
// a lane errs by less than 1e-6 of (|q| + radius) (a few roundings of quantities of that size:
// the relative coordinates, the unit frame, the corners in it); triangles are passed over only
// when farther than the best by 1e-5 of it, a tenfold margin. Ties and the minimum itself
// always reach the exact test.
void visit_leaf(const LeafPack& k, const Corners* corners, const std::vector<int>& faces, QueryState& st) {
  const Vec3 q = st.p - k.origin;
  const double reach = q.norm() + k.radius;
  std::uint32_t todo = (std::uint32_t{1} << k.count) - 1;
  if (st.mask)
    for (int l = 0; l < k.count; ++l)
      if (!st.mask[faces[static_cast<std::size_t>(k.first + l)]]) todo &= ~(std::uint32_t{1} << l);
  if (!todo) return;
  float d[LeafPack::kLanes];
  if (reach < kFloatReach) {
    lane_distances(k, static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()), d);
  } else {
    std::fill(d, d + LeafPack::kLanes, 0.0f);
  }
  for (std::uint32_t a = k.always; a; a &= a - 1) d[std::countr_zero(a)] = 0.0f;
  const double margin = 1e-5 * reach;
  const auto threshold = [&] {
    const double r = std::sqrt(st.best_d2) + margin;
    return r * r * (1.0 + 1e-6);
  };
  // The lanes farther than the best so far leave now, all at once: the best only shrinks, so
  // the loop below would stop before reaching any of them. The rest are tested in the same
  // order as before.
  if (st.best_d2 < kInf) {
    // d ≤ t exactly when d ≤ the largest float not above t (t > 0: the float below a
    // positive float, +∞ included, is the one whose bits are one less).
    const double t = threshold();
    float tf = static_cast<float>(t);
    if (static_cast<double>(tf) > t) tf = std::bit_cast<float>(std::bit_cast<std::uint32_t>(tf) - 1u);
    std::uint32_t near = 0;
    for (int o = 0; o < LeafPack::kLanes; o += 4) near |= lanes_at_most(load_lanes<Float4>(d + o), tf) << o;
    todo &= near;
  }
  while (todo) {
    int lane = std::countr_zero(todo);
    for (std::uint32_t m = todo & (todo - 1); m; m &= m - 1) {
      const int l = std::countr_zero(m);
      if (d[l] < d[lane]) lane = l;
    }
    if (st.best_d2 < kInf && static_cast<double>(d[lane]) > threshold()) break;
    const std::size_t pos = static_cast<std::size_t>(k.first + lane);
    const Corners& c = corners[pos];
    st.exact(faces[pos], c[0], c[1], c[2]);
    todo &= ~(std::uint32_t{1} << lane);
  }
}

// Embree calls this for every triangle in a visited leaf; shrinking the radius prunes the
// rest of the traversal.
bool point_query_callback(RTCPointQueryFunctionArguments* args) {
  auto* state = static_cast<QueryState*>(args->userPtr);
  if (!state->consider(static_cast<int>(args->primID))) return false;
  const float radius = search_radius(std::sqrt(state->best_d2), state->slack);
  if (radius < args->query->radius) {
    args->query->radius = radius;
    return true;
  }
  return false;
}

}  // namespace

ClosestPoint SurfaceIndex::Impl::query(const Vec3& p, int hint_face, double max_distance, const char* mask) const {
  if (log && max_distance == kInf && !mask) [[unlikely]] {
    const std::lock_guard<std::mutex> lock(log_mutex);
    log->push_back({p, hint_face});
  }
#ifdef FLANK_SLOW_QUERIES
  // A deliberate regression for test builds only (CMake -DFLANK_SLOW_QUERIES=ON): every
  // query is answered twice. It exists to prove that `scripts/scaling-report --check` catches
  // a slowdown; release builds never define it.
  volatile const int twice = query_once(p, hint_face, max_distance, mask).face;
  (void)twice;
#endif
  return query_once(p, hint_face, max_distance, mask);
}

ClosestPoint SurfaceIndex::Impl::query_once(const Vec3& p, int hint_face, double max_distance,
                                            const char* mask) const {
  ClosestPoint out;
  const int nf = mesh.face_count();
  if (nf == 0) return out;

  QueryState state{triangles.data(), p};
  state.slack = slack;
  state.mask = mask;
  // A bound a little wide of max_distance² (its rounding), the answer checked against
  // max_distance itself below: a face at exactly max_distance counts.
  const double bound2 = max_distance < kInf ? max_distance * max_distance * (1.0 + 1e-12) : kInf;
  state.best_d2 = bound2;
  const bool hinted = hint_face >= 0 && hint_face < nf && (!mask || mask[hint_face]);
  if (engine == QueryEngine::kEmbree) {
    alignas(16) RTCPointQuery q;
    q.x = static_cast<float>(p.x() - origin.x());
    q.y = static_cast<float>(p.y() - origin.y());
    q.z = static_cast<float>(p.z() - origin.z());
    q.time = 0.0f;
    q.radius = bound2 < kInf ? search_radius(std::sqrt(bound2), slack) : std::numeric_limits<float>::infinity();
    // Embree 3 culls BVH nodes against the radius the query starts with and applies the
    // shrunk radius only when popping its stack, so a tight start is what makes warm queries
    // cheap.
    if (hinted) {
      state.consider(hint_face);
      q.radius = search_radius(std::sqrt(state.best_d2), slack);
    }
    RTCPointQueryContext context;
    rtcInitPointQueryContext(&context);
    rtcPointQuery(scene, &q, &context, &point_query_callback, &state);
  } else if (engine == QueryEngine::kCells) {
    // Every face within max_distance ≤ reach of p is listed in p's cell; no other can answer.
    for (const std::int32_t f : cells.items_at(p)) {
      if (mask && !mask[f]) continue;
      state.exact(f, mesh.V.row(mesh.F(f, 0)), mesh.V.row(mesh.F(f, 1)), mesh.V.row(mesh.F(f, 2)));
    }
  } else {
    // The hint's exact distance bounds the search from the start.
    if (hinted) {
      const Corners& c = leaf_corners[static_cast<std::size_t>(face_position[static_cast<std::size_t>(hint_face)])];
      state.exact(hint_face, c[0], c[1], c[2]);
    }
    tree.nearest(p, state.best_d2, [&](std::int32_t leaf) {
      visit_leaf(packs[static_cast<std::size_t>(leaf)], leaf_corners.data(), tree.order(), state);
    });
  }
  if (state.best_face == kNoFace) return out;

  if (std::sqrt(state.best_d2) > max_distance) return out;
  const int f = state.best_face;
  const Vec3 normal = normals.row(f);
  const Vec3 diff = p - state.best_point;
  out.point = state.best_point;
  out.face = f;
  out.distance = std::sqrt(state.best_d2);
  if (out.distance > on_surface) {
    out.direction = diff / out.distance;
  } else {
    out.direction = normal;
  }
  out.signed_distance = diff.dot(normal) < 0.0 ? -out.distance : out.distance;

  bool on_boundary = false;
  const int region = state.best_region;
  if (mask)
    on_boundary = masked_on_boundary(f, region, mask);
  else if (region >= 1 && region <= 3)
    on_boundary = (edge_boundary[static_cast<std::size_t>(f)] >> (region - 1)) & 1u;
  else if (region >= 4)
    on_boundary = vertex_boundary[static_cast<std::size_t>(mesh.F(f, region - 4))] != 0;
  // Beyond the edge, not above it: g leaves the normal direction.
  out.boundary = on_boundary && std::abs(out.direction.dot(normal)) < 1.0 - 1e-9;
  out.on_boundary = on_boundary;
  return out;
}

SurfaceIndex::SurfaceIndex(const Mesh& mesh, QueryEngine engine) : SurfaceIndex(mesh, engine, kInf, 0) {}

SurfaceIndex SurfaceIndex::within_reach(Mesh mesh, double reach, std::size_t queries) {
  if (!(reach > 0.0) || !std::isfinite(reach))
    throw std::invalid_argument("SurfaceIndex::within_reach: the reach must be positive and finite");
  return SurfaceIndex(std::move(mesh), QueryEngine::kCells, reach, queries);
}

namespace {
// Whether `queries` bounded queries cost more on a grid of cells listing `entries` faces in
// `cells` cells than on a box tree over `faces` faces, its build included. Measured on Ω's
// indices of the faces of tests/data and of the 1M-triangle cone (one thread, per face and
// per query, in µs): the cells' build 0.10–0.11 and a query 0.26 plus 0.0103 per face its
// cell lists (16.7 faces on the faces' Ω, 394 on the 1M cone's finish, whose vertex band is
// ten tolerances wide over faces a tenth of that); the tree's build 0.45–0.48 and a query
// 0.45–0.58, whatever the reach. The tree wins where Q (items − 28) > 35 F; the rule asks for
// twice that on both sides, the mean over the occupied cells standing for the cells queried.
bool tree_is_cheaper(std::size_t queries, std::size_t faces, std::size_t entries, std::size_t cells) {
  if (queries == 0 || cells == 0) return false;
  const double items = static_cast<double>(entries) / static_cast<double>(cells);
  return static_cast<double>(queries) * (items - 32.0) > 64.0 * static_cast<double>(faces);
}
}  // namespace

SurfaceIndex::SurfaceIndex(Mesh mesh_given, QueryEngine engine, double reach, std::size_t queries)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.engine = engine;
  m.reach = reach;
  m.mesh = std::move(mesh_given);
  const Mesh& mesh = m.mesh;
  const int nf = mesh.face_count();
  if (m.engine == QueryEngine::kCells) {
    // An index for a few bounded queries (Ω's): its two builds are independent, so they run
    // side by side: the faces' adjacency after the edges' sort (mostly serial), and the faces'
    // boxes and their cell table (both on every thread: kernels/cell_grid.h), which is two
    // thirds of the work. Each writes its own members; the result does not depend on which
    // ends first.
    // Queries read the corners from the mesh: a table of them (72 bytes a face) was fresh
    // memory whose first touch, on Ω's 104k faces of the 13k cone part, cost 2k page faults.
    const double scale = m.set_frame();
    const double grow = reach * (1.0 + 1e-9) + 1e-12 * scale;
    parallel_invoke_each(2, [&](std::size_t task) {
      if (task == 0) {
        const Buffer<KeyedIndex> edges = sorted_edge_slots(mesh);
        // Through the flag, so that masked queries find it done.
        std::call_once(m.subset_once, [&] { m.build_subset_adjacency(edges, true); });
        return;
      }
      // Each face's box grown by the reach (a little wider, and by the coordinates'
      // rounding): a point within the reach of a face lies in the grown box.
      Buffer<Vec3> lo(static_cast<std::size_t>(nf)), hi(static_cast<std::size_t>(nf));
      parallel_for(0, static_cast<std::size_t>(nf), [&](std::size_t begin, std::size_t end) {
        for (std::size_t f = begin; f < end; ++f) {
          const auto i = static_cast<Eigen::Index>(f);
          const Vec3 a = mesh.V.row(mesh.F(i, 0)), b = mesh.V.row(mesh.F(i, 1));
          const Vec3 c = mesh.V.row(mesh.F(i, 2));
          lo[f] = (a.cwiseMin(b).cwiseMin(c).array() - grow).matrix();
          hi[f] = (a.cwiseMax(b).cwiseMax(c).array() + grow).matrix();
        }
      }, 4096);
      m.cells = CellGrid(lo, hi);
    });
    // Told of many queries where a cell lists many faces (a reach many faces wide): the tree
    // answers them for less, its build included, with the same answers (tree_is_cheaper).
    if (tree_is_cheaper(queries, static_cast<std::size_t>(nf), m.cells.entries(), m.cells.cells())) {
      m.engine = QueryEngine::kBoxTree;
      m.cells = CellGrid();
      m.build_search(corner_table(mesh), 1e-12 * scale);
    }
    return;
  }
  // The boundary (from the sorted edges) and the rest (the frame, the corners and the search
  // structure) are independent and each writes its own members, so they are built side by
  // side from the start: the other thread takes the edges' work while this one makes the
  // normals and corners and the tree's top splits. The search structure, which makes
  // the large allocations, is built on this thread, and the edges' buffer is allocated here
  // too: from a worker thread's heap they were unmapped when freed, and the next index of a
  // large mesh faulted them in again (the 256k cone rung in a loop: 51k page faults before
  // the two ran side by side, 167k after, 50k with this).
  Buffer<KeyedIndex> edges(static_cast<std::size_t>(nf) * 3);
  run_beside(
      [&] {
        fill_sorted_edge_slots(mesh, edges);
        m.build_boundary(edges);
      },
      [&] {
        const double scale = m.set_frame();
        m.build_search(corner_table(mesh), 1e-12 * scale);
      });
}

double SurfaceIndex::Impl::set_frame() {
  normals = face_normals(mesh);
  const BoundingBox box = bounding_box(mesh);
  origin = 0.5 * (box.min + box.max);
  diagonal = box.diagonal();
  slack = 1e-6 * diagonal;
  // Footpoints are rounded relative to the coordinates' magnitude, not to the diagonal.
  const double scale = std::max({diagonal, box.min.cwiseAbs().maxCoeff(), box.max.cwiseAbs().maxCoeff()});
  on_surface = 1e-14 * scale;
  return scale;
}

void SurfaceIndex::Impl::build_search(std::span<const Corners> corners, double pad) {
  const int nf = mesh.face_count();
  if (engine == QueryEngine::kEmbree) {
    triangles.resize(corners.size());
    for (int f = 0; f < nf; ++f) {
      const Corners& c = corners[static_cast<std::size_t>(f)];
      Triangle& t = triangles[static_cast<std::size_t>(f)];
      t.a = c[0], t.b = c[1], t.c = c[2];
      t.centre = (t.a + t.b + t.c) / 3.0;
      const Vec3 n = normals.row(f);
      t.normal = n.allFinite() ? n : Vec3::Zero();
      // Rounded up a little: the disc must hold the triangle whatever the rounding.
      t.radius = std::max({(t.a - t.centre).norm(), (t.b - t.centre).norm(), (t.c - t.centre).norm()}) *
                 (1.0 + 1e-12) + 1e-300;
      t.thickness = t.normal == Vec3::Zero()
                        ? 0.0
                        : 2.0 * std::max({std::abs(t.normal.dot(t.a - t.centre)), std::abs(t.normal.dot(t.b - t.centre)),
                                          std::abs(t.normal.dot(t.c - t.centre))}) + on_surface;
    }
    build_scene();
  } else {
    build_tree(corners, pad);
  }
}

namespace {

// Lane l of pack k holds triangle c, in single precision relative to k.origin; a sliver whose
// frame single precision cannot hold goes to k.always.
void pack_lane(LeafPack& k, int l, const Corners& c) {
  const Vec3 a = c[0] - k.origin;
  const Vec3 ab = c[1] - c[0], ac = c[2] - c[0];
  const double lab = ab.norm();
  Vec3 e1 = Vec3::Zero(), e2 = Vec3::Zero(), n = Vec3::Zero();
  double bx = 0, cx = 0, cy = 0;
  bool ok = lab > 0.0 && k.radius < kFloatReach;
  if (ok) {
    e1 = ab / lab;
    const Vec3 cr = e1.cross(ac);
    const double lcr = cr.norm();
    ok = lcr > 1e-6 * std::max(lab, ac.norm());  // not a sliver for float frames
    if (ok) {
      n = cr / lcr;
      e2 = n.cross(e1);
      bx = lab, cx = ac.dot(e1), cy = ac.dot(e2);
    }
  }
  if (!ok) {
    k.always |= std::uint32_t{1} << l;
    e1 = e2 = n = Vec3::Zero();
    bx = cx = cy = 0.0;
  }
  const auto f = [](double x) { return static_cast<float>(x); };
  const Vec3 af = ok ? a : Vec3::Zero();
  k.ax[l] = f(af.x()), k.ay[l] = f(af.y()), k.az[l] = f(af.z());
  k.e1x[l] = f(e1.x()), k.e1y[l] = f(e1.y()), k.e1z[l] = f(e1.z());
  k.e2x[l] = f(e2.x()), k.e2y[l] = f(e2.y()), k.e2z[l] = f(e2.z());
  k.nx[l] = f(n.x()), k.ny[l] = f(n.y()), k.nz[l] = f(n.z());
  k.bx[l] = f(bx), k.cx[l] = f(cx), k.cy[l] = f(cy);
  // 1/|e|² of the float corners, so that t = 1 lands on the stored end.
  const auto inv = [](double x2) { return x2 > 0.0 ? static_cast<float>(1.0 / x2) : 0.0f; };
  const double fbx = k.bx[l], fcx = k.cx[l], fcy = k.cy[l];
  k.inv_ab[l] = ok ? inv(fbx * fbx) : 0.0f;
  k.inv_ac[l] = ok ? inv(fcx * fcx + fcy * fcy) : 0.0f;
  k.inv_bc[l] = ok ? inv((fcx - fbx) * (fcx - fbx) + fcy * fcy) : 0.0f;
}

}  // namespace

void SurfaceIndex::Impl::build_tree(std::span<const Corners> corners, double pad) {
  tree = ObbTree(corners, pad);
  const std::vector<int>& order = tree.order();
  leaf_corners = Buffer<Corners>(order.size());
  face_position = Buffer<std::int32_t>(order.size());
  parallel_for(0, order.size(), [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      leaf_corners[i] = corners[static_cast<std::size_t>(order[i])];
      face_position[static_cast<std::size_t>(order[i])] = static_cast<std::int32_t>(i);
    }
  }, 1024);
  const std::span<const ObbLeaf> leaves = tree.leaves();
  packs = Buffer<LeafPack>(leaves.size());
  parallel_for(0, leaves.size(), [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      LeafPack& k = packs[i];
      k.radius = 0.0;  // every lane's arrays are written below (pack_lane)
      k.always = 0;
      k.first = leaves[i].first;
      k.count = leaves[i].count;
      assert(k.count >= 1 && k.count <= LeafPack::kLanes);
      Vec3 sum = Vec3::Zero();
      for (int l = 0; l < k.count; ++l) {
        const Corners& c = leaf_corners[static_cast<std::size_t>(k.first + l)];
        sum += c[0] + c[1] + c[2];
      }
      k.origin = sum / (3.0 * k.count);
      for (int l = 0; l < k.count; ++l) {
        const Corners& c = leaf_corners[static_cast<std::size_t>(k.first + l)];
        for (const Vec3* v : {&c[0], &c[1], &c[2]}) k.radius = std::max(k.radius, (*v - k.origin).norm());
      }
      // Unused lanes repeat lane 0: their arithmetic stays finite, their results unread.
      for (int l = 0; l < LeafPack::kLanes; ++l)
        pack_lane(k, l, leaf_corners[static_cast<std::size_t>(k.first + (l < k.count ? l : 0))]);
      k.always &= (std::uint32_t{1} << k.count) - 1;
    }
  }, 32);
}

SurfaceIndex::~SurfaceIndex() = default;
SurfaceIndex::SurfaceIndex(SurfaceIndex&&) noexcept = default;
SurfaceIndex& SurfaceIndex::operator=(SurfaceIndex&&) noexcept = default;

const Mesh& SurfaceIndex::mesh() const { return impl_->mesh; }
double SurfaceIndex::diagonal() const { return impl_->diagonal; }
QueryEngine SurfaceIndex::engine() const { return impl_->engine; }
const Points& SurfaceIndex::normals() const { return impl_->normals; }

bool SurfaceIndex::is_boundary_vertex(int v) const {
  assert(v >= 0 && v < impl_->mesh.vertex_count());
  return impl_->vertex_boundary[static_cast<std::size_t>(v)] != 0;
}

namespace {
void require_unbounded(double reach) {
  if (reach < kInf)
    throw std::logic_error("SurfaceIndex: an index made by within_reach answers bounded queries only");
}
}  // namespace

ClosestPoint SurfaceIndex::closest_point(const Vec3& p, int hint_face) const {
  require_unbounded(impl_->reach);
  return impl_->query(p, hint_face);
}

std::vector<ClosestPoint> SurfaceIndex::Impl::batch(PointsRef queries, std::span<const int> hints,
                                                    double max_distance, const char* mask) const {
  assert(hints.empty() || hints.size() == static_cast<std::size_t>(queries.rows()));
  const auto count = static_cast<std::size_t>(queries.rows());
  std::vector<ClosestPoint> out(count);
  parallel_for(
      0, count,
      [&](std::size_t begin, std::size_t end) {
        // Without a hint, the previous query's face: batches are coherent (along lines, rows).
        int previous = -1;
        for (std::size_t i = begin; i < end; ++i) {
          const int hint = i < hints.size() ? hints[i] : previous;
          out[i] = query(queries.row(static_cast<Eigen::Index>(i)), hint, max_distance, mask);
          previous = out[i].face;
        }
      },
      64);
  return out;
}

std::vector<ClosestPoint> SurfaceIndex::closest_points(PointsRef queries,
                                                       std::span<const int> hints) const {
  require_unbounded(impl_->reach);
  return impl_->batch(queries, hints, kInf, nullptr);
}

std::vector<ClosestPoint> SurfaceIndex::closest_points_within(PointsRef queries, double max_distance,
                                                              std::span<const char> face_mask) const {
  assert(max_distance >= 0.0);
  assert(face_mask.empty() || face_mask.size() == static_cast<std::size_t>(impl_->mesh.face_count()));
  if (max_distance > impl_->reach)
    throw std::logic_error("SurfaceIndex: a bounded query looks farther than the index's reach");
  if (!face_mask.empty()) impl_->need_subset_adjacency();
  return impl_->batch(queries, {}, max_distance, face_mask.empty() ? nullptr : face_mask.data());
}

void SurfaceIndex::record_queries(std::vector<RecordedQuery>* log) { impl_->log = log; }

void SurfaceIndex::closest_points_serial(PointsRef queries, std::span<const int> hints,
                                         std::span<ClosestPoint> out) const {
  assert(hints.empty() || hints.size() == static_cast<std::size_t>(queries.rows()));
  assert(out.size() == static_cast<std::size_t>(queries.rows()));
  require_unbounded(impl_->reach);
  const std::size_t count = std::min(out.size(), static_cast<std::size_t>(queries.rows()));
  const Impl& m = *impl_;
  int previous = -1;
  for (std::size_t i = 0; i < count; ++i) {
    const int hint = i < hints.size() ? hints[i] : previous;
    out[i] = m.query(queries.row(static_cast<Eigen::Index>(i)), hint);
    previous = out[i].face;
  }
}

}  // namespace flank
