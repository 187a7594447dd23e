#include "kernels/cell_grid.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cassert>
#include <cmath>
#include <limits>

namespace flank {

namespace {

constexpr std::uint64_t kEmpty = ~std::uint64_t{0};
constexpr int kBits = 21;                                 // per axis in a cell's key
constexpr std::int64_t kMaxDim = std::int64_t{1} << 20;  // cells per axis at most
// More (item, cell) pairs than this many per item: the cells are too small for the boxes
// (a few large boxes among small ones), and the grid doubles its cell size.
constexpr double kMaxPairsPerItem = 16.0;

std::uint64_t key_of(std::int64_t x, std::int64_t y, std::int64_t z) {
  return static_cast<std::uint64_t>(x) | (static_cast<std::uint64_t>(y) << kBits) |
         (static_cast<std::uint64_t>(z) << (2 * kBits));
}

}  // namespace

std::int64_t CellGrid::coordinate(double x, int k) const {
  const double t = (x - origin_[k]) * inverse_;
  if (!(t >= 0.0) || !(t < static_cast<double>(dims_[k]))) return -1;
  return static_cast<std::int64_t>(t);
}

std::size_t CellGrid::probe(std::uint64_t key) const {
  std::uint64_t s = (key * 0x9E3779B97F4A7C15ull) >> shift_;  // Fibonacci hashing
  while (keys_[s] != key && keys_[s] != kEmpty) s = (s + 1) & mask_;
  return static_cast<std::size_t>(s);
}

std::int64_t CellGrid::slot_of(std::uint64_t key) const {
  if (keys_.empty()) return -1;
  const std::size_t s = probe(key);
  return keys_[s] == key ? static_cast<std::int64_t>(s) : -1;
}

CellGrid::CellGrid(std::span<const Vec3> lo, std::span<const Vec3> hi) {
  assert(lo.size() == hi.size());
  const std::size_t n = lo.size();
  if (n == 0) return;
  Vec3 glo = lo[0], ghi = hi[0];
  std::vector<double> side(n);
  for (std::size_t i = 0; i < n; ++i) {
    glo = glo.cwiseMin(lo[i]), ghi = ghi.cwiseMax(hi[i]);
    side[i] = (hi[i] - lo[i]).maxCoeff();
  }
  origin_ = glo;
  std::nth_element(side.begin(), side.begin() + static_cast<std::ptrdiff_t>(n / 2), side.end());
  const Vec3 extent = ghi - glo;
  cell_ = std::max(side[n / 2], extent.maxCoeff() / static_cast<double>(kMaxDim - 2));
  if (!(cell_ > 0.0)) cell_ = 1.0;  // every box one and the same point

  // Each item's cell ranges; doubling the cells while the boxes span too many.
  std::vector<std::array<std::int64_t, 6>> range(n);
  double pairs = 0.0;  // (item, cell): counted in double, a too small cell may overflow
  for (;;) {
    inverse_ = 1.0 / cell_;
    for (int k = 0; k < 3; ++k) dims_[k] = static_cast<std::int64_t>((ghi[k] - origin_[k]) * inverse_) + 1;
    pairs = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      double cells = 1.0;
      for (int k = 0; k < 3; ++k) {
        range[i][k] = coordinate(lo[i][k], k);
        range[i][3 + k] = coordinate(hi[i][k], k);
        assert(range[i][k] >= 0 && range[i][3 + k] >= range[i][k]);
        cells *= static_cast<double>(range[i][3 + k] - range[i][k] + 1);
      }
      pairs += cells;
    }
    if (pairs <= kMaxPairsPerItem * static_cast<double>(n) + 64.0) break;
    cell_ *= 2.0;
  }

  // Occupied cells in an open-addressing table of at least twice as many slots as pairs;
  // counted, then filled in item order.
  const auto total = static_cast<std::size_t>(pairs);  // exact: at most 16 per item here
  const std::size_t capacity = std::bit_ceil(std::max<std::size_t>(2 * total, 16));
  mask_ = capacity - 1;
  shift_ = 64 - std::countr_zero(capacity);
  keys_.assign(capacity, kEmpty);
  std::vector<std::int32_t> count(capacity, 0);
  auto insert = [&](std::uint64_t key) {
    const std::size_t s = probe(key);
    if (keys_[s] == kEmpty) keys_[s] = key, ++cells_;
    return s;
  };
  auto for_cells = [&](const std::array<std::int64_t, 6>& r, auto&& f) {
    for (std::int64_t z = r[2]; z <= r[5]; ++z)
      for (std::int64_t y = r[1]; y <= r[4]; ++y)
        for (std::int64_t x = r[0]; x <= r[3]; ++x) f(key_of(x, y, z));
  };
  for (std::size_t i = 0; i < n; ++i) for_cells(range[i], [&](std::uint64_t key) { ++count[insert(key)]; });
  start_.assign(capacity + 1, 0);
  for (std::size_t s = 0; s < capacity; ++s) start_[s + 1] = start_[s] + count[s];
  items_.resize(total);
  std::vector<std::int32_t> fill(start_.begin(), start_.end() - 1);
  for (std::size_t i = 0; i < n; ++i)
    for_cells(range[i], [&](std::uint64_t key) {
      const auto s = static_cast<std::size_t>(slot_of(key));
      items_[static_cast<std::size_t>(fill[s]++)] = static_cast<std::int32_t>(i);
    });
}

std::span<const std::int32_t> CellGrid::items_at(const Vec3& p) const {
  const std::int64_t x = coordinate(p.x(), 0), y = coordinate(p.y(), 1), z = coordinate(p.z(), 2);
  if (x < 0 || y < 0 || z < 0) return {};
  const std::int64_t s = slot_of(key_of(x, y, z));
  if (s < 0) return {};
  const auto b = static_cast<std::size_t>(start_[static_cast<std::size_t>(s)]);
  const auto e = static_cast<std::size_t>(start_[static_cast<std::size_t>(s) + 1]);
  return {items_.data() + b, e - b};
}

}  // namespace flank
