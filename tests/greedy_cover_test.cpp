// The greedy cover and its local improvement against brute force over small pools, and the
// uncovered regions of a grid mesh against their areas and centroids summed by hand.
#include "solver/greedy_cover.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

#include "kernels/parallel.h"

namespace flank {
namespace {

Patch make_patch(std::vector<int> vertices, double error = 0.0) {
  Patch p;
  p.covered_vertices = std::move(vertices);
  p.error.max = error;
  return p;
}

std::vector<int> range_of(int first, int last) {  // [first, last]
  std::vector<int> v;
  for (int i = first; i <= last; ++i) v.push_back(i);
  return v;
}

// A patch covering the run of `1 + rng() % max_len` vertices from a random one, cyclically
// over V, with an error of 0.01 × (rng() % error_levels): the random pools' entries.
Patch random_run(std::mt19937& rng, int V, int max_len, int error_levels) {
  std::vector<int> verts;
  const int first = static_cast<int>(rng() % V), len = 1 + static_cast<int>(rng() % max_len);
  for (int i = 0; i < len; ++i) verts.push_back((first + i) % V);
  return make_patch(verts, 0.01 * static_cast<double>(rng() % error_levels));
}

// V vertex areas, each 0.5, 1 or 1.5: equal sums, and so ties, are common.
VecX three_valued_areas(std::mt19937& rng, int V) {
  VecX area(V);
  for (int v = 0; v < V; ++v) area(v) = 0.5 * (1 + static_cast<int>(rng() % 3));
  return area;
}

double union_area(const std::vector<Patch>& pool, const std::vector<int>& picks, const VecX& area) {
  std::vector<char> seen(static_cast<std::size_t>(area.size()), 0);
  double sum = 0.0;
  for (int k : picks)
    for (int v : pool[static_cast<std::size_t>(k)].covered_vertices)
      if (!seen[static_cast<std::size_t>(v)]) seen[static_cast<std::size_t>(v)] = 1, sum += area(v);
  return sum;
}

// Σ area(v) over `list` where keep(v), summed as the cover sums (kCoverBlock): the first
// block's terms added one by one to `start`, each later block's from zero and added after.
template <class Keep>
double block_sum(const std::vector<int>& list, double start, const VecX& area, Keep keep) {
  double total = start;
  for (std::size_t b = 0; b < list.size(); b += kCoverBlock) {
    double sum = b == 0 ? start : 0.0;
    for (std::size_t i = b; i < std::min(list.size(), b + kCoverBlock); ++i)
      if (keep(list[i])) sum += area(list[i]);
    total = b == 0 ? sum : total + sum;
  }
  return total;
}

double gain_over(const Patch& p, const std::vector<char>& covered, const VecX& area) {
  return block_sum(p.covered_vertices, 0.0, area, [&](int v) { return !covered[static_cast<std::size_t>(v)]; });
}

// Everything a Cover states about itself, recomputed from its picks: vertex_patch names the
// pick that first covered each vertex, covered_area sums them, curve is the covered fraction
// after each pick (so non-decreasing), used marks exactly the picks, and each pick took the
// largest gain left (ties: lower error, then lower pool index) among the unused entries of the
// pool. With `ordered` (a cover rebuilt by improve_cover / order_cover) the order is not
// checked: order_cover may take the reverse of backward elimination.
void expect_cover_consistent(const std::vector<Patch>& pool, const VecX& area, const Cover& c,
                             bool ordered = false) {
  const std::size_t V = static_cast<std::size_t>(area.size());
  ASSERT_EQ(c.vertex_patch.size(), V);
  ASSERT_EQ(c.curve.size(), c.picks.size());
  EXPECT_DOUBLE_EQ(c.total_area, area.sum());
  std::vector<int> first(V, -1);
  std::vector<char> covered(V, 0), used(pool.size(), 0);
  double covered_area = 0.0;
  for (std::size_t k = 0; k < c.picks.size(); ++k) {
    const int pick = c.picks[k];
    ASSERT_GE(pick, 0);
    ASSERT_LT(pick, static_cast<int>(pool.size()));
    EXPECT_FALSE(used[static_cast<std::size_t>(pick)]) << "picked twice: " << pick;
    // Greedy: no unused patch would have added more, or as much with a lower error, or as
    // much with the same error and a lower index.
    const double g = gain_over(pool[static_cast<std::size_t>(pick)], covered, area);
    std::vector<int> rivals;
    if (!ordered)
      for (std::size_t q = 0; q < pool.size(); ++q)
        if (!used[q] && static_cast<int>(q) != pick) rivals.push_back(static_cast<int>(q));
    for (int qi : rivals) {
      const auto q = static_cast<std::size_t>(qi);
      const double h = gain_over(pool[q], covered, area);
      EXPECT_LE(h, g) << "pick " << k << " pool " << q;
      if (h == g) {
        const double eq = pool[q].error.max, ep = pool[static_cast<std::size_t>(pick)].error.max;
        EXPECT_TRUE(eq > ep || (eq == ep && static_cast<int>(q) > pick)) << "tie at pick " << k << " pool " << q;
      }
    }
    used[static_cast<std::size_t>(pick)] = 1;
    const std::vector<int>& list = pool[static_cast<std::size_t>(pick)].covered_vertices;
    covered_area = block_sum(list, covered_area, area, [&](int v) { return !covered[static_cast<std::size_t>(v)]; });
    for (int v : list)
      if (!covered[static_cast<std::size_t>(v)]) {
        covered[static_cast<std::size_t>(v)] = 1;
        first[static_cast<std::size_t>(v)] = static_cast<int>(k);
      }
    // Exactly: the cover sums the same terms in the same order (each new vertex's area, pick
    // after pick, in each patch's order and blocks), however its loops share out the work.
    EXPECT_EQ(c.curve[k], covered_area / area.sum()) << "pick " << k;
    if (k > 0) {
      EXPECT_GE(c.curve[k], c.curve[k - 1]);
    }
  }
  EXPECT_EQ(c.vertex_patch, first);
  EXPECT_EQ(c.covered_area, covered_area);
  ASSERT_EQ(c.used.size(), pool.size());
  for (std::size_t q = 0; q < pool.size(); ++q) EXPECT_EQ(c.used[q] != 0, used[q] != 0) << "pool " << q;
}

// Every cover of `covers` the same as the first, field by field, bit for bit.
void expect_all_equal(const std::vector<Cover>& covers) {
  for (std::size_t k = 1; k < covers.size(); ++k) {
    SCOPED_TRACE(::testing::Message() << "cover " << k);
    EXPECT_EQ(covers[0].picks, covers[k].picks);
    EXPECT_EQ(covers[0].curve, covers[k].curve);
    EXPECT_EQ(covers[0].vertex_patch, covers[k].vertex_patch);
    EXPECT_EQ(covers[0].covered_area, covers[k].covered_area);
    EXPECT_EQ(covers[0].used, covers[k].used);
  }
}

CoverOptions take_all(int max_patches) {
  CoverOptions o;
  o.coverage_target = 1.0;
  o.max_patches = max_patches;
  o.min_gain = 0.0;
  return o;
}

TEST(GreedyCover, EmptyCover) {
  const VecX area = VecX::LinSpaced(5, 1.0, 5.0);
  const Cover c = empty_cover(area);
  EXPECT_EQ(c.vertex_patch, std::vector<int>(5, -1));
  EXPECT_TRUE(c.picks.empty());
  EXPECT_TRUE(c.curve.empty());
  EXPECT_EQ(c.covered_area, 0.0);
  EXPECT_EQ(c.total_area, 15.0);
  EXPECT_EQ(c.fraction(), 0.0);
  EXPECT_EQ(empty_cover(VecX()).fraction(), 0.0);
}

// The first pick is the patch of the largest area, not of the most vertices.
TEST(GreedyCover, FirstPickHasTheLargestArea) {
  VecX area(10);
  area << 1, 1, 1, 1, 1, 1, 4, 4, 0.5, 0.5;
  const std::vector<Patch> pool = {
      make_patch(range_of(0, 5)),   // 6 vertices, area 6
      make_patch({6, 7}),           // 2 vertices, area 8
      make_patch({3, 4, 5, 8, 9}),  // area 4
  };
  Cover c = empty_cover(area);
  greedy_cover(pool, area, take_all(10), &c);
  ASSERT_FALSE(c.picks.empty());
  EXPECT_EQ(c.picks[0], 1);
  EXPECT_EQ(c.picks, (std::vector<int>{1, 0, 2}));
  EXPECT_DOUBLE_EQ(c.fraction(), 1.0);
  expect_cover_consistent(pool, area, c);
}

// Equal gains: the lower error, then the lower pool index.
TEST(GreedyCover, TiesGoToTheLowerErrorThenTheLowerIndex) {
  const VecX area = VecX::Ones(12);
  const std::vector<Patch> pool = {
      make_patch({0, 1, 2}, 0.5), make_patch({3, 4, 5}, 0.1), make_patch({6, 7, 8}, 0.1),
      make_patch({9, 10, 11}, 0.05), make_patch({9, 10}, 0.0)};
  Cover c = empty_cover(area);
  greedy_cover(pool, area, take_all(4), &c);
  EXPECT_EQ(c.picks, (std::vector<int>{3, 1, 2, 0}));
  expect_cover_consistent(pool, area, c);
  // All errors equal: pool order.
  std::vector<Patch> same = pool;
  for (Patch& p : same) p.error.max = 0.2;
  Cover d = empty_cover(area);
  greedy_cover(same, area, take_all(4), &d);
  EXPECT_EQ(d.picks, (std::vector<int>{0, 1, 2, 3}));
  expect_cover_consistent(same, area, d);
}

// min_gain: a patch adding exactly the minimum is taken, one adding less is not.
TEST(GreedyCover, MinGainStops) {
  const VecX area = VecX::Ones(8);  // total 8
  const std::vector<Patch> pool = {make_patch(range_of(0, 3)), make_patch({4, 5}), make_patch({5, 6}),
                                   make_patch({7})};
  CoverOptions o = take_all(10);
  o.min_gain = 0.125;  // one vertex of eight
  Cover c = empty_cover(area);
  greedy_cover(pool, area, o, &c);
  EXPECT_EQ(c.picks, (std::vector<int>{0, 1, 2, 3}));
  o.min_gain = 0.25;  // two vertices: {5, 6} adds one once {4, 5} is in
  Cover d = empty_cover(area);
  greedy_cover(pool, area, o, &d);
  EXPECT_EQ(d.picks, (std::vector<int>{0, 1}));
  expect_cover_consistent(pool, area, d);
}

// max_patches counts the whole cover, across calls; max_picks the picks of one call.
TEST(GreedyCover, MaxPatchesAndMaxPicksStop) {
  const VecX area = VecX::Ones(10);
  std::vector<Patch> pool;
  for (int k = 0; k < 5; ++k) pool.push_back(make_patch({2 * k, 2 * k + 1}, 0.1 * k));
  Cover c = empty_cover(area);
  greedy_cover(pool, area, take_all(2), &c);
  EXPECT_EQ(c.picks.size(), 2u);
  greedy_cover(pool, area, take_all(2), &c);
  EXPECT_EQ(c.picks.size(), 2u);
  greedy_cover(pool, area, take_all(3), &c);
  EXPECT_EQ(c.picks.size(), 3u);
  expect_cover_consistent(pool, area, c);

  // One pick per call gives the same cover as one call.
  CoverOptions one = take_all(10);
  one.max_picks = 1;
  Cover step = empty_cover(area);
  for (int call = 1; call <= 5; ++call) {
    greedy_cover(pool, area, one, &step);
    EXPECT_EQ(step.picks.size(), static_cast<std::size_t>(call));
  }
  Cover all = empty_cover(area);
  greedy_cover(pool, area, take_all(10), &all);
  EXPECT_EQ(step.picks, all.picks);
  EXPECT_EQ(step.vertex_patch, all.vertex_patch);
  EXPECT_EQ(step.curve, all.curve);
  // Nothing left: further calls add nothing.
  greedy_cover(pool, area, one, &step);
  EXPECT_EQ(step.picks.size(), 5u);
}

// coverage_target: no pick once the covered fraction reaches it (inclusive).
TEST(GreedyCover, CoverageTargetStops) {
  const VecX area = VecX::Ones(8);
  const std::vector<Patch> pool = {make_patch(range_of(0, 2)), make_patch({3}), make_patch({4, 5}),
                                   make_patch({6, 7})};
  CoverOptions o = take_all(10);
  o.coverage_target = 0.625;  // 5 of 8
  Cover c = empty_cover(area);
  greedy_cover(pool, area, o, &c);
  // 3/8, then 5/8 reached exactly: stop.
  EXPECT_EQ(c.picks, (std::vector<int>{0, 2}));
  EXPECT_DOUBLE_EQ(c.fraction(), 0.625);
  o.coverage_target = 0.63;
  Cover d = empty_cover(area);
  greedy_cover(pool, area, o, &d);
  EXPECT_EQ(d.picks, (std::vector<int>{0, 2, 3}));
}

// Random pools with a fixed seed: every invariant of the cover, and it extends itself.
TEST(GreedyCover, RandomPoolsKeepEveryInvariant) {
  std::mt19937 rng(4242);
  std::uniform_real_distribution<double> uni(0.1, 2.0);
  for (int trial = 0; trial < 100; ++trial) {
    const int V = 30 + static_cast<int>(rng() % 30), P = 4 + static_cast<int>(rng() % 10);
    VecX area(V);
    for (int v = 0; v < V; ++v) area(v) = uni(rng);
    std::vector<Patch> pool;
    for (int k = 0; k < P; ++k) pool.push_back(random_run(rng, V, V / 2, 4));
    CoverOptions o;
    o.coverage_target = 0.9, o.max_patches = 6, o.min_gain = 0.02;
    Cover c = empty_cover(area);
    greedy_cover(pool, area, o, &c);
    SCOPED_TRACE(::testing::Message() << "trial " << trial);
    expect_cover_consistent(pool, area, c);
    EXPECT_LE(static_cast<int>(c.picks.size()), o.max_patches);
    // Why it stopped: the cap, the target, or no patch adds min_gain.
    std::vector<char> covered(static_cast<std::size_t>(V), 0);
    for (int v = 0; v < V; ++v) covered[static_cast<std::size_t>(v)] = c.vertex_patch[static_cast<std::size_t>(v)] >= 0;
    double best_left = 0.0;
    for (std::size_t q = 0; q < pool.size(); ++q)
      if (!c.used[q]) best_left = std::max(best_left, gain_over(pool[q], covered, area));
    EXPECT_TRUE(static_cast<int>(c.picks.size()) == o.max_patches || c.fraction() >= o.coverage_target ||
                best_left < o.min_gain * c.total_area);
  }
}

// The classic case where greedy is myopic: a large middle patch overlaps two disjoint halves
// that together cover everything. With two patches greedy takes the middle and one half;
// improve_cover swaps the middle for the other half and reaches the optimum, rebuilt in
// greedy order.
TEST(ImproveCover, SwapReachesTheOptimumOfTheClassicCase) {
  const VecX area = VecX::Ones(8);
  const std::vector<Patch> pool = {
      make_patch(range_of(1, 6), 0.0),  // middle: 6
      make_patch(range_of(0, 3), 0.3),  // left half: 4
      make_patch(range_of(4, 7), 0.2),  // right half: 4
  };
  Cover c = empty_cover(area);
  greedy_cover(pool, area, take_all(2), &c);
  ASSERT_EQ(c.picks, (std::vector<int>{0, 2}));  // the middle, then the right half (lower error)
  EXPECT_DOUBLE_EQ(c.covered_area, 7.0);
  improve_cover(pool, area, 10, &c);
  EXPECT_DOUBLE_EQ(c.covered_area, 8.0);
  EXPECT_DOUBLE_EQ(c.fraction(), 1.0);
  // Greedy order over the two halves: equal gains, the lower error first.
  EXPECT_EQ(c.picks, (std::vector<int>{2, 1}));
  EXPECT_EQ(c.curve, (std::vector<double>{0.5, 1.0}));
  expect_cover_consistent(pool, area, c, true);
  // No swap allowed: only re-ordered, nothing gained.
  Cover d = empty_cover(area);
  greedy_cover(pool, area, take_all(2), &d);
  improve_cover(pool, area, 0, &d);
  EXPECT_EQ(d.picks, (std::vector<int>{0, 2}));
  EXPECT_DOUBLE_EQ(d.covered_area, 7.0);
  // An empty cover stays empty.
  Cover e = empty_cover(area);
  improve_cover(pool, area, 10, &e);
  EXPECT_TRUE(e.picks.empty());
}

// The number of patches stays, even when a swap makes a pick redundant: greedy takes p0, p1,
// p2 (9 of 10 vertices); swapping p0 for p3 covers all 10 with p3 and p2 alone, and p1 stays
// (decompose compares picks.size() with the count before the round).
TEST(ImproveCover, KeepsTheNumberOfPatches) {
  const VecX area = VecX::Ones(10);
  const std::vector<Patch> pool = {make_patch({0, 2, 3, 6, 8, 9}, 0.00), make_patch({4, 6, 7}, 0.01),
                                   make_patch({0, 5, 6, 7, 9}, 0.02), make_patch({0, 1, 2, 3, 4, 8}, 0.03)};
  Cover c = empty_cover(area);
  greedy_cover(pool, area, take_all(3), &c);
  ASSERT_EQ(c.picks, (std::vector<int>{0, 1, 2}));
  ASSERT_DOUBLE_EQ(c.covered_area, 9.0);
  improve_cover(pool, area, 10, &c);
  EXPECT_DOUBLE_EQ(c.covered_area, 10.0);
  EXPECT_EQ(c.picks.size(), 3u);
}

// The rebuilt cover breaks ties by pool index, as greedy_cover documents ("ties: the lower
// error, then the lower pool index"). Classic case with equal errors: greedy takes the middle
// (0) and the left half (1); the swap puts the right half (2) in; the two equal halves come
// back as [1, 2].
TEST(ImproveCover, RebuildBreaksTiesByPoolIndex) {
  const VecX area = VecX::Ones(8);
  const std::vector<Patch> pool = {make_patch(range_of(1, 6)), make_patch(range_of(0, 3)), make_patch(range_of(4, 7))};
  Cover c = empty_cover(area);
  greedy_cover(pool, area, take_all(2), &c);
  ASSERT_EQ(c.picks, (std::vector<int>{0, 1}));
  improve_cover(pool, area, 10, &c);
  EXPECT_DOUBLE_EQ(c.covered_area, 8.0);
  EXPECT_EQ(c.picks, (std::vector<int>{1, 2}));
}

// Random small instances with a fixed seed, against brute force over every k-subset
// (k = 2, 3): improve_cover never lowers the covered area, never exceeds the optimum, keeps
// the number of patches (when nothing it picks is redundant), ends where no single swap gains,
// and the rebuilt cover is greedy over its picks. Reports how often it reaches the optimum.
TEST(ImproveCover, NeverLosesAreaAndEndsAtASwapLocalOptimum) {
  std::mt19937 rng(99);
  std::uniform_real_distribution<double> uni(0.5, 1.5);
  int instances = 0, optimal = 0, greedy_optimal = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const int V = 10 + static_cast<int>(rng() % 8), P = 5 + static_cast<int>(rng() % 4);
    const int k = 2 + trial % 2;
    VecX area(V);
    for (int v = 0; v < V; ++v) area(v) = uni(rng);
    std::vector<Patch> pool;
    for (int p = 0; p < P; ++p) {
      std::vector<int> verts;
      for (int v = 0; v < V; ++v)
        if (rng() % 3 == 0) verts.push_back(v);
      if (verts.empty()) verts.push_back(static_cast<int>(rng() % V));
      pool.push_back(make_patch(verts, 0.01 * p));
    }
    Cover c = empty_cover(area);
    greedy_cover(pool, area, take_all(k), &c);
    const double before = c.covered_area;
    const std::vector<int> greedy_picks = c.picks;
    improve_cover(pool, area, 100, &c);
    SCOPED_TRACE(::testing::Message() << "trial " << trial << " k " << k);
    expect_cover_consistent(pool, area, c, true);
    EXPECT_GE(c.covered_area, before - 1e-12);
    EXPECT_NEAR(c.covered_area, union_area(pool, c.picks, area), 1e-12);

    // Brute force over k-subsets (bitmasks of P ≤ 8 entries).
    double best = 0.0;
    for (unsigned mask = 0; mask < (1u << P); ++mask) {
      if (__builtin_popcount(mask) != k) continue;
      std::vector<int> subset;
      for (int p = 0; p < P; ++p)
        if (mask >> p & 1u) subset.push_back(p);
      best = std::max(best, union_area(pool, subset, area));
    }
    EXPECT_LE(c.covered_area, best + 1e-12);
    // A swap local optimum: no pick exchanged for an unpicked patch covers more.
    if (c.covered_area < area.sum() - 1e-12) {
      EXPECT_EQ(c.picks.size(), greedy_picks.size());
      for (std::size_t i = 0; i < c.picks.size(); ++i)
        for (int q = 0; q < P; ++q) {
          if (c.used[static_cast<std::size_t>(q)]) continue;
          std::vector<int> swapped = c.picks;
          swapped[i] = q;
          EXPECT_LE(union_area(pool, swapped, area), c.covered_area + 1e-9 * area.sum()) << "swap " << i << " for " << q;
        }
    }
    ++instances;
    optimal += c.covered_area >= best - 1e-12;
    greedy_optimal += before >= best - 1e-12;
  }
  // Local search must do at least as well as greedy alone on this family, and usually reach
  // the optimum.
  EXPECT_GE(optimal, greedy_optimal);
  EXPECT_GE(optimal, instances * 9 / 10);
  std::printf("[ improve ] optimum reached in %d of %d instances (greedy alone: %d)\n", optimal, instances,
              greedy_optimal);
}

// The cover's sums run in parallel, each into its own slot, and the choices are made after,
// serially: the same cover at one thread and at two, ties included, and from extend_cover as
// from greedy_cover and improve_cover. Pools large enough to be split (dozens of patches over
// thousands of vertices), with areas from three values and errors from two, so that equal
// gains are common and the tie rules decide.
TEST(GreedyCover, SameCoverWhateverTheThreadCount) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 12; ++trial) {
    const int V = 2000 + static_cast<int>(rng() % 2000), P = 20 + static_cast<int>(rng() % 40);
    const VecX area = three_valued_areas(rng, V);
    std::vector<Patch> pool;
    for (int k = 0; k < P; ++k) pool.push_back(random_run(rng, V, V / 4, 2));
    if (trial % 3 == 0) pool.push_back(pool[rng() % pool.size()]);  // an exact duplicate
    CoverOptions o;
    o.coverage_target = 0.99, o.max_patches = 4 + trial % 6, o.min_gain = 0.001;
    std::vector<Cover> covers;
    for (const int threads : {1, 2}) {
      const ThreadLimit limit(threads);
      Cover c = empty_cover(area);
      greedy_cover(pool, area, o, &c);
      improve_cover(pool, area, 8, &c);
      covers.push_back(c);
      Cover e = empty_cover(area);  // the two calls in one
      extend_cover(pool, area, o, 8, &e);
      covers.push_back(e);
    }
    SCOPED_TRACE(::testing::Message() << "trial " << trial);
    expect_all_equal(covers);
    expect_cover_consistent(pool, area, covers[1], true);
  }
}

