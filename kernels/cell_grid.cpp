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

double CellGrid::pairs(std::span<const Vec3> lo, std::span<const Vec3> hi) const {
  // Per block of items, then summed in block order: the same sum whatever the thread count
  // (and exact where it decides anything, at most 16 pairs an item).
  const std::size_t n = lo.size(), block = 4096, blocks = (n + block - 1) / block;
  std::vector<double> part(blocks, 0.0);
  parallel_for(0, blocks, [&](std::size_t b0, std::size_t b1) {
    std::int64_t r[6];
    for (std::size_t b = b0; b < b1; ++b)
      for (std::size_t i = b * block; i < std::min(n, (b + 1) * block); ++i) {
        range_of(lo[i], hi[i], r);
        part[b] += static_cast<double>(r[3] - r[0] + 1) * static_cast<double>(r[4] - r[1] + 1) *
                   static_cast<double>(r[5] - r[2] + 1);
      }
  }, 1);
  double sum = 0.0;
  for (const double p : part) sum += p;
  return sum;
}

std::size_t CellGrid::Table::probe(std::uint64_t key) const {
  std::uint64_t s = (key * 0x9E3779B97F4A7C15ull) >> shift;  // Fibonacci hashing
  for (std::int32_t c = slots[s]; c >= 0 && keys[static_cast<std::size_t>(c)] != key; c = slots[s])
    s = (s + 1) & mask;
  return static_cast<std::size_t>(s);
}

void CellGrid::Table::resize(std::size_t capacity) {
  slots.assign(capacity, -1);
  mask = capacity - 1;
  shift = 64 - std::countr_zero(capacity);
  for (std::size_t c = 0; c < keys.size(); ++c)
    slots[probe(keys[c])] = static_cast<std::int32_t>(c);
}

std::int32_t CellGrid::Table::cell_of(std::uint64_t key) {
  std::size_t s = probe(key);
  if (slots[s] >= 0) return slots[s];
  keys.push_back(key);
  if (2 * keys.size() > slots.size()) {
    resize(2 * slots.size());  // finds the new key too
    return static_cast<std::int32_t>(keys.size() - 1);
  }
  slots[s] = static_cast<std::int32_t>(keys.size() - 1);
  return slots[s];
}

// Consecutive items, [begin, end): their cells numbered in the order the chunk meets them,
// each with its count of the chunk's items, and then where in the grid they go.
struct CellGrid::Chunk {
  std::size_t begin = 0, end = 0;
  Table table;
  std::vector<std::int32_t> count;   // per cell of the chunk
  std::vector<std::int32_t> global;  // the chunk's cell → the grid's
  std::vector<std::int32_t> before;  // the chunk's cell → its items in earlier chunks
};

