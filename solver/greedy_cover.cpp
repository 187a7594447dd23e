#include "solver/greedy_cover.h"

#include <algorithm>
#include <cstdint>
#include <limits>
#include <numeric>
#include <span>

#include "kernels/parallel.h"

namespace flank {

// The cover's loops judge every entry of the pool (or every pick) against the same state, so
// each entry's sum is computed on its own, in parallel, into per-entry storage, and the choice
// is made after, serially, in the order and with the tie rules the serial loops had: the
// result is the same bit for bit whatever the thread count. An entry sums a patch's covered
// vertices, a few thousand: a few microseconds, so each is a task of its own, and the longest
// are taken first (longest_first). A long list is summed in blocks (kCoverBlock), each a task
// of its own.
namespace {
// The blocks of a list of n vertices: at least one.
std::size_t blocks_of(std::size_t n) { return std::max<std::size_t>(1, (n + kCoverBlock - 1) / kCoverBlock); }

// Block b of `list`.
std::span<const int> block(const std::vector<int>& list, std::size_t b) {
  const std::size_t first = b * kCoverBlock;
  return std::span<const int>(list).subspan(first, std::min(kCoverBlock, list.size() - first));
}

// The tasks 0 .. n − 1 in the order their threads should take them: the longest (by
// `length`) first, ties in task order. A pool's lists run from a few vertices to a third of
// Φ; taken longest first, one at a time, the threads finish together (in the pool's order, a
// long list taken last kept one thread summing alone while the other waited).
template <class Length>
std::vector<std::size_t> longest_first(std::size_t n, Length&& length) {
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return length(a) > length(b); });
  return order;
}

// Σ area(v) over v in `vertices` where keep(v), in the list's order.
template <class Keep>
double area_where(const std::vector<int>& vertices, const VecX& area, Keep&& keep) {
  double sum = 0.0;
  for (int v : vertices)
    if (keep(static_cast<std::size_t>(v))) sum += area(v);
  return sum;
}
}  // namespace

namespace {
// Makes `c` the empty cover of Φ, whose vertex areas `area` sum to `total`, keeping its
// storage. The sum (area.sum(); 4 MB read on the 1M cone) is the caller's: Φ does not change.
// With `crew`, Φ's owners, where `c` holds them already, are cleared in two halves (2 MB).
void clear_cover(const VecX& area, double total, Cover& c, Crew* crew = nullptr) {
  const auto n = static_cast<std::size_t>(area.size());
  c.used.clear();
  c.picks.clear();
  c.curve.clear();
  c.covered_area = 0.0;
  c.total_area = total;
  if (!crew || c.vertex_patch.size() != n) {
    c.vertex_patch.assign(n, -1);
    return;
  }
  crew->parallel_for(0, 2, [&](std::size_t half, std::size_t) {
    std::fill(c.vertex_patch.begin() + static_cast<std::ptrdiff_t>(half * n / 2),
              c.vertex_patch.begin() + static_cast<std::ptrdiff_t>((half + 1) * n / 2), -1);
  }, 1);
}
}  // namespace

Cover empty_cover(const VecX& area) {
  Cover c;
  clear_cover(area, area.sum(), c);
  return c;
}

