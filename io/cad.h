// CAD files through Open CASCADE, kept out of this header and out of the program (a module
// opened when first needed): STEP and IGES B-rep parts read, their faces listed and
// tessellated into one sewn mesh; B-spline surfaces fitted to grids of points and written as
// named STEP or IGES faces; solids of revolution written as STEP.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "io/read_mesh.h"
#include "kernels/mesh.h"
#include "kernels/types.h"

namespace flank::io {

// .step, .stp, .iges, .igs (any case).
bool is_cad_path(const std::string& path);

// A STEP or IGES file is read whole by OCCT; 1 GiB is far beyond any single part.
constexpr std::uint64_t kMaxCadFileBytes = std::uint64_t{1} << 30;

struct CadFace {
  int index = 0;        // 1-based, in the order the file's shape lists its faces
  std::string surface;  // plane, cylinder, cone, sphere, torus, bezier, bspline, revolution, extrusion, offset, other
  double area = 0.0;    // mm²
  Vec3 min = Vec3::Zero(), max = Vec3::Zero();  // bounding box
};

struct CadTessellation {
  LoadedMesh mesh;         // validated and repaired as a mesh file is (format "step"/"iges")
  double deviation = 0.0;  // the largest chord deviation measured: mesh to B-rep faces, mm
  int faces = 0;           // faces tessellated
};

// Open CASCADE is loaded (the CAD module, io/cad_module.h) when a STEP or IGES file is first
// read or written: STEP's module for STEP files, IGES's (STEP's code with IGES's translator)
// for IGES files. A command that will write a STEP file calls this first: STEP's module is
// then opened on a thread of its own while the command works (OCCT's libraries took 50–80 ms
// to load on the 2-core machines here; about 40% less since the module no longer uses XCAF,
// and a further 20% since IGES's translator has a module of its own).
void preload_cad_module();
// Waits for a preload still opening the module; returns at once when none is. A program that
// preloads calls this before it exits: the opening thread runs Open CASCADE's static
// initialisers and the module's warm-up, and exit's destructors must not run under them.
void settle_cad_module();
// Waits for the module of the file NAME (by its extension) if it is being opened, opens it if
// not; throws io::Error("NAME: why") when it cannot be opened.
void require_cad_module(const std::string& name);

// A B-rep part: the faces of a STEP or IGES file.
class CadPart {
 public:
  // Throws io::Error("PATH: problem") for what read_mesh refuses (not a regular file, empty,
  // too large) and for files OCCT cannot read, crashes on (tried first in a child process),
  // or that hold no face. The trial read in a child is killed after `probe_seconds` (0: a
  // minute plus 10 s per MB of file).
  static CadPart read(const std::string& path, double probe_seconds = 0);
  CadPart(CadPart&&) noexcept;
  CadPart& operator=(CadPart&&) noexcept;
  ~CadPart();

  const std::string& format() const;  // "step" or "iges"
  const std::vector<CadFace>& faces() const;
  // Throws io::Error naming the face when an index is out of range; all faces when empty.
  void check_faces(const std::vector<int>& faces) const;
  BoundingBox bounding_box(const std::vector<int>& faces) const;
  // The chosen faces (all when empty) sewn and tessellated with a chord deviation of at most
  // `deviation` mm, in pieces on the threads the caller has (ThreadLimit); the mesh does not
  // depend on their count.
  CadTessellation tessellate(const std::vector<int>& faces, double deviation,
                             const ReadOptions& options = {}) const;
  // Face `index` (1-based) evaluated at normalised parameters (u, v) ∈ [0, 1]² of its
  // surface's natural bounds (the tests read a written B-spline face back this way).
  Vec3 face_point(int index, double u, double v) const;
  // The distance from `p` to the nearest of the file's faces (all of them), mm.
  double distance(const Vec3& p) const;
  // The name a STEP face carries in the file, or "" (IGES: always "").
  std::string face_name(int index) const;

 private:
  struct Impl;
  explicit CadPart(std::unique_ptr<Impl> impl);
  static std::unique_ptr<Impl> read_in_process(const std::string& path);
  // tessellate's work; `parallel` false in the trial read's forked child.
  CadTessellation tessellate(const std::vector<int>& faces, double deviation, const ReadOptions& options,
                             bool parallel) const;
  std::unique_ptr<Impl> impl_;
};

// A B-spline surface approximating a grid: `grid` holds rows × cols points, row-major, rows
// along u and columns along v, point (i, j) at parameters (i / (rows − 1), j / (cols − 1)).
class SplineSurface {
 public:
  // Cubic (up to degree 8 where needed), C2, approximating every grid point within
  // `tolerance`; with `tolerance` 0, the C2 cubic interpolating every grid point.
  // Throws io::Error(`name`: problem) if OCCT cannot fit it.
  static SplineSurface fit(const std::string& name, const Points& grid, int rows, int cols,
                           double tolerance);
  // The clamped cubic B-spline surface with these poles (nu × nv, row-major, rows along u)
  // on clamped knot vectors of nu + 4 and nv + 4 values over [0, 1].
  static SplineSurface from_poles(const std::string& name, const Points& poles, int nu, int nv,
                                  const std::vector<double>& knots_u, const std::vector<double>& knots_v);
  SplineSurface(const SplineSurface&);
  SplineSurface& operator=(const SplineSurface&);
  ~SplineSurface();

  Vec3 point(double u, double v) const;  // (u, v) ∈ [0, 1]²
  int poles_u() const;
  int poles_v() const;
  int degree_u() const;
  int degree_v() const;

 private:
  struct Impl;
  explicit SplineSurface(std::shared_ptr<const Impl> impl);
  std::shared_ptr<const Impl> impl_;
  friend struct CadWriter;
};

struct NamedSurface {
  std::string name;
  SplineSurface surface;
};
// One face per surface, named, in a STEP (AP214) or IGES (5.3) file by extension. The surface
// normal is ∂u × ∂v. Written through write_file_atomic; no surfaces give a STEP file with an
// empty data section.
void write_surfaces(const std::filesystem::path& path, const std::vector<NamedSurface>& surfaces);

// A solid of revolution: the meridian (axial position, radius ≥ 0), axial positions strictly
// increasing, closed by flat ends on the axis and revolved about `axis` through `origin`
// (axial position 0 at `origin`, growing along `axis`).
struct RevolvedSolid {
  std::string name;
  std::vector<Vec2> meridian;
  Vec3 origin = Vec3::Zero();
  Vec3 axis = Vec3::UnitZ();
};
// The solids in one STEP (AP214) file, each a named product (none: an empty data section).
void write_solids(const std::filesystem::path& path, const std::vector<RevolvedSolid>& solids);

}  // namespace flank::io