// Lists longer than a block (kCoverBlock): a part one patch covers, and pools of a few long
// patches. Their sums are split into blocks, each a task of its own: the same cover at one
// thread and at two, from greedy_cover and improve_cover, extend_cover and order_cover alike,
// its covered area summed block by block (expect_cover_consistent). Areas over six orders of
// magnitude, so that how the terms are grouped shows in the sums' last bits; lists in no
// order.
TEST(GreedyCover, LongListsSumInBlocksTheSameAtAnyThreadCount) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> exponent(-4.0, 2.0);
  const int V = 8 * static_cast<int>(kCoverBlock) + 1234;
  VecX area(V);
  for (int v = 0; v < V; ++v) area(v) = std::pow(10.0, exponent(rng));
  for (int trial = 0; trial < 7; ++trial) {
    SCOPED_TRACE(::testing::Message() << "trial " << trial);
    const int P = trial == 0 ? 1 : 2 + trial;  // trial 0: one patch over nearly all of Φ
    std::vector<Patch> pool;
    for (int k = 0; k < P; ++k)
      pool.push_back(trial == 0 ? make_patch(range_of(7, V - 3)) : random_run(rng, V, V, 2));
    for (Patch& p : pool) std::shuffle(p.covered_vertices.begin(), p.covered_vertices.end(), rng);
    CoverOptions o = take_all(P);                  // every entry picked: none to swap in
    if (trial % 2 == 0 && P > 1) o.max_patches = P - 1;  // one left over to swap in
    // One pick of several: improve_cover keeps greedy's cover of it as order_cover's.
    if (trial == 6) o.max_patches = 1;
    if (trial == 0) {
      // The data tells the blocks from one sum in the list's order.
      double plain = 0.0;
      for (int v : pool[0].covered_vertices) plain += area(v);
      ASSERT_GT(pool[0].covered_vertices.size(), 8 * kCoverBlock);
      ASSERT_NE(plain, block_sum(pool[0].covered_vertices, 0.0, area, [](int) { return true; }));
    }
    std::vector<Cover> covers;
    for (const int threads : {1, 2}) {
      const ThreadLimit limit(threads);
      Cover c = empty_cover(area);
      greedy_cover(pool, area, o, &c);
      expect_cover_consistent(pool, area, c);
      improve_cover(pool, area, 4, &c);
      covers.push_back(c);
      Cover e = empty_cover(area);  // the two calls in one
      extend_cover(pool, area, o, 4, &e);
      covers.push_back(e);
      covers.push_back(order_cover(pool, area, c.picks));
    }
    expect_all_equal(covers);
    expect_cover_consistent(pool, area, covers[0], true);
  }
}

