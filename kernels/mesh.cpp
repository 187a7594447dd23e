#include "kernels/mesh.h"

#include <algorithm>
#include <cstdint>
#include <unordered_map>

#include "kernels/parallel.h"

namespace flank {

BoundingBox bounding_box(const Mesh& mesh) {
  BoundingBox box;
  if (mesh.V.rows() == 0) return box;
  box.min = mesh.V.colwise().minCoeff().transpose();
  box.max = mesh.V.colwise().maxCoeff().transpose();
  return box;
}

double bbox_diagonal(const Mesh& mesh) { return bounding_box(mesh).diagonal(); }

Points face_normals(const Mesh& mesh) {
  Points N(mesh.F.rows(), 3);
  parallel_for(0, static_cast<std::size_t>(mesh.F.rows()), [&](std::size_t begin, std::size_t end) {
    for (auto f = static_cast<Eigen::Index>(begin); f < static_cast<Eigen::Index>(end); ++f) {
      const Vec3 p0 = mesh.V.row(mesh.F(f, 0));
      const Vec3 n = (Vec3(mesh.V.row(mesh.F(f, 1))) - p0).cross(Vec3(mesh.V.row(mesh.F(f, 2))) - p0);
      const double len = n.norm();
      N.row(f) = len > 0 ? Vec3(n / len) : Vec3::Zero();
    }
  }, 4096);
  return N;
}

VecX face_areas(const Mesh& mesh) {
  VecX A(mesh.F.rows());
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    const Vec3 p0 = mesh.V.row(mesh.F(f, 0));
    A(f) = 0.5 * (Vec3(mesh.V.row(mesh.F(f, 1))) - p0).cross(Vec3(mesh.V.row(mesh.F(f, 2))) - p0).norm();
  }
  return A;
}

VecX vertex_areas(const Mesh& mesh) {
  const VecX A = face_areas(mesh);
  VecX out = VecX::Zero(mesh.V.rows());
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) out(mesh.F(f, k)) += A(f) / 3.0;
  return out;
}

double total_area(const Mesh& mesh) { return face_areas(mesh).sum(); }

Mesh subdivide_midpoint(const Mesh& mesh) {
  const int nv = mesh.vertex_count(), nf = mesh.face_count();
  std::unordered_map<std::uint64_t, int> midpoint;  // undirected edge → new vertex
  midpoint.reserve(static_cast<std::size_t>(3 * nf / 2 + 1));
  std::vector<Vec3> added;
  auto mid = [&](int a, int b) {
    const auto key = (static_cast<std::uint64_t>(std::min(a, b)) << 32) | static_cast<std::uint32_t>(std::max(a, b));
    const auto [it, inserted] = midpoint.try_emplace(key, nv + static_cast<int>(added.size()));
    if (inserted) added.emplace_back(0.5 * (Vec3(mesh.V.row(a)) + Vec3(mesh.V.row(b))));
    return it->second;
  };
  Mesh out;
  out.F.resize(4 * static_cast<Eigen::Index>(nf), 3);
  for (int f = 0; f < nf; ++f) {
    const int a = mesh.F(f, 0), b = mesh.F(f, 1), c = mesh.F(f, 2);
    const int ab = mid(a, b), bc = mid(b, c), ca = mid(c, a);
    out.F.row(4 * f + 0) << a, ab, ca;
    out.F.row(4 * f + 1) << ab, b, bc;
    out.F.row(4 * f + 2) << ca, bc, c;
    out.F.row(4 * f + 3) << ab, bc, ca;
  }
  out.V.resize(nv + static_cast<Eigen::Index>(added.size()), 3);
  if (nv > 0) out.V.topRows(nv) = mesh.V;
  for (std::size_t k = 0; k < added.size(); ++k) out.V.row(nv + static_cast<Eigen::Index>(k)) = added[k].transpose();
  return out;
}

Points vertex_normals(const Mesh& mesh) {
  Points N = Points::Zero(mesh.vertex_count(), 3);
  for (int f = 0; f < mesh.face_count(); ++f) {
    const Vec3 a = mesh.V.row(mesh.F(f, 0)), b = mesh.V.row(mesh.F(f, 1)), c = mesh.V.row(mesh.F(f, 2));
    const Vec3 n = (b - a).cross(c - a);  // twice the area times the unit normal
    for (int k = 0; k < 3; ++k) N.row(mesh.F(f, k)) += n.transpose();
  }
  for (int v = 0; v < mesh.vertex_count(); ++v) {
    const double len = N.row(v).norm();
    if (len > 0) N.row(v) /= len;
  }
  return N;
}

}  // namespace flank
