#include "kernels/memory.h"

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace flank {

void retain_freed_memory() {
#if defined(__GLIBC__)
  // Setting either threshold also turns off glibc's own adjustment of both.
  mallopt(M_MMAP_THRESHOLD, 256 << 20);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
#endif
}

}  // namespace flank
