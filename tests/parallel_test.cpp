#include "kernels/parallel.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

namespace flank {
namespace {

// A Buffer's elements are what its filler writes; an empty one holds nothing.
TEST(Parallel, BufferHoldsWhatAParallelLoopWrites) {
  Buffer<double> b(100000);
  ASSERT_EQ(b.size(), 100000u);
  parallel_for(0, b.size(), [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) b[i] = 0.5 * static_cast<double>(i);
  }, 1024);
  for (std::size_t i = 0; i < b.size(); ++i) ASSERT_EQ(b[i], 0.5 * static_cast<double>(i));
  const std::span<const double> view = std::as_const(b);
  EXPECT_EQ(view.size(), b.size());
  EXPECT_EQ(view.data(), b.data());
  const Buffer<int> none(0);
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(none.begin(), none.end());
}

// run_beside runs `here` on the calling thread (where the index makes its large allocations)
// and `beside` too, at 1 and 2 threads; what either throws reaches the caller, after both
// have finished.
TEST(Parallel, RunBesideRunsHereOnTheCallingThreadAndBothToTheEnd) {
  for (const int threads : {1, 2}) {
    const ThreadLimit limit(threads);
    const std::thread::id caller = std::this_thread::get_id();
    std::thread::id here_on;
    bool here_ran = false, beside_ran = false;
    run_beside([&] { beside_ran = true; },
               [&] {
                 here_on = std::this_thread::get_id();
                 here_ran = true;
               });
    EXPECT_TRUE(here_ran && beside_ran) << threads << " threads";
    EXPECT_EQ(here_on, caller) << threads << " threads";

    bool finished = false;
    EXPECT_THROW(run_beside([] { throw std::runtime_error("beside"); }, [&] { finished = true; }),
                 std::runtime_error);
    EXPECT_TRUE(finished);
    finished = false;
    try {
      run_beside([&] { finished = true; }, [] { throw std::invalid_argument("here"); });
      ADD_FAILURE() << "nothing thrown";
    } catch (const std::invalid_argument& e) {
      EXPECT_STREQ(e.what(), "here");
    }
    EXPECT_TRUE(finished) << "beside ran to its end before the exception left";
  }
}

// on_each_worker_thread: the function runs on a worker thread before that thread's first
// task, once per thread however many loops follow, and never on the calling thread. Two
// tasks that each wait until both have started force a worker into the loop.
// start_worker_threads starts them with no loop to run: the first loop of a process (the
// index of the part) no longer waits for the thread to be made and to run its
// on_each_worker_thread work, which the CLI now overlaps with reading the input.
TEST(Parallel, StartWorkerThreadsStartsThemBeforeAnyLoop) {
#if defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "the ThreadSanitizer build runs loops on threads of their own: a no-op there";
#else
  const ThreadLimit limit(2);
  if (max_threads() < 2) GTEST_SKIP() << "one thread only";
  static std::atomic<int> started{0};
  on_each_worker_thread([] { ++started; });
  EXPECT_EQ(started.load(), 0);
  start_worker_threads();
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (started == 0 && std::chrono::steady_clock::now() < until) std::this_thread::yield();
  EXPECT_GE(started.load(), 1) << "no worker started in 20 s";
#endif
}

TEST(Parallel, OnEachWorkerThreadRunsOncePerWorkerBeforeItsFirstTask) {
#if defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "the ThreadSanitizer build runs loops on threads of their own: a no-op there";
#else
  const ThreadLimit limit(2);
  if (max_threads() < 2) GTEST_SKIP() << "one thread only";
  const std::thread::id caller = std::this_thread::get_id();
  // Static: the function stays installed for the rest of the process.
  static std::mutex mutex;
  static std::vector<std::thread::id> ran_on;
  on_each_worker_thread([] {
    const std::lock_guard<std::mutex> lock(mutex);
    ran_on.push_back(std::this_thread::get_id());
  });
  for (int loop = 0; loop < 5; ++loop) {
    std::atomic<int> started{0};
    std::atomic<bool> worker_had_run{true};
    parallel_invoke_each(2, [&](std::size_t) {
      {
        const std::lock_guard<std::mutex> lock(mutex);
        const bool seen = std::find(ran_on.begin(), ran_on.end(), std::this_thread::get_id()) != ran_on.end();
        if (!seen && std::this_thread::get_id() != caller) worker_had_run = false;
      }
      ++started;
      const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
      while (started < 2 && std::chrono::steady_clock::now() < until) std::this_thread::yield();
    });
    EXPECT_EQ(started, 2) << "loop " << loop << ": no worker took the second task in 20 s";
    EXPECT_TRUE(worker_had_run) << "loop " << loop << ": a worker ran a task before the function";
  }
  {
    const std::lock_guard<std::mutex> lock(mutex);
    EXPECT_GE(ran_on.size(), 1u);
    for (std::size_t i = 0; i < ran_on.size(); ++i) {
      EXPECT_NE(ran_on[i], caller);
      for (std::size_t j = 0; j < i; ++j) EXPECT_NE(ran_on[i], ran_on[j]) << "twice on one thread";
    }
  }
  // A second function installed later runs too, on the workers that already ran the first.
  static std::atomic<int> second_ran{0};
  on_each_worker_thread([] { ++second_ran; });
  for (int loop = 0; loop < 3 && second_ran == 0; ++loop) {
    std::atomic<int> started{0};
    parallel_invoke_each(2, [&](std::size_t) {
      ++started;
      const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
      while (started < 2 && std::chrono::steady_clock::now() < until) std::this_thread::yield();
    });
  }
  EXPECT_GE(second_ran.load(), 1);
#endif
}

// run_if_idle: on one thread `maybe` never runs. On two, a free thread takes it up while
// `here` waits for it, and the call says so; an offer nobody took before `here` ended is
// withdrawn, and never runs after it. What `maybe` throws reaches the caller.
TEST(Parallel, RunIfIdleRunsTheOfferOnlyBesideHere) {
  {
    const ThreadLimit limit(1);
    bool maybe_ran = false, here_ran = false;
    EXPECT_FALSE(run_if_idle([&] { maybe_ran = true; }, [&] { here_ran = true; }));
    EXPECT_TRUE(here_ran);
    EXPECT_FALSE(maybe_ran);
  }
  const ThreadLimit limit(2);
  std::atomic<bool> started{false};
  std::thread::id maybe_on;
  const auto wait_for_start = [&] {
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (!started && std::chrono::steady_clock::now() < until) std::this_thread::yield();
  };
  const bool ran = run_if_idle(
      [&] {
        maybe_on = std::this_thread::get_id();
        started = true;
      },
      wait_for_start);
  EXPECT_TRUE(ran);
  EXPECT_TRUE(started);
  EXPECT_NE(maybe_on, std::this_thread::get_id());

  // Offered many times while `here` is quick: whenever the call says it did not run, it did
  // not run later either (checked once every call has returned).
  int said_ran = 0, did_run = 0;
  for (int k = 0; k < 200; ++k) {
    std::atomic<bool> this_ran{false};
    const bool r = run_if_idle([&] { this_ran = true; }, [] {});
    EXPECT_EQ(r, this_ran.load()) << "offer " << k;
    said_ran += r;
    did_run += this_ran.load();
  }
  EXPECT_EQ(said_ran, did_run);

  {  // forced, for tests of the code that uses the offers: taken on the caller, first
    const OffersAlwaysTaken taken;
    std::vector<int> order;
    EXPECT_TRUE(run_if_idle([&] { order.push_back(1); }, [&] { order.push_back(2); }));
    EXPECT_EQ(order, (std::vector<int>{1, 2}));
    const ThreadLimit one(1);
    EXPECT_FALSE(run_if_idle([&] { order.push_back(3); }, [] {}));
    EXPECT_EQ(order.size(), 2u);
  }

  started = false;
  EXPECT_THROW(run_if_idle(
                   [&] {
                     started = true;
                     throw std::runtime_error("maybe");
                   },
                   wait_for_start),
               std::runtime_error);
}

// with_crew: over many steps with serial work between them, every chunk of every step runs
// once, at 1 and 2 threads; at 2 the other thread takes part (two chunks that wait for each
// other run on two threads). What a chunk or the stage throws reaches the caller.
TEST(Parallel, CrewRunsEveryChunkOnceAndTheOtherThreadTakesPart) {
  const auto size_of = [](int step) { return 1 + static_cast<std::size_t>(step) * 5 % 1000; };
  for (const int threads : {1, 2}) {
    const ThreadLimit limit(threads);
    std::vector<int> runs(1000, 0);
    with_crew([&](Crew& crew) {
      for (int step = 0; step < 200; ++step) {
        crew.parallel_for(0, size_of(step), [&](std::size_t b, std::size_t e) {
          for (std::size_t i = b; i < e; ++i) ++runs[i];
        }, 3);
      }
    });
    for (std::size_t i = 0; i < runs.size(); ++i) {
      int want = 0;
      for (int step = 0; step < 200; ++step) want += i < size_of(step);
      ASSERT_EQ(runs[i], want) << "index " << i << ", " << threads << " threads";
    }
  }
  {
    const ThreadLimit limit(2);
    if (max_threads() >= 2) {
      std::atomic<int> started{0};
      std::thread::id ran_on[2];
      with_crew([&](Crew& crew) {
        crew.parallel_for(0, 2, [&](std::size_t b, std::size_t) {
          ran_on[b] = std::this_thread::get_id();
          ++started;
          const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
          while (started < 2 && std::chrono::steady_clock::now() < until) std::this_thread::yield();
        }, 1);
      });
      EXPECT_NE(ran_on[0], ran_on[1]) << "the other thread took no chunk in 20 s";
    }
  }
  for (const int threads : {1, 2}) {
    const ThreadLimit limit(threads);
    EXPECT_THROW(with_crew([](Crew& crew) {
                   crew.parallel_for(0, 100, [](std::size_t b, std::size_t) {
                     if (b == 40) throw std::runtime_error("chunk");
                   }, 1);
                 }),
                 std::runtime_error);
    EXPECT_THROW(with_crew([](Crew&) { throw std::invalid_argument("stage"); }), std::invalid_argument);
  }
}

}  // namespace
}  // namespace flank
