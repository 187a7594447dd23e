// What the CAD module hands to io/cad.cpp. The module (libflank_cad.so, io/cad_module.cpp) is
// all of flank's Open CASCADE code; the program opens it with dlopen when a STEP or IGES file
// is first read or written, or earlier on a thread of its own (io::preload_cad_module), so
// that no run pays for loading OCCT's libraries before its work starts (80 of the 90 ms a
// `flank --version` took when the program was linked with them). Both sides are built
// together from this header, so C++ types cross it, and io::Error thrown in the module is
// caught as such in the program; the version guards against a stale module.
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "io/cad.h"
#include "kernels/types.h"

namespace flank::io::cad_module {

constexpr int kVersion = 2;

// Whether a CAD file's lower-case extension (io::lower_extension) is STEP's; IGES's otherwise.
inline bool step_extension(const std::string& ext) { return ext == ".step" || ext == ".stp"; }

struct Shape;    // a read part's shape and its faces' map (OCCT's), owned by the module
struct Surface;  // a B-spline surface (OCCT's)

// Every function throws io::Error("NAME: problem"), NAME being the file (or surface) named.
struct Api {
  int version = 0;
  // The part in the STEP (`step`) or IGES file `path` (already checked to be a regular file
  // of at most kMaxCadFileBytes): its shape; its faces and their names filled in.
  std::shared_ptr<const Shape> (*read)(const std::string& path, bool step, std::vector<CadFace>& faces,
                                       std::vector<std::string>& names) = nullptr;
  // Faces `faces` (1-based, sorted, distinct), each cut into its share by area of some 8
  // pieces, sewn within `sew` and tessellated within `deviation` mm: points (xyz), triangles
  // and the largest chord deviation measured. With `parallel`, the pieces are meshed on
  // oneTBB's threads (never in a forked child: oneTBB's threads do not survive a fork); the
  // mesh is the same either way.
  void (*tessellate)(const Shape& shape, const std::string& path, const std::vector<int>& faces, double sew,
                     double deviation, bool parallel, std::vector<double>& xyz, std::vector<int>& triangles,
                     double& measured) = nullptr;
  Vec3 (*face_point)(const Shape& shape, const std::string& path, int index, double u, double v) = nullptr;
  double (*distance)(const Shape& shape, const std::string& path, const Vec3& p) = nullptr;

  std::shared_ptr<const Surface> (*fit)(const std::string& name, const Points& grid, int rows, int cols,
                                        double tolerance) = nullptr;
  std::shared_ptr<const Surface> (*from_poles)(const std::string& name, const Points& poles, int nu, int nv,
                                               const std::vector<double>& knots_u,
                                               const std::vector<double>& knots_v) = nullptr;
  Vec3 (*point)(const Surface& surface, double u, double v) = nullptr;
  // Poles along u and v, degrees along u and v.
  void (*size)(const Surface& surface, int& poles_u, int& poles_v, int& degree_u, int& degree_v) = nullptr;

  // The bytes of a STEP or IGES file (by `path`'s extension, .step/.stp/.iges/.igs) holding
  // the named faces, at least one; its header names `path`'s file name.
  std::string (*surfaces_file)(const std::string& path,
                               const std::vector<std::pair<std::string, const Surface*>>& surfaces) = nullptr;
  // The bytes of a STEP file holding the solids, at least one.
  std::string (*solids_file)(const std::string& path, const std::vector<RevolvedSolid>& solids) = nullptr;
};

}  // namespace flank::io::cad_module

// The module's one entry point.
extern "C" const flank::io::cad_module::Api* flank_cad_module();