namespace {
// True when `c` has as many picks as it may, or covers the target.
bool full(const Cover& c, const CoverOptions& o) {
  return static_cast<int>(c.picks.size()) >= o.max_patches ||
         c.covered_area >= o.coverage_target * c.total_area;
}

// greedy_cover's picks, with `crew` for the sums.
void greedy_on(Crew& crew, const std::vector<Patch>& pool, const VecX& area, const CoverOptions& o, Cover* c) {
  c->used.resize(pool.size(), 0);
  // One task per block of each entry's list: entry k's are first[k] .. first[k + 1) - 1.
  std::vector<std::size_t> first(pool.size() + 1, 0);
  for (std::size_t k = 0; k < pool.size(); ++k)
    first[k + 1] = first[k] + blocks_of(pool[k].covered_vertices.size());
  std::vector<std::size_t> entry(first.back());
  for (std::size_t k = 0; k < pool.size(); ++k)
    for (std::size_t t = first[k]; t < first[k + 1]; ++t) entry[t] = k;
  // Per block, of this pick: its new vertices' area, from zero; and per entry, its first
  // block's new areas added one by one to the cover's area, as the cover's sum after the pick
  // starts (kCoverBlock). An entry's gain and its covered area once picked follow from these
  // in a few additions, and the update after the pick only marks its vertices. (Summed after
  // the pick, the covered area was a chain of dependent additions over thousands of vertices
  // on one thread while the others waited: on HECC a's first cover, 43 µs of greedy's 240 at
  // one thread, and of its 137 at two.)
  std::vector<double> part(first.back(), 0.0), lead(pool.size(), 0.0);
  const std::vector<std::size_t> longest = longest_first(first.back(), [&](std::size_t t) {
    return block(pool[entry[t]].covered_vertices, t - first[entry[t]]).size();
  });
  for (int picked = 0; o.max_picks <= 0 || picked < o.max_picks; ++picked) {
    const int id = static_cast<int>(c->picks.size());
    if (full(*c, o)) break;
    crew.parallel_for(0, first.back(), [&](std::size_t b, std::size_t e) {
      for (std::size_t r = b; r < e; ++r) {
        const std::size_t t = longest[r];
        const std::size_t k = entry[t];
        if (c->used[k]) continue;
        double gain = 0.0, sum = c->covered_area;
        for (int v : block(pool[k].covered_vertices, t - first[k]))
          if (c->vertex_patch[static_cast<std::size_t>(v)] < 0) gain += area(v), sum += area(v);
        part[t] = gain;
        if (t == first[k]) lead[k] = sum;
      }
    }, 1);
    int pick = -1;
    double best_gain = 0.0;
    for (std::size_t k = 0; k < pool.size(); ++k) {
      if (c->used[k]) continue;
      double gain = part[first[k]];
      for (std::size_t t = first[k] + 1; t < first[k + 1]; ++t) gain += part[t];
      const bool better = pick < 0 || gain > best_gain ||
                          (gain == best_gain && pool[k].error.max < pool[static_cast<std::size_t>(pick)].error.max);
      if (better) pick = static_cast<int>(k), best_gain = gain;
    }
    if (pick < 0 || best_gain < o.min_gain * c->total_area) break;
    const auto k = static_cast<std::size_t>(pick);
    c->used[k] = 1;
    // A patch lists each vertex once: its blocks mark different vertices.
    const auto mark = [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i)
        for (int v : block(pool[k].covered_vertices, i)) {
          int& owner = c->vertex_patch[static_cast<std::size_t>(v)];
          owner = owner < 0 ? id : owner;
        }
    };
    const std::size_t blocks = first[k + 1] - first[k];
    if (blocks > 1)
      crew.parallel_for(0, blocks, mark, 1);
    else
      mark(0, 1);
    double after = lead[k];
    for (std::size_t t = first[k] + 1; t < first[k + 1]; ++t) after += part[t];
    c->covered_area = after;
    c->picks.push_back(pick);
    c->curve.push_back(c->fraction());
  }
}

// Per vertex, how many picks cover it (the word's high bits) and the sum of their slots,
// their indices into the picks (its low kSlotBits): where one pick covers a vertex, the sum
// is that pick's slot. One word a vertex: the swaps' sums read one array where they read two,
// and a tally's build and updates write one. A count is at most P and a sum at most P² / 2:
// a 32-bit word (8 bits and 24) holds both for up to kNarrowPicks picks, which covers every
// default run (20 patches at most), and a 64-bit word (32 and 32) for any cover the command
// line allows.
template <class Word>
using Tally = std::vector<Word>;
template <class Word>
constexpr int kSlotBits = sizeof(Word) == 4 ? 24 : 32;
template <class Word>
constexpr Word kOnePick = Word{1} << kSlotBits<Word>;
constexpr std::size_t kNarrowPicks = 255;

// True when one pick covers the vertex of tally word `w` (its count is 1).
template <class Word>
bool one_pick(Word w) {
  return static_cast<Word>(w - kOnePick<Word>) < kOnePick<Word>;
}

// Per vertex, how many of `picks` (pool indices) cover it, as a Tally without the slots.
template <class Word>
Tally<Word> count_covering(const std::vector<Patch>& pool, const VecX& area,
                           const std::vector<int>& picks) {
  Tally<Word> count(static_cast<std::size_t>(area.size()), 0);
  for (int k : picks)
    for (int v : pool[static_cast<std::size_t>(k)].covered_vertices)
      count[static_cast<std::size_t>(v)] += kOnePick<Word>;
  return count;
}

