// Mesh readers: STL (ASCII and binary), OBJ (polygons fan-triangulated), PLY (ASCII and
// binary little-endian). The result is validated and repaired into a Mesh that the kernels
// may trust; a file that cannot be trusted throws io::Error with one line naming the file
// and the problem.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "kernels/mesh.h"

namespace flank::io {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// What flank refuses to read, checked before memory is allocated for it. Reading costs about
// 120 bytes per triangle (issue 14 measured 2.5 GB for 20.7 M triangles) and the solver's
// index several times more; the largest real parts we know are ~2 M triangles, so 10 M leaves
// 5x headroom and keeps a read near 1 GB. A binary STL has 3 vertices per triangle.
constexpr std::int64_t kMaxTriangles = 10'000'000;
constexpr std::int64_t kMaxVertices = 3 * kMaxTriangles;
// Polygons are fan-triangulated, and every sliver of a fan spans the polygon, so the
// closest-point index cannot tell them apart: decompose on one disk-shaped n-gon took 3.7 s
// at n = 256, 10 s at 1,000 (a well-shaped 1,000-triangle square: 2 s), over a minute at
// 10,000 and > 240 s at 200,000 (issue 14 row 10). CAD exporters write n-gons only for planar
// faces, and a circle within 1e-5 of its radius takes ~700 segments: a longer polygon is
// refused, naming it, rather than read into a part that cannot be processed.
constexpr std::int64_t kMaxPolygonVertices = 1'000;
// An ASCII STL of kMaxTriangles takes ~2.5 GB; the whole file is read into memory.
constexpr std::uint64_t kMaxMeshFileBytes = std::uint64_t{4} << 30;

struct ReadOptions {
  bool flip = false;  // reverse the orientation after making it consistent (--flip)
  // Count the edge-connected components (MeshReport::components, −1 when not counted).
  // `flank info` prints them; nothing the solver does reads them. Where the faces are listed
  // in no spatial order (the NASA faces' STL files) nearly every link between neighbours
  // joins two of the read's pieces of 2048 faces, and the count is a union-find over those
  // links on one thread: some 0.1 ms of HECC a's 1.2 ms read at two threads.
  bool count_components = true;
};

struct MeshReport {
  std::string format;          // "stl-ascii", "stl-binary", "obj", "ply-ascii", "ply-binary"
  int input_vertices = 0;      // as stored in the file
  int input_faces = 0;         // triangles after polygon triangulation
  int welded_vertices = 0;     // duplicates merged (exact position match)
  int degenerate_faces = 0;    // zero-area or repeated-index faces dropped
  int duplicate_faces = 0;     // faces on the same three (welded) vertices as an earlier one, dropped
  int unused_vertices = 0;     // vertices referenced by no face, removed
  int flipped_faces = 0;       // faces reversed to make the orientation consistent
  int components = 0;          // edge-connected components; −1 when not counted
  int boundary_edges = 0;
  int non_manifold_edges = 0;  // edges with more than two faces
  bool orientable = true;      // false if some component cannot be oriented consistently
};

struct LoadedMesh {
  Mesh mesh;
  MeshReport report;
};

// Throws io::Error("PATH: problem") for a path that is not a regular file, and for
// unreadable, too large, truncated, malformed, non-finite, out-of-range, empty or fully
// degenerate input.
LoadedMesh read_mesh(const std::string& path, const ReadOptions& options = {});

// The same from the file's bytes; `name` stands for the path in messages and its extension
// picks the format as read_mesh's does (the fuzzers' entry point).
LoadedMesh read_mesh_bytes(const std::string& name, std::string_view bytes,
                           const ReadOptions& options = {});

// The hash the repair's weld sorts points by: equal points share it (−0 taken as +0 first),
// unequal ones seldom do, and then are told apart by their coordinates. Here for the test of
// that case.
std::uint32_t weld_hash(const double point[3]);

// The same validation and repair from a triangle soup (3 coordinates per vertex, 3 indices per
// triangle, indices in range): what the CAD reader makes of a tessellation. `format` is
// reported as given.
LoadedMesh repair_triangles(const std::string& name, std::vector<double> xyz,
                            std::vector<int> triangles, std::string format,
                            const ReadOptions& options = {});

}  // namespace flank::io
