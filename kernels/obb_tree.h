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
#include <span>
#include <vector>

#include "kernels/types.h"

namespace flank {

struct ObbNode {
  Vec3 centre = Vec3::Zero();
  std::array<Vec3, 3> axes{Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ()};  // orthonormal
  Vec3 half = Vec3::Zero();  // half extents along the axes, padded for rounding
  // Inner node: the left child is the next node (pre-order), the right one `right` nodes on.
  // Leaf: right == 0 and the items are order()[first, first + count).
  std::int32_t right = 0;
  std::int32_t first = 0;
  std::int32_t count = 0;

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

class ObbTree {
 public:
  ObbTree() = default;
  // Builds over triangles given as 3 corners each; `pad` (≥ 0) widens every box so that
  // rounding in lower_bound2 never cuts off a triangle (a few 1e-13 of the coordinates'
  // magnitude is plenty). Deterministic whatever the thread count.
  ObbTree(std::span<const std::array<Vec3, 3>> triangles, double pad);

  const std::vector<ObbNode>& nodes() const { return nodes_; }
  // Item (triangle) indices in leaf order.
  const std::vector<int>& order() const { return order_; }

  // Depth-first, nearer child first. `visit(position)` is called for every leaf item whose
  // box is not farther than `best_d2` (position indexes order()); it may lower best_d2.
  // Boxes are pruned only when strictly farther, so every item at the minimum distance is
  // visited: ties can be broken by the caller independently of the visiting order.
  template <class Visit>
  void nearest(const Vec3& p, double& best_d2, Visit&& visit) const;

 private:
  std::vector<ObbNode> nodes_;
  std::vector<int> order_;
};

template <class Visit>
void ObbTree::nearest(const Vec3& p, double& best_d2, Visit&& visit) const {
  if (nodes_.empty()) return;
  struct Entry {
    std::int32_t node;
    double lb2;
  };
  // Median splits keep the depth at ⌈log2(items)⌉ + 1; one entry per level is pending.
  Entry stack[96];
  int top = 0;
  stack[top++] = {0, nodes_[0].lower_bound2(p)};
  while (top > 0) {
    const Entry e = stack[--top];
    if (e.lb2 > best_d2) continue;
    std::int32_t n = e.node;
    // Descend towards the nearer child, leaving the farther one on the stack.
    while (!nodes_[static_cast<std::size_t>(n)].leaf()) {
      const std::int32_t a = n + 1;
      const std::int32_t b = n + nodes_[static_cast<std::size_t>(n)].right;
      const double la = nodes_[static_cast<std::size_t>(a)].lower_bound2(p);
      const double lb = nodes_[static_cast<std::size_t>(b)].lower_bound2(p);
      const bool a_first = la <= lb;
      const std::int32_t near = a_first ? a : b, far = a_first ? b : a;
      const double lnear = a_first ? la : lb, lfar = a_first ? lb : la;
      if (lfar <= best_d2) stack[top++] = {far, lfar};
      if (lnear > best_d2) {
        n = -1;
        break;
      }
      n = near;
    }
    if (n < 0) continue;
    const ObbNode& leaf = nodes_[static_cast<std::size_t>(n)];
    for (std::int32_t i = leaf.first; i < leaf.first + leaf.count; ++i) visit(i);
  }
}

}  // namespace flank