template <class Word>
void order_on(Crew& crew, const std::vector<Patch>& pool, const VecX& area, double total, std::vector<int> picks,
              Cover* c, const Tally<Word>& count = {});

// improve_cover's swaps of `picks` (pool indices, the cover's picks), with `crew` for the
// sums. Returns the Tally of the picks it leaves.
template <class Word>
Tally<Word> swap_picks(Crew& crew, const std::vector<Patch>& pool, const VecX& area, int max_swaps,
                       double total_area, std::vector<int>& picks) {
  constexpr Word kOne = kOnePick<Word>;
  const std::size_t V = static_cast<std::size_t>(area.size());
  const std::size_t P = picks.size();
  // The picks' Tally. A swap keeps the slot of the pick it takes out for the one it puts in,
  // so the tally moves only on the two patches' vertices.
  Tally<Word> tally(V, 0);
  const auto add = [&](std::size_t k, Word word) {  // to entry k's vertices
    for (int v : pool[k].covered_vertices) tally[static_cast<std::size_t>(v)] += word;
  };
  const auto take = [&](std::size_t k, Word word) {  // from entry k's vertices
    for (int v : pool[k].covered_vertices) tally[static_cast<std::size_t>(v)] -= word;
  };
  const auto pick_at = [&](std::size_t slot) { return static_cast<Word>(kOne + slot); };
  std::vector<int> slot_of(pool.size(), -1);  // per pool entry: its slot, or −1 if not picked
  for (std::size_t i = 0; i < P; ++i) {
    const auto k = static_cast<std::size_t>(picks[i]);
    add(k, pick_at(i));
    slot_of[k] = static_cast<int>(i);
  }
  // A swap of pick i (out) for entry j (in) gains the area of j's vertices that no pick
  // covers, or that i alone covers, and loses the area that i alone covers: one pass over j's
  // vertices gives its gain for every i at once (what no pick covers adds to each i's sum,
  // what pick i alone covers to i's), where taking each i out on its own would pass over
  // every entry once per pick. Each sum gets the same terms in the same order (the order of
  // j's vertices) as summing j's gain with i taken out: the same values, bit for bit. A
  // patch lists each covered vertex once (evaluate_patch). One pass over the pool sums both:
  // a pick's entry its loss, any other entry its gains (one fork per swap, not two).
  const std::vector<std::size_t> longest =
      longest_first(pool.size(), [&](std::size_t j) { return pool[j].covered_vertices.size(); });
  std::vector<double> loss(P), gain(pool.size() * P);  // gain: row j, column i
  for (int swap = 0; swap < max_swaps; ++swap) {
    const double least = 1e-9 * total_area;  // a swap must gain more than rounding
    crew.parallel_for(0, pool.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t r = b; r < e; ++r) {
        const std::size_t j = longest[r];
        if (slot_of[j] >= 0) {
          double sum = 0.0;
          for (int v : pool[j].covered_vertices)  // where one pick covers v
            if (one_pick(tally[static_cast<std::size_t>(v)])) sum += area(v);
          loss[static_cast<std::size_t>(slot_of[j])] = sum;
          continue;
        }
        double* sum = &gain[j * P];
        std::fill(sum, sum + P, 0.0);
        for (int v : pool[j].covered_vertices) {
          const Word w = tally[static_cast<std::size_t>(v)];
          const double a = area(v);
          if (w == 0)  // no pick
            for (std::size_t i = 0; i < P; ++i) sum[i] += a;
          else if (one_pick(w))  // the low bits are its slot
            sum[w - kOne] += a;
        }
      }
    }, 1);
    // Per pick taken out, the first entry at the largest gain over `least`; then the first
    // pick at the largest.
    double best_delta = least;
    int best_out = -1, best_in = -1;
    for (std::size_t i = 0; i < P; ++i) {
      double delta = least;
      int in = -1;
      for (std::size_t j = 0; j < pool.size(); ++j) {
        const double d = gain[j * P + i] - loss[i];
        if (slot_of[j] < 0 && d > delta) delta = d, in = static_cast<int>(j);
      }
      if (in >= 0 && delta > best_delta) best_delta = delta, best_out = static_cast<int>(i), best_in = in;
    }
    if (best_out < 0) break;
    const auto out = static_cast<std::size_t>(picks[static_cast<std::size_t>(best_out)]);
    take(out, pick_at(static_cast<std::size_t>(best_out)));
    add(static_cast<std::size_t>(best_in), pick_at(static_cast<std::size_t>(best_out)));
    slot_of[out] = -1;
    slot_of[static_cast<std::size_t>(best_in)] = best_out;
    picks[static_cast<std::size_t>(best_out)] = best_in;
  }
  return tally;
}

