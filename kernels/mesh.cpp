#include "kernels/mesh.h"

#include <algorithm>
#include <cassert>
#include <cstdint>
#include <numeric>
#include <span>
#include <unordered_map>
#include <utility>
#include <vector>

#include "kernels/parallel.h"

namespace flank {

BoundingBox bounding_box(const Mesh& mesh) {
  BoundingBox box;
  if (mesh.V.rows() == 0) return box;
  box.min = mesh.V.colwise().minCoeff().transpose();
  box.max = mesh.V.colwise().maxCoeff().transpose();
  return box;
}

double bbox_diagonal(const Mesh& mesh) { return bounding_box(mesh).diagonal(); }

Points face_normals(const Mesh& mesh) {
  Points N(mesh.F.rows(), 3);
  parallel_for(0, static_cast<std::size_t>(mesh.F.rows()), [&](std::size_t begin, std::size_t end) {
    for (auto f = static_cast<Eigen::Index>(begin); f < static_cast<Eigen::Index>(end); ++f) {
      const Vec3 p0 = mesh.V.row(mesh.F(f, 0));
      const Vec3 n = (Vec3(mesh.V.row(mesh.F(f, 1))) - p0).cross(Vec3(mesh.V.row(mesh.F(f, 2))) - p0);
      const double len = n.norm();
      N.row(f) = len > 0 ? Vec3(n / len) : Vec3::Zero();
    }
  }, 1024);
  return N;
}

VecX face_areas(const Mesh& mesh) {
  VecX A(mesh.F.rows());
  parallel_for(0, static_cast<std::size_t>(mesh.F.rows()), [&](std::size_t begin, std::size_t end) {
    for (auto f = static_cast<Eigen::Index>(begin); f < static_cast<Eigen::Index>(end); ++f) {
      const Vec3 p0 = mesh.V.row(mesh.F(f, 0));
      const Vec3 p1 = mesh.V.row(mesh.F(f, 1)), p2 = mesh.V.row(mesh.F(f, 2));
      A(f) = 0.5 * (p1 - p0).cross(p2 - p0).norm();
    }
  }, 16384);
  return A;
}

VecX vertex_areas(const Mesh& mesh) {
  const VecX A = face_areas(mesh);
  VecX out = VecX::Zero(mesh.V.rows());
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) out(mesh.F(f, k)) += A(f) / 3.0;
  return out;
}

double total_area(const Mesh& mesh) { return face_areas(mesh).sum(); }

namespace {
template <class Item>
void radix_sort_items(std::span<Item> items, int key_bits) {
  constexpr int kDigitBits = 11;
  constexpr std::size_t kBuckets = std::size_t{1} << kDigitBits;
  constexpr std::size_t kChunk = 16384;  // below two of these, one chunk: a fork costs more
  const std::size_t n = items.size();
  if (n < 2) return;
  const auto threads = static_cast<std::size_t>(max_threads());
  const std::size_t chunks = std::clamp<std::size_t>(std::min(n / kChunk, threads), 1, 8);
  const auto bound = [&](std::size_t c) { return n * c / chunks; };
  Buffer<Item> spare(n);
  std::span<Item> from = items, to{spare.data(), n};
  // count[c][d]: chunk c's items with digit d; then where chunk c puts its next item of digit d.
  std::vector<std::size_t> count(chunks * kBuckets);
  for (int shift = 0; shift < key_bits; shift += kDigitBits) {
    std::fill(count.begin(), count.end(), 0);
    // Each loop's bounds and spans are locals: stored counts could alias captured ones.
    parallel_invoke_each(chunks, [&](std::size_t c) {
      std::size_t* h = &count[c * kBuckets];
      const Item *i = from.data() + bound(c), *end = from.data() + bound(c + 1);
      for (; i < end; ++i) ++h[(i->key >> shift) & (kBuckets - 1)];
    });
    std::size_t running = 0;
    bool one_digit = false;
    for (std::size_t d = 0; d < kBuckets; ++d) {
      const std::size_t first = running;
      for (std::size_t c = 0; c < chunks; ++c)
        running += std::exchange(count[c * kBuckets + d], running);
      one_digit = one_digit || running - first == n;
    }
    if (one_digit) continue;
    parallel_invoke_each(chunks, [&](std::size_t c) {
      std::size_t* next = &count[c * kBuckets];
      Item* out = to.data();
      const Item *i = from.data() + bound(c), *end = from.data() + bound(c + 1);
      for (; i < end; ++i) out[next[(i->key >> shift) & (kBuckets - 1)]++] = *i;
    });
    std::swap(from, to);
  }
  if (from.data() != items.data())
    parallel_for(0, n, [&](std::size_t begin, std::size_t end) {
      std::copy(from.data() + begin, from.data() + end, items.data() + begin);
    }, kChunk);
}
}  // namespace