// improve_cover's swap search as it is specified: each pick taken out in turn, the counts of
// the others recounted, every unpicked entry's gain summed over them, the first entry at the
// largest gain minus loss, then the first pick at the largest (improve_cover sums every pick's
// swaps in one pass over each entry). Then the same order_cover.
Cover improved_by_taking_each_out(const std::vector<Patch>& pool, const VecX& area, int max_swaps, Cover c) {
  std::vector<int> picks = c.picks;
  for (int swap = 0; swap < max_swaps; ++swap) {
    const double least = 1e-9 * c.total_area;
    double best_delta = least;
    int best_out = -1, best_in = -1;
    for (std::size_t i = 0; i < picks.size(); ++i) {
      std::vector<int> others(static_cast<std::size_t>(area.size()), 0);
      for (std::size_t o = 0; o < picks.size(); ++o)
        if (o != i)
          for (int v : pool[static_cast<std::size_t>(picks[o])].covered_vertices) ++others[static_cast<std::size_t>(v)];
      double loss = 0.0;
      for (int v : pool[static_cast<std::size_t>(picks[i])].covered_vertices)
        if (others[static_cast<std::size_t>(v)] == 0) loss += area(v);
      double delta = least;
      int in = -1;
      for (std::size_t j = 0; j < pool.size(); ++j) {
        if (std::find(picks.begin(), picks.end(), static_cast<int>(j)) != picks.end()) continue;
        double gain = 0.0;
        for (int v : pool[j].covered_vertices)
          if (others[static_cast<std::size_t>(v)] == 0) gain += area(v);
        if (gain - loss > delta) delta = gain - loss, in = static_cast<int>(j);
      }
      if (in >= 0 && delta > best_delta) best_delta = delta, best_out = static_cast<int>(i), best_in = in;
    }
    if (best_out < 0) break;
    picks[static_cast<std::size_t>(best_out)] = best_in;
  }
  return order_cover(pool, area, picks);
}

