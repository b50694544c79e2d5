// The critical step of the current configuration, and its refresh as the body
// deforms: each element's exact rest step (core/model.hpp, lane_dt) scaled by
// how much it has been squashed and stiffened since, through the same lane
// kernels as the forces (core/kernels/kernels.hpp). advance() (core/stepper.hpp)
// plans its sub-steps on it; a proxy that squashes the elements under it
// within one interval splits the rest of that interval again. A quadratic
// tet's rest step is its own (compute_p2_critical_dt), scaled by its
// corners' squash and stiffening as a linear tet's: the same measure of
// how far the element has left its rest shape.
#pragma once

#include <cstdint>
#include <vector>

#include "core/kernels/kernels.hpp"
#include "core/model.hpp"
#include "core/state.hpp"

namespace tactile {

template <class Real>
class CriticalStep {
 public:
  // contact_surface: the surface nodes contact pushes (Contact's numbering of
  // s.contact.pushed); empty for a model without proxies.
  CriticalStep(const Model<Real>& model, const std::vector<int32_t>& contact_surface);

  // Over every element [s].
  double compute(const State<Real>& s) const;
  // Over the lane blocks [begin, end) only.
  double compute(const State<Real>& s, int32_t begin, int32_t end) const;
  // Over the elements around the surface nodes the latest step's contact
  // pushed (the model's rest step when it pushed none). Allocates nothing.
  double compute_contact(const State<Real>& s);
  // Whether the latest step pushed nodes whose elements compute_contact examines.
  bool contact_pushed(const State<Real>& s) const { return !contact_tets_.empty() && !s.contact.pushed.empty(); }

  // Brings s.critical up to date at the start of an advance(): a sixteenth
  // of the body, then the elements contact pushed; returns s.critical.dt.
  double refresh(State<Real>& s);

 private:
  const Model<Real>& model_;
  const KernelTable<Real>& kernels_;
  // A proxy squashes the elements under it faster than the sweep comes
  // round: those around the nodes it pushed are examined after every step.
  std::vector<int32_t> contact_tet_begin_;  // per contact surface node: range in contact_tets_ (+1)
  std::vector<int32_t> contact_tets_;       // the tets around each contact surface node
  std::vector<uint32_t> tet_mark_;          // per tet: the pass that last examined it (n_tets)
  uint32_t mark_ = 0;
  std::vector<int32_t> examined_;  // the tets a pass examines (capacity: contact_tets_)
  // The lanes of those tets gathered into one block for the kernel, with their rest steps.
  ElementBlock<Real> gathered_{};
  double gathered_dt_[kLanes<Real>] = {};
};

}  // namespace tactile