// improve_cover's swaps and rebuild, with `crew` for the sums, tallied in `Word`s.
template <class Word>
void improve_with(Crew& crew, const std::vector<Patch>& pool, const VecX& area, int max_swaps,
                  Cover* c) {
  std::vector<int> picks = c->picks;
  // With every entry picked (the pool of a part one patch covers) there is none to swap in.
  Tally<Word> count;
  if (picks.size() < pool.size())
    count = swap_picks<Word>(crew, pool, area, max_swaps, c->total_area, picks);
  order_on<Word>(crew, pool, area, c->total_area, picks, c, count);
}

void improve_on(Crew& crew, const std::vector<Patch>& pool, const VecX& area, int max_swaps, Cover* c) {
  if (c->picks.size() <= kNarrowPicks)
    improve_with<std::uint32_t>(crew, pool, area, max_swaps, c);
  else
    improve_with<std::uint64_t>(crew, pool, area, max_swaps, c);
}
}  // namespace

void greedy_cover(const std::vector<Patch>& pool, const VecX& area, const CoverOptions& o, Cover* c) {
  c->used.resize(pool.size(), 0);
  if (!full(*c, o)) with_crew([&](Crew& crew) { greedy_on(crew, pool, area, o, c); });
}

void improve_cover(const std::vector<Patch>& pool, const VecX& area, int max_swaps, Cover* c) {
  if (!c->picks.empty()) with_crew([&](Crew& crew) { improve_on(crew, pool, area, max_swaps, c); });
}

void extend_cover(const std::vector<Patch>& pool, const VecX& area, const CoverOptions& o, int max_swaps,
                  Cover* c) {
  c->used.resize(pool.size(), 0);
  if (full(*c, o) && c->picks.empty()) return;
  with_crew([&](Crew& crew) {
    if (!full(*c, o)) greedy_on(crew, pool, area, o, c);
    if (!c->picks.empty()) improve_on(crew, pool, area, max_swaps, c);
  });
}

namespace {
// The cover of `order` (pool indices) taken in that order, made in `c` (whatever it held: its
// storage is reused); `total` is area.sum(). With `crew`, each pick's blocks (kCoverBlock) are
// marked and summed in parallel.
void cover_in_order(const std::vector<Patch>& pool, const VecX& area, double total, const std::vector<int>& order,
                    Cover& c, Crew* crew = nullptr) {
  clear_cover(area, total, c, crew);
  c.used.assign(pool.size(), 0);
  std::vector<double> part;
  for (int k : order) {
    const int id = static_cast<int>(c.picks.size());
    const std::vector<int>& list = pool[static_cast<std::size_t>(k)].covered_vertices;
    // Block 0 adds to the covered area, the others sum from zero; a patch lists each vertex
    // once, so the blocks mark different vertices.
    part.assign(blocks_of(list.size()), 0.0);
    const auto add = [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) {
        double sum = i == 0 ? c.covered_area : 0.0;
        for (int v : block(list, i))
          if (c.vertex_patch[static_cast<std::size_t>(v)] < 0)
            c.vertex_patch[static_cast<std::size_t>(v)] = id, sum += area(v);
        part[i] = sum;
      }
    };
    if (crew && part.size() > 1)
      crew->parallel_for(0, part.size(), add, 1);
    else
      add(0, part.size());
    double sum = part[0];
    for (std::size_t i = 1; i < part.size(); ++i) sum += part[i];
    c.covered_area = sum;
    c.used[static_cast<std::size_t>(k)] = 1;
    c.picks.push_back(k);
    c.curve.push_back(c.fraction());
  }
}
}  // namespace

// The two orders below choose, step by step, the pick with the best sum over its vertices.
// A pick's sum moves only one way from step to step, so its last value bounds the next: a
// greedy gain only falls as more is covered, and a loss only grows as picks are dropped
// (the sum of fewer, or more, of the same non-negative terms, added in the same order, and
// rounding keeps that order). Each step sums afresh only the picks whose bound could still
// beat or tie the best fresh sum, taken best bound first: the choice is the same as summing
// every pick, bit for bit, at a fraction of the sums.

