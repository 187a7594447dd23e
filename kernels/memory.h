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

}  // namespace flank
