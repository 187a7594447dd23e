// A bounding-volume hierarchy of oriented boxes over Φ's triangles, for exact closest points
// (DESIGN "Closest points"). Query points sit a cutter radius above Φ; an axis-aligned box of
// a tilted piece of surface is as thick as it is wide, so a ball that only touches Φ at the
// footpoint still overlaps a disc of boxes around it whose width grows with the cutter
// radius over the box size, i.e. as √(triangles). A box aligned with the piece's own
// principal directions is thin across the surface, and the same ball overlaps O(1) boxes per
// level: the query cost grows with log(triangles), and a good starting radius (the previous
// footpoint's face) leaves little to visit.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <span>
#include <vector>

#include "kernels/lanes.h"
#include "kernels/parallel.h"
#include "kernels/types.h"

namespace flank {

// No default member initialisers: the build writes every field of every node, and the tree's
// node array is not filled with defaults first (that was a serial pass over fresh memory).
struct ObbNode {
  Vec3 centre;
  std::array<Vec3, 3> axes;  // orthonormal
  Vec3 half;                 // half extents along the axes, padded for rounding
  // Inner node: the left child is the next node (pre-order), the right one `right` nodes on.
  // Leaf: right == 0 and the items are order()[first, first + count).
  std::int32_t right;
  std::int32_t first;
  std::int32_t count;

  bool leaf() const { return right == 0; }

  // A lower bound of the squared distance from p to anything inside the box.
  double lower_bound2(const Vec3& p) const {
    // Branch-free: which side of a box a query lies on is a coin toss for the branch
    // predictor, and a miss costs more than the arithmetic.
    const Vec3 d = p - centre;
    const double e0 = std::max(std::abs(axes[0].dot(d)) - half[0], 0.0);
    const double e1 = std::max(std::abs(axes[1].dot(d)) - half[1], 0.0);
    const double e2 = std::max(std::abs(axes[2].dot(d)) - half[2], 0.0);
    return e0 * e0 + e1 * e1 + e2 * e2;
  }
};

// The tree as queries walk it: every node holds the boxes of up to four children (two levels
// of the binary tree) in single precision, side by side, so that one node costs a few cache
// lines and its four tests run as one vector loop. Rounding is made safe twice: each float box
// is widened to contain the double box it comes from, and a box is pruned only when it is
// farther than the best distance by a margin larger than float evaluation error.
struct ObbWideNode {
  static constexpr int kLanes = 4;
  float centre[3][kLanes];
  float axes[9][kLanes];  // axis k, component j at [3 k + j]
  float half[3][kLanes];
  // Per lane: >= 0 an inner node's index; < 0 a leaf, leaves()[-1 - child].
  std::int32_t child[kLanes];
  std::int32_t count;  // lanes in use, 2 to 4
};

struct ObbLeaf {
  std::int32_t first;
  std::int32_t count;
};

class ObbTree {
 public:
  // A leaf holds at most this many items (median splits stop below it).
  static constexpr int kMaxLeafItems = 8;

  ObbTree() = default;
  // Builds over triangles given as 3 corners each; `pad` (≥ 0) widens every box so that
  // rounding never cuts off a triangle (a few 1e-13 of the coordinates' magnitude is
  // plenty). Deterministic whatever the thread count.
  ObbTree(std::span<const std::array<Vec3, 3>> triangles, double pad);

  // The binary tree in pre-order, in double precision (what the wide nodes are made from).
  std::span<const ObbNode> nodes() const { return nodes_; }
  // Item (triangle) indices in leaf order.
  const std::vector<int>& order() const { return order_; }
  // The tree as queries walk it (node 0 is the root unless the whole tree is one leaf), its
  // leaves, and the point its float boxes are relative to.
  std::span<const ObbWideNode> wide_nodes() const { return wide_; }
  std::span<const ObbLeaf> leaves() const { return leaves_; }
  const Vec3& origin() const { return origin_; }

  // Depth-first, nearest box first. `visit(leaf)` is called for every leaf whose box may hold
  // a point not farther than √best_d2 (leaf indexes leaves(); its items are the positions
  // order()[first, first + count)); it may lower best_d2. Boxes are pruned only when
  // certainly farther, so every leaf holding an item at the minimum distance is visited: ties
  // can be broken by the caller independently of the visiting order.
  template <class Visit>
  void nearest(const Vec3& p, double& best_d2, Visit&& visit) const;

 private:
  // The squared pruning distance in float: √best_d2 widened by the float error bound.
  float threshold(double best_d2, double query_scale) const;

