#include "kernels/surface_index.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cfenv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>

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

struct SurfaceIndex::Impl {
  Mesh mesh;
  Points normals;
  std::vector<Triangle> triangles;          // per face, double precision, for the exact callback
  QueryEngine engine = QueryEngine::kBoxTree;
  ObbTree tree;                             // kBoxTree
  std::vector<Triangle> leaf_triangles;     // kBoxTree: triangles in tree.order(), contiguous
  std::vector<int> leaf_faces;              // kBoxTree: their faces
  std::vector<std::uint8_t> edge_boundary;  // per face, bit k: edge (k, k+1 mod 3) is a boundary
  std::vector<std::uint8_t> vertex_boundary;
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

  void build_adjacency();
  void build_scene();
  void build_tree(double pad);

  ClosestPoint query(const Vec3& p, int hint_face) const;
  ClosestPoint query_once(const Vec3& p, int hint_face) const;
};

void SurfaceIndex::Impl::build_adjacency() {
  const int nf = mesh.face_count();
  std::vector<std::pair<std::uint64_t, int>> edges;  // (min,max) vertex key, 3 f + k
  edges.reserve(static_cast<std::size_t>(nf) * 3);
  for (int f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const auto u = static_cast<std::uint32_t>(mesh.F(f, k));
      const auto v = static_cast<std::uint32_t>(mesh.F(f, (k + 1) % 3));
      const std::uint64_t key = (std::uint64_t{std::min(u, v)} << 32) | std::max(u, v);
      edges.emplace_back(key, 3 * f + k);
    }
  std::sort(edges.begin(), edges.end());
  edge_boundary.assign(static_cast<std::size_t>(nf), 0);
  vertex_boundary.assign(static_cast<std::size_t>(mesh.vertex_count()), 0);
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i + 1;
    while (j < edges.size() && edges[j].first == edges[i].first) ++j;
    if (j - i == 1) {  // an edge of exactly one face
      const int f = edges[i].second / 3;
      const int k = edges[i].second % 3;
      edge_boundary[static_cast<std::size_t>(f)] |= static_cast<std::uint8_t>(1u << k);
      vertex_boundary[static_cast<std::size_t>(mesh.F(f, k))] = 1;
      vertex_boundary[static_cast<std::size_t>(mesh.F(f, (k + 1) % 3))] = 1;
    }
    i = j;
  }
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
  const Triangle* triangles;
  Vec3 p;
  Vec3 best_point = Vec3::Zero();
  double best_d2 = kInf;
  int best_face = kNoFace;
  int best_region = 0;
  double slack = 0.0;

  // Exact distance to face f; keeps the lexicographic minimum of (distance², face), so the
  // answer does not depend on the visiting order (hint or not, BVH order).
  bool consider(int f) { return consider(f, triangles[f]); }
  bool consider(int f, const Triangle& t) {
    int region = 0;
    // d² ≥ lb² > best_d2: the triangle can neither win nor tie. The bound's own rounding is
    // under 1e-15 of (lb² + |p − centre|²); the margin is a thousandfold.
    const double lb2 = t.lower_bound2(p);
    if (lb2 > best_d2 && lb2 - best_d2 > 1e-12 * (lb2 + (p - t.centre).squaredNorm())) return false;
    const Vec3 q = closest_on_triangle(p, t.a, t.b, t.c, region);
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
};

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

ClosestPoint SurfaceIndex::Impl::query(const Vec3& p, int hint_face) const {
#ifdef FLANK_SLOW_QUERIES
  // A deliberate regression for test builds only (CMake -DFLANK_SLOW_QUERIES=ON): every
  // query is answered twice. It exists to prove that `scripts/scaling-report --check` catches
  // a slowdown; release builds never define it.
  volatile const int twice = query_once(p, hint_face).face;
  (void)twice;
#endif
  return query_once(p, hint_face);
}

ClosestPoint SurfaceIndex::Impl::query_once(const Vec3& p, int hint_face) const {
  ClosestPoint out;
  if (triangles.empty()) return out;

  QueryState state{triangles.data(), p};
  state.slack = slack;
  alignas(16) RTCPointQuery q;
  q.x = static_cast<float>(p.x() - origin.x());
  q.y = static_cast<float>(p.y() - origin.y());
  q.z = static_cast<float>(p.z() - origin.z());
  q.time = 0.0f;
  q.radius = std::numeric_limits<float>::infinity();
  // Embree 3 culls BVH nodes against the radius the query starts with and applies the
  // shrunk radius only when popping its stack, so a tight start is what makes warm queries
  // cheap.
  if (hint_face >= 0 && hint_face < static_cast<int>(triangles.size())) {
    state.consider(hint_face);
    q.radius = search_radius(std::sqrt(state.best_d2), slack);
  }
  if (engine == QueryEngine::kEmbree) {
    RTCPointQueryContext context;
    rtcInitPointQueryContext(&context);
    rtcPointQuery(scene, &q, &context, &point_query_callback, &state);
  } else {
    tree.nearest(p, state.best_d2, [&](std::int32_t i) {
      state.consider(leaf_faces[static_cast<std::size_t>(i)],
                     leaf_triangles[static_cast<std::size_t>(i)]);
    });
  }
  if (state.best_face == kNoFace) return out;

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
  if (region >= 1 && region <= 3)
    on_boundary = (edge_boundary[static_cast<std::size_t>(f)] >> (region - 1)) & 1u;
  else if (region >= 4)
    on_boundary = vertex_boundary[static_cast<std::size_t>(mesh.F(f, region - 4))] != 0;
  // Beyond the edge, not above it: g leaves the normal direction.
  out.boundary = on_boundary && std::abs(out.direction.dot(normal)) < 1.0 - 1e-9;
  out.on_boundary = on_boundary;
  return out;
}