// The same swaps, bit for bit, as the search specified above, on pools where equal gains
// are common (areas from three values): the ties go the same way.
TEST(ImproveCover, SameSwapsAsTakingEachPickOutInTurn) {
  std::mt19937 rng(11);
  int swapped = 0;
  for (int trial = 0; trial < 100; ++trial) {
    const int V = 200 + static_cast<int>(rng() % 800), P = 10 + static_cast<int>(rng() % 30);
    const VecX area = three_valued_areas(rng, V);
    std::vector<Patch> pool;
    for (int k = 0; k < P; ++k) pool.push_back(random_run(rng, V, V / 3, 2));
    CoverOptions o;
    o.coverage_target = 0.99, o.max_patches = 2 + trial % 7, o.min_gain = 0.001;
    Cover c = empty_cover(area);
    greedy_cover(pool, area, o, &c);
    const Cover want = improved_by_taking_each_out(pool, area, 8, c);
    swapped += want.picks != order_cover(pool, area, c.picks).picks;
    improve_cover(pool, area, 8, &c);
    SCOPED_TRACE(::testing::Message() << "trial " << trial);
    EXPECT_EQ(c.picks, want.picks);
    EXPECT_EQ(c.covered_area, want.covered_area);
    EXPECT_EQ(c.vertex_patch, want.vertex_patch);
  }
  std::printf("[ improve ] %d of 100 covers changed by swaps\n", swapped);
  EXPECT_GE(swapped, 10);  // the pools exercise the swaps, not only the rebuild
}

