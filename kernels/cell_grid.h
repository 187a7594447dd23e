// A uniform grid over axis-aligned boxes: each occupied cell lists the items whose box overlaps
// it, so a point's cell lists every item whose box holds the point. Built in time linear in the
// items (a hash of the occupied cells, no tree), it serves an index that lives for a few
// queries of a bounded reach: Ω's, one per candidate patch (kernels/surface_index.h,
// QueryEngine::kCells), where building the box tree cost more than all its queries.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "kernels/types.h"

namespace flank {

class CellGrid {
 public:
  CellGrid() = default;
  // Item i's box is [lo[i], hi[i]] (finite, lo ≤ hi). The cell size is about the median
  // box's largest side, larger where that would put too many cells on the grid.
  // Built on every thread, in chunks of consecutive items; the grid (its cells, their
  // numbering and their lists) is the same whatever the thread count.
  CellGrid(std::span<const Vec3> lo, std::span<const Vec3> hi);

  // The items whose box may hold p, in increasing order: every item whose box holds p is
  // among them (the cell of a coordinate is monotone in it, so a point inside a box lies in
  // one of the box's cells whatever the rounding).
  std::span<const std::int32_t> items_at(const Vec3& p) const;

  std::size_t cells() const { return cells_; }
  std::size_t entries() const { return items_.size(); }
  // Hash slots: at most four per occupied cell (at least 16), whatever the boxes span.
  std::size_t slots() const { return table_.slots.size(); }

 private:
  // Open addressing over the occupied cells only (kept at most half full): a slot holds a
  // cell's number (-1 when free), cells are numbered in the order they were first met, and
  // keys[c] is cell c's key.
  struct Table {
    std::vector<std::int32_t> slots;
    std::vector<std::uint64_t> keys;
    std::uint64_t mask = 0;
    int shift = 64;  // a key's home slot: its hash's top bits

    // The slot holding `key`, or the free slot where it would go (linear probing).
    std::size_t probe(std::uint64_t key) const;
    // The number of the cell with `key`, made (and the table grown) if new.
    std::int32_t cell_of(std::uint64_t key);
    void resize(std::size_t capacity);
  };
  struct Chunk;

  // The cell coordinate of x along axis k, or -1 beyond the grid.
  std::int64_t coordinate(double x, int k) const;
  // The cell ranges of the box [lo, hi] (x, y, z lows, then highs).
  void range_of(const Vec3& lo, const Vec3& hi, std::int64_t* r) const;
  // The (item, cell) pairs of the boxes with the current cell size.
  double pairs(std::span<const Vec3> lo, std::span<const Vec3> hi) const;

  Vec3 origin_ = Vec3::Zero();
  double cell_ = 1.0, inverse_ = 1.0;
  std::int64_t dims_[3] = {0, 0, 0};
  Table table_;
  // Cell c's items are items_[start_[c], start_[c + 1]).
  std::vector<std::int32_t> start_;
  std::vector<std::int32_t> items_;
  std::size_t cells_ = 0;
};

}  // namespace flank
