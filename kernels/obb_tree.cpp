#include "kernels/obb_tree.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <numeric>
#include <utility>

#include "kernels/parallel.h"

namespace flank {

namespace {

constexpr int kLeafItems = ObbTree::kMaxLeafItems;
// Subtrees larger than this build their two halves concurrently. Each half writes its nodes
// straight into its own range of the one node list (a subtree's node count depends on its
// item count alone), so a split costs a task, not a copy.
constexpr int kParallelItems = 256;

// What the subtree over n items (median splits down to kLeafItems) holds, for every n the
// tree meets (two per level), filled before the build and only read during it: its binary
// nodes, and the wide nodes and leaves it collapses into. All depend on n alone, so every
// subtree's range of each list is known before it is built.
class SubtreeSizes {
 public:
  struct Counts {
    std::int32_t nodes = 1, wide = 0, leaves = 1;  // a leaf's
  };
  explicit SubtreeSizes(int n) { fill(n); }
  Counts operator()(int n) const { return n <= kLeafItems ? Counts{} : counts_.at(n); }

  // The item counts of the lanes of the wide node made from a binary node over n > kLeafItems
  // items: each child, or where it is inner, its two children. Returns the lane count.
  static int lanes(int n, int* out) {
    int count = 0;
    for (const int c : {n / 2, n - n / 2}) {
      if (c <= kLeafItems) {
        out[count++] = c;
      } else {
        out[count++] = c / 2;
        out[count++] = c - c / 2;
      }
    }
    return count;
  }

 private:
  Counts fill(int n) {
    if (n <= kLeafItems) return {};
    if (const auto it = counts_.find(n); it != counts_.end()) return it->second;
    Counts c{1 + fill(n / 2).nodes + fill(n - n / 2).nodes, 1, 0};
    int lane_items[ObbWideNode::kLanes];
    const int count = lanes(n, lane_items);
    for (int l = 0; l < count; ++l) {
      const Counts sub = fill(lane_items[l]);
      c.wide += sub.wide;
      c.leaves += sub.leaves;
    }
    counts_.emplace(n, c);
    return c;
  }
  std::map<int, Counts> counts_;
};

// First and second moments of a triangle's corners, relative to the bounding box's centre
// (so that the covariance of a small node far from the origin does not cancel away).
struct Moments {
  Vec3 sum;  // Σ v
  std::array<double, 6> outer;  // Σ v vᵀ: xx, yy, zz, xy, xz, yz
};

struct Builder {
  std::span<const std::array<Vec3, 3>> triangles;
  std::span<int> items;
  // Per item, left uninitialised until the parallel loop writes them: the first touch of
  // fresh memory (a page fault per 4 KiB) then happens on every thread, not on one.
  std::unique_ptr<Vec3[]> centroids;
  std::unique_ptr<Moments[]> moments;
  double pad = 0.0;
  Vec3 origin = Vec3::Zero();
  const SubtreeSizes& sizes;

  // The box of items[begin, end): principal axes of the corners (an orthonormal frame
  // whatever the spread: a degenerate covariance falls back to the coordinate axes).
  ObbNode box(int begin, int end) const {
    Vec3 sum = Vec3::Zero();
    std::array<double, 6> outer{};
    for (int i = begin; i < end; ++i) {
      const Moments& m = moments[static_cast<std::size_t>(items[static_cast<std::size_t>(i)])];
      sum += m.sum;
      for (int k = 0; k < 6; ++k) outer[static_cast<std::size_t>(k)] += m.outer[static_cast<std::size_t>(k)];
    }
    const double n = 3.0 * (end - begin);
    const Vec3 mean_rel = sum / n;
    Mat3 cov;
    cov << outer[0], outer[3], outer[4], outer[3], outer[1], outer[5], outer[4], outer[5], outer[2];
    cov = cov / n - mean_rel * mean_rel.transpose();
    const Vec3 mean = mean_rel + origin;
    ObbNode node;
    node.axes = {Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ()};  // unless the spread gives better
    node.right = node.first = node.count = 0;
    Eigen::SelfAdjointEigenSolver<Mat3> eig;
    eig.computeDirect(cov);
    // Eigenvalues ascend: axes[0] is across the surface, axes[2] along its longest spread.
    const Vec3 u = eig.eigenvectors().col(2);
    const Vec3 w = eig.eigenvectors().col(1);
    Vec3 a2 = u.normalized();
    Vec3 a1 = w - w.dot(a2) * a2;
    a1.normalize();
    const Vec3 a0 = a1.cross(a2);
    if (a0.allFinite() && a1.allFinite() && a2.allFinite() && std::abs(a0.norm() - 1.0) < 1e-9)
      node.axes = {a0, a1, a2};
    Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity());
    Vec3 hi = -lo;
    for (int i = begin; i < end; ++i)
      for (const Vec3& v : triangles[static_cast<std::size_t>(items[static_cast<std::size_t>(i)])])
        for (int k = 0; k < 3; ++k) {
          const double x = node.axes[static_cast<std::size_t>(k)].dot(v - mean);
          lo[k] = std::min(lo[k], x);
          hi[k] = std::max(hi[k], x);
        }
    const Vec3 mid = 0.5 * (lo + hi);
    node.centre = mean + mid[0] * node.axes[0] + mid[1] * node.axes[1] + mid[2] * node.axes[2];
    node.half = 0.5 * (hi - lo) + Vec3::Constant(pad);
    return node;
  }