// The same at 255 picks and at 300: improve_cover keeps each vertex's count and slot sum in
// one 32-bit word up to 255 picks and in a 64-bit word beyond, where a slot sum outgrows 24
// bits. Short entries over a long strip, all of them picked up to the cap (no minimum gain).
TEST(ImproveCover, SameSwapsAsTakingEachPickOutInTurnAtManyPicks) {
  std::mt19937 rng(17);
  for (const int max_patches : {255, 300}) {
    SCOPED_TRACE(::testing::Message() << max_patches << " picks at most");
    const int V = 6000, P = 400;
    const VecX area = three_valued_areas(rng, V);
    std::vector<Patch> pool;
    for (int k = 0; k < P; ++k) pool.push_back(random_run(rng, V, 12, 2));
    Cover c = empty_cover(area);
    greedy_cover(pool, area, take_all(max_patches), &c);
    ASSERT_EQ(static_cast<int>(c.picks.size()), max_patches);
    const Cover want = improved_by_taking_each_out(pool, area, 8, c);
    EXPECT_NE(want.picks, order_cover(pool, area, c.picks).picks);  // the swaps changed it
    improve_cover(pool, area, 8, &c);
    EXPECT_EQ(c.picks, want.picks);
    EXPECT_EQ(c.covered_area, want.covered_area);
    EXPECT_EQ(c.vertex_patch, want.vertex_patch);
  }
}

