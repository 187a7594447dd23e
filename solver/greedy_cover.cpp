#include "solver/greedy_cover.h"

#include <algorithm>
#include <numeric>

namespace flank {

Cover empty_cover(const VecX& area) {
  Cover c;
  c.vertex_patch.assign(static_cast<std::size_t>(area.size()), -1);
  c.total_area = area.sum();
  return c;
}

void greedy_cover(const std::vector<Patch>& pool, const VecX& area, const CoverOptions& o, Cover* c) {
  c->used.resize(pool.size(), 0);
  for (int picked = 0; o.max_picks <= 0 || picked < o.max_picks; ++picked) {
    const int id = static_cast<int>(c->picks.size());
    if (id >= o.max_patches) break;
    if (c->covered_area >= o.coverage_target * c->total_area) break;
    int pick = -1;
    double best_gain = 0.0;
    for (std::size_t k = 0; k < pool.size(); ++k) {
      if (c->used[k]) continue;
      double gain = 0.0;
      for (int v : pool[k].covered_vertices)
        if (c->vertex_patch[static_cast<std::size_t>(v)] < 0) gain += area(v);
      const bool better = pick < 0 || gain > best_gain ||
                          (gain == best_gain && pool[k].error.max < pool[static_cast<std::size_t>(pick)].error.max);
      if (better) pick = static_cast<int>(k), best_gain = gain;
    }
    if (pick < 0 || best_gain < o.min_gain * c->total_area) break;
    c->used[static_cast<std::size_t>(pick)] = 1;
    for (int v : pool[static_cast<std::size_t>(pick)].covered_vertices)
      if (c->vertex_patch[static_cast<std::size_t>(v)] < 0) c->vertex_patch[static_cast<std::size_t>(v)] = id, c->covered_area += area(v);
    c->picks.push_back(pick);
    c->curve.push_back(c->fraction());
  }
}

void improve_cover(const std::vector<Patch>& pool, const VecX& area, int max_swaps, Cover* c) {
  if (c->picks.empty()) return;
  const std::size_t V = static_cast<std::size_t>(area.size());
  std::vector<int> count(V, 0);  // picked patches covering each vertex
  std::vector<char> picked(pool.size(), 0);
  for (int k : c->picks) {
    picked[static_cast<std::size_t>(k)] = 1;
    for (int v : pool[static_cast<std::size_t>(k)].covered_vertices) ++count[static_cast<std::size_t>(v)];
  }
  std::vector<int> picks = c->picks;
  for (int swap = 0; swap < max_swaps; ++swap) {
    double best_delta = 1e-9 * c->total_area;  // a swap must gain more than rounding
    int best_out = -1, best_in = -1;
    for (std::size_t i = 0; i < picks.size(); ++i) {
      const Patch& out = pool[static_cast<std::size_t>(picks[i])];
      double loss = 0.0;
      for (int v : out.covered_vertices) {
        if (count[static_cast<std::size_t>(v)] == 1) loss += area(v);
        --count[static_cast<std::size_t>(v)];
      }
      for (std::size_t j = 0; j < pool.size(); ++j) {
        if (picked[j]) continue;
        double gain = 0.0;
        for (int v : pool[j].covered_vertices)
          if (count[static_cast<std::size_t>(v)] == 0) gain += area(v);
        if (gain - loss > best_delta) best_delta = gain - loss, best_out = static_cast<int>(i), best_in = static_cast<int>(j);
      }
      for (int v : out.covered_vertices) ++count[static_cast<std::size_t>(v)];
    }
    if (best_out < 0) break;
    for (int v : pool[static_cast<std::size_t>(picks[best_out])].covered_vertices) --count[static_cast<std::size_t>(v)];
    for (int v : pool[static_cast<std::size_t>(best_in)].covered_vertices) ++count[static_cast<std::size_t>(v)];
    picked[static_cast<std::size_t>(picks[best_out])] = 0;
    picked[static_cast<std::size_t>(best_in)] = 1;
    picks[static_cast<std::size_t>(best_out)] = best_in;
  }
  // Rebuild in greedy order over the picks alone.
  std::vector<Patch> chosen;
  chosen.reserve(picks.size());
  for (int k : picks) chosen.push_back(pool[static_cast<std::size_t>(k)]);
  Cover rebuilt = empty_cover(area);
  CoverOptions all;
  all.coverage_target = 1.0;
  all.max_patches = static_cast<int>(picks.size());
  all.min_gain = 0.0;
  greedy_cover(chosen, area, all, &rebuilt);
  rebuilt.used.assign(pool.size(), 0);
  for (int& k : rebuilt.picks) {
    k = picks[static_cast<std::size_t>(k)];
    rebuilt.used[static_cast<std::size_t>(k)] = 1;
  }
  *c = std::move(rebuilt);
}

std::vector<UncoveredRegion> uncovered_regions(const Mesh& mesh, const std::vector<int>& vertex_patch,
                                               const VecX& area) {
  const int V = mesh.vertex_count();
  std::vector<int> parent(static_cast<std::size_t>(V));
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (int f = 0; f < mesh.face_count(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.F(f, k), b = mesh.F(f, (k + 1) % 3);
      if (vertex_patch[a] < 0 && vertex_patch[b] < 0) parent[find(a)] = find(b);
    }
  std::vector<UncoveredRegion> regions;
  std::vector<int> slot(static_cast<std::size_t>(V), -1);
  for (int v = 0; v < V; ++v) {
    if (vertex_patch[v] >= 0) continue;
    const int r = find(v);
    if (slot[r] < 0) {
      slot[r] = static_cast<int>(regions.size());
      regions.emplace_back();
    }
    UncoveredRegion& u = regions[static_cast<std::size_t>(slot[r])];
    u.area += area(v);
    u.centroid += area(v) * mesh.V.row(v).transpose();
    ++u.vertices;
  }
  for (UncoveredRegion& u : regions)
    if (u.area > 0) u.centroid /= u.area;
  std::stable_sort(regions.begin(), regions.end(),
                   [](const UncoveredRegion& a, const UncoveredRegion& b) { return a.area > b.area; });
  return regions;
}

}  // namespace flank