void radix_sort_by_key(std::span<KeyedIndex> items, int key_bits) {
  radix_sort_items(items, key_bits);
}

void radix_sort_by_key(std::span<NarrowKeyedIndex> items, int key_bits) {
  assert(key_bits <= 32);
  radix_sort_items(items, key_bits);
}

// Not a comparison sort: the slots are counted into buckets by their edge's lower vertex in
// slot order (so each bucket holds its slots in slot order), then each bucket, a vertex's
// few edges, is sorted by the higher vertex. The order is total, so this is exactly the
// order std::sort gives, in time linear in the slots. The faces are counted and placed in up
// to eight chunks side by side: a chunk's slots go after those of the chunks before it in
// each bucket, which keeps slot order. Chunks from 4096 faces: two chunks write into the
// same buckets' cache lines, but a face's 24k faces placed on one thread cost more (the
// fiftieth part).
void fill_sorted_edge_slots(const Mesh& mesh, std::span<KeyedIndex> edges) {
  constexpr std::size_t kChunkFaces = 4096, kChunkVertices = 16384;
  const int nf = mesh.face_count();
  const auto nv = static_cast<std::size_t>(mesh.vertex_count());
  assert(edges.size() == static_cast<std::size_t>(nf) * 3);
  const auto faces = static_cast<std::size_t>(nf);
  const auto threads = static_cast<std::size_t>(max_threads());
  const std::size_t chunks = std::clamp<std::size_t>(std::min(faces / kChunkFaces, threads), 1, 8);
  const auto first_face = [&](std::size_t c) { return static_cast<int>(faces * c / chunks); };
  // next[c][u]: chunk c's slots whose lower vertex is u, then where chunk c puts its next one.
  // Each chunk zeroes its own counts.
  Buffer<std::int32_t> next(chunks * nv);
  parallel_invoke_each(chunks, [&](std::size_t c) {
    std::int32_t* count = next.data() + c * nv;
    std::fill(count, count + nv, 0);
    for (int f = first_face(c), end = first_face(c + 1); f < end; ++f)
      for (int k = 0; k < 3; ++k) ++count[edge_key(mesh, f, k) >> 32];
  });
  // bucket_end[u + 1]: where u's bucket ends (and u + 1's begins). The running sum over the
  // vertices runs in ranges side by side: each range's total first, then each range from
  // the sum of the totals before it (a serial pass was some 0.1 ms of a 154k-face read).
  Buffer<std::int32_t> bucket_end(nv + 1);
  bucket_end[0] = 0;
  const std::size_t ranges = std::clamp<std::size_t>(std::min(nv / kChunkVertices, threads), 1, 8);
  const auto first_vertex = [&](std::size_t r) { return nv * r / ranges; };
  std::vector<std::int32_t> before(ranges + 1, 0);  // before[r + 1]: range r's slots
  if (ranges > 1)
    parallel_invoke_each(ranges, [&](std::size_t r) {
      std::int32_t total = 0;
      for (std::size_t c = 0; c < chunks; ++c)
        for (std::size_t u = first_vertex(r), end = first_vertex(r + 1); u < end; ++u)
          total += next[c * nv + u];
      before[r + 1] = total;
    });
  std::partial_sum(before.begin(), before.end(), before.begin());
  const auto place_range = [&](std::size_t r) {
    std::int32_t running = before[r];
    for (std::size_t u = first_vertex(r), end = first_vertex(r + 1); u < end; ++u) {
      for (std::size_t c = 0; c < chunks; ++c) running += std::exchange(next[c * nv + u], running);
      bucket_end[u + 1] = running;
    }
  };
  if (ranges > 1)
    parallel_invoke_each(ranges, place_range);
  else
    place_range(0);
  parallel_invoke_each(chunks, [&](std::size_t c) {
    std::int32_t* place = next.data() + c * nv;
    for (int f = first_face(c), end = first_face(c + 1); f < end; ++f)
      for (int k = 0; k < 3; ++k) {
        const std::uint64_t key = edge_key(mesh, f, k);
        edges[static_cast<std::size_t>(place[key >> 32]++)] = {key, 3 * f + k};
      }
  });
  parallel_for(0, nv, [&](std::size_t begin, std::size_t end) {
    for (std::size_t u = begin; u < end; ++u) {
      const auto first = edges.begin() + bucket_end[u], last = edges.begin() + bucket_end[u + 1];
      if (last - first > 16) {
        std::sort(first, last);
        continue;
      }
      // Insertion: the slots arrive in slot order, so equal keys keep it.
      for (auto i = first + 1; i < last; ++i)
        for (auto j = i; j > first && *j < *(j - 1); --j) std::iter_swap(j, j - 1);
    }
  }, 4096);
}