// The two orders as specified: every pick summed afresh at every step.
std::vector<int> greedy_order_summing_all(const std::vector<Patch>& pool, const VecX& area,
                                          const std::vector<int>& picks) {
  std::vector<int> order;
  std::vector<char> covered(static_cast<std::size_t>(area.size()), 0), taken(picks.size(), 0);
  for (std::size_t step = 0; step < picks.size(); ++step) {
    int best = -1;
    double best_gain = -1.0;
    for (std::size_t i = 0; i < picks.size(); ++i) {
      if (taken[i]) continue;
      const Patch& p = pool[static_cast<std::size_t>(picks[i])];
      const double gain = gain_over(p, covered, area);
      const auto best_error = [&] {
        return pool[static_cast<std::size_t>(picks[static_cast<std::size_t>(best)])].error.max;
      };
      if (best < 0 || gain > best_gain || (gain == best_gain && p.error.max < best_error()))
        best = static_cast<int>(i), best_gain = gain;
    }
    taken[static_cast<std::size_t>(best)] = 1;
    order.push_back(picks[static_cast<std::size_t>(best)]);
    for (int v : pool[static_cast<std::size_t>(order.back())].covered_vertices)
      covered[static_cast<std::size_t>(v)] = 1;
  }
  return order;
}

std::vector<int> elimination_order_summing_all(const std::vector<Patch>& pool, const VecX& area,
                                               const std::vector<int>& picks) {
  std::vector<int> dropped;
  std::vector<int> count(static_cast<std::size_t>(area.size()), 0);
  for (int k : picks)
    for (int v : pool[static_cast<std::size_t>(k)].covered_vertices) ++count[static_cast<std::size_t>(v)];
  std::vector<char> gone(picks.size(), 0);
  for (std::size_t step = 0; step < picks.size(); ++step) {
    int worst = -1;
    double worst_loss = 0.0;
    for (std::size_t i = picks.size(); i-- > 0;) {
      if (gone[i]) continue;
      double loss = 0.0;
      for (int v : pool[static_cast<std::size_t>(picks[i])].covered_vertices)
        if (count[static_cast<std::size_t>(v)] == 1) loss += area(v);
      if (worst < 0 || loss < worst_loss) worst = static_cast<int>(i), worst_loss = loss;
    }
    gone[static_cast<std::size_t>(worst)] = 1;
    dropped.push_back(picks[static_cast<std::size_t>(worst)]);
    for (int v : pool[static_cast<std::size_t>(dropped.back())].covered_vertices)
      --count[static_cast<std::size_t>(v)];
  }
  std::reverse(dropped.begin(), dropped.end());
  return dropped;
}

