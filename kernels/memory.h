// How the process keeps memory it frees: a setting an application makes once, at start (the
// flank command line and flank_bench do). Library code never calls it.
#pragma once

namespace flank {

// Freed memory stays with the process for the next allocation instead of going back to the
// operating system. Every candidate patch builds an index over its Ω and drops it (tens of MB
// for a large patch); glibc returns blocks past its mmap threshold (at most 32 MiB) at once,
// and the next patch's index then page-faults all of its memory afresh: on the 1M-triangle
// rung, 416k faults and 8.7 s of `decompose` before, 214k and 7.2 s after. Blocks up to
// 256 MiB come from the heap and up to 1 GiB of free heap is kept. True where the settings
// took effect; a no-op returning false where the C library is not glibc.
bool retain_freed_memory();

// Fresh memory comes in 2 MiB pages where Linux allows them (transparent huge pages, in its
// default "madvise" mode). A one-shot run pays for every page it touches past its peak, and
// on the 2-core virtual machines flank runs on a 4 KiB page's first touch takes 12-15 µs
// (bench/memory_benchmark.cpp, BM_FirstTouch): `flank decompose` of the 13k cone part
// faulted 11k pages on one thread, some 0.13 s of its 0.55 s; a 2 MiB page costs about what
// 16 small ones do. The main heap's first 240 MiB, and 48 MiB of each worker thread's own
// heap (as the thread starts: on_each_worker_thread), are reserved at once (address space
// only) and advised for huge pages; call after retain_freed_memory, which keeps the
// reservations from being handed back. (Sending every thread to the main heap instead, one
// arena, made the blade faces 4-5% slower on 2 threads.) True where the advice was taken and
// the system grants huge pages; false and a no-op elsewhere (not glibc, the sanitizers'
// allocators, huge pages off). The flank command line and flank_bench skip it when the
// environment sets FLANK_HUGE_PAGES=0.
bool prefer_huge_pages();

}  // namespace flank
