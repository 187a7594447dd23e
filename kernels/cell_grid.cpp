#include "kernels/cell_grid.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cassert>
#include <cmath>
#include <limits>

#include "kernels/parallel.h"

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

void CellGrid::range_of(const Vec3& lo, const Vec3& hi, std::int64_t* r) const {
  for (int k = 0; k < 3; ++k) {
    r[k] = coordinate(lo[k], k);
    r[3 + k] = coordinate(hi[k], k);
    assert(r[k] >= 0 && r[3 + k] >= r[k]);
  }
}

std::size_t CellGrid::probe(std::uint64_t key) const {
  std::uint64_t s = (key * 0x9E3779B97F4A7C15ull) >> shift_;  // Fibonacci hashing
  for (std::int32_t c = table_[s]; c >= 0 && keys_[static_cast<std::size_t>(c)] != key; c = table_[s])
    s = (s + 1) & mask_;
  return static_cast<std::size_t>(s);
}

void CellGrid::resize_table(std::size_t capacity) {
  table_.assign(capacity, -1);
  mask_ = capacity - 1;
  shift_ = 64 - std::countr_zero(capacity);
  for (std::size_t c = 0; c < cells_; ++c) table_[probe(keys_[c])] = static_cast<std::int32_t>(c);
}

std::int32_t CellGrid::cell_of(std::uint64_t key) {
  std::size_t s = probe(key);
  if (table_[s] >= 0) return table_[s];
  if (2 * (cells_ + 1) > table_.size()) {
    keys_.push_back(key);  // found by the rehash
    ++cells_;
    resize_table(2 * table_.size());
    return static_cast<std::int32_t>(cells_ - 1);
  }
  keys_.push_back(key);
  table_[s] = static_cast<std::int32_t>(cells_++);
  return table_[s];
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

  // The cell size, doubled while the boxes span too many cells.
  double pairs = 0.0;  // (item, cell): counted in double, a too small cell may overflow
  std::int64_t r[6];
  for (;;) {
    inverse_ = 1.0 / cell_;
    for (int k = 0; k < 3; ++k) dims_[k] = static_cast<std::int64_t>((ghi[k] - origin_[k]) * inverse_) + 1;
    pairs = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      range_of(lo[i], hi[i], r);
      pairs += static_cast<double>(r[3] - r[0] + 1) * static_cast<double>(r[4] - r[1] + 1) *
               static_cast<double>(r[5] - r[2] + 1);
    }
    if (pairs <= kMaxPairsPerItem * static_cast<double>(n) + 64.0) break;
    cell_ *= 2.0;
  }

  // The occupied cells, numbered in item order, and their item counts; then each cell's items
  // in item order. The table grows with the cells met, from 16 slots: one item's box shares
  // most cells with its neighbours'. (A table per pair was most of the cost of the index; on
  // Ω's grid of the 13k part, 104k faces in 41k cells, a table sized by pairs / 4 took 4 MB,
  // whose first touch alone took 13 ms.) The second pass finds each pair's cell again rather
  // than keeping it from the first: fresh memory costs more than the lookup
  // (BM_FirstTouch).
  const auto total = static_cast<std::size_t>(pairs);  // exact: at most 16 per item here
  resize_table(16);
  // The cells met lately, by coordinates: neighbouring items (a mesh's faces mostly come in
  // surface order) meet the same few cells again and find them here. A cache only: the
  // cells and their numbers are what the table alone gives.
  struct Recent {
    std::uint64_t key = kEmpty;
    std::int32_t cell = -1;
  };
  std::array<Recent, 64> recent;
  const auto for_each_cell = [&](std::size_t i, auto&& f) {
    range_of(lo[i], hi[i], r);
    for (std::int64_t z = r[2]; z <= r[5]; ++z)
      for (std::int64_t y = r[1]; y <= r[4]; ++y)
        for (std::int64_t x = r[0]; x <= r[3]; ++x) {
          const std::uint64_t key = key_of(x, y, z);
          Recent& seen = recent[static_cast<std::size_t>((x + 3 * y + 5 * z) & 63)];
          if (seen.key != key) seen = {key, cell_of(key)};
          f(seen.cell);
        }
  };
  std::vector<std::int32_t> count;
  for (std::size_t i = 0; i < n; ++i)
    for_each_cell(i, [&](std::int32_t c) {
      if (static_cast<std::size_t>(c) == count.size()) count.push_back(0);
      ++count[static_cast<std::size_t>(c)];
    });
  start_.resize(cells_ + 1);
  start_[0] = 0;
  for (std::size_t c = 0; c < cells_; ++c) start_[c + 1] = start_[c] + count[c];
  assert(static_cast<std::size_t>(start_[cells_]) == total);
  items_.resize(total);
  for (std::size_t c = 0; c < cells_; ++c) count[c] = start_[c];  // now each cell's next place
  for (std::size_t i = 0; i < n; ++i)
    for_each_cell(i, [&](std::int32_t c) {
      items_[static_cast<std::size_t>(count[static_cast<std::size_t>(c)]++)] = static_cast<std::int32_t>(i);
    });
}

std::span<const std::int32_t> CellGrid::items_at(const Vec3& p) const {
  const std::int64_t x = coordinate(p.x(), 0), y = coordinate(p.y(), 1), z = coordinate(p.z(), 2);
  if (x < 0 || y < 0 || z < 0 || table_.empty()) return {};
  const std::int32_t cell = table_[probe(key_of(x, y, z))];
  if (cell < 0) return {};
  const auto b = static_cast<std::size_t>(start_[static_cast<std::size_t>(cell)]);
  const auto e = static_cast<std::size_t>(start_[static_cast<std::size_t>(cell) + 1]);
  return {items_.data() + b, e - b};
}

}  // namespace flank
