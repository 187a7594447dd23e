// One libFuzzer target per reader (FLANK_FUZZ_STL, _OBJ, _PLY, _LINES, _MOTION, _STEP, _IGES). Any input
// must give either a result that keeps the reader's promises or io::Error with one printable
// line naming the file; anything else (a crash, a sanitizer report, another exception, a
// broken promise) is a finding.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "io/cad.h"
#include "io/read_lines.h"
#include "io/read_mesh.h"

namespace {

#if defined(FLANK_FUZZ_STL)
const std::string kName = "fuzz.stl";
#elif defined(FLANK_FUZZ_OBJ)
const std::string kName = "fuzz.obj";
#elif defined(FLANK_FUZZ_PLY)
const std::string kName = "fuzz.ply";
#elif defined(FLANK_FUZZ_STEP) || defined(FLANK_FUZZ_IGES)
// OCCT reads from a path: each input goes to this file (one per process, in the temp folder).
const std::string kName = (std::filesystem::temp_directory_path() /
                           ("flank-fuzz-" + std::to_string(::getpid()) +
#if defined(FLANK_FUZZ_STEP)
                            ".step"
#else
                            ".igs"
#endif
                            )).string();
#else
const std::string kName = "fuzz.txt";
#endif

#if defined(FLANK_FUZZ_STEP) || defined(FLANK_FUZZ_IGES)
// The input file goes when the fuzzer exits (libFuzzer ends a run with exit()): every run
// had left one in the temp folder.
struct RemoveAtExit {
  ~RemoveAtExit() {
    std::error_code ignored;
    std::filesystem::remove(kName, ignored);
  }
} remove_at_exit;
#endif

void expect(bool promise) {
  if (!promise) std::abort();
}

// What read_mesh promises the kernels (kernels/mesh.h): faces index existing vertices, no
// face repeats a vertex, coordinates are finite, and something is left. (Unused by the targets
// that read no mesh: --lines and --motion.)
[[maybe_unused]] void check(const flank::io::LoadedMesh& m) {
  const flank::Mesh& mesh = m.mesh;
  expect(mesh.face_count() > 0 && mesh.vertex_count() > 0);
  expect(mesh.V.allFinite());
  for (int f = 0; f < mesh.face_count(); ++f) {
    for (int k = 0; k < 3; ++k) expect(mesh.F(f, k) >= 0 && mesh.F(f, k) < mesh.vertex_count());
    expect(mesh.F(f, 0) != mesh.F(f, 1) && mesh.F(f, 1) != mesh.F(f, 2) && mesh.F(f, 0) != mesh.F(f, 2));
  }
  expect(m.report.input_faces == mesh.face_count() + m.report.degenerate_faces + m.report.duplicate_faces);
}

}  // namespace

#if defined(FLANK_FUZZ_STEP) || defined(FLANK_FUZZ_IGES)
// The CAD module (Open CASCADE's readers) opened before the first input, so that its coverage
// counters are libFuzzer's from the start.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  flank::io::require_cad_module(kName);
  return 0;
}
#endif

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
#if defined(FLANK_FUZZ_LINES)
    for (const flank::io::AxisRow& row : flank::io::parse_lines_text(kName, bytes))
      expect(row.a.allFinite() && row.b.allFinite() && row.a != row.b);
#elif defined(FLANK_FUZZ_STEP) || defined(FLANK_FUZZ_IGES)
    {
      std::ofstream out(kName, std::ios::binary | std::ios::trunc);
      out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    }
    // Within the fuzzer's 10 s per input: a slower read is refused, not a finding.
    const flank::io::CadPart part = flank::io::CadPart::read(kName, 5.0);
    expect(!part.faces().empty());
    // Tessellate what a small part would be (a bounded amount of work): the mesh must keep
    // read_mesh's promises too.
    const flank::BoundingBox box = part.bounding_box({});
    if (part.faces().size() <= 8 && box.diagonal() > 1e-6 && box.diagonal() < 1e6)
      check(part.tessellate({}, 1e-2 * box.diagonal()).mesh);
#elif defined(FLANK_FUZZ_MOTION)
    const flank::io::ControlPoints m = flank::io::parse_motion_text(kName, bytes);
    expect(m.a.rows() >= 4 && m.a.rows() == m.b.rows() && m.a.allFinite() && m.b.allFinite());
#else
    check(flank::io::read_mesh_bytes(kName, bytes));
#endif
  } catch (const flank::io::Error& e) {
    const std::string_view message = e.what();
    expect(message.substr(0, kName.size() + 2) == kName + ": ");
    for (const char c : message) expect(c >= 0x20 && c < 0x7f);
  }
  return 0;
}
