#include "kernels/mesh.h"

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
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    const Vec3 p0 = mesh.V.row(mesh.F(f, 0));
    const Vec3 n = (Vec3(mesh.V.row(mesh.F(f, 1))) - p0).cross(Vec3(mesh.V.row(mesh.F(f, 2))) - p0);
    const double len = n.norm();
    N.row(f) = len > 0 ? Vec3(n / len) : Vec3::Zero();
  }
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

}  // namespace flank
