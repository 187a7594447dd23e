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
  while (table_[s].key != key && table_[s].key != kEmpty) s = (s + 1) & mask_;
  return static_cast<std::size_t>(s);
}

void CellGrid::resize_table(std::size_t capacity) {
  std::vector<Slot> old = std::move(table_);
  table_.assign(capacity, Slot{kEmpty, -1});
  mask_ = capacity - 1;
  shift_ = 64 - std::countr_zero(capacity);
  for (const Slot& s : old)
    if (s.key != kEmpty) table_[probe(s.key)] = s;
}

std::int32_t CellGrid::cell_of(std::uint64_t key) {
  std::size_t s = probe(key);
  if (table_[s].key == key) return table_[s].cell;
  if (2 * (cells_ + 1) > table_.size()) {
    resize_table(2 * table_.size());
    s = probe(key);
  }
  table_[s] = {key, static_cast<std::int32_t>(cells_++)};
  return table_[s].cell;
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
  // in item order. Neighbouring boxes share most of their cells, so the table is sized by
  // the cells met, not by the pairs (a table per pair was most of the cost of the index).
  const auto total = static_cast<std::size_t>(pairs);  // exact: at most 16 per item here
  resize_table(std::bit_ceil(std::max<std::size_t>(total / 4, 16)));
  std::vector<std::int32_t> count;
  // Each pair's cell, as the count meets it: the fill then reads them in order, with no box
  // ranges or hash probes again.
  Buffer<std::int32_t> pair_cell(total);  // written before read: not zeroed first
  Buffer<std::int32_t> spans(n);          // each item's number of cells
  std::size_t j = 0;
  for (std::size_t i = 0; i < n; ++i) {
    range_of(lo[i], hi[i], r);
    const std::size_t first = j;
    for (std::int64_t z = r[2]; z <= r[5]; ++z)
      for (std::int64_t y = r[1]; y <= r[4]; ++y)
        for (std::int64_t x = r[0]; x <= r[3]; ++x) {
          const std::int32_t c = cell_of(key_of(x, y, z));
          if (static_cast<std::size_t>(c) == count.size()) count.push_back(0);
          ++count[static_cast<std::size_t>(c)];
          pair_cell[j++] = c;
        }
    spans[i] = static_cast<std::int32_t>(j - first);
  }
  assert(j == total);
  start_.resize(cells_ + 1);
  start_[0] = 0;
  for (std::size_t c = 0; c < cells_; ++c) start_[c + 1] = start_[c] + count[c];
  items_.resize(total);
  for (std::size_t c = 0; c < cells_; ++c) count[c] = start_[c];  // now each cell's next place
  j = 0;
  for (std::size_t i = 0; i < n; ++i)
    for (std::int32_t m = 0; m < spans[i]; ++m)
      items_[static_cast<std::size_t>(count[static_cast<std::size_t>(pair_cell[j++])]++)] = static_cast<std::int32_t>(i);
}

std::span<const std::int32_t> CellGrid::items_at(const Vec3& p) const {
  const std::int64_t x = coordinate(p.x(), 0), y = coordinate(p.y(), 1), z = coordinate(p.z(), 2);
  if (x < 0 || y < 0 || z < 0 || table_.empty()) return {};
  const Slot& slot = table_[probe(key_of(x, y, z))];
  if (slot.key == kEmpty) return {};
  const auto b = static_cast<std::size_t>(start_[static_cast<std::size_t>(slot.cell)]);
  const auto e = static_cast<std::size_t>(start_[static_cast<std::size_t>(slot.cell) + 1]);
  return {items_.data() + b, e - b};
}

}  // namespace flank