  // Writes the subtree of items[begin, end) in pre-order from `self` on
  // (sizes(end - begin).nodes nodes); `keys` is scratch.
  void build(ObbNode* self, int begin, int end, std::vector<std::pair<double, int>>& keys) const {
    *self = box(begin, end);
    if (end - begin <= kLeafItems) {
      self->first = begin;
      self->count = end - begin;
      return;
    }
    // Median split of the centroids along the box's longest axis; ties by item index, so
    // the halves do not depend on the order the items arrive in.
    int axis = 0;
    self->half.maxCoeff(&axis);
    const Vec3 dir = self->axes[static_cast<std::size_t>(axis)];
    const int mid = begin + (end - begin) / 2;
    keys.resize(static_cast<std::size_t>(end - begin));
    for (int i = begin; i < end; ++i) {
      const int item = items[static_cast<std::size_t>(i)];
      keys[static_cast<std::size_t>(i - begin)] = {dir.dot(centroids[static_cast<std::size_t>(item)]), item};
    }
    std::nth_element(keys.begin(), keys.begin() + (mid - begin), keys.end());
    for (int i = begin; i < end; ++i) items[static_cast<std::size_t>(i)] = keys[static_cast<std::size_t>(i - begin)].second;
    self->right = 1 + sizes(mid - begin).nodes;
    ObbNode* left = self + 1;
    ObbNode* right = self + self->right;
    if (end - begin <= kParallelItems) {
      build(left, begin, mid, keys);
      build(right, mid, end, keys);
      return;
    }
    parallel_invoke_each(2, [&](std::size_t h) {
      std::vector<std::pair<double, int>> scratch;
      if (h == 0)
        build(left, begin, mid, scratch);
      else
        build(right, mid, end, scratch);
    });
  }
};

// A float not below x: the nearest one, one step up (no comparison with x, which the compiler
// may carry out in double: see set_half).
float round_up(double x) {
  return std::nextafter(static_cast<float>(x), std::numeric_limits<float>::infinity());
}

// Collapses the binary tree into nodes of up to four children (ObbWideNode), in pre-order:
// a wide node, then its lanes' subtrees in lane order; leaves in the order they are met.
// Each lane's range of both lists is known in advance (SubtreeSizes), so large subtrees are
// collapsed concurrently into their own ranges.
struct Collapser {
  std::span<const ObbNode> nodes;
  Vec3 origin;
  std::span<ObbWideNode> wide;
  std::span<ObbLeaf> leaves;
  const SubtreeSizes& sizes;

  // The lane code of binary node n over `items` items: a leaf's (negative, written at
  // leaves[leaf]) or the index of the wide node written at wide[index].
  std::int32_t lane(std::int32_t n, int items, std::int32_t index, std::int32_t leaf) {
    const ObbNode& b = nodes[static_cast<std::size_t>(n)];
    if (b.leaf()) {
      leaves[static_cast<std::size_t>(leaf)] = {b.first, b.count};
      return -1 - leaf;
    }
    node(n, items, index, leaf);
    return index;
  }

  // Widens lane l's float box to hold the double `box`: the half extents are computed from the
  // floats as stored. Not inlined on purpose: GCC 12 at -O3 (SLP vectorizer) was seen to
  // forward the double values into a float→double round trip written right after the
  // stores, dropping the rounding (tests/obb_tree_test.cpp WideFloatBoxesHoldTheirTriangles
  // caught boxes 2e-7 of their size too small); a separate function only sees the floats.
  [[gnu::noinline]] void set_half(ObbWideNode& w, int l, const ObbNode& box) const {
    Vec3 cf, af[3];
    for (int j = 0; j < 3; ++j) {
      cf[j] = static_cast<double>(w.centre[j][l]);
      for (int k = 0; k < 3; ++k) af[k][j] = static_cast<double>(w.axes[3 * k + j][l]);
    }
    const Vec3 centre = box.centre - origin;
    for (int k = 0; k < 3; ++k) {
      // The double box lies in the slab |af · (x − origin − cf)| ≤ this.
      double reach = std::abs(af[k].dot(centre - cf));
      for (int i = 0; i < 3; ++i) reach += std::abs(af[k].dot(box.axes[static_cast<std::size_t>(i)])) * box.half[i];
      w.half[k][l] = round_up(reach * (1.0 + 1e-12));
    }
  }

