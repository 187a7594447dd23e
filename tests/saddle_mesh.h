// A small grid over a saddle z = xy − √2, with coordinates that are not short decimals: the
// writers' tests check that every coordinate comes back as written.
#pragma once

#include <cmath>

#include "kernels/mesh.h"

namespace flank::testing {

inline Mesh saddle_mesh(int nx, int ny) {
  Mesh m;
  m.V.resize(nx * ny, 3);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const double x = i / 3.0, y = j * 0.1 + 1e-9;
      m.V.row(j * nx + i) << x, y, x * y - std::sqrt(2.0);
    }
  m.F.resize(2 * (nx - 1) * (ny - 1), 3);
  int f = 0;
  for (int j = 0; j + 1 < ny; ++j)
    for (int i = 0; i + 1 < nx; ++i) {
      const int a = j * nx + i, b = a + 1, c = a + nx + 1, d = a + nx;
      m.F.row(f++) << a, b, c;
      m.F.row(f++) << a, c, d;
    }
  return m;
}

}  // namespace flank::testing
