// The one place that names the threading library (STYLE 8). Bodies receive half-open index
// ranges; below `grain` items everything runs on the calling thread. Results that are
// written per index are deterministic; reductions go through per-index storage and a
// serial combine so that they never depend on the thread count.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <utility>

namespace flank {

void parallel_for(std::size_t begin, std::size_t end,
                  const std::function<void(std::size_t, std::size_t)>& body,
                  std::size_t grain = 64);

// Runs the tasks concurrently (one task each) and returns when all are done.
void parallel_invoke_each(std::size_t count, const std::function<void(std::size_t)>& task);

// Sorts ascending by (key, value), concurrently. The pairs' order is total, so the result is
// the one std::sort gives whatever the thread count.
void parallel_sort(std::span<std::pair<std::uint64_t, int>> items);

// Caps the worker threads while it lives (--threads). n <= 0 leaves the default.
class ThreadLimit {
 public:
  explicit ThreadLimit(int n);
  ~ThreadLimit();
  ThreadLimit(const ThreadLimit&) = delete;
  ThreadLimit& operator=(const ThreadLimit&) = delete;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Threads available to parallel_for right now.
int max_threads();

// In the ThreadSanitizer build (FLANK_TSAN_THREADS) only: third-party code that threads
// through oneTBB, Embree's BVH build, runs on the calling thread from now on, because TSan
// cannot see the synchronisation inside those uninstrumented libraries. A no-op otherwise.
void serialize_library_threads();

}  // namespace flank