  // Writes the wide node for inner binary node n over `items` items at wide[index] (its
  // lanes: n's grandchildren, or a child itself where that is a leaf), its subtrees after it
  // and their leaves from leaves[leaf] on.
  void node(std::int32_t n, int items, std::int32_t index, std::int32_t leaf) {
    std::int32_t lanes[ObbWideNode::kLanes];
    int count = 0;
    const ObbNode& b = nodes[static_cast<std::size_t>(n)];
    for (const std::int32_t c : {n + 1, n + b.right}) {
      const ObbNode& child = nodes[static_cast<std::size_t>(c)];
      if (child.leaf()) {
        lanes[count++] = c;
      } else {
        lanes[count++] = c + 1;
        lanes[count++] = c + child.right;
      }
    }
    int lane_items[ObbWideNode::kLanes];
    [[maybe_unused]] const int lane_count = SubtreeSizes::lanes(items, lane_items);
    assert(lane_count == count);
    ObbWideNode w{};
    w.count = count;
    std::int32_t first_index[ObbWideNode::kLanes], first_leaf[ObbWideNode::kLanes];
    std::int32_t next_index = index + 1, next_leaf = leaf;
    for (int l = 0; l < count; ++l) {
      const ObbNode& box = nodes[static_cast<std::size_t>(lanes[l])];
      for (int j = 0; j < 3; ++j) {
        w.centre[j][l] = static_cast<float>(box.centre[j] - origin[j]);
        for (int k = 0; k < 3; ++k)
          w.axes[3 * k + j][l] = static_cast<float>(box.axes[static_cast<std::size_t>(k)][j]);
      }
      set_half(w, l, box);
      first_index[l] = next_index, first_leaf[l] = next_leaf;
      const SubtreeSizes::Counts sub = sizes(lane_items[l]);
      next_index += sub.wide, next_leaf += sub.leaves;
    }
    const auto collapse = [&](std::size_t l) {
      w.child[l] = lane(lanes[l], lane_items[l], first_index[l], first_leaf[l]);
    };
    if (items <= kParallelItems) {
      for (int l = 0; l < count; ++l) collapse(static_cast<std::size_t>(l));
    } else {
      parallel_invoke_each(static_cast<std::size_t>(count), collapse);
    }
    wide[static_cast<std::size_t>(index)] = w;
  }
};

}  // namespace

ObbTree::ObbTree(std::span<const std::array<Vec3, 3>> triangles, double pad) {
  const auto count = static_cast<int>(triangles.size());
  order_.resize(triangles.size());
  std::iota(order_.begin(), order_.end(), 0);
  if (count == 0) return;
  const SubtreeSizes sizes(count);
  Builder b{triangles, order_, {}, {}, pad, Vec3::Zero(), sizes};
  Vec3 lo = triangles[0][0], hi = lo;
  for (const auto& t : triangles)
    for (const Vec3& v : t) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  b.origin = 0.5 * (lo + hi);
  b.centroids.reset(new Vec3[triangles.size()]);
  b.moments.reset(new Moments[triangles.size()]);
  parallel_for(0, triangles.size(), [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f) {
      b.centroids[f] = (triangles[f][0] + triangles[f][1] + triangles[f][2]) / 3.0;
      Moments m{Vec3::Zero(), {}};
      for (const Vec3& corner : triangles[f]) {
        const Vec3 v = corner - b.origin;
        m.sum += v;
        m.outer[0] += v.x() * v.x(), m.outer[1] += v.y() * v.y(), m.outer[2] += v.z() * v.z();
        m.outer[3] += v.x() * v.y(), m.outer[4] += v.x() * v.z(), m.outer[5] += v.y() * v.z();
      }
      b.moments[f] = m;
    }
  }, 1024);
  const SubtreeSizes::Counts total = sizes(count);
  nodes_ = Buffer<ObbNode>(static_cast<std::size_t>(total.nodes));
  std::vector<std::pair<double, int>> keys;
  b.build(nodes_.data(), 0, count, keys);

  origin_ = b.origin;
  scale_ = 0.5 * (hi - lo).norm();
  wide_ = Buffer<ObbWideNode>(static_cast<std::size_t>(total.wide));
  leaves_ = Buffer<ObbLeaf>(static_cast<std::size_t>(total.leaves));
  Collapser c{nodes_, origin_, wide_, leaves_, sizes};
  c.lane(0, count, 0, 0);
}

}  // namespace flank
