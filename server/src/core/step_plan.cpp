#include "core/step_plan.hpp"

#include <algorithm>

namespace tactile {

namespace {

// Share of each part of a pair that its thread always takes (to the nearest
// strip): the rest, in the middle of the pair, goes in chunks of whole
// strips to whichever thread gets there first (see elastic_part).
constexpr int32_t kShareOwnPercent = 75;
// Chunks per pair, at most. A chunk is what one thread may be left waiting
// for, and each adds a force array the correctors read: a strip of the sweep
// reaches the layer of nodes before it, so a chunk's array spans about a
// layer, and small chunks pile several arrays on each node, which lengthens
// the correctors; a few chunks keep both the wait and the correctors short
// (fem_bench --only=threads and --only=passes; docs/perf.md, Threads).
constexpr int32_t kShareMaxChunks = 8;

}  // namespace

template <class Real>
StepPlan make_step_plan(const Model<Real>& model, bool parallel) {
  StepPlan plan;
  using Part = StepPlan::Part;
  using Region = StepPlan::Region;
  using Chunk = StepPlan::Chunk;
  using EssentialEntry = StepPlan::EssentialEntry;
  // The model's parts (integrator.threads of them, fewer on small meshes).
  if (parallel) {
    for (const ModelPart& mp : model.parts)
      plan.parts.push_back({mp.block_begin, mp.block_end, mp.node_begin, mp.node_end});
  } else {
    plan.parts.push_back({0, static_cast<int32_t>(model.blocks.size()), 0, model.n_nodes});
  }
  const auto n_parts = static_cast<int32_t>(plan.parts.size());
  // The nodes each block touches, rounded out to 16.
  const auto n_blocks = static_cast<int32_t>(model.blocks.size());
  std::vector<int32_t> lo(size_t(n_blocks), model.n_nodes), hi(size_t(n_blocks), 0);
  const bool quadratic = !model.quadratic_blocks.empty();  // (the same lanes, ten nodes a lane)
  for (int32_t b = 0; b < n_blocks; ++b) {
    for (int l = 0; l < kLanes<Real>; ++l) {
      if (model.lane_tet[size_t(b) * kLanes<Real> + size_t(l)] < 0) continue;  // padding adds only zeros
      for (int c = 0; c < (quadratic ? 10 : 4); ++c) {
        const int32_t node4 =
            quadratic ? model.quadratic_blocks[size_t(b)].node4[c][l] : model.blocks[size_t(b)].node4[c][l];
        lo[size_t(b)] = std::min(lo[size_t(b)], node4 / 4 / 16 * 16);
        hi[size_t(b)] = std::max(hi[size_t(b)], (node4 / 4 + 16) / 16 * 16);
      }
    }
  }
  // Force arrays ("regions"): one per part for the blocks it always takes,
  // then one per middle chunk of each pair (see elastic_part). Each holds
  // only the nodes its blocks touch, at an offset into the force slots of at
  // least its first node (so that the array's start plus the offset stays inside them); the parts are
  // slabs of the body, so regions overlap only where their elements meet.
  int64_t next = 0;
  auto add_region = [&](int32_t b0, int32_t b1) {
    int32_t rlo = model.n_nodes, rhi = 0;
    for (int32_t b = b0; b < b1; ++b) {
      rlo = std::min(rlo, lo[size_t(b)]);
      rhi = std::max(rhi, hi[size_t(b)]);
    }
    if (rlo >= rhi) rlo = rhi = 0;
    const int64_t base = std::max(next, int64_t(rlo));  // both multiples of 16
    plan.regions.push_back({base - rlo, rlo, rhi});
    next = base + (rhi - rlo);
    return static_cast<int32_t>(plan.regions.size() - 1);
  };
  // Where strips start (model.hpp): a range of blocks that cut a strip would
  // touch the nodes of the whole strip, so shares and chunks end there.
  std::vector<int32_t> cuts;
  for (const ElementGroup& g : model.groups) {
    for (int32_t b = g.begin; b < g.end; b += kStripBlocks) cuts.push_back(b);
    cuts.push_back(g.end);
  }
  std::sort(cuts.begin(), cuts.end());
  cuts.erase(std::unique(cuts.begin(), cuts.end()), cuts.end());
  auto snap = [&cuts](int32_t b) {  // the strip start nearest b
    if (cuts.empty()) return b;
    const auto it = std::lower_bound(cuts.begin(), cuts.end(), b);
    if (it == cuts.end()) return cuts.back();
    if (it == cuts.begin() || *it - b <= b - *(it - 1)) return *it;
    return *(it - 1);
  };
  const int32_t n_pairs = n_parts / 2;
  for (int32_t p = 0; p < n_parts; ++p) {
    Part& part = plan.parts[size_t(p)];
    part.own_begin = part.block_begin;
    part.own_end = part.block_end;
    if (p < 2 * n_pairs) {
      part.side = p % 2 == 0 ? 1 : 2;
      part.share = p / 2;
      const int32_t own = (part.block_end - part.block_begin) * kShareOwnPercent / 100;
      if (part.side == 1)
        part.own_end = std::clamp(snap(part.block_begin + own), part.block_begin, part.block_end);
      else
        part.own_begin = std::clamp(snap(part.block_end - own), part.block_begin, part.block_end);
    }
    part.own_region = add_region(part.own_begin, part.own_end);
  }
  for (int32_t k = 0; k < n_pairs; ++k) {
    Part& left = plan.parts[size_t(2 * k)];
    Part& right = plan.parts[size_t(2 * k + 1)];
    const int32_t m0 = left.own_end, m1 = right.own_begin;  // the middle, whole strips
    std::vector<int32_t> strips;                            // its strip starts, and its end
    for (int32_t c : cuts)
      if (c >= m0 && c <= m1) strips.push_back(c);
    const auto n_strips = static_cast<int32_t>(strips.size()) - 1;
    const int32_t n_chunks = std::min(n_strips, kShareMaxChunks);
    left.chunk_begin = right.chunk_begin = static_cast<int32_t>(plan.chunks.size());
    for (int32_t j = 0; j < n_chunks; ++j) {  // whole strips, as even as they go
      const int32_t b0 = strips[size_t(int64_t(n_strips) * j / n_chunks)];
      const int32_t b1 = strips[size_t(int64_t(n_strips) * (j + 1) / n_chunks)];
      plan.chunks.push_back({b0, b1, add_region(b0, b1), 0, -1});
    }
    left.chunk_end = right.chunk_end = static_cast<int32_t>(plan.chunks.size());
  }
  plan.force_slots = next;
  // Which regions hold each 16 nodes, in plan.regions order: the correctors sum
  // them in that order whichever thread filled them.
  const int32_t n_groups = (model.n_nodes + 15) / 16;
  plan.group_begin.assign(size_t(n_groups) + 1, 0);
  for (const Region& r : plan.regions)
    for (int32_t g = r.begin / 16; g < r.end / 16; ++g) ++plan.group_begin[size_t(g) + 1];
  for (int32_t g = 0; g < n_groups; ++g) plan.group_begin[size_t(g) + 1] += plan.group_begin[size_t(g)];
  plan.group_offset.assign(size_t(plan.group_begin.back()), 0);
  std::vector<int32_t> group_region(plan.group_offset.size(), 0);  // the same lists, as region indices
  {
    std::vector<int32_t> fill(plan.group_begin.begin(), plan.group_begin.end() - 1);
    for (size_t r = 0; r < plan.regions.size(); ++r)
      for (int32_t g = plan.regions[r].begin / 16; g < plan.regions[r].end / 16; ++g) {
        group_region[size_t(fill[size_t(g)])] = int32_t(r);
        plan.group_offset[size_t(fill[size_t(g)]++)] = plan.regions[r].offset;
      }
  }
  // The parts whose nodes a range of blocks reads (parts tile the nodes in order).
  auto waits = [&](int32_t b0, int32_t b1, int32_t& wait_lo, int32_t& wait_hi) {
    int32_t nlo = model.n_nodes, nhi = 0;
    for (int32_t b = b0; b < b1; ++b) {
      nlo = std::min(nlo, lo[size_t(b)]);
      nhi = std::max(nhi, hi[size_t(b)]);
    }
    wait_lo = 0;
    wait_hi = -1;
    for (int32_t q = 0; q < n_parts; ++q) {
      const Part& part = plan.parts[size_t(q)];
      if (part.node_begin >= nhi || part.node_end <= nlo || part.node_begin >= part.node_end) continue;
      if (wait_hi < wait_lo) wait_lo = q;
      wait_hi = q;
    }
  };
  for (Part& part : plan.parts) waits(part.own_begin, part.own_end, part.wait_lo, part.wait_hi);
  for (Chunk& c : plan.chunks) waits(c.block_begin, c.block_end, c.wait_lo, c.wait_hi);
  {
    int32_t c = 0;
    for (size_t k = 0; k < model.essential.size(); ++k)
      for (int32_t i : model.essential[k].nodes) plan.essential_entries.push_back({int32_t(k), i, c++});
    // By part (a node's entries stay in set order: a node in two sets takes the later one's motion).
    auto part_of = [&](int32_t node) {
      int32_t q = 0;
      while (q + 1 < n_parts && node >= plan.parts[size_t(q)].node_end) ++q;
      return q;
    };
    std::stable_sort(
        plan.essential_entries.begin(), plan.essential_entries.end(),
        [&](const EssentialEntry& a, const EssentialEntry& b) { return part_of(a.node) < part_of(b.node); });
    size_t k = 0;
    for (int32_t q = 0; q < n_parts; ++q) {
      plan.parts[size_t(q)].essential_begin = k;
      while (k < plan.essential_entries.size() && part_of(plan.essential_entries[k].node) == q) ++k;
      plan.parts[size_t(q)].essential_end = k;
    }
  }
  // Who fills each region, and each part's nodes in A (only its own blocks'
  // region holds them: the longer run of such 16-node groups at either end of
  // its range) and B (the rest, with the regions they wait for).
  plan.region_part.assign(plan.regions.size(), -1);
  plan.region_pair.assign(plan.regions.size(), -1);
  for (int32_t q = 0; q < n_parts; ++q) plan.region_part[size_t(plan.parts[size_t(q)].own_region)] = q;
  for (int32_t k = 0; k < n_pairs; ++k)
    for (int32_t j = plan.parts[size_t(2 * k)].chunk_begin; j < plan.parts[size_t(2 * k)].chunk_end; ++j)
      plan.region_pair[size_t(plan.chunks[size_t(j)].region)] = k;
  for (Part& part : plan.parts) {
    const int32_t g0 = part.node_begin / 16, g1 = (part.node_end + 15) / 16;
    auto own_only = [&](int32_t g) {
      for (int32_t k = plan.group_begin[size_t(g)]; k < plan.group_begin[size_t(g) + 1]; ++k)
        if (group_region[size_t(k)] != part.own_region) return false;
      return true;
    };
    int32_t head = g0, tail = g1;
    while (head < g1 && own_only(head)) ++head;
    while (tail > head && own_only(tail - 1)) --tail;
    auto node = [&](int32_t g) { return std::min(g * 16, part.node_end); };
    if (head - g0 >= g1 - tail) {
      part.a_begin = part.node_begin, part.a_end = node(head), part.b_begin = node(head), part.b_end = part.node_end;
    } else {
      part.a_begin = node(tail), part.a_end = part.node_end, part.b_begin = part.node_begin, part.b_end = node(tail);
    }
    std::vector<int32_t> wait;
    for (int32_t g = part.b_begin / 16; g < (part.b_end + 15) / 16 && part.b_begin < part.b_end; ++g)
      for (int32_t k = plan.group_begin[size_t(g)]; k < plan.group_begin[size_t(g) + 1]; ++k)
        wait.push_back(group_region[size_t(k)]);
    std::sort(wait.begin(), wait.end());
    wait.erase(std::unique(wait.begin(), wait.end()), wait.end());
    part.wait_region_begin = plan.wait_regions.size();
    plan.wait_regions.insert(plan.wait_regions.end(), wait.begin(), wait.end());
    part.wait_region_end = plan.wait_regions.size();
  }
  return plan;
}

template StepPlan make_step_plan(const Model<float>&, bool);
template StepPlan make_step_plan(const Model<double>&, bool);

}  // namespace tactile