  // Buffers (kernels/parallel.h): written by the concurrent build, not zeroed before.
  Buffer<ObbNode> nodes_;
  std::vector<int> order_;
  Buffer<ObbWideNode> wide_;
  Buffer<ObbLeaf> leaves_;
  Vec3 origin_ = Vec3::Zero();  // wide boxes are relative to it
  double scale_ = 0.0;          // the coordinates' magnitude about origin_
};

inline float ObbTree::threshold(double best_d2, double query_scale) const {
  if (!(best_d2 < std::numeric_limits<double>::infinity())) return std::numeric_limits<float>::infinity();
  // Float evaluation of a lane errs by under 1e-6 of (|p − origin| + box distance + scale);
  // 1e-5 of each is a tenfold margin.
  const double r = std::sqrt(best_d2) * (1.0 + 1e-5) + 1e-5 * (scale_ + query_scale);
  const double t = r * r * (1.0 + 1e-6);
  return t < static_cast<double>(std::numeric_limits<float>::max()) ? static_cast<float>(t)
                                                                    : std::numeric_limits<float>::infinity();
}

template <class Visit>
void ObbTree::nearest(const Vec3& p, double& best_d2, Visit&& visit) const {
  if (wide_.empty()) {
    if (leaves_.size() == 1) visit(std::int32_t{0});  // a tree of one leaf
    return;
  }
  const Vec3 rel = p - origin_;
  const double query_scale = rel.norm();
  const float px = static_cast<float>(rel.x()), py = static_cast<float>(rel.y()),
              pz = static_cast<float>(rel.z());
  float thr = threshold(best_d2, query_scale);
  // A stack entry is one 64-bit word: the lane's lower bound (a float ≥ 0, whose bits order
  // as its values do) above its child code. Entries stored and loaded whole: two 32-bit
  // halves written apart and read as one stall the load on store forwarding, and that stall
  // was a tenth of the whole search.
  const auto entry = [](float lb2, std::int32_t child) {
    std::uint32_t bits;
    std::memcpy(&bits, &lb2, sizeof bits);
    return (std::uint64_t{bits} << 32) | static_cast<std::uint32_t>(child);
  };
  const auto bound_of = [](std::uint64_t e) {
    const auto bits = static_cast<std::uint32_t>(e >> 32);
    float lb2;
    std::memcpy(&lb2, &bits, sizeof lb2);
    return lb2;
  };
  // Each node pushes at most 3 entries and the depth is ⌈log4(leaves)⌉ + 1.
  std::uint64_t stack[3 * 40];
  int top = 0;
  stack[top++] = entry(0.0f, 0);
  while (top > 0) {
    const std::uint64_t e = stack[--top];
    if (bound_of(e) > thr) continue;
    const auto child = static_cast<std::int32_t>(static_cast<std::uint32_t>(e));
    if (child < 0) {
      visit(static_cast<std::int32_t>(-1 - child));
      thr = threshold(best_d2, query_scale);
      continue;
    }
    const ObbWideNode& n = wide_[static_cast<std::size_t>(child)];
    // The four boxes at once, one lane each.
    static_assert(sizeof(Float4) == ObbWideNode::kLanes * sizeof(float));
    const Float4 dx = splat<Float4>(px) - load_lanes<Float4>(n.centre[0]);
    const Float4 dy = splat<Float4>(py) - load_lanes<Float4>(n.centre[1]);
    const Float4 dz = splat<Float4>(pz) - load_lanes<Float4>(n.centre[2]);
    Float4 sum = splat<Float4>(0.0f);
    for (int k = 0; k < 3; ++k) {
      const Float4 x = load_lanes<Float4>(n.axes[3 * k]) * dx + load_lanes<Float4>(n.axes[3 * k + 1]) * dy +
                       load_lanes<Float4>(n.axes[3 * k + 2]) * dz;
      const Float4 excess = lane_max(lane_abs(x) - load_lanes<Float4>(n.half[k]), splat<Float4>(0.0f));
      sum += excess * excess;
    }
    float lb[ObbWideNode::kLanes];
    store_lanes(sum, lb);
    // The lanes within reach, nearest last on the stack (popped first): an insertion sort of
    // the whole words, so equal bounds go by child code.
    const int bottom = top;
    for (int l = 0; l < n.count; ++l) {
      if (lb[l] > thr) continue;
      const std::uint64_t x = entry(lb[l], n.child[l]);
      int j = top++;
      while (j > bottom && stack[j - 1] < x) {
        stack[j] = stack[j - 1];
        --j;
      }
      stack[j] = x;
    }
  }
}

}  // namespace flank
