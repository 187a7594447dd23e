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
  *c = order_cover(pool, area, picks);
}

namespace {
// The cover of `order` (pool indices) taken in that order.
Cover cover_in_order(const std::vector<Patch>& pool, const VecX& area, const std::vector<int>& order) {
  Cover c = empty_cover(area);
  c.used.assign(pool.size(), 0);
  for (int k : order) {
    const int id = static_cast<int>(c.picks.size());
    for (int v : pool[static_cast<std::size_t>(k)].covered_vertices)
      if (c.vertex_patch[static_cast<std::size_t>(v)] < 0)
        c.vertex_patch[static_cast<std::size_t>(v)] = id, c.covered_area += area(v);
    c.used[static_cast<std::size_t>(k)] = 1;
    c.picks.push_back(k);
    c.curve.push_back(c.fraction());
  }
  return c;
}
}  // namespace

Cover order_cover(const std::vector<Patch>& pool, const VecX& area, std::vector<int> picks) {
  std::sort(picks.begin(), picks.end());
  // Greedy: largest gain first, ties to the lower pool index.
  std::vector<int> greedy;
  {
    std::vector<char> covered(static_cast<std::size_t>(area.size()), 0), taken(picks.size(), 0);
    for (std::size_t step = 0; step < picks.size(); ++step) {
      int best = -1;
      double best_gain = -1.0;
      for (std::size_t i = 0; i < picks.size(); ++i) {
        if (taken[i]) continue;
        const Patch& p = pool[static_cast<std::size_t>(picks[i])];
        double gain = 0.0;
        for (int v : p.covered_vertices)
          if (!covered[static_cast<std::size_t>(v)]) gain += area(v);
        const bool better = best < 0 || gain > best_gain ||
                            (gain == best_gain && p.error.max < pool[static_cast<std::size_t>(picks[best])].error.max);
        if (better) best = static_cast<int>(i), best_gain = gain;
      }
      taken[static_cast<std::size_t>(best)] = 1;
      greedy.push_back(picks[static_cast<std::size_t>(best)]);
      for (int v : pool[static_cast<std::size_t>(greedy.back())].covered_vertices) covered[static_cast<std::size_t>(v)] = 1;
    }
  }
  // Backward elimination: drop the pick that loses the least area, ties the higher pool index.
  std::vector<int> eliminated;
  {
    std::vector<int> count(static_cast<std::size_t>(area.size()), 0);
    for (int k : picks)
      for (int v : pool[static_cast<std::size_t>(k)].covered_vertices) ++count[static_cast<std::size_t>(v)];
    std::vector<char> gone(picks.size(), 0);
    for (std::size_t step = 0; step < picks.size(); ++step) {
      int worst = -1;
      double worst_loss = 0.0;
      for (std::size_t i = picks.size(); i-- > 0;) {
        if (gone[i]) continue;
        double loss = 0.0;
        for (int v : pool[static_cast<std::size_t>(picks[i])].covered_vertices)
          if (count[static_cast<std::size_t>(v)] == 1) loss += area(v);
        if (worst < 0 || loss < worst_loss) worst = static_cast<int>(i), worst_loss = loss;
      }
      gone[static_cast<std::size_t>(worst)] = 1;
      eliminated.push_back(picks[static_cast<std::size_t>(worst)]);
      for (int v : pool[static_cast<std::size_t>(eliminated.back())].covered_vertices) --count[static_cast<std::size_t>(v)];
    }
    std::reverse(eliminated.begin(), eliminated.end());
  }
  Cover a = cover_in_order(pool, area, greedy), b = cover_in_order(pool, area, eliminated);
  double sa = 0.0, sb = 0.0;
  for (double x : a.curve) sa += x;
  for (double x : b.curve) sb += x;
  return sb > sa * (1.0 + 1e-12) ? b : a;
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
