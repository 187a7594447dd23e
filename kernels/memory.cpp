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

namespace flank {

bool retain_freed_memory() {
#if defined(__GLIBC__)
  // Setting either threshold also turns off glibc's own adjustment of both.
  return mallopt(M_MMAP_THRESHOLD, 256 << 20) == 1 && mallopt(M_TRIM_THRESHOLD, 1 << 30) == 1;
#else
  return false;
#endif
}

bool prefer_huge_pages() {
#if defined(__GLIBC__) && !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
  // "always [madvise] never": the advice counts unless the bracketed choice is never.
  std::string modes;
  std::getline(std::ifstream("/sys/kernel/mm/transparent_hugepage/enabled"), modes);
  if (modes.find("[always]") == std::string::npos && modes.find("[madvise]") == std::string::npos) return false;
  // Below the mmap threshold (retain_freed_memory: 256 MiB) a block comes from the heap, so
  // this one grows the heap by its size without touching it; freed, it stays there (under
  // the trim threshold, 1 GiB) as the free top every later block is carved from.
  constexpr std::size_t kReserve = std::size_t{240} << 20, kHuge = std::size_t{2} << 20;
  void* block = std::malloc(kReserve);
  if (!block) return false;
  const auto begin = (reinterpret_cast<std::uintptr_t>(block) + kHuge - 1) & ~(kHuge - 1);
  const auto end = (reinterpret_cast<std::uintptr_t>(block) + kReserve) & ~(kHuge - 1);
  const bool advised = end > begin && madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE) == 0;
  std::free(block);
  return advised;
#else
  return false;
#endif
}

}  // namespace flank
