// The scaling ladder's benchmarks are registered at run time (their names carry each rung's
// triangle count, read from the bundled blade and the faces of tests/data), so bench/main.cpp
// calls this before running.
#pragma once

namespace flank {

void register_ladder_benchmarks();

}  // namespace flank
