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

// Runs `here` on the calling thread and `beside` concurrently with it (on another thread when
// one is free, else on this one after `here`); returns when both are done, rethrowing what
// either threw. For two independent builds where one makes the large allocations: made on the
// calling thread they come from the main heap, which keeps what it frees (kernels/memory.h);
// a worker thread's heap unmaps whatever outgrows its first 64 MiB once it is freed, and the
// next build faults those pages in again.
void run_beside(const std::function<void()>& beside, const std::function<void()>& here);

// Runs `here` on the calling thread and offers `maybe` to another: `maybe` runs only if a
// thread that is free starts it while `here` runs, never after `here` (on one thread, never).
// Returns whether it ran; an exception from either reaches the caller after both are done.
// For work that the next step needs only perhaps: done on a thread that would idle, at no
// cost to the calling thread, and skipped when none is free.
bool run_if_idle(const std::function<void()>& maybe, const std::function<void()>& here);

// For tests: while one lives, run_if_idle takes every offer as if a free thread always did:
// with max_threads() >= 2 it runs `maybe` on the calling thread, then `here`, and returns
// true. Whether another thread is free in time depends on the machine's load, so the paths
// that use what was made ahead are tested with this, deterministically.
class OffersAlwaysTaken {
 public:
  OffersAlwaysTaken();
  ~OffersAlwaysTaken();
  OffersAlwaysTaken(const OffersAlwaysTaken&) = delete;
  OffersAlwaysTaken& operator=(const OffersAlwaysTaken&) = delete;
};

// A stage made of many short parallel steps with serial work between them (the cover's picks
// and swaps: some tens of microseconds each), where a fork and join per step would cost as
// much as the step: an idle thread takes some 35-90 µs to wake on the machines here
// (bench/fork_join_benchmark.cpp). with_crew runs `stage` on the calling thread and wakes the
// other threads once; between the stage's steps they wait spinning, not sleeping, and each
// Crew::parallel_for runs on every thread that is there. A thread that is not free when the
// stage starts joins later, or never: the caller then runs every chunk itself. Each chunk
// runs once, whoever runs it, so results written per index are the same whatever the
// thread count. Inside `stage`, parallel steps go through the crew, not flank::parallel_for
// (the crew's other threads would not take part). Returns when `stage` has, rethrowing what
// it or a chunk threw (the first, where several did).
class Crew {
 public:
  // As flank::parallel_for: body(b, e) over chunks of `grain` of [begin, end), returning
  // when every chunk has run.
  void parallel_for(std::size_t begin, std::size_t end,
                    const std::function<void(std::size_t, std::size_t)>& body, std::size_t grain = 64);

 private:
  struct State;
  friend void with_crew(const std::function<void(Crew&)>& stage);
  explicit Crew(State* state) : state_(state) {}
  State* state_;
};

void with_crew(const std::function<void(Crew&)>& stage);

// A fixed number of elements, default-initialised: for elements without a constructor that
// writes (Eigen vectors, floats), nothing is written until the code that fills them does.
// A std::vector of n zeroes its memory on the calling thread, so the first touch of every
// fresh page (a fault per 4 KiB) happens there, serially, before a parallel loop can fill it.
template <class T>
class Buffer {
 public:
  Buffer() = default;
  explicit Buffer(std::size_t n) : data_(n ? std::make_unique_for_overwrite<T[]>(n) : nullptr), size_(n) {}
  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  T* data() { return data_.get(); }
  const T* data() const { return data_.get(); }
  T& operator[](std::size_t i) { return data_[i]; }
  const T& operator[](std::size_t i) const { return data_[i]; }
  T* begin() { return data(); }
  T* end() { return data() + size_; }
  const T* begin() const { return data(); }
  const T* end() const { return data() + size_; }
  operator std::span<T>() { return {data(), size_}; }
  operator std::span<const T>() const { return {data(), size_}; }

 private:
  std::unique_ptr<T[]> data_;
  std::size_t size_ = 0;
};

// From now on, `f` runs once on each worker thread, when the thread first takes part in
// parallel work (before its first task): a per-thread setting an application makes once, at
// start (kernels/memory.cpp). Call it at most once or twice in a process: each call adds
// an observer that lives until the process ends. A no-op in the ThreadSanitizer build.
void on_each_worker_thread(std::function<void()> f);

// Starts the worker threads now and returns at once: a process's first parallel loop
// otherwise waits for them to be created and to run their on_each_worker_thread work. Called
// before the input is read, their start overlaps the reading. Nothing to wait for, and a
// no-op at one thread or in the ThreadSanitizer build.
void start_worker_threads();

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
