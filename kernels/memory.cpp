#include "kernels/memory.h"

// <cstdlib> first: it defines __GLIBC__ (through <features.h>) where the C library is glibc.
// Tested before any C library header, the macro is undefined and the settings below vanish
// (as they did from 85ae086 until the sixteenth part of issue 13).
#include <cstdlib>

#if defined(__GLIBC__)
#include <malloc.h>
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

}  // namespace flank
