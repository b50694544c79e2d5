// How a step's work splits over threads (core/step_plan.hpp): plain data,
// checked directly for the invariants the stepper's lock-free passes rely on.
#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include "core/step_plan.hpp"
#include "fem_fixtures.hpp"

namespace tactile {
namespace {

// A beam clamped at x = 0 and pushed at x = 1, split `threads` ways.
template <class Real>
Model<Real> beam(int32_t threads) {
  ModelSpec spec;
  spec.mesh = make_box(Vec3(0.0), Vec3(1.0, 0.2, 0.2), {40, 6, 6});
  spec.materials = {MaterialSpec{MaterialModel::StVK, 1e5, 0.3, 1000}};
  spec.integrator.threads = threads;
  EssentialBc clamp;
  clamp.name = "clamp";
  clamp.where.kind = NodeSelector::Kind::Box;
  clamp.where.lo = Vec3(0.0);
  clamp.where.hi = Vec3(0.0, 0.2, 0.2);
  EssentialBc push = clamp;
  push.name = "push";
  push.where.lo = Vec3(1.0, 0.0, 0.0);
  push.where.hi = Vec3(1.0, 0.2, 0.2);
  spec.essential = {clamp, push};
  return build_model<Real>(spec);
}

// The nodes [lo, hi) the elements of blocks [b0, b1) touch.
template <class Real>
std::pair<int32_t, int32_t> nodes_of(const Model<Real>& m, int32_t b0, int32_t b1) {
  int32_t lo = m.n_nodes, hi = 0;
  for (int32_t b = b0; b < b1; ++b)
    for (int l = 0; l < kLanes<Real>; ++l) {
      if (m.lane_tet[size_t(b) * kLanes<Real> + size_t(l)] < 0) continue;
      for (int c = 0; c < 4; ++c) {
        const int32_t i = m.blocks[size_t(b)].node4[c][l] / 4;
        lo = std::min(lo, i);
        hi = std::max(hi, i + 1);
      }
    }
  return {lo, hi};
}

template <class Real>
void check_plan(int32_t threads) {
  SCOPED_TRACE(std::to_string(threads) + " threads, " + (sizeof(Real) == 4 ? "float" : "double"));
  const Model<Real> m = beam<Real>(threads);
  const StepPlan plan = make_step_plan(m, threads > 1);
  const auto n_blocks = int32_t(m.blocks.size());
  ASSERT_EQ(plan.parts.size(), threads > 1 ? m.parts.size() : 1u);
  if (threads > 1) {
    EXPECT_GE(plan.parts.size(), 2u);
  }

  // The parts tile the blocks and the nodes, in order.
  int32_t block = 0, node = 0;
  for (const StepPlan::Part& p : plan.parts) {
    EXPECT_EQ(p.block_begin, block);
    EXPECT_EQ(p.node_begin, node);
    block = p.block_end;
    node = p.node_end;
    // Its own share lies within its blocks; its nodes are A then B (or B then A), nothing left out.
    EXPECT_LE(p.block_begin, p.own_begin);
    EXPECT_LE(p.own_end, p.block_end);
    const bool a_first = p.a_begin == p.node_begin;
    EXPECT_EQ(a_first ? p.a_end : p.b_end, a_first ? p.b_begin : p.a_begin);
    EXPECT_EQ(std::min(p.a_begin, p.b_begin), p.node_begin);
    EXPECT_EQ(std::max(p.a_end, p.b_end), p.node_end);
  }
  EXPECT_EQ(block, n_blocks);
  EXPECT_EQ(node, m.n_nodes);

  // A pair's middle chunks cover exactly what neither part's own share takes.
  for (size_t k = 0; k + 1 < plan.parts.size(); k += 2) {
    const StepPlan::Part &left = plan.parts[k], &right = plan.parts[k + 1];
    EXPECT_EQ(left.side, 1);
    EXPECT_EQ(right.side, 2);
    int32_t b = left.own_end;
    for (int32_t j = left.chunk_begin; j < left.chunk_end; ++j) {
      EXPECT_EQ(plan.chunks[size_t(j)].block_begin, b);
      b = plan.chunks[size_t(j)].block_end;
    }
    EXPECT_EQ(b, right.own_begin);
  }

  // Every region holds the nodes its blocks touch, and no two regions share
  // a force slot (two threads never add into one array).
  auto covers = [&](int32_t region, int32_t b0, int32_t b1) {
    if (b0 == b1) return;
    const auto [lo, hi] = nodes_of(m, b0, b1);
    const StepPlan::Region& r = plan.regions[size_t(region)];
    EXPECT_LE(r.begin, lo);
    EXPECT_GE(r.end, hi);
    EXPECT_EQ(r.begin % 16, 0);
    EXPECT_EQ(r.end % 16, 0);
  };
  for (const StepPlan::Part& p : plan.parts) covers(p.own_region, p.own_begin, p.own_end);
  for (const StepPlan::Chunk& c : plan.chunks) covers(c.region, c.block_begin, c.block_end);
  std::vector<std::pair<int64_t, int64_t>> slots;
  for (const StepPlan::Region& r : plan.regions) {
    if (r.begin == r.end) continue;
    slots.emplace_back(r.offset + r.begin, r.offset + r.end);
    EXPECT_GE(r.offset, 0);
    EXPECT_LE(r.offset + r.end, plan.force_slots);
  }
  std::sort(slots.begin(), slots.end());
  for (size_t k = 1; k < slots.size(); ++k) EXPECT_LE(slots[k - 1].second, slots[k].first);

  // Each 16 nodes list the offsets of exactly the regions that hold them, in region order.
  const int32_t groups = (m.n_nodes + 15) / 16;
  ASSERT_EQ(plan.group_begin.size(), size_t(groups) + 1);
  for (int32_t g = 0; g < groups; ++g) {
    std::vector<int64_t> want;
    for (const StepPlan::Region& r : plan.regions)
      if (r.begin <= 16 * g && 16 * (g + 1) <= r.end) want.push_back(r.offset);
    const std::vector<int64_t> got(plan.group_offset.begin() + plan.group_begin[size_t(g)],
                                   plan.group_offset.begin() + plan.group_begin[size_t(g) + 1]);
    EXPECT_EQ(got, want) << "group " << g;
  }

  // Every constrained node's entry once, with its part's range holding it.
  size_t n_entries = 0;
  for (const EssentialSet& set : m.essential) n_entries += set.nodes.size();
  EXPECT_EQ(plan.essential_entries.size(), n_entries);
  EXPECT_GT(n_entries, 0u);
  for (const StepPlan::Part& p : plan.parts)
    for (size_t k = p.essential_begin; k < p.essential_end; ++k) {
      const int32_t i = plan.essential_entries[k].node;
      EXPECT_TRUE(i >= p.node_begin && i < p.node_end) << i;
    }
  EXPECT_EQ(plan.parts.back().essential_end, n_entries);
}

TEST(StepPlan, OnePartCoversEverything) {
  check_plan<double>(1);
  check_plan<float>(1);
}
TEST(StepPlan, PartsTileTheBodyAndRegionsNeverShareASlot) {
  for (int32_t threads : {2, 3, 4}) {
    check_plan<double>(threads);
    check_plan<float>(threads);
  }
}

}  // namespace
}  // namespace tactile
