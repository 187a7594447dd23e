#include "kernels/parallel.h"

#ifdef FLANK_TSAN_THREADS
#include <tbb/global_control.h>

#include <algorithm>
#include <atomic>
#include <exception>
#include <thread>
#include <vector>
#else
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <mutex>
#include <stdexcept>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>
#include <tbb/task_scheduler_observer.h>
#endif

#include <atomic>
#include <exception>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>

namespace flank {

namespace {
std::atomic<int> g_offers_always_taken{0};  // OffersAlwaysTaken alive

// run_if_idle where nothing is offered: on one thread (`maybe` never runs), or with every
// offer taken (OffersAlwaysTaken). Whether `maybe` ran, or nothing when an offer is to be made.
std::optional<bool> run_without_offer(const std::function<void()>& maybe, const std::function<void()>& here) {
  if (max_threads() < 2) {
    here();
    return false;
  }
  if (g_offers_always_taken > 0) {
    maybe();
    here();
    return true;
  }
  return std::nullopt;
}
}  // namespace

OffersAlwaysTaken::OffersAlwaysTaken() { ++g_offers_always_taken; }
OffersAlwaysTaken::~OffersAlwaysTaken() { --g_offers_always_taken; }

namespace {
// What a parallel loop runs on the calling thread at once: nothing, or a single chunk. True
// when that was the whole loop; a grain of 0 becomes 1.
bool ran_here(std::size_t begin, std::size_t end, const std::function<void(std::size_t, std::size_t)>& body,
              std::size_t& grain) {
  if (grain == 0) grain = 1;
  if (end <= begin) return true;
  if (end - begin > grain) return false;
  body(begin, end);
  return true;
}

void spin_pause() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#else
  std::this_thread::yield();
#endif
}
}  // namespace

// The crew's state. The step under way lives on the caller's stack for the length of its
// Crew::parallel_for, so a helper announces itself (`inside`) before it reads `step`, and
// the caller withdraws the step (null) before it waits for `inside` to fall to 0: with both
// sequentially consistent, either the caller sees the helper inside or the helper sees no
// step, and no helper touches a step that has returned.
struct Crew::State {
  struct Step {
    const std::function<void(std::size_t, std::size_t)>* body = nullptr;
    std::size_t begin = 0, end = 0, grain = 1, chunks = 0;
    std::atomic<std::size_t> next{0};  // the next chunk to take
    std::atomic<std::size_t> done{0};  // chunks run
  };
  std::atomic<Step*> step{nullptr};
  std::atomic<int> inside{0};     // helpers that may be reading `step`
  std::atomic<bool> over{false};  // the stage has returned: helpers leave
  std::mutex mutex;
  std::exception_ptr failed;  // the first exception a chunk threw, under `mutex`

  void run_chunks(Step& st) {
    for (std::size_t c = st.next++; c < st.chunks; c = st.next++) {
      try {
        (*st.body)(st.begin + c * st.grain, std::min(st.end, st.begin + (c + 1) * st.grain));
      } catch (...) {
        const std::lock_guard lock(mutex);
        if (!failed) failed = std::current_exception();
      }
      st.done.fetch_add(1, std::memory_order_release);
    }
  }

  // A helper's life: the chunks of every step it sees, until the stage is over.
  void help() {
    while (!over.load(std::memory_order_acquire)) {
      if (step.load(std::memory_order_relaxed) == nullptr) {
        spin_pause();
        continue;
      }
      ++inside;
      if (Step* st = step.load()) run_chunks(*st);
      --inside;
    }
  }
};

void Crew::parallel_for(std::size_t begin, std::size_t end,
                        const std::function<void(std::size_t, std::size_t)>& body, std::size_t grain) {
  if (ran_here(begin, end, body, grain)) return;
  State::Step st;
  st.body = &body, st.begin = begin, st.end = end, st.grain = grain;
  st.chunks = (end - begin + grain - 1) / grain;
  state_->step.store(&st);
  state_->run_chunks(st);
  while (st.done.load(std::memory_order_acquire) < st.chunks) spin_pause();
  state_->step.store(nullptr);
  while (state_->inside.load() != 0) spin_pause();
  std::exception_ptr failed;
  {
    const std::lock_guard lock(state_->mutex);
    failed = std::exchange(state_->failed, nullptr);
  }
  if (failed) std::rethrow_exception(failed);
}

