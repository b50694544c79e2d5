#include "core/critical_step.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tactile {

template <class Real>
CriticalStep<Real>::CriticalStep(const Model<Real>& model, const std::vector<int32_t>& contact_surface)
    : model_(model), kernels_(kernels<Real>()) {
  if (contact_surface.empty()) return;
  std::vector<int32_t> index(size_t(model_.n_nodes), -1);
  for (size_t k = 0; k < contact_surface.size(); ++k) index[size_t(contact_surface[k])] = int32_t(k);
  contact_tet_begin_.assign(contact_surface.size() + 1, 0);
  const TetMesh& mesh = model_.mesh;
  for (size_t e = 0; e < mesh.tets.size(); ++e)
    for (int k = 0; k < mesh.nodes_per_tet(); ++k)
      if (const int32_t i = mesh.node(e, k); index[size_t(i)] >= 0) ++contact_tet_begin_[size_t(index[size_t(i)]) + 1];
  for (size_t k = 0; k < contact_surface.size(); ++k) contact_tet_begin_[k + 1] += contact_tet_begin_[k];
  contact_tets_.assign(size_t(contact_tet_begin_.back()), 0);
  std::vector<int32_t> fill(contact_tet_begin_.begin(), contact_tet_begin_.end() - 1);
  for (size_t e = 0; e < mesh.tets.size(); ++e)
    for (int k = 0; k < mesh.nodes_per_tet(); ++k)
      if (const int32_t i = mesh.node(e, k); index[size_t(i)] >= 0)
        contact_tets_[size_t(fill[size_t(index[size_t(i)])]++)] = int32_t(e);
  tet_mark_.assign(size_t(model_.n_tets), 0);
  examined_.reserve(contact_tets_.size());
}

template <class Real>
double CriticalStep<Real>::compute(const State<Real>& s) const {
  return compute(s, 0, static_cast<int32_t>(model_.blocks.size()));
}

template <class Real>
double CriticalStep<Real>::compute(const State<Real>& s, int32_t begin, int32_t end) const {
  // Lane blocks, SIMD (kernels.hpp), so that the sixteenth of the body
  // refresh() examines each call adds little to a frame beside its steps
  // (fem_bench --only=refresh; docs/perf.md, The critical step's refresh).
  double dt = model_.dt_rest;
  for (const ElementGroup& g : model_.groups) {
    const int32_t b0 = std::max(g.begin, begin), b1 = std::min(g.end, end);
    if (b0 >= b1) continue;
    dt = std::min(dt, kernels_.critical[int(g.model)](model_.blocks.data(), b0, b1, s.u.data(), model_.lane_dt.data()));
  }
  return dt;
}

template <class Real>
double CriticalStep<Real>::compute_contact(const State<Real>& s) {
  if (++mark_ == 0) {  // wrapped: no tet may keep a mark of this pass
    std::fill(tet_mark_.begin(), tet_mark_.end(), 0u);
    mark_ = 1;
  }
  examined_.clear();  // (its capacity holds every contact tet: no allocation)
  for (int32_t k : s.contact.pushed)
    for (int32_t j = contact_tet_begin_[size_t(k)]; j < contact_tet_begin_[size_t(k) + 1]; ++j) {
      const int32_t e = contact_tets_[size_t(j)];
      if (tet_mark_[size_t(e)] == mark_) continue;
      tet_mark_[size_t(e)] = mark_;
      examined_.push_back(e);
    }
  // Their lanes, gathered W at a time into one block per material model, run
  // through the same kernel as the sweep (compute).
  constexpr int W = kLanes<Real>;
  double dt = model_.dt_rest;
  for (int m = 0; m < kMaterialModelCount; ++m) {
    int n = 0;
    auto flush = [&] {
      for (int l = n; l < W; ++l) {  // padding: F = I at any u, no step of its own
        for (int c = 0; c < 4; ++c) gathered_.node4[c][l] = gathered_.node4[0][0];
        for (int q = 0; q < 9; ++q) gathered_.Dinv[q][l] = (q % 4 == 0) ? Real(1) : Real(0);
        gathered_dt_[l] = std::numeric_limits<double>::infinity();
      }
      dt = std::min(dt, kernels_.critical[m](&gathered_, 0, 1, s.u.data(), gathered_dt_));
      n = 0;
    };
    for (int32_t e : examined_) {
      if (int(model_.tet_model[size_t(e)]) != m) continue;
      const auto lane = size_t(model_.tet_lane[size_t(e)]);
      const ElementBlock<Real>& B = model_.blocks[lane / W];
      const size_t l = lane % W;
      for (int c = 0; c < 4; ++c) gathered_.node4[c][n] = B.node4[c][l];
      for (int q = 0; q < 9; ++q) gathered_.Dinv[q][n] = B.Dinv[q][l];
      gathered_dt_[n] = model_.lane_dt[lane];
      if (++n == W) flush();
    }
    if (n > 0) flush();
  }
  return dt;
}

template <class Real>
double CriticalStep<Real>::refresh(State<Real>& s) {
  // The estimate changes slowly, so each call re-examines a sixteenth of the
  // elements: every element is seen again within 16 calls, at an even cost
  // per call (a full pass at once is a spike a real-time loop would feel as
  // a missed deadline). Until a sweep completes, the lower of the last
  // sweep's estimate and this one's so far.
  constexpr int32_t kSweepCalls = 16;
  CriticalStepSweep& c = s.critical;
  if (c.refreshed_at < 0) {
    c.dt = c.last = compute(s);
    c.next = 0;
    c.min = model_.dt_rest;
    c.refreshed_at = s.step;
  } else {
    const auto n_blocks = static_cast<int32_t>(model_.blocks.size());
    const int32_t chunk = (n_blocks + kSweepCalls - 1) / kSweepCalls;
    const int32_t end = std::min(n_blocks, c.next + chunk);
    c.min = std::min(c.min, compute(s, c.next, end));
    c.next = end;
    if (c.next >= n_blocks) {
      c.last = c.min;
      c.min = model_.dt_rest;
      c.next = 0;
      c.refreshed_at = s.step;
    }
    c.dt = std::min(c.last, c.min);
  }
  if (contact_pushed(s)) c.dt = std::min(c.dt, compute_contact(s));
  return c.dt;
}

template class CriticalStep<float>;
template class CriticalStep<double>;

}  // namespace tactile
