// How a step's work splits over threads: plain data, built once from a
// model (make_step_plan) and read by the stepper (core/stepper.cpp, whose
// elastic_part says how the parts run).
//
// The model's parts are slabs of the body: part p takes the lane blocks
// [block_begin, block_end) and the nodes [node_begin, node_end). Parts 2k
// and 2k + 1 form a pair: each always takes its own share of its blocks,
// and the middle between the two shares goes in chunks of whole strips
// (model.hpp) to whichever thread gets there first. Forces go into
// "regions": one array per part's own share and one per middle chunk, each
// covering only the nodes its blocks touch, so that two threads never add
// into one array; the corrector sums a node's regions in a fixed order
// (group_offset), whichever thread filled each. Tests:
// server/tests/core/step_plan_test.cpp.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/model.hpp"

namespace tactile {

struct StepPlan {
  struct Part {
    int32_t block_begin, block_end;  // lane blocks
    int32_t node_begin, node_end;    // nodes
    // Parts 2k and 2k + 1 share the middle of their blocks (see
    // elastic_part): 1 for the one whose own share is on the left, 2 for
    // the one on the right, 0 for a part without a partner.
    int32_t side = 0;
    int32_t share = -1;                      // its pair's index (the stepper's shares_)
    int32_t own_begin = 0, own_end = 0;      // the blocks it always takes
    int32_t own_region = 0;                  // where their forces go, in regions
    int32_t chunk_begin = 0, chunk_end = 0;  // its pair's middle chunks, in chunks
    // The parts whose nodes its own blocks read: [wait_lo, wait_hi].
    int32_t wait_lo = 0, wait_hi = -1;
    // Its constrained nodes' entries, [essential_begin, essential_end) in essential_entries.
    size_t essential_begin = 0, essential_end = 0;
    // Its nodes in two ranges for the corrector inside the element pass: A,
    // held by its own blocks' force array alone (corrected as soon as those
    // are done), then B, after the regions [wait_region_begin,
    // wait_region_end) of wait_regions are done.
    int32_t a_begin = 0, a_end = 0, b_begin = 0, b_end = 0;
    size_t wait_region_begin = 0, wait_region_end = 0;
  };
  // A force array: the nodes [begin, end) (multiples of 16) one part's own
  // blocks or one middle chunk touch, stored at the stepper's f_[offset + begin, offset + end).
  struct Region {
    int64_t offset;
    int32_t begin, end;
  };
  // A middle chunk: blocks [block_begin, block_end), forces into `region`.
  struct Chunk {
    int32_t block_begin, block_end, region;
    int32_t wait_lo, wait_hi;  // the parts whose nodes its blocks read
  };
  // One node of one essential set: c counts the sets' nodes in order (the
  // index into the stepper's v_prescribed_ and a_prescribed_).
  struct EssentialEntry {
    int32_t set, node, c;
  };

  std::vector<Part> parts;
  std::vector<Region> regions;  // parts' own shares, then middle chunks
  std::vector<Chunk> chunks;
  // Per 16 nodes g, the offsets of the regions that hold them, in regions
  // order: group_offset[group_begin[g] .. group_begin[g + 1]).
  std::vector<int32_t> group_begin;
  std::vector<int64_t> group_offset;
  std::vector<int32_t> region_part;               // per region: the part whose own blocks fill it, or -1
  std::vector<int32_t> region_pair;               // per region: the pair whose middle chunk fills it, or -1
  std::vector<int32_t> wait_regions;              // per part, the regions its B nodes wait for
  std::vector<EssentialEntry> essential_entries;  // grouped by part, each part's in set order
  int64_t force_slots = 0;                        // the regions' arrays laid end to end [nodes]
};

// The model's parts when `parallel` (a pool of two threads or more runs
// them), else one part covering everything.
template <class Real>
StepPlan make_step_plan(const Model<Real>& model, bool parallel);

}  // namespace tactile
