// A triangle mesh Φ: the design surface. Validation and repair happen in io::read_mesh;
// everything downstream may assume finite coordinates, indices in range, no degenerate faces.
#pragma once

#include "kernels/types.h"

namespace flank {

struct Mesh {
  Points V;  // #V by 3 vertex positions
  Faces F;   // #F by 3 vertex indices, counter-clockwise seen from the tool side

  int vertex_count() const { return static_cast<int>(V.rows()); }
  int face_count() const { return static_cast<int>(F.rows()); }
};

struct BoundingBox {
  Vec3 min = Vec3::Zero();
  Vec3 max = Vec3::Zero();
  double diagonal() const { return (max - min).norm(); }
};

BoundingBox bounding_box(const Mesh& mesh);
double bbox_diagonal(const Mesh& mesh);
// #F by 3 unit face normals (right-hand rule on F's order).
Points face_normals(const Mesh& mesh);
// #V unit area-weighted vertex normals, oriented like F (zero for unused vertices).
Points vertex_normals(const Mesh& mesh);
// #F face areas.
VecX face_areas(const Mesh& mesh);
// #V barycentric vertex areas (a third of each incident face): the area a vertex stands for.
VecX vertex_areas(const Mesh& mesh);
double total_area(const Mesh& mesh);
// Splits every triangle into four at its edge midpoints (shared edges share the midpoint):
// 4× the faces on exactly the same surface, orientation kept. Used to re-mesh a part finer
// for the scaling benchmarks without changing its shape.
Mesh subdivide_midpoint(const Mesh& mesh);

}  // namespace flank
