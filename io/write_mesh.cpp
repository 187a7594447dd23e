// Plain triangle meshes: binary STL, OBJ, binary little-endian PLY.
#include "io/write_mesh.h"

#include <string>

#include "io/encode.h"
#include "io/read_mesh.h"

namespace flank::io {
namespace {

namespace fs = std::filesystem;

Vec3 vertex(const Mesh& mesh, int f, int k) { return mesh.V.row(mesh.F(f, k)).transpose(); }

void write_stl(std::ostream& out, const Mesh& mesh) {
  Bytes b;
  std::string header = "flank binary STL";  // must not start with "solid"
  header.resize(80, ' ');
  b.text(header);
  b.u32(static_cast<std::uint32_t>(mesh.face_count()));
  for (int f = 0; f < mesh.face_count(); ++f) {
    const Vec3 p0 = vertex(mesh, f, 0), p1 = vertex(mesh, f, 1), p2 = vertex(mesh, f, 2);
    Vec3 n = (p1 - p0).cross(p2 - p0);
    const double length = n.norm();
    n = length > 0 ? Vec3(n / length) : Vec3::Zero();
    for (const Vec3& p : {n, p0, p1, p2})
      for (int k = 0; k < 3; ++k) b.f32(p(k));
    b.u16(0);
  }
  out << b.str();
}

void write_obj(std::ostream& out, const Mesh& mesh) {
  std::string s = "# flank mesh: " + std::to_string(mesh.vertex_count()) + " vertices, " +
                  std::to_string(mesh.face_count()) + " triangles\n";
  for (int v = 0; v < mesh.vertex_count(); ++v)
    s += "v " + shortest(mesh.V(v, 0)) + " " + shortest(mesh.V(v, 1)) + " " +
         shortest(mesh.V(v, 2)) + "\n";
  for (int f = 0; f < mesh.face_count(); ++f)
    s += "f " + std::to_string(mesh.F(f, 0) + 1) + " " + std::to_string(mesh.F(f, 1) + 1) + " " +
         std::to_string(mesh.F(f, 2) + 1) + "\n";
  out << s;
}

void write_ply(std::ostream& out, const Mesh& mesh) {
  Bytes b;
  b.text("ply\nformat binary_little_endian 1.0\ncomment flank mesh\nelement vertex " +
         std::to_string(mesh.vertex_count()) +
         "\nproperty double x\nproperty double y\nproperty double z\nelement face " +
         std::to_string(mesh.face_count()) + "\nproperty list uchar int vertex_indices\nend_header\n");
  for (int v = 0; v < mesh.vertex_count(); ++v)
    for (int k = 0; k < 3; ++k) b.f64(mesh.V(v, k));
  for (int f = 0; f < mesh.face_count(); ++f) {
    b.u8(3);
    for (int k = 0; k < 3; ++k) b.i32(mesh.F(f, k));
  }
  out << b.str();
}

}  // namespace

void write_mesh(const fs::path& path, const Mesh& mesh) {
  const std::string ext = lower_extension(path);
  if (ext == ".stl") {
    write_file_atomic(path, [&](std::ostream& out) { write_stl(out, mesh); });
  } else if (ext == ".obj") {
    write_file_atomic(path, [&](std::ostream& out) { write_obj(out, mesh); });
  } else if (ext == ".ply") {
    write_file_atomic(path, [&](std::ostream& out) { write_ply(out, mesh); });
  } else {
    throw Error(path.string() + ": " + "unsupported mesh extension '" + one_line(ext) + "' (expected .stl, .obj or .ply)");
  }
}

}  // namespace flank::io