CellGrid::CellGrid(std::span<const Vec3> lo, std::span<const Vec3> hi) {
  assert(lo.size() == hi.size());
  const std::size_t n = lo.size();
  if (n == 0) return;
  Vec3 glo = lo[0], ghi = hi[0];
  std::vector<double> side(n);
  {
    const std::size_t block = 4096, blocks = (n + block - 1) / block;
    std::vector<Vec3> blo(blocks, glo), bhi(blocks, ghi);
    parallel_for(0, blocks, [&](std::size_t b0, std::size_t b1) {
      for (std::size_t b = b0; b < b1; ++b) {
        Vec3 block_lo = glo, block_hi = ghi;
        for (std::size_t i = b * block; i < std::min(n, (b + 1) * block); ++i) {
          block_lo = block_lo.cwiseMin(lo[i]), block_hi = block_hi.cwiseMax(hi[i]);
          side[i] = (hi[i] - lo[i]).maxCoeff();
        }
        blo[b] = block_lo, bhi[b] = block_hi;
      }
    }, 1);
    for (std::size_t b = 0; b < blocks; ++b) glo = glo.cwiseMin(blo[b]), ghi = ghi.cwiseMax(bhi[b]);
  }
  origin_ = glo;
  std::nth_element(side.begin(), side.begin() + static_cast<std::ptrdiff_t>(n / 2), side.end());
  const Vec3 extent = ghi - glo;
  cell_ = std::max(side[n / 2], extent.maxCoeff() / static_cast<double>(kMaxDim - 2));
  if (!(cell_ > 0.0)) cell_ = 1.0;  // every box one and the same point

  // The cell size, doubled while the boxes span too many cells. (item, cell) pairs are
  // counted in double: a too small cell may overflow.
  double total_pairs = 0.0;
  for (;;) {
    inverse_ = 1.0 / cell_;
    for (int k = 0; k < 3; ++k) dims_[k] = static_cast<std::int64_t>((ghi[k] - origin_[k]) * inverse_) + 1;
    total_pairs = pairs(lo, hi);
    if (total_pairs <= kMaxPairsPerItem * static_cast<double>(n) + 64.0) break;
    cell_ *= 2.0;
  }

  // The occupied cells, numbered in item order, and their item counts; then each cell's items
  // in item order. A table grows with the cells met, from 16 slots: one item's box shares
  // most cells with its neighbours'. (A table per pair was most of the cost of the index; on
  // Ω's grid of the 13k part, 104k faces in 41k cells, a table sized by pairs / 4 took 4 MB,
  // whose first touch alone took 13 ms.) The second pass finds each pair's cell again rather
  // than keeping it from the first: fresh memory costs more than the lookup
  // (BM_FirstTouch).
  //
  // On every thread: each chunk of consecutive items numbers its own cells in its item
  // order, with a table of its own. The first chunk's table becomes the grid's, and the
  // others' cells are added to it chunk by chunk, in their order: a cell is then numbered
  // where the items in order first meet it, as one pass over all of them numbers it, so the
  // grid is the same whatever the number of chunks. Each chunk then places its items after
  // those of the chunks before it, in every cell.
  const auto total = static_cast<std::size_t>(total_pairs);  // exact: at most 16 per item here
  constexpr std::size_t kChunkItems = 8192;  // items a chunk at least: fewer are one pass
  const auto threads = static_cast<std::size_t>(std::max(1, max_threads()));
  const std::size_t chunk_count = std::clamp<std::size_t>(n / kChunkItems, 1, threads);
  std::vector<Chunk> chunks(chunk_count);
  for (std::size_t c = 0; c < chunk_count; ++c)
    chunks[c].begin = n * c / chunk_count, chunks[c].end = n * (c + 1) / chunk_count;
  // Calls f(cell) for each cell of item i's box, the cell found in `table`; `made` adds
  // cells not yet in it. The cells met lately are cached by coordinates: neighbouring items
  // (a mesh's faces mostly come in surface order) meet the same few cells again and find
  // them here. A cache only: the cells and their numbers are what the table alone gives.
  struct Recent {
    std::uint64_t key = kEmpty;
    std::int32_t cell = -1;
  };
  using RecentCells = std::array<Recent, 64>;
  const auto for_each_cell = [&](std::size_t i, Table& table, bool made, RecentCells& recent, auto&& f) {
    std::int64_t r[6];
    range_of(lo[i], hi[i], r);
    for (std::int64_t z = r[2]; z <= r[5]; ++z)
      for (std::int64_t y = r[1]; y <= r[4]; ++y)
        for (std::int64_t x = r[0]; x <= r[3]; ++x) {
          const std::uint64_t key = key_of(x, y, z);
          Recent& seen = recent[static_cast<std::size_t>((x + 3 * y + 5 * z) & 63)];
          if (seen.key != key)
            seen = {key, made ? table.cell_of(key) : table.slots[table.probe(key)]};
          f(seen.cell);
        }
  };
  parallel_invoke_each(chunk_count, [&](std::size_t c) {
    Chunk& chunk = chunks[c];
    chunk.table.resize(16);
    RecentCells recent;
    for (std::size_t i = chunk.begin; i < chunk.end; ++i)
      for_each_cell(i, chunk.table, true, recent, [&](std::int32_t cell) {
        if (static_cast<std::size_t>(cell) == chunk.count.size()) chunk.count.push_back(0);
        ++chunk.count[static_cast<std::size_t>(cell)];
      });
  });
  const std::size_t first_cells = chunks[0].count.size();
  table_ = std::move(chunks[0].table);
  std::vector<std::int32_t> count = std::move(chunks[0].count);
  for (std::size_t c = 1; c < chunk_count; ++c) {
    Chunk& chunk = chunks[c];
    chunk.global.resize(chunk.count.size());
    chunk.before.resize(chunk.count.size());
    for (std::size_t k = 0; k < chunk.count.size(); ++k) {
      const std::int32_t g = table_.cell_of(chunk.table.keys[k]);
      if (static_cast<std::size_t>(g) == count.size()) count.push_back(0);
      chunk.global[k] = g;
      chunk.before[k] = count[static_cast<std::size_t>(g)];
      count[static_cast<std::size_t>(g)] += chunk.count[k];
    }
  }
  cells_ = table_.keys.size();
  start_.resize(cells_ + 1);
  start_[0] = 0;
  for (std::size_t c = 0; c < cells_; ++c) start_[c + 1] = start_[c] + count[c];
  assert(static_cast<std::size_t>(start_[cells_]) == total);
  items_.resize(total);
  parallel_invoke_each(chunk_count, [&](std::size_t c) {
    Chunk& chunk = chunks[c];
    // Each cell's next place: the first chunk's cells are the grid's.
    std::vector<std::int32_t> next;
    if (c == 0) {
      next.assign(start_.begin(), start_.begin() + static_cast<std::ptrdiff_t>(first_cells));
    } else {
      next.resize(chunk.global.size());
      for (std::size_t k = 0; k < next.size(); ++k)
        next[k] = start_[static_cast<std::size_t>(chunk.global[k])] + chunk.before[k];
    }
    Table& table = c == 0 ? table_ : chunk.table;
    RecentCells recent;
    for (std::size_t i = chunk.begin; i < chunk.end; ++i)
      for_each_cell(i, table, false, recent, [&](std::int32_t cell) {
        const auto place = static_cast<std::size_t>(next[static_cast<std::size_t>(cell)]++);
        items_[place] = static_cast<std::int32_t>(i);
      });
  });
}

std::span<const std::int32_t> CellGrid::items_at(const Vec3& p) const {
  const std::int64_t x = coordinate(p.x(), 0), y = coordinate(p.y(), 1), z = coordinate(p.z(), 2);
  if (x < 0 || y < 0 || z < 0 || table_.slots.empty()) return {};
  const std::int32_t cell = table_.slots[table_.probe(key_of(x, y, z))];
  if (cell < 0) return {};
  const auto b = static_cast<std::size_t>(start_[static_cast<std::size_t>(cell)]);
  const auto e = static_cast<std::size_t>(start_[static_cast<std::size_t>(cell) + 1]);
  return {items_.data() + b, e - b};
}

}  // namespace flank