#ifdef FLANK_TSAN_THREADS
// The ThreadSanitizer build (scripts/test --tsan) runs the same chunks on plain std::threads.
// oneTBB's scheduler lives in libtbb, which is not instrumented: TSan cannot see the
// happens-before edges of its task pool and of the join at the end of a parallel_for, and
// reports every parallel loop as a race. Thread creation and join it does see, so what it
// reports here is a race in flank's own code. Chunks are taken from a shared counter by
// max_threads() threads, the caller included, as TBB's workers would take them.
namespace {
std::atomic<int> g_thread_limit{0};

void run_chunks(std::size_t chunks, const std::function<void(std::size_t)>& chunk) {
  const std::size_t threads = std::min<std::size_t>(chunks, static_cast<std::size_t>(max_threads()));
  std::atomic<std::size_t> next{0};
  auto worker = [&] {
    for (std::size_t c = next++; c < chunks; c = next++) chunk(c);
  };
  std::vector<std::thread> pool;
  for (std::size_t t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (std::thread& t : pool) t.join();
}
}  // namespace

void parallel_for(std::size_t begin, std::size_t end,
                  const std::function<void(std::size_t, std::size_t)>& body, std::size_t grain) {
  if (end <= begin) return;
  if (grain == 0) grain = 1;
  const std::size_t chunks = (end - begin + grain - 1) / grain;
  run_chunks(chunks, [&](std::size_t c) { body(begin + c * grain, std::min(end, begin + (c + 1) * grain)); });
}

void parallel_invoke_each(std::size_t count, const std::function<void(std::size_t)>& task) {
  run_chunks(count, task);
}

void run_beside(const std::function<void()>& beside, const std::function<void()>& here) {
  if (max_threads() < 2) {  // both to the end, as with two threads; `here`'s exception wins
    try {
      here();
    } catch (...) {
      try {
        beside();
      } catch (...) {
      }
      throw;
    }
    beside();
    return;
  }
  std::exception_ptr failed;
  std::thread other([&] {
    try {
      beside();
    } catch (...) {
      failed = std::current_exception();
    }
  });
  try {
    here();
  } catch (...) {
    other.join();
    throw;
  }
  other.join();
  if (failed) std::rethrow_exception(failed);
}

bool run_if_idle(const std::function<void()>& maybe, const std::function<void()>& here) {
  if (const std::optional<bool> ran = run_without_offer(maybe, here)) return *ran;
  std::atomic<int> state{0};  // 0 offered, 1 taken up, 2 withdrawn
  std::exception_ptr failed;
  std::thread other([&] {
    int offered = 0;
    if (!state.compare_exchange_strong(offered, 1)) return;
    try {
      maybe();
    } catch (...) {
      failed = std::current_exception();
    }
  });
  int offered = 0;
  try {
    here();
  } catch (...) {
    state.compare_exchange_strong(offered, 2);
    other.join();
    throw;
  }
  const bool ran = !state.compare_exchange_strong(offered, 2);
  other.join();
  if (failed) std::rethrow_exception(failed);
  return ran;
}

void with_crew(const std::function<void(Crew&)>& stage) {
  Crew::State state;
  Crew crew(&state);
  std::vector<std::thread> helpers;
  for (int h = 1; h < max_threads(); ++h) helpers.emplace_back([&] { state.help(); });
  const auto finish = [&] {
    state.over = true;
    for (std::thread& t : helpers) t.join();
  };
  try {
    stage(crew);
  } catch (...) {
    finish();
    throw;
  }
  finish();
}

struct ThreadLimit::Impl {
  int previous = 0;
};

ThreadLimit::ThreadLimit(int n) : impl_(std::make_unique<Impl>()) {
  impl_->previous = g_thread_limit.load();
  if (n > 0) g_thread_limit = n;
}

ThreadLimit::~ThreadLimit() { g_thread_limit = impl_->previous; }

int max_threads() {
  const int limit = g_thread_limit.load();
  return limit > 0 ? limit : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

void serialize_library_threads() {
  static const tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
}

void on_each_worker_thread(std::function<void()>) {}  // the std::threads here live for one loop

void start_worker_threads() {}

#else

void parallel_for(std::size_t begin, std::size_t end,
                  const std::function<void(std::size_t, std::size_t)>& body, std::size_t grain) {
  if (ran_here(begin, end, body, grain)) return;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(begin, end, grain),
                    [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
}

void run_beside(const std::function<void()>& beside, const std::function<void()>& here) {
  tbb::task_group group;
  group.run([&] { beside(); });
  try {
    here();
  } catch (...) {
    try {
      group.wait();
    } catch (...) {  // what `here` threw is the one reported
    }
    throw;
  }
  group.wait();  // rethrows what `beside` threw
}

bool run_if_idle(const std::function<void()>& maybe, const std::function<void()>& here) {
  if (const std::optional<bool> ran = run_without_offer(maybe, here)) return *ran;
  std::atomic<int> state{0};  // 0 offered, 1 taken up, 2 withdrawn
  tbb::task_group group;
  group.run([&] {
    int offered = 0;
    if (state.compare_exchange_strong(offered, 1)) maybe();
  });
  int offered = 0;
  try {
    here();
  } catch (...) {
    state.compare_exchange_strong(offered, 2);
    try {
      group.wait();
    } catch (...) {  // what `here` threw is the one reported
    }
    throw;
  }
  const bool ran = !state.compare_exchange_strong(offered, 2);
  group.wait();  // runs the withdrawn offer here, which then returns at once; rethrows `maybe`'s
  return ran;
}

void parallel_invoke_each(std::size_t count, const std::function<void(std::size_t)>& task) {
  if (count == 0) return;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 1),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i < r.end(); ++i) task(i);
                    });
}