Buffer<KeyedIndex> sorted_edge_slots(const Mesh& mesh) {
  Buffer<KeyedIndex> edges(static_cast<std::size_t>(mesh.face_count()) * 3);
  fill_sorted_edge_slots(mesh, edges);
  return edges;
}

Mesh subdivide_midpoint(const Mesh& mesh) {
  const int nv = mesh.vertex_count(), nf = mesh.face_count();
  std::unordered_map<std::uint64_t, int> midpoint;  // undirected edge → new vertex
  midpoint.reserve(static_cast<std::size_t>(3 * nf / 2 + 1));
  std::vector<Vec3> added;
  auto mid = [&](int a, int b) {
    const auto key = (static_cast<std::uint64_t>(std::min(a, b)) << 32) | static_cast<std::uint32_t>(std::max(a, b));
    const auto [it, inserted] = midpoint.try_emplace(key, nv + static_cast<int>(added.size()));
    if (inserted) added.emplace_back(0.5 * (Vec3(mesh.V.row(a)) + Vec3(mesh.V.row(b))));
    return it->second;
  };
  Mesh out;
  out.F.resize(4 * static_cast<Eigen::Index>(nf), 3);
  for (int f = 0; f < nf; ++f) {
    const int a = mesh.F(f, 0), b = mesh.F(f, 1), c = mesh.F(f, 2);
    const int ab = mid(a, b), bc = mid(b, c), ca = mid(c, a);
    out.F.row(4 * f + 0) << a, ab, ca;
    out.F.row(4 * f + 1) << ab, b, bc;
    out.F.row(4 * f + 2) << ca, bc, c;
    out.F.row(4 * f + 3) << ab, bc, ca;
  }
  out.V.resize(nv + static_cast<Eigen::Index>(added.size()), 3);
  if (nv > 0) out.V.topRows(nv) = mesh.V;
  for (std::size_t k = 0; k < added.size(); ++k) out.V.row(nv + static_cast<Eigen::Index>(k)) = added[k].transpose();
  return out;
}

Points vertex_normals(const Mesh& mesh) {
  Points N = Points::Zero(mesh.vertex_count(), 3);
  for (int f = 0; f < mesh.face_count(); ++f) {
    const Vec3 a = mesh.V.row(mesh.F(f, 0)), b = mesh.V.row(mesh.F(f, 1)), c = mesh.V.row(mesh.F(f, 2));
    const Vec3 n = (b - a).cross(c - a);  // twice the area times the unit normal
    for (int k = 0; k < 3; ++k) N.row(mesh.F(f, k)) += n.transpose();
  }
  for (int v = 0; v < mesh.vertex_count(); ++v) {
    const double len = N.row(v).norm();
    if (len > 0) N.row(v) /= len;
  }
  return N;
}

}  // namespace flank
