#include "kernels/parallel.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <utility>
#include <vector>

namespace flank {
namespace {

// The concurrent sort gives std::sort's order at any thread count, duplicate keys included
// (the index adjacency sorts edge keys that repeat once per face sharing the edge).
TEST(Parallel, SortEqualsStdSortWhateverTheThreadCount) {
  std::mt19937_64 rng(5);
  std::vector<std::pair<std::uint64_t, int>> items(200000);
  for (std::size_t i = 0; i < items.size(); ++i) items[i] = {rng() % 50000, static_cast<int>(rng() % 1000)};
  std::vector<std::pair<std::uint64_t, int>> expected = items;
  std::sort(expected.begin(), expected.end());
  for (const int threads : {1, 2}) {
    const ThreadLimit limit(threads);
    std::vector<std::pair<std::uint64_t, int>> sorted = items;
    parallel_sort(sorted);
    EXPECT_EQ(sorted, expected) << threads << " threads";
  }
}

}  // namespace
}  // namespace flank
