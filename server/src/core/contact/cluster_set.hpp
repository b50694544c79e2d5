// Contact's broad phase: the items a proxy may touch (a body's free surface
// nodes, its boundary faces, an embedded surface's vertices or triangles),
// consecutive in Morton order of their rest positions, in clusters, each
// cluster in groups. A group lists the vertices its items move (slots, or
// embedded vertices), once each; its box bounds them over the step, and a
// cluster's box bounds its groups'. visit_cluster() tests a cluster's box
// against a proxy's, then its groups', and calls back for the items of the
// groups that meet it: a proxy far from the body costs one test a cluster.
//
// The boxes are kept one of two ways. fit() sets them each step to the
// vertices at both ends of the step (nodes and faces: a vertex is a slot,
// whose positions the step has). An embedded surface's are kept between
// steps in the ContactState and grown by how far any vertex can have moved
// since they were fitted (Contact::sweep_embedded): its vertices' positions
// cost a weighted sum each, so they are worked out only near a proxy.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <numeric>
#include <vector>

#include <glm/common.hpp>

#include "core/mesh.hpp"

namespace tactile {

inline bool boxes_meet(const Vec3& alo, const Vec3& ahi, const Vec3& blo, const Vec3& bhi) {
  return alo.x <= bhi.x && blo.x <= ahi.x && alo.y <= bhi.y && blo.y <= ahi.y && alo.z <= bhi.z && blo.z <= ahi.z;
}

// The order of `points` by the Morton code of their place in `box`: items
// near each other in space end up near each other in a cluster.
inline std::vector<size_t> morton_order(const std::vector<Vec3>& points, const Aabb& box) {
  const Vec3 extent = glm::max(box.size(), Vec3(1e-30));
  std::vector<uint32_t> key(points.size());
  for (size_t k = 0; k < points.size(); ++k) key[k] = compute_morton_code((points[k] - box.lo) / extent);
  std::vector<size_t> order(points.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return key[a] < key[b]; });
  return order;
}

struct ClusterSet {
  std::vector<int32_t> group_begin{0};              // per cluster: its first group (one more at the end)
  std::vector<std::array<int32_t, 2>> group_items;  // per group: its items [begin, end)
  std::vector<int32_t> vertices, vertex_begin{0};   // per group: its items' vertices, once each
  // This step's boxes per cluster (grown, where kept), and per group (as
  // fitted; a visit grows them by the cluster's `grow`).
  std::vector<Vec3> lo, hi, group_lo, group_hi;
  std::vector<double> grow;  // per cluster [m]

  size_t clusters() const { return group_begin.size() - 1; }
  size_t groups() const { return group_items.size(); }
  bool empty() const { return group_items.empty(); }

  // Items [0, n) in clusters of `cluster_items`, each in groups of
  // `group_items`; of(i, out) appends item i's vertices to out.
  template <class Of>
  static ClusterSet build(int32_t n, int32_t cluster_items, int32_t group_items, const Of& of) {
    ClusterSet set;
    for (int32_t b = 0; b < n; b += cluster_items) {
      const int32_t end = std::min(n, b + cluster_items);
      for (int32_t gb = b; gb < end; gb += group_items) {
        const int32_t ge = std::min(end, gb + group_items);
        std::vector<int32_t> v;
        for (int32_t i = gb; i < ge; ++i) of(i, v);
        std::sort(v.begin(), v.end());
        v.erase(std::unique(v.begin(), v.end()), v.end());
        set.group_items.push_back({gb, ge});
        set.vertices.insert(set.vertices.end(), v.begin(), v.end());
        set.vertex_begin.push_back(int32_t(set.vertices.size()));
      }
      set.group_begin.push_back(int32_t(set.group_items.size()));
    }
    set.lo.assign(set.clusters(), Vec3(0.0));
    set.hi.assign(set.clusters(), Vec3(0.0));
    set.group_lo.assign(set.groups(), Vec3(0.0));
    set.group_hi.assign(set.groups(), Vec3(0.0));
    set.grow.assign(set.clusters(), 0.0);
    return set;
  }

  // Every group's and cluster's box fitted to its vertices at both ends of
  // the step (x0[v], x1[v]), none grown.
  void fit(const std::vector<Vec3>& x0, const std::vector<Vec3>& x1) {
    constexpr double inf = std::numeric_limits<double>::infinity();
    for (size_t c = 0; c < clusters(); ++c) {
      lo[c] = Vec3(inf);
      hi[c] = Vec3(-inf);
      for (int32_t g = group_begin[c]; g < group_begin[c + 1]; ++g) {
        Vec3 glo(inf), ghi(-inf);
        for (int32_t m = vertex_begin[size_t(g)]; m < vertex_begin[size_t(g) + 1]; ++m) {
          const auto v = size_t(vertices[size_t(m)]);
          glo = glm::min(glo, glm::min(x0[v], x1[v]));
          ghi = glm::max(ghi, glm::max(x0[v], x1[v]));
        }
        group_lo[size_t(g)] = glo;
        group_hi[size_t(g)] = ghi;
        lo[c] = glm::min(lo[c], glo);
        hi[c] = glm::max(hi[c], ghi);
      }
      grow[c] = 0;
    }
  }

  // Calls visit(item) for each item of cluster c's groups whose box, grown
  // by grow[c], meets [blo, bhi]; the groups' boxes from glo, ghi (this set's
  // own, or kept elsewhere), indexed by group.
  template <class Visit>
  void visit_cluster(size_t c, const Vec3* glo, const Vec3* ghi, const Vec3& blo, const Vec3& bhi,
                     const Visit& visit) const {
    if (!boxes_meet(lo[c], hi[c], blo, bhi)) return;
    const Vec3 g(grow[c]);
    for (int32_t k = group_begin[c]; k < group_begin[c + 1]; ++k) {
      if (!boxes_meet(glo[k] - g, ghi[k] + g, blo, bhi)) continue;
      for (int32_t i = group_items[size_t(k)][0]; i < group_items[size_t(k)][1]; ++i) visit(i);
    }
  }
};

}  // namespace tactile
