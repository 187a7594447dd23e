// Four single-precision lanes as one value, for the closest-point search's box and triangle
// tests: a GCC and Clang vector extension, which compiles to the target's vector instructions
// (SSE on any x86-64) with no intrinsics and no -march. The auto-vectoriser would not take these
// loops (their min, max and selects read as control flow to it). Four lanes, not eight: wider
// vectors change the calling convention without AVX (-Wpsabi).
#pragma once

#include <cstdint>
#include <cstring>

namespace flank {

using Float4 = float __attribute__((vector_size(16)));

// Unaligned load and store of a vector from/to floats.
template <class V>
inline V load_lanes(const float* p) {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <class V>
inline void store_lanes(const V& v, float* p) {
  std::memcpy(p, &v, sizeof v);
}
template <class V>
inline V splat(float x) {
  return V{} + x;
}
// Lane-wise min, max, |x| and the selection `mask ? a : b`.
template <class V>
inline V lane_min(V a, V b) {
  return a < b ? a : b;
}
template <class V>
inline V lane_max(V a, V b) {
  return a > b ? a : b;
}
template <class V>
inline V lane_abs(V a) {
  return lane_max(a, -a);
}
// Bit l set where lane l of `a` is ≤ t (four lanes).
inline std::uint32_t lanes_at_most(Float4 a, float t) {
  using Int4 = std::int32_t __attribute__((vector_size(16)));
  const Int4 bits = (a <= splat<Float4>(t)) & Int4{1, 2, 4, 8};
  return static_cast<std::uint32_t>(bits[0] | bits[1] | bits[2] | bits[3]);
}

}  // namespace flank
