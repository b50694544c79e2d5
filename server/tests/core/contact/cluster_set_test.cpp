// Contact's broad phase (core/contact/cluster_set.hpp) on hand-built items:
// the grouping, boxes that bound every vertex's path over the step, and a
// visit that reaches every item whose vertices come near a box and skips the
// groups far from it.
#include <gtest/gtest.h>

#include <set>
#include <vector>

#include "core/contact/cluster_set.hpp"

namespace tactile {
namespace {

// Items 0..n-1 on a line along x, item i moving from x = i cm to x = i cm + 5 mm over the step; item i's
// vertices are i and i + 1 (a chain of segments).
struct Chain {
  int32_t n;
  std::vector<Vec3> x0, x1;
  explicit Chain(int32_t items) : n(items) {
    for (int32_t v = 0; v <= n; ++v) {
      x0.emplace_back(0.01 * v, 0.0, 0.0);
      x1.emplace_back(0.01 * v + 0.005, 0.0, 0.0);
    }
  }
  ClusterSet set(int32_t cluster_items, int32_t group_items) const {
    return ClusterSet::build(n, cluster_items, group_items, [](int32_t i, std::vector<int32_t>& out) {
      out.push_back(i);
      out.push_back(i + 1);
    });
  }
};

TEST(ClusterSet, GroupsItemsInClustersAndListsEachGroupsVerticesOnce) {
  const ClusterSet s = Chain(20).set(8, 3);
  ASSERT_EQ(s.clusters(), 3u);  // 8 + 8 + 4 items
  EXPECT_EQ(s.groups(), 3u + 3u + 2u);
  EXPECT_EQ(s.group_items[1][0], 3);
  EXPECT_EQ(s.group_items[1][1], 6);
  // Group 1 holds items 3, 4, 5: vertices 3..6, once each, sorted.
  std::vector<int32_t> v(s.vertices.begin() + s.vertex_begin[1], s.vertices.begin() + s.vertex_begin[2]);
  EXPECT_EQ(v, (std::vector<int32_t>{3, 4, 5, 6}));
  EXPECT_EQ(s.group_items.back()[1], 20);
}

TEST(ClusterSet, FittedBoxesBoundEveryVertexAtBothEndsOfTheStep) {
  const Chain c(20);
  ClusterSet s = c.set(8, 3);
  s.fit(c.x0, c.x1);
  for (size_t k = 0; k < s.clusters(); ++k)
    for (int32_t g = s.group_begin[k]; g < s.group_begin[k + 1]; ++g)
      for (int32_t m = s.vertex_begin[size_t(g)]; m < s.vertex_begin[size_t(g) + 1]; ++m)
        for (const Vec3& x : {c.x0[size_t(s.vertices[size_t(m)])], c.x1[size_t(s.vertices[size_t(m)])]}) {
          EXPECT_TRUE(boxes_meet(x, x, s.group_lo[size_t(g)], s.group_hi[size_t(g)]));
          EXPECT_TRUE(boxes_meet(x, x, s.lo[k], s.hi[k]));
        }
  // Tight: cluster 1's box runs from vertex 8 at the start to vertex 16 at the end.
  EXPECT_DOUBLE_EQ(s.lo[1].x, 0.08);
  EXPECT_DOUBLE_EQ(s.hi[1].x, 0.165);
}

TEST(ClusterSet, AVisitReachesTheItemsNearABoxAndOnlyTheirGroups) {
  const Chain c(40);
  ClusterSet s = c.set(8, 4);
  s.fit(c.x0, c.x1);
  // A box around x = 12.2 cm: items whose segment passes near it are 11 and 12 (and 10's end reaches 11.5 cm).
  const Vec3 lo(0.122, -0.001, -0.001), hi(0.123, 0.001, 0.001);
  std::set<int32_t> seen;
  for (size_t k = 0; k < s.clusters(); ++k)
    s.visit_cluster(k, s.group_lo.data(), s.group_hi.data(), lo, hi, [&](int32_t i) { seen.insert(i); });
  // Every item whose vertices' boxes meet it is visited...
  for (int32_t i = 0; i < c.n; ++i) {
    const Vec3 ilo = glm::min(c.x0[size_t(i)], c.x1[size_t(i) + 1]),
               ihi = glm::max(c.x0[size_t(i)], c.x1[size_t(i) + 1]);
    if (boxes_meet(ilo, ihi, lo, hi)) {
      EXPECT_TRUE(seen.count(i)) << i;
    }
  }
  // ...and only those of one group of four (items 8-11) or two (8-15): not the other 32.
  EXPECT_LE(seen.size(), 8u);
  EXPECT_TRUE(seen.count(11) && seen.count(12));
}

TEST(ClusterSet, AGrownClusterReachesItemsThatMovedSinceItsBoxesWereFitted) {
  Chain c(16);
  ClusterSet s = c.set(16, 4);
  s.fit(c.x0, c.x1);
  // The chain moves 3 cm up after the fit; a box there finds nothing until the cluster is grown by the move.
  const Vec3 lo(0.0, 0.029, -0.001), hi(0.2, 0.031, 0.001);
  int visited = 0;
  s.visit_cluster(0, s.group_lo.data(), s.group_hi.data(), lo, hi, [&](int32_t) { ++visited; });
  EXPECT_EQ(visited, 0);
  s.grow[0] = 0.03;
  s.lo[0] -= Vec3(0.03);
  s.hi[0] += Vec3(0.03);
  s.visit_cluster(0, s.group_lo.data(), s.group_hi.data(), lo, hi, [&](int32_t) { ++visited; });
  EXPECT_EQ(visited, 16);
}

}  // namespace
}  // namespace tactile
