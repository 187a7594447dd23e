// The greedy cover of the automatic decomposition (DESIGN "Greedy cover"): from a pool of
// candidate patches, repeatedly take the one that adds the most uncovered area of Φ (ties: the
// lower error, then the lower pool index) until the coverage target, the patch cap, or a gain
// below the minimum. What stays uncovered is reported as edge-connected regions, for ball-end
// finishing.
#pragma once

#include <cstddef>
#include <vector>

#include "kernels/mesh.h"
#include "solver/patch.h"

namespace flank {

// The cover sums a patch's vertex areas in blocks of this many vertices of its list: the
// first block's terms added one by one to the sum's start, each later block's summed on its
// own from zero and added after, in order. For a list of one block that is the plain sum in
// the list's order. The blocks let one long list (a part one patch covers: 129,000 vertices
// on the 256k cone) be summed on several threads; they are fixed, so the sums are the same
// whatever the thread count. The covered area is summed this way pick by pick, from the
// cover's area before; a greedy gain from zero.
inline constexpr std::size_t kCoverBlock = 4096;

struct CoverOptions {
  double coverage_target = 0.95;  // stop at this covered fraction of Φ's area
  int max_patches = 20;           // patches in the cover, in all
  double min_gain = 0.005;        // a patch must add at least this fraction of Φ's area
  int max_picks = 0;              // picks in this call; 0: no limit
};

// The state of a cover: which patch covers each Φ vertex, and what is picked so far.
struct Cover {
  std::vector<int> vertex_patch;  // #V: the index into `picks` covering it, −1 if none
  std::vector<char> used;         // per pool entry: picked
  std::vector<int> picks;         // pool indices in the order picked
  std::vector<double> curve;      // covered fraction after each pick
  double covered_area = 0.0;
  double total_area = 0.0;

  double fraction() const { return total_area > 0 ? covered_area / total_area : 0.0; }
};

// An empty cover of Φ (vertex areas `area`, #V).
Cover empty_cover(const VecX& area);

// Extends `cover` by greedy picks from `pool` (entries already used are skipped; `used` grows
// to the pool's size). Deterministic: the order of the pool decides ties.
void greedy_cover(const std::vector<Patch>& pool, const VecX& area, const CoverOptions& options,
                  Cover* cover);

// Local improvement of a cover (the greedy choice is myopic: an early large patch may leave
// gaps that no later one fills well): while some swap of a picked patch for an unpicked one of
// the pool covers more area, make the best such swap. The number of patches stays; the picks
// are then ordered by order_cover and the cover rebuilt. Deterministic. Each patch lists a
// covered vertex once (as evaluate_patch makes them).
void improve_cover(const std::vector<Patch>& pool, const VecX& area, int max_swaps, Cover* cover);

// greedy_cover, then improve_cover where the cover has picks: the same cover as the two calls,
// with the threads woken once for both (kernels/parallel.h, with_crew).
void extend_cover(const std::vector<Patch>& pool, const VecX& area, const CoverOptions& options,
                  int max_swaps, Cover* cover);

// The cover of exactly `picks` (pool indices), in the order that covers the most early on: the
// greedy order (the largest gain first) or the reverse of backward elimination (dropping, from
// the whole set, the pick that loses the least area, first dropped last), whichever covers more
// summed over 1, 2, …, k patches; ties keep the greedy order. Greedy commits to its first large
// patch; elimination judges every patch against all the others, and on blade faces its first
// eight often cover several percent more. Ties within either go to the lower pool index.
Cover order_cover(const std::vector<Patch>& pool, const VecX& area, std::vector<int> picks);

// order_cover's two orders of `picks` (pool indices). The greedy order takes the largest gain
// first (ties: the lower error, then the earlier in `picks`); elimination drops the pick that
// loses the least (ties: the later in `picks`), and its order is the reverse of the drops.
std::vector<int> greedy_order(const std::vector<Patch>& pool, const VecX& area, const std::vector<int>& picks);
std::vector<int> elimination_order(const std::vector<Patch>& pool, const VecX& area, const std::vector<int>& picks);

struct UncoveredRegion {
  double area = 0.0;
  Vec3 centroid = Vec3::Zero();
  int vertices = 0;
};

// Edge-connected regions of uncovered vertices (vertex_patch < 0), largest first.
std::vector<UncoveredRegion> uncovered_regions(const Mesh& mesh, const std::vector<int>& vertex_patch,
                                               const VecX& area);

}  // namespace flank
