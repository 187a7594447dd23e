// Mesh readers: STL (ASCII and binary), OBJ (polygons fan-triangulated), PLY (ASCII and
// binary little-endian). The result is validated and repaired into a Mesh that the kernels
// may trust; a file that cannot be trusted throws io::Error with one line naming the file
// and the problem.
#pragma once

#include <stdexcept>
#include <string>

#include "kernels/mesh.h"

namespace flank::io {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ReadOptions {
  bool flip = false;  // reverse the orientation after making it consistent (--flip)
};

struct MeshReport {
  std::string format;          // "stl-ascii", "stl-binary", "obj", "ply-ascii", "ply-binary"
  int input_vertices = 0;      // as stored in the file
  int input_faces = 0;         // triangles after polygon triangulation
  int welded_vertices = 0;     // duplicates merged (exact position match)
  int degenerate_faces = 0;    // zero-area or repeated-index faces dropped
  int unused_vertices = 0;     // vertices referenced by no face, removed
  int flipped_faces = 0;       // faces reversed to make the orientation consistent
  int components = 0;          // edge-connected components
  int boundary_edges = 0;
  int non_manifold_edges = 0;  // edges with more than two faces
  bool orientable = true;      // false if some component cannot be oriented consistently
};

struct LoadedMesh {
  Mesh mesh;
  MeshReport report;
};

// Throws io::Error("PATH: problem") for unreadable, truncated, malformed, non-finite,
// out-of-range, empty or fully degenerate input.
LoadedMesh read_mesh(const std::string& path, const ReadOptions& options = {});

}  // namespace flank::io
