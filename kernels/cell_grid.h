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
  // Deterministic.
  CellGrid(std::span<const Vec3> lo, std::span<const Vec3> hi);

  // The items whose box may hold p, in increasing order: every item whose box holds p is
  // among them (the cell of a coordinate is monotone in it, so a point inside a box lies in
  // one of the box's cells whatever the rounding).
  std::span<const std::int32_t> items_at(const Vec3& p) const;

  std::size_t cells() const { return cells_; }
  std::size_t entries() const { return items_.size(); }

 private:
  // The cell coordinate of x along axis k, or -1 beyond the grid.
  std::int64_t coordinate(double x, int k) const;
  // The slot holding `key`, or the free slot where it would go (linear probing).
  std::size_t probe(std::uint64_t key) const;
  std::int64_t slot_of(std::uint64_t key) const;  // -1 if the cell is empty

  Vec3 origin_ = Vec3::Zero();
  double cell_ = 1.0, inverse_ = 1.0;
  std::int64_t dims_[3] = {0, 0, 0};
  // Open addressing: keys_[slot] (kEmpty when free), the slot's items at
  // items_[start_[slot], start_[slot + 1]).
  std::vector<std::uint64_t> keys_;
  std::vector<std::int32_t> start_;
  std::vector<std::int32_t> items_;
  std::uint64_t mask_ = 0;
  int shift_ = 64;  // a key's home slot: its hash's top bits
  std::size_t cells_ = 0;
};

}  // namespace flank
