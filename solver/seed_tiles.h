// Seeds of the automatic decomposition (DESIGN "Automatic decomposition"): Φ is tiled by
// farthest-point sampling of its vertices, and every seed carries the local frame that the
// candidate lines are laid out in — normal, principal directions and curvatures.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "kernels/mesh.h"
#include "kernels/types.h"

namespace flank {

struct Seed {
  int vertex = -1;              // Φ vertex the seed sits on
  Vec3 point = Vec3::Zero();    // its position
  Vec3 normal = Vec3::UnitZ();  // unit, area-weighted vertex normal, oriented like F
  // Unit principal directions in the tangent plane: dir_min belongs to the principal
  // curvature of smallest |k| (the cutter axis wants to lie along it), and
  // dir_max = normal × dir_min, so (dir_min, dir_max, normal) is right-handed.
  Vec3 dir_max = Vec3::UnitY();
  Vec3 dir_min = Vec3::UnitX();
  // Principal curvatures along dir_min / dir_max, positive where Φ bends toward the normal.
  // Both 0 (and the directions an arbitrary tangent frame) when the fit had too few points.
  double k_min = 0.0, k_max = 0.0;
};

struct SeedOptions {
  double spacing = 0.0;       // target distance between seeds (required > 0)
  std::vector<char> allowed;  // empty: every vertex may be a seed; else #V 0/1 (re-seeding)
  int max_seeds = 100000;

  std::string validate() const;  // empty if OK
};

// Farthest-point sampling with Euclidean distances over the allowed vertices: the first seed
// is the allowed vertex smallest in (x, y, z), then the allowed vertex farthest from all
// seeds so far (ties: lowest index) is added while that distance is ≥ spacing and fewer
// than max_seeds were chosen. So the seeds are pairwise ≥ spacing apart and, unless
// max_seeds stopped it, every allowed vertex lies within spacing of a seed.
// Curvature: least-squares height field h = a x² + b xy + c y² + d x + e y in the seed's
// tangent frame over the Φ vertices within max(spacing/4, 3 × mean edge length).
// Deterministic and independent of the thread count. Empty if the options are invalid or
// `allowed` is neither empty nor #V long.
std::vector<Seed> seed_tiles(const Mesh& mesh, const SeedOptions& options);

// seed_tiles on one mesh, called again and again (a decomposition seeds each round): what
// does not depend on the options, the mesh's scale and the vertex grid of each cell size
// asked, is made once and kept. The same seeds as seed_tiles. Keeps a reference to the mesh;
// not for concurrent calls.
class SeedTiler {
 public:
  explicit SeedTiler(const Mesh& mesh);
  ~SeedTiler();
  SeedTiler(const SeedTiler&) = delete;
  SeedTiler& operator=(const SeedTiler&) = delete;
  std::vector<Seed> operator()(const SeedOptions& options);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace flank