std::vector<int> greedy_order(const std::vector<Patch>& pool, const VecX& area, const std::vector<int>& picks) {
  const std::size_t P = picks.size();
  std::vector<int> greedy;
  std::vector<char> covered(static_cast<std::size_t>(area.size()), 0), taken(P, 0), fresh(P);
  std::vector<double> bound(P, std::numeric_limits<double>::infinity());  // at least the gain
  const auto error = [&](int i) {
    return pool[static_cast<std::size_t>(picks[static_cast<std::size_t>(i)])].error.max;
  };
  for (std::size_t step = 0; step < P; ++step) {
    std::fill(fresh.begin(), fresh.end(), 0);
    int best = -1;
    double best_gain = -1.0;
    for (;;) {
      int next = -1;  // the largest bound not summed this step, the lower index first
      for (std::size_t i = 0; i < P; ++i)
        if (!taken[i] && !fresh[i] && (next < 0 || bound[i] > bound[static_cast<std::size_t>(next)]))
          next = static_cast<int>(i);
      if (next < 0 || (best >= 0 && bound[static_cast<std::size_t>(next)] < best_gain)) break;
      const Patch& p = pool[static_cast<std::size_t>(picks[static_cast<std::size_t>(next)])];
      const double gain = area_where(p.covered_vertices, area, [&](std::size_t v) { return !covered[v]; });
      bound[static_cast<std::size_t>(next)] = gain;
      fresh[static_cast<std::size_t>(next)] = 1;
      const bool better = best < 0 || gain > best_gain ||
                          (gain == best_gain && (error(next) < error(best) ||
                                                 (error(next) == error(best) && next < best)));
      if (better) best = next, best_gain = gain;
    }
    taken[static_cast<std::size_t>(best)] = 1;
    greedy.push_back(picks[static_cast<std::size_t>(best)]);
    for (int v : pool[static_cast<std::size_t>(greedy.back())].covered_vertices) covered[static_cast<std::size_t>(v)] = 1;
  }
  return greedy;
}

namespace {
// elimination_order, with `count` the Tally of `picks` (its counts; the slots' sums, which
// it does not read, go stale as picks are dropped).
template <class Word>
std::vector<int> eliminate(const std::vector<Patch>& pool, const VecX& area, const std::vector<int>& picks,
                           Tally<Word> count) {
  const std::size_t P = picks.size();
  std::vector<int> eliminated;
  std::vector<char> gone(P, 0), fresh(P);
  std::vector<double> bound(P, 0.0);  // at most the loss
  for (std::size_t step = 0; step < P; ++step) {
    std::fill(fresh.begin(), fresh.end(), 0);
    int worst = -1;
    double worst_loss = 0.0;
    for (;;) {
      int next = -1;  // the smallest bound not summed this step, the higher index first
      for (std::size_t i = P; i-- > 0;)
        if (!gone[i] && !fresh[i] && (next < 0 || bound[i] < bound[static_cast<std::size_t>(next)]))
          next = static_cast<int>(i);
      if (next < 0 || (worst >= 0 && bound[static_cast<std::size_t>(next)] > worst_loss)) break;
      const Patch& p = pool[static_cast<std::size_t>(picks[static_cast<std::size_t>(next)])];
      const double loss =
          area_where(p.covered_vertices, area, [&](std::size_t v) { return one_pick(count[v]); });
      bound[static_cast<std::size_t>(next)] = loss;
      fresh[static_cast<std::size_t>(next)] = 1;
      if (worst < 0 || loss < worst_loss || (loss == worst_loss && next > worst))
        worst = next, worst_loss = loss;
    }
    gone[static_cast<std::size_t>(worst)] = 1;
    eliminated.push_back(picks[static_cast<std::size_t>(worst)]);
    for (int v : pool[static_cast<std::size_t>(eliminated.back())].covered_vertices)
      count[static_cast<std::size_t>(v)] -= kOnePick<Word>;
  }
  std::reverse(eliminated.begin(), eliminated.end());
  return eliminated;
}
}  // namespace

