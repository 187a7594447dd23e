#include "kernels/memory.h"

// <cstdlib> first: it defines __GLIBC__ (through <features.h>) where the C library is glibc.
// Tested before any C library header, the macro is undefined and the settings below vanish
// (as they did from 85ae086 until the sixteenth part of issue 13).
#include <cstdlib>

#if defined(__GLIBC__)
#include <malloc.h>
#include <sys/mman.h>

#include <cstdint>
#include <fstream>
#include <string>
#endif

#include "kernels/parallel.h"

namespace flank {

bool retain_freed_memory() {
#if defined(__GLIBC__)
  // Setting either threshold also turns off glibc's own adjustment of both.
  return mallopt(M_MMAP_THRESHOLD, 256 << 20) == 1 && mallopt(M_TRIM_THRESHOLD, 1 << 30) == 1;
#else
  return false;
#endif
}

namespace {

#if defined(__GLIBC__) && !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
// Grows the calling thread's heap by `bytes` without touching it and advises that range for
// huge pages. Below the mmap threshold (retain_freed_memory: 256 MiB) a block comes from
// the thread's heap; freed, it stays there (under the trim threshold, 1 GiB) as the free top
// every later block of that heap is carved from.
bool advise_fresh_heap(std::size_t bytes) {
  constexpr std::size_t kHuge = std::size_t{2} << 20;
  void* block = std::malloc(bytes);
  if (!block) return false;
  const auto begin = (reinterpret_cast<std::uintptr_t>(block) + kHuge - 1) & ~(kHuge - 1);
  const auto end = (reinterpret_cast<std::uintptr_t>(block) + bytes) & ~(kHuge - 1);
  const bool advised = end > begin && madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE) == 0;
  std::free(block);
  if (!advised) return false;
  // The heap below `begin` (its first, partly used 2 MiB) cannot be a huge page: blocks carved
  // from there would be faulted 4 KiB at a time. Held, never touched, it leaves every later
  // block to start in the advised range.
  const std::size_t gap = begin - reinterpret_cast<std::uintptr_t>(block);
  if (gap > 64) {
    void* held = std::malloc(gap - 32);  // its chunk ends 32 bytes below `begin`
    // The compiler may not drop the allocation: its address escapes to memory it cannot see.
    asm volatile("" : : "r"(held) : "memory");
  }
  return true;
}
#endif

}  // namespace

bool prefer_huge_pages() {
#if defined(__GLIBC__) && !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
  // "always [madvise] never": the advice counts unless the bracketed choice is never.
  std::string modes;
  std::getline(std::ifstream("/sys/kernel/mm/transparent_hugepage/enabled"), modes);
  if (modes.find("[always]") == std::string::npos && modes.find("[madvise]") == std::string::npos) return false;
  // The main heap's first 240 MiB. A worker thread's heap is a reservation of 64 MiB that
  // glibc maps as it grows, and a block that does not fit goes to a fresh one, which is
  // unmapped again once empty: 48 MiB of each worker's first heap, advised as the thread
  // starts, stay with it.
  if (!advise_fresh_heap(std::size_t{240} << 20)) return false;
  on_each_worker_thread([] { advise_fresh_heap(std::size_t{48} << 20); });
  return true;
#else
  return false;
#endif
}

}  // namespace flank
