// A triangle mesh Φ: the design surface. Validation and repair happen in io::read_mesh;
// everything downstream may assume finite coordinates, indices in range, no degenerate faces.
#pragma once

#include <cstdint>
#include <span>

#include "kernels/parallel.h"
#include "kernels/types.h"

namespace flank {

struct Mesh {
  Points V;  // #V by 3 vertex positions
  Faces F;   // #F by 3 vertex indices, counter-clockwise seen from the tool side

  int vertex_count() const { return static_cast<int>(V.rows()); }
  int face_count() const { return static_cast<int>(F.rows()); }
};

struct BoundingBox {
  Vec3 min = Vec3::Zero();
  Vec3 max = Vec3::Zero();
  double diagonal() const { return (max - min).norm(); }
};

BoundingBox bounding_box(const Mesh& mesh);
double bbox_diagonal(const Mesh& mesh);
// #F by 3 unit face normals (right-hand rule on F's order).
Points face_normals(const Mesh& mesh);
// #V unit area-weighted vertex normals, oriented like F (zero for unused vertices).
Points vertex_normals(const Mesh& mesh);
// #F face areas.
VecX face_areas(const Mesh& mesh);
// #V barycentric vertex areas (a third of each incident face): the area a vertex stands for.
VecX vertex_areas(const Mesh& mesh);
double total_area(const Mesh& mesh);
// A key and the index it belongs to, ordered by both. Trivial: a buffer of them costs no
// writes until the code that fills it does (see Buffer). NarrowKeyedIndex, with a key of at
// most 32 bits, takes half the bytes: for sorts of 32-bit hashes (the weld's, the copies'),
// whose passes then move half the memory.
template <class Key>
struct BasicKeyedIndex {
  Key key;
  std::int32_t index;
  friend bool operator<(const BasicKeyedIndex& a, const BasicKeyedIndex& b) {
    return a.key < b.key || (a.key == b.key && a.index < b.index);
  }
  friend bool operator==(const BasicKeyedIndex&, const BasicKeyedIndex&) = default;
};
using KeyedIndex = BasicKeyedIndex<std::uint64_t>;
using NarrowKeyedIndex = BasicKeyedIndex<std::uint32_t>;
// Sorts by key, keeping the order of equal keys: items that arrive in index order leave in
// KeyedIndex's order. Keys must be below 2^key_bits. Radix passes of 11 bits from the lowest
// (a pass skipped where every key has the same digit), each on up to eight chunks side by side:
// linear in the items, and as fast on random keys (hashes) as on ordered ones; a comparison
// sort mispredicts most of its branches on random keys. A stable sort's result is unique, so
// it is the same whatever the thread count.
void radix_sort_by_key(std::span<KeyedIndex> items, int key_bits);
void radix_sort_by_key(std::span<NarrowKeyedIndex> items, int key_bits);  // key_bits ≤ 32
// The key of edge (k, k + 1 mod 3) of face f: its vertex pair, the lower in the high 32 bits.
inline std::uint64_t edge_key(const Mesh& mesh, int f, int k) {
  const auto u = static_cast<std::uint32_t>(mesh.F(f, k));
  const auto v = static_cast<std::uint32_t>(mesh.F(f, (k + 1) % 3));
  return (std::uint64_t{u < v ? u : v} << 32) | (u < v ? v : u);
}
// Every edge slot, 3 f + k for edge (k, k + 1 mod 3) of face f, keyed by its vertex pair (the
// lower vertex in the high 32 bits), sorted by (key, slot): the slots of one edge are
// adjacent. The order std::sort gives, in time linear in the slots. Into `edges` (3 × #F).
void fill_sorted_edge_slots(const Mesh& mesh, std::span<KeyedIndex> edges);
Buffer<KeyedIndex> sorted_edge_slots(const Mesh& mesh);
// Splits every triangle into four at its edge midpoints (shared edges share the midpoint):
// 4× the faces on exactly the same surface, orientation kept. Used to re-mesh a part finer
// for the scaling benchmarks without changing its shape.
Mesh subdivide_midpoint(const Mesh& mesh);

}  // namespace flank