std::vector<int> elimination_order(const std::vector<Patch>& pool, const VecX& area, const std::vector<int>& picks) {
  using Word = std::uint64_t;
  return eliminate<Word>(pool, area, picks, count_covering<Word>(pool, area, picks));
}

namespace {
// order_cover's cover of `picks`, made in `c` (its storage reused: on a part of 129,000
// vertices a fresh cover's first touch of its pages cost more than the sums); `count` is
// count_covering of `picks` where the swaps left it (read only), or empty; `total` is
// area.sum().
template <class Word>
void order_on(Crew& crew, const std::vector<Patch>& pool, const VecX& area, double total, std::vector<int> picks,
              Cover* c, const Tally<Word>& count) {
  std::sort(picks.begin(), picks.end());
  // One pick has one order. A cover of that pick alone is that order's cover already: greedy
  // and cover_in_order mark its vertices and sum its blocks the same way, from the same empty
  // cover (on the 1M cone, some 40% of the cover stage was this cover made again).
  if (picks.size() == 1 && c->picks == picks) {
    c->used.resize(pool.size(), 0);
    return;
  }
  // Otherwise its cover is made once, its blocks shared out.
  if (picks.size() <= 1) {
    cover_in_order(pool, area, total, picks, *c, &crew);
    return;
  }
  // The two orders and their covers are independent: one task each. (Their steps, a few
  // sums each over a dozen picks, are too short to split: a fork per step cost more than
  // it saved.) The elimination counts down its own copy of `count`, the swaps' tally: the
  // other thread has read every line of the tally in the swaps, and each line's first write
  // here took it back from that thread's cache. Counting down the tally itself, the
  // elimination ran some 40% slower at two threads than at one, on either thread (Rotor 67
  // upper: 365 and 487 µs); on the copy, read from this thread's own cache, it runs as fast.
  // The calling thread takes it (the first task), as it wrote the swaps' last update.
  Cover& a = *c;
  Cover b;
  crew.parallel_for(0, 2, [&](std::size_t task, std::size_t) {
    if (task == 0) {
      Tally<Word> own =
          count.empty() ? count_covering<Word>(pool, area, picks) : Tally<Word>(count);
      cover_in_order(pool, area, total, eliminate(pool, area, picks, std::move(own)), b);
    } else {
      cover_in_order(pool, area, total, greedy_order(pool, area, picks), a);
    }
  }, 1);
  double sa = 0.0, sb = 0.0;
  for (double x : a.curve) sa += x;
  for (double x : b.curve) sb += x;
  if (sb > sa * (1.0 + 1e-12)) a = std::move(b);
}
}  // namespace

Cover order_cover(const std::vector<Patch>& pool, const VecX& area, std::vector<int> picks) {
  Cover out;
  const double total = area.sum();
  with_crew([&](Crew& crew) {
    if (picks.size() <= kNarrowPicks)
      order_on<std::uint32_t>(crew, pool, area, total, std::move(picks), &out);
    else
      order_on<std::uint64_t>(crew, pool, area, total, std::move(picks), &out);
  });
  return out;
}

std::vector<UncoveredRegion> uncovered_regions(const Mesh& mesh, const std::vector<int>& vertex_patch,
                                               const VecX& area) {
  const int V = mesh.vertex_count();
  std::vector<int> parent(static_cast<std::size_t>(V));
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (int f = 0; f < mesh.face_count(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.F(f, k), b = mesh.F(f, (k + 1) % 3);
      if (vertex_patch[a] < 0 && vertex_patch[b] < 0) parent[find(a)] = find(b);
    }
  std::vector<UncoveredRegion> regions;
  std::vector<int> slot(static_cast<std::size_t>(V), -1);
  for (int v = 0; v < V; ++v) {
    if (vertex_patch[v] >= 0) continue;
    const int r = find(v);
    if (slot[r] < 0) {
      slot[r] = static_cast<int>(regions.size());
      regions.emplace_back();
    }
    UncoveredRegion& u = regions[static_cast<std::size_t>(slot[r])];
    u.area += area(v);
    u.centroid += area(v) * mesh.V.row(v).transpose();
    ++u.vertices;
  }
  for (UncoveredRegion& u : regions)
    if (u.area > 0) u.centroid /= u.area;
  std::stable_sort(regions.begin(), regions.end(),
                   [](const UncoveredRegion& a, const UncoveredRegion& b) { return a.area > b.area; });
  return regions;
}

}  // namespace flank