void with_crew(const std::function<void(Crew&)>& stage) {
  Crew::State state;
  Crew crew(&state);
  tbb::task_group group;  // a helper not taken up by the end runs here, in wait(), and leaves
  for (int h = 1; h < max_threads(); ++h) group.run([&] { state.help(); });
  try {
    stage(crew);
  } catch (...) {
    state.over = true;
    group.wait();
    throw;
  }
  state.over = true;
  group.wait();
}

struct ThreadLimit::Impl {
  std::unique_ptr<tbb::global_control> control;
};

ThreadLimit::ThreadLimit(int n) : impl_(std::make_unique<Impl>()) {
  if (n > 0)
    impl_->control = std::make_unique<tbb::global_control>(
        tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(n));
}

ThreadLimit::~ThreadLimit() = default;

int max_threads() {
  return static_cast<int>(
      tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

void serialize_library_threads() {}

namespace {
// Runs its function once on each worker thread, when the thread first enters the scheduler.
class FirstEntry : public tbb::task_scheduler_observer {
 public:
  explicit FirstEntry(std::function<void()> f) : f_(std::move(f)), bit_(std::uint64_t{1} << next_bit()) {
    observe(true);
  }
  void on_scheduler_entry(bool is_worker) override {
    if (!is_worker) return;
    // Per observer: a thread that entered for one has yet to enter for another. A thread's
    // record is a trivially destructible thread_local: the first use of one with a destructor
    // (a vector) registers it under the dynamic loader's lock (__cxa_thread_atexit), and waits
    // out any dlopen in progress, the CAD module's among them.
    thread_local std::uint64_t entered = 0;
    if (entered & bit_) return;
    entered |= bit_;
    f_();
  }

 private:
  static int next_bit() {
    static std::atomic<int> next{0};
    const int bit = next++;
    if (bit >= 64) throw std::logic_error("on_each_worker_thread: more than 64 functions");
    return bit;
  }
  std::function<void()> f_;
  std::uint64_t bit_;
};
}  // namespace

void on_each_worker_thread(std::function<void()> f) {
  // Never destroyed: it observes for the rest of the process, and at exit the scheduler may
  // outlive any static object. Kept in a never-destroyed list that a global points to: once
  // oneTBB drops its own list at exit, the observer and oneTBB's record of it only point to
  // each other, and LeakSanitizer reported them as leaked (once in four CI runs).
  static std::mutex mutex;
  static auto* const kept = new std::vector<const FirstEntry*>;
  const FirstEntry* entry = new FirstEntry(std::move(f));
  const std::lock_guard lock(mutex);
  kept->push_back(entry);
}

void start_worker_threads() {
  // One empty task for each worker the limit allows: enqueued work wakes them (creating them
  // the first time), and whoever runs it returns at once.
  for (int w = 1; w < max_threads(); ++w) tbb::this_task_arena::enqueue([] {});
}

#endif  // FLANK_TSAN_THREADS

}  // namespace flank