// The orders sum again only the picks whose last sum could still beat or tie the best: the
// same orders, ties included, as summing every pick at every step. Pools with equal sums
// common (three area values, two error levels, entries repeated).
TEST(OrderCover, SameOrdersAsSummingEveryPickEachStep) {
  std::mt19937 rng(5);
  int orders_differ = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const int V = 100 + static_cast<int>(rng() % 400), P = 2 + static_cast<int>(rng() % 24);
    const VecX area = three_valued_areas(rng, V);
    std::vector<Patch> pool;
    for (int k = 0; k < P; ++k)
      pool.push_back(k > 0 && rng() % 5 == 0 ? pool[rng() % static_cast<unsigned>(k)]
                                             : random_run(rng, V, V / 2, 2));
    std::vector<int> picks;
    for (int k = 0; k < P; ++k)
      if (rng() % 4 != 0) picks.push_back(k);
    SCOPED_TRACE(::testing::Message() << "trial " << trial);
    const std::vector<int> greedy = greedy_order(pool, area, picks);
    const std::vector<int> eliminated = elimination_order(pool, area, picks);
    EXPECT_EQ(greedy, greedy_order_summing_all(pool, area, picks));
    EXPECT_EQ(eliminated, elimination_order_summing_all(pool, area, picks));
    orders_differ += greedy != eliminated;
  }
  EXPECT_GE(orders_differ, 50);  // the two orders are not the same search
}

// order_cover returns the picks themselves, in an order that covers at least as much summed
// over 1..k as the greedy order does, and covers more with fewer patches when greedy commits
// to a large patch first: here the big middle patch (6 of 10 vertices) overlaps both halves
// (5 each); greedy takes it first (6, 8, 10), elimination drops it (5, 10, 10).
TEST(OrderCover, AtLeastAsGoodAsGreedySummedOverPrefixes) {
  VecX area = VecX::Ones(10);
  std::vector<Patch> pool = {make_patch({2, 3, 4, 5, 6, 7}, 0.0), make_patch({0, 1, 2, 3, 4}, 0.0),
                             make_patch({5, 6, 7, 8, 9}, 0.0)};
  const Cover c = order_cover(pool, area, {0, 1, 2});
  expect_cover_consistent(pool, area, c, true);
  std::vector<int> sorted = c.picks;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_EQ(sorted, (std::vector<int>{0, 1, 2}));
  ASSERT_EQ(c.curve.size(), 3u);
  EXPECT_NEAR(c.curve[1], 1.0, 1e-12);  // the two halves first
  EXPECT_EQ(c.picks[2], 0);
  // Random pools: never below the greedy order's sum.
  std::mt19937 rng(7);
  for (int trial = 0; trial < 200; ++trial) {
    const int V = 12, P = 6;
    VecX a(V);
    for (int v = 0; v < V; ++v) a(v) = 0.5 + (rng() % 100) / 100.0;
    std::vector<Patch> q;
    for (int p = 0; p < P; ++p) {
      std::vector<int> verts;
      for (int v = 0; v < V; ++v)
        if (rng() % 3 == 0) verts.push_back(v);
      if (verts.empty()) verts.push_back(p);
      q.push_back(make_patch(verts, 0.01 * p));
    }
    Cover g = empty_cover(a);
    greedy_cover(q, a, take_all(P), &g);
    const Cover o = order_cover(q, a, g.picks);
    expect_cover_consistent(q, a, o, true);
    double sg = 0, so = 0;
    for (double x : g.curve) sg += x;
    for (double x : o.curve) so += x;
    EXPECT_GE(so, sg - 1e-12) << "trial " << trial;
  }
}