SurfaceIndex::SurfaceIndex(const Mesh& mesh, QueryEngine engine)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.engine = engine;
  m.mesh = mesh;
  m.normals = face_normals(mesh);
  const BoundingBox box = bounding_box(mesh);
  m.origin = 0.5 * (box.min + box.max);
  m.diagonal = box.diagonal();
  m.slack = 1e-6 * m.diagonal;
  // Footpoints are rounded relative to the coordinates' magnitude, not to the diagonal.
  const double scale =
      std::max({m.diagonal, box.min.cwiseAbs().maxCoeff(), box.max.cwiseAbs().maxCoeff()});
  m.on_surface = 1e-14 * scale;

  const int nf = mesh.face_count();
  m.triangles.resize(static_cast<std::size_t>(nf));
  for (int f = 0; f < nf; ++f) {
    Triangle& t = m.triangles[static_cast<std::size_t>(f)];
    t.a = mesh.V.row(mesh.F(f, 0));
    t.b = mesh.V.row(mesh.F(f, 1));
    t.c = mesh.V.row(mesh.F(f, 2));
    t.centre = (t.a + t.b + t.c) / 3.0;
    const Vec3 n = (t.b - t.a).cross(t.c - t.a);
    const double area2 = n.norm();
    t.normal = area2 > 0.0 && std::isfinite(area2) ? Vec3(n / area2) : Vec3::Zero();
    // Rounded up a little: the disc must hold the triangle whatever the rounding.
    t.radius = std::max({(t.a - t.centre).norm(), (t.b - t.centre).norm(), (t.c - t.centre).norm()}) *
               (1.0 + 1e-12) + 1e-300;
    t.thickness = t.normal == Vec3::Zero()
                      ? 0.0
                      : 2.0 * std::max({std::abs(t.normal.dot(t.a - t.centre)), std::abs(t.normal.dot(t.b - t.centre)),
                                        std::abs(t.normal.dot(t.c - t.centre))}) + m.on_surface;
  }
  m.build_adjacency();
  if (m.engine == QueryEngine::kEmbree)
    m.build_scene();
  else
    m.build_tree(1e-12 * scale);
}

void SurfaceIndex::Impl::build_tree(double pad) {
  std::vector<std::array<Vec3, 3>> corners(triangles.size());
  for (std::size_t f = 0; f < triangles.size(); ++f)
    corners[f] = {triangles[f].a, triangles[f].b, triangles[f].c};
  tree = ObbTree(corners, pad);
  leaf_faces = tree.order();
  leaf_triangles.resize(leaf_faces.size());
  for (std::size_t i = 0; i < leaf_faces.size(); ++i)
    leaf_triangles[i] = triangles[static_cast<std::size_t>(leaf_faces[i])];
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

ClosestPoint SurfaceIndex::closest_point(const Vec3& p, int hint_face) const {
  return impl_->query(p, hint_face);
}

std::vector<ClosestPoint> SurfaceIndex::closest_points(PointsRef queries,
                                                       std::span<const int> hints) const {
  assert(hints.empty() || hints.size() == static_cast<std::size_t>(queries.rows()));
  const auto count = static_cast<std::size_t>(queries.rows());
  std::vector<ClosestPoint> out(count);
  const Impl& m = *impl_;
  parallel_for(
      0, count,
      [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
          const int hint = i < hints.size() ? hints[i] : -1;
          out[i] = m.query(queries.row(static_cast<Eigen::Index>(i)), hint);
        }
      },
      64);
  return out;
}

void SurfaceIndex::closest_points_serial(PointsRef queries, std::span<const int> hints,
                                         std::span<ClosestPoint> out) const {
  assert(hints.empty() || hints.size() == static_cast<std::size_t>(queries.rows()));
  assert(out.size() == static_cast<std::size_t>(queries.rows()));
  const std::size_t count = std::min(out.size(), static_cast<std::size_t>(queries.rows()));
  const Impl& m = *impl_;
  for (std::size_t i = 0; i < count; ++i) {
    const int hint = i < hints.size() ? hints[i] : -1;
    out[i] = m.query(queries.row(static_cast<Eigen::Index>(i)), hint);
  }
}

}  // namespace flank
