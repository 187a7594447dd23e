// A stand-in for the CAD module that opens slowly (tests only, through $FLANK_CAD_MODULE): its
// entry takes 300 ms, then looks at a static of its own, as Open CASCADE's warm-up uses its
// libraries' statics while the module opens. A program that exits meanwhile without
// io::settle_cad_module has exit destroy that static first (its destructor was registered
// after everything the program made before), and this module then ends the process with
// abort(). It is not flank's module: its entry returns no table.
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <thread>

namespace {

std::atomic<bool> destroyed{false};  // trivially destructible: still readable during exit
struct Witness {
  ~Witness() { destroyed.store(true); }
} witness;

}  // namespace

// The loader (io/cad.cpp) takes any null table as "not this flank's CAD module".
extern "C" const void* flank_cad_module() {
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  if (destroyed.load()) std::abort();
  return nullptr;
}