// --- uncovered_regions --------------------------------------------------------------------

// (nu + 1) × (nv + 1) vertices on a gently curved sheet, quads split along (i, j)–(i+1, j+1).
Mesh sheet(int nu, int nv) {
  Mesh m;
  m.V.resize(static_cast<Eigen::Index>(nu + 1) * (nv + 1), 3);
  for (int i = 0; i <= nu; ++i)
    for (int j = 0; j <= nv; ++j)
      m.V.row(i * (nv + 1) + j) << 0.5 * i, 0.3 * j + 0.02 * i * i, 0.05 * i * j;
  m.F.resize(2 * static_cast<Eigen::Index>(nu) * nv, 3);
  Eigen::Index f = 0;
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const int a = i * (nv + 1) + j, b = a + nv + 1, c = b + 1, d = a + 1;
      m.F.row(f++) << a, b, c;
      m.F.row(f++) << a, c, d;
    }
  return m;
}

TEST(UncoveredRegions, TwoBlocksGiveTwoRegionsLargestFirst) {
  const int nu = 9, nv = 9;
  const Mesh m = sheet(nu, nv);
  const VecX area = vertex_areas(m);
  auto id = [&](int i, int j) { return i * (nv + 1) + j; };
  std::vector<int> vp(static_cast<std::size_t>(m.vertex_count()), 0);
  std::vector<int> small, large;
  for (int i = 0; i <= 2; ++i)
    for (int j = 0; j <= 2; ++j) small.push_back(id(i, j));  // a corner: 9 vertices
  for (int i = 4; i <= 8; ++i)
    for (int j = 5; j <= 8; ++j) large.push_back(id(i, j));  // inside: 20 vertices
  for (int v : small) vp[static_cast<std::size_t>(v)] = -1;
  for (int v : large) vp[static_cast<std::size_t>(v)] = -1;
  const std::vector<UncoveredRegion> regions = uncovered_regions(m, vp, area);
  ASSERT_EQ(regions.size(), 2u);
  auto expect_region = [&](const UncoveredRegion& r, const std::vector<int>& verts) {
    double a = 0.0;
    Vec3 c = Vec3::Zero();
    for (int v : verts) a += area(v), c += area(v) * m.V.row(v).transpose();
    c /= a;
    EXPECT_EQ(r.vertices, static_cast<int>(verts.size()));
    EXPECT_NEAR(r.area, a, 1e-12 * a);
    EXPECT_LT((r.centroid - c).norm(), 1e-12 * (1.0 + c.norm()));
  };
  EXPECT_GT(regions[0].area, regions[1].area);
  expect_region(regions[0], large);
  expect_region(regions[1], small);

  // Nothing uncovered: no region; everything uncovered: one, the whole sheet.
  EXPECT_TRUE(uncovered_regions(m, std::vector<int>(vp.size(), 3), area).empty());
  const std::vector<UncoveredRegion> all = uncovered_regions(m, std::vector<int>(vp.size(), -1), area);
  ASSERT_EQ(all.size(), 1u);
  EXPECT_NEAR(all[0].area, total_area(m), 1e-12 * total_area(m));
  EXPECT_EQ(all[0].vertices, m.vertex_count());
}

// Regions are connected by mesh edges only: two uncovered vertices across a quad's diagonal
// are one region when the diagonal is an edge, two when it is not.
TEST(UncoveredRegions, ConnectedByEdgesOnly) {
  const int nv = 5;
  const Mesh m = sheet(5, nv);
  const VecX area = vertex_areas(m);
  auto id = [&](int i, int j) { return i * (nv + 1) + j; };
  std::vector<int> vp(static_cast<std::size_t>(m.vertex_count()), 0);
  vp[static_cast<std::size_t>(id(2, 2))] = vp[static_cast<std::size_t>(id(3, 3))] = -1;  // the split diagonal
  EXPECT_EQ(uncovered_regions(m, vp, area).size(), 1u);
  std::vector<int> wp(static_cast<std::size_t>(m.vertex_count()), 0);
  wp[static_cast<std::size_t>(id(2, 3))] = wp[static_cast<std::size_t>(id(3, 2))] = -1;  // the other one
  const std::vector<UncoveredRegion> two = uncovered_regions(m, wp, area);
  ASSERT_EQ(two.size(), 2u);
  EXPECT_EQ(two[0].vertices + two[1].vertices, 2);
}

}  // namespace
}  // namespace flank
