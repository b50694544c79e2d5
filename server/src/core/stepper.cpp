#include "core/stepper.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

#include "core/quadratic.hpp"

namespace tactile {

const char* to_string(Fault::Kind k) {
  switch (k) {
    case Fault::Kind::None: return "none";
    case Fault::Kind::NonFinite: return "non-finite";
    case Fault::Kind::Inverted: return "inverted";
    case Fault::Kind::EnergyGrowth: return "energy-growth";
    case Fault::Kind::StepTooLarge: return "step-too-large";
  }
  return "?";
}

const char* to_string(Pass p) {
  switch (p) {
    case Pass::Predict: return "predict";
    case Pass::Essential: return "essential";
    case Pass::Elastic: return "elastic";
    case Pass::Loads: return "loads";
    case Pass::Correct: return "correct";
    case Pass::Contact: return "contact";
    case Pass::BodyContact: return "body_contact";
    case Pass::Guard: return "guard";
  }
  return "?";
}

namespace {

// Rigid motion of an essential BC at time t: position, velocity, acceleration.
struct Kinematics {
  Vec3 x, v, a;
};
Kinematics compute_bc_kinematics(const EssentialBc& bc, const Vec3& X, double t) {
  Vec3 r = X - bc.centre;
  Vec3 v{0.0}, a{0.0};
  if (bc.angle) {
    const ProfileValue th = compute_profile(*bc.angle, t);
    const Vec3 k = glm::normalize(bc.axis);
    const double c = std::cos(th.s), s = std::sin(th.s);
    r = r * c + glm::cross(k, r) * s + k * glm::dot(k, r) * (1.0 - c);  // Rodrigues
    const Vec3 kr = glm::cross(k, r);
    v = th.ds * kr;
    a = th.dds * kr + th.ds * th.ds * glm::cross(k, kr);
  }
  Vec3 x = bc.centre + r;
  if (bc.shift) {
    const ProfileValue d = compute_profile(*bc.shift, t);
    x += bc.direction * d.s;
    v += bc.direction * d.ds;
    a += bc.direction * d.dds;
  }
  return {x, v, a};
}

std::string list_ids(const std::vector<int32_t>& ids) {
  std::ostringstream out;
  for (size_t i = 0; i < ids.size() && i < 10; ++i) out << (i ? ", " : "") << ids[i];
  if (ids.size() > 10) out << ", ... (" << ids.size() << " in all)";
  return out.str();
}

}  // namespace

template <class Real>
Stepper<Real>::Stepper(const Model<Real>& model, ParallelFor* parallel)
    : model_(model),
      parallel_(parallel),
      kernels_(kernels<Real>()),
      contact_(model),
      body_contact_(model, parallel),
      critical_(model, model.proxies.empty() ? std::vector<int32_t>{} : contact_.surface_nodes()),
      // One part covering everything without a pool to run them on.
      plan_(make_step_plan(model, parallel && parallel->workers() >= 2)) {
  correct_ = kernels_.correct[model_.effects.gravity ? 1 : 0][model_.effects.damping ? 1 : 0];
  n_parts_ = static_cast<int32_t>(plan_.parts.size());
  energy_floor_ = energy_floor(model_);
  shares_ = std::make_unique<PairShare[]>(size_t(std::max(n_parts_ / 2, 1)));
  f_.assign(size_t(plan_.force_slots), Node4<Real>{});
  predicted_ = std::make_unique<OnceClaim[]>(size_t(n_parts_));
  own_claim_ = std::make_unique<OnceClaim[]>(size_t(n_parts_));
  region_done_ = std::make_unique<RegionDone[]>(plan_.regions.size());
  u4_.assign(size_t(model_.n_nodes), Node4<Real>{});
  elastic_.assign(plan_.regions.size(), ElasticSums{});
  correct_sums_.assign(size_t(n_parts_), CorrectSums{});
  for (const LoadSet& load : model_.loads) loaded_.insert(loaded_.end(), load.nodes.begin(), load.nodes.end());
  u_before_.assign(model_.constrained.size() + loaded_.size(), Vec3(0.0));
  a_prescribed_.assign(3 * model_.constrained.size(), Real(0));
  v_prescribed_.assign(3 * model_.constrained.size(), Real(0));
}

template <class Real>
State<Real> Stepper<Real>::make_state() const {
  State<Real> s;
  s.u.assign(3 * size_t(model_.n_nodes), Real(0));
  s.v = s.u;
  s.a = s.u;
  s.reaction.assign(3 * model_.constrained.size(), Real(0));
  contact_.init(s.contact);
  s.energy.load_force.assign(loaded_.size(), Vec3(0.0));
  return s;
}

template <class Real>
void Stepper<Real>::run_parts(void (*fn)(void*, int32_t), void* ctx) {
  if (n_parts_ == 1)
    fn(ctx, 0);
  else
    parallel_->run(n_parts_, fn, ctx);
}

template <class Real>
void Stepper<Real>::predict_part(void* ctx, int32_t p) {
  auto* self = static_cast<Stepper*>(ctx);
  const Part& part = self->plan_.parts[size_t(p)];
  State<Real>& s = *self->cur_;
  self->kernels_.predict(part.node_begin, part.node_end, self->cur_dt_, s.u.data(), s.v.data(), s.a.data(),
                         self->u4_.data());
}

template <class Real>
void Stepper<Real>::pad_part(void* ctx, int32_t p) {
  auto* self = static_cast<Stepper*>(ctx);
  const Part& part = self->plan_.parts[size_t(p)];
  self->kernels_.pad(part.node_begin, part.node_end, self->cur_->u.data(), self->u4_.data());
}

template <class Real>
void Stepper<Real>::elastic_blocks(int32_t begin, int32_t end, int32_t r) {
  Node4<Real>* f = f_.data() + plan_.regions[size_t(r)].offset;
  ElasticSums sums;
  for (const ElementGroup& g : model_.groups) {
    const int32_t b0 = std::max(g.begin, begin), b1 = std::min(g.end, end);
    if (b0 >= b1) continue;
    const ElasticSums s =
        model_.quadratic_blocks.empty()
            ? kernels_.forces[int(g.model)](model_.blocks.data(), b0, b1, Real(g.lambda), Real(g.mu), u4_.data(), f)
            : kernels_.quadratic_forces[int(g.model)](model_.quadratic_blocks.data(), b0, b1, Real(g.lambda),
                                                      Real(g.mu), u4_.data(), f);
    sums.energy += s.energy;
    sums.inverted += s.inverted;
  }
  elastic_[size_t(r)] = sums;
}

template <class Real>
void Stepper<Real>::run_elastic() {
  for (int32_t p = 0; p + 1 < n_parts_; p += 2) {
    const Part& left = plan_.parts[size_t(p)];
    shares_[size_t(left.share)].reset(left.chunk_begin, left.chunk_end);
  }
  run_parts(&Stepper::elastic_part, this);  // the pool's hand-off publishes the resets above
}

template <class Real>
void Stepper<Real>::elastic_part(void* ctx, int32_t p) {
  auto* self = static_cast<Stepper*>(ctx);
  const Part& part = self->plan_.parts[size_t(p)];
  if (!self->fused_) {
    // Every region is zero on entry: the correctors cleared every entry they read.
    self->elastic_blocks(part.own_begin, part.own_end, part.own_region);
    if (part.side != 0) self->claim_chunks(part.share, part.side);
    return;
  }
  // Split over threads, one job per part does the whole step's node and
  // element work: this step's positions first, this part's own, then those
  // of the parts whose nodes its blocks read; its own blocks; its share of
  // its pair's middle; then the corrector, first on the nodes only its own
  // blocks touch, then on the rest once the regions that hold them are done.
  // Whatever it needs that no thread has claimed yet it does itself (a pool
  // may run the parts in any order, even one after the other on one thread),
  // so a wait only ever waits for a thread at work. The corrector's two
  // ranges are fixed and summed in order: the result does not depend on
  // which thread did what.
  self->ensure_predicted(p);
  self->ensure_own(p);  // (which sees to the other parts' positions its blocks read)
  if (part.side != 0) self->claim_chunks(part.share, part.side);
  if (!self->fused_correct_) return;
  self->ensure_region(part.own_region);
  const CorrectSums a = self->correct_range(part.a_begin, part.a_end);
  for (size_t k = part.wait_region_begin; k < part.wait_region_end; ++k)
    self->ensure_region(self->plan_.wait_regions[k]);
  const CorrectSums b = self->correct_range(part.b_begin, part.b_end);
  self->correct_sums_[size_t(p)] = {a.abs_a + b.abs_a, a.mv2 + b.mv2, a.mgu + b.mgu, a.ma2 + b.ma2};
}

template <class Real>
void Stepper<Real>::claim_chunks(int32_t k, int side) {
  // Two parts of a pair share the middle of their blocks, in chunks: each
  // takes its own share first (three quarters of its part, at the pair's
  // ends), then claims middle chunks (whole strips) from its side until the
  // two meet. A thread that runs slower (a busier core, a later start) then
  // leaves more of the middle to its partner instead of holding up the step
  // (fem_bench --only=threads; docs/perf.md, Threads). Each chunk has its
  // own force array, which the correctors add in a fixed order: the result
  // is the same bit for bit wherever the two threads meet (resim relies on
  // it).
  for (int32_t next; (next = shares_[size_t(k)].claim(side)) >= 0;) {
    const Chunk& c = plan_.chunks[size_t(next)];
    if (fused_) {
      for (int32_t q = c.wait_lo; q <= c.wait_hi; ++q) ensure_predicted(q);
    }
    elastic_blocks(c.block_begin, c.block_end, c.region);
    if (fused_) region_done_[size_t(c.region)].publish(epoch_);
  }
}

template <class Real>
void Stepper<Real>::ensure_own(int32_t q) {
  run_once(own_claim_[size_t(q)], epoch_, [&] {
    const Part& part = plan_.parts[size_t(q)];
    for (int32_t w = part.wait_lo; w <= part.wait_hi; ++w) ensure_predicted(w);
    // Every region is zero on entry: the correctors cleared every entry they read.
    elastic_blocks(part.own_begin, part.own_end, part.own_region);
    region_done_[size_t(part.own_region)].publish(epoch_);
  });
}

template <class Real>
void Stepper<Real>::ensure_region(int32_t r) {
  const RegionDone& done = region_done_[size_t(r)];
  if (done.done(epoch_)) return;
  if (plan_.region_part[size_t(r)] >= 0)
    ensure_own(plan_.region_part[size_t(r)]);
  else if (plan_.region_pair[size_t(r)] >= 0)
    claim_chunks(plan_.region_pair[size_t(r)], 1);
  done.wait(epoch_);  // claimed: a thread is at it
}

template <class Real>
CorrectSums Stepper<Real>::correct_range(int32_t begin, int32_t end) {
  if (begin >= end) return CorrectSums{};
  const Model<Real>& m = model_;
  State<Real>& s = *cur_;
  CorrectArgs<Real> args{};
  args.begin = begin;
  args.end = end;
  args.dt = cur_dt_;
  args.f = f_.data();
  args.group_begin = plan_.group_begin.data();
  args.group_offset = plan_.group_offset.data();
  args.inv_m = m.inv_m.data();
  args.m = m.m.data();
  for (int k = 0; k < 3; ++k) args.g[k] = Real(m.effects.g[k]);
  args.alpha = Real(m.effects.alpha);
  args.u = s.u.data();
  args.v = s.v.data();
  args.a = s.a.data();
  return correct_(args);
}

template <class Real>
void Stepper<Real>::correct_part(void* ctx, int32_t p) {
  auto* self = static_cast<Stepper*>(ctx);
  const Part& part = self->plan_.parts[size_t(p)];
  self->correct_sums_[size_t(p)] = self->correct_range(part.node_begin, part.node_end);
}

template <class Real>
void Stepper<Real>::apply_essential_positions(State<Real>& s, double t, size_t begin, size_t end) {
  // Essential BCs set displacement and velocity directly, section 4.1.
  for (size_t k = begin; k < end; ++k) {
    const EssentialEntry& entry = plan_.essential_entries[k];
    const EssentialSet& set = model_.essential[size_t(entry.set)];
    const auto i = size_t(entry.node), c = size_t(entry.c);
    const Vec3& X = model_.mesh.X[i];
    const Kinematics kin = set.moving ? compute_bc_kinematics(set.spec, X, t) : Kinematics{X, Vec3(0.0), Vec3(0.0)};
    const Vec3 u = kin.x - X;
    for (int d = 0; d < 3; ++d) {
      s.u[3 * i + size_t(d)] = Real(u[d]);
      u4_[i].v[d] = Real(u[d]);  // the element pass's copy
      v_prescribed_[3 * c + size_t(d)] = Real(kin.v[d]);
      a_prescribed_[3 * c + size_t(d)] = Real(kin.a[d]);
    }
  }
}

template <class Real>
void Stepper<Real>::ensure_predicted(int32_t q) {
  run_once(predicted_[size_t(q)], epoch_, [&] {
    const Part& part = plan_.parts[size_t(q)];
    State<Real>& s = *cur_;
    kernels_.predict(part.node_begin, part.node_end, cur_dt_, s.u.data(), s.v.data(), s.a.data(), u4_.data());
    apply_essential_positions(s, cur_t1_, part.essential_begin, part.essential_end);
  });
}

template <class Real>
void Stepper<Real>::apply_essential_rates(State<Real>& s, double t, double dt) {
  (void)t;
  // The corrector computed a from the forces alone; the constraint supplies
  // the difference: r = m (a_prescribed - a) (1 + alpha dt / 2), eq. (10).
  const double q = model_.effects.damping ? 1.0 + 0.5 * model_.effects.alpha * dt : 1.0;
  double work = 0, mv2_delta = 0, ma2_delta = 0;
  size_t c = 0;
  for (const EssentialSet& set : model_.essential) {
    for (int32_t i : set.nodes) {
      const size_t j = 3 * size_t(i);
      const double m = double(model_.m[size_t(i)]);
      const Vec3& u0 = u_before_[c];
      for (int d = 0; d < 3; ++d) {
        const double v_free = double(s.v[j + size_t(d)]), v_held = double(v_prescribed_[3 * c + size_t(d)]);
        mv2_delta += m * (v_held * v_held - v_free * v_free);
        const double a_free = double(s.a[j + size_t(d)]), a_held = double(a_prescribed_[3 * c + size_t(d)]);
        ma2_delta += m * (a_held * a_held - a_free * a_free);
        const double r_new = m * (double(a_prescribed_[3 * c + size_t(d)]) - double(s.a[j + size_t(d)])) * q;
        const double r_old = double(s.reaction[3 * c + size_t(d)]);  // set at t_0 by apply_initial_acceleration
        work += 0.5 * (r_old + r_new) * (double(s.u[j + size_t(d)]) - u0[d]);  // trapezoid
        s.reaction[3 * c + size_t(d)] = Real(r_new);
        s.v[j + size_t(d)] = v_prescribed_[3 * c + size_t(d)];
        s.a[j + size_t(d)] = a_prescribed_[3 * c + size_t(d)];
      }
      ++c;
    }
  }
  s.work_essential += work;
  essential_mv2_delta_ = mv2_delta;
  essential_ma2_delta_ = ma2_delta;
}

template <class Real>
void Stepper<Real>::add_load_force(int32_t node, const Vec3& force) {
  // Into the first region that holds the node: the corrector reads it there.
  for (const Region& r : plan_.regions) {
    if (node < r.begin || node >= r.end) continue;
    Real* f = f_[size_t(r.offset + node)].v;
    for (int d = 0; d < 3; ++d) f[d] += Real(force[d]);
    return;
  }
}

template <class Real>
void Stepper<Real>::apply_loads(State<Real>& s, double t) {
  double work = 0;
  size_t c = 0;
  for (const LoadSet& load : model_.loads) {
    const double scale = load.spec.scale ? compute_profile(*load.spec.scale, t).s : 1.0;
    for (size_t k = 0; k < load.nodes.size(); ++k, ++c) {
      const size_t j = 3 * size_t(load.nodes[k]);
      const Vec3 force = load.spec.force * (scale * load.weight[k]);
      const Vec3& u0 = u_before_[model_.constrained.size() + c];
      add_load_force(load.nodes[k], force);
      for (int d = 0; d < 3; ++d)  // trapezoid over the step
        work += 0.5 * (s.energy.load_force[c][d] + force[d]) * (double(s.u[j + size_t(d)]) - u0[d]);
      s.energy.load_force[c] = force;
    }
  }
  s.work_loads += work;
}

template <class Real>
void Stepper<Real>::apply_initial_acceleration(State<Real>& s) {
  // Newmark starts from an acceleration consistent with the forces, eq. (1):
  // M a_0 = F_0 - R(u_0) - D v_0. The corrector with dt = 0 computes exactly
  // that and leaves v alone.
  cur_ = &s;
  cur_dt_ = Real(0);
  if (!model_.essential.empty()) apply_essential_positions(s, s.t, 0, plan_.essential_entries.size());
  run_parts(&Stepper::pad_part, this);  // no predictor has written u4_
  run_elastic();
  if (!model_.loads.empty()) {
    size_t c = 0;
    for (const LoadSet& load : model_.loads) {
      for (size_t k = 0; k < load.nodes.size(); ++k, ++c) add_load_force(load.nodes[k], s.energy.load_force[c]);
    }
  }
  run_parts(&Stepper::correct_part, this);
  double ma2 = 0;
  for (int32_t p = 0; p < n_parts_; ++p) ma2 += correct_sums_[size_t(p)].ma2;
  // Constrained nodes follow their motion; the constraint supplies the rest.
  size_t c = 0;
  for (const EssentialSet& set : model_.essential) {
    for (int32_t i : set.nodes) {
      const size_t j = 3 * size_t(i);
      const double m = double(model_.m[size_t(i)]);
      for (size_t d = 0; d < 3; ++d) {
        const double a_held = double(a_prescribed_[3 * c + d]), a_free = double(s.a[j + d]);
        ma2 += m * (a_held * a_held - a_free * a_free);
        s.reaction[3 * c + d] = Real(m * (a_held - a_free));
        s.v[j + d] = v_prescribed_[3 * c + d];
        s.a[j + d] = a_prescribed_[3 * c + d];
      }
      ++c;
    }
  }
  s.energy.initial_ma2 = ma2;
}

template <class Real>
Fault Stepper<Real>::step(State<Real>& s, double dt) {
  if (s.fault) return s.fault;
  if (!(dt > 0) || !std::isfinite(dt))
    return make_fault(Fault::Kind::StepTooLarge, s, "time step must be finite and > 0, got " + std::to_string(dt), {});
  cur_ = &s;
  cur_dt_ = Real(dt);
  cur_t1_ = s.t + dt;
  const double dt_before = s.energy.open ? s.energy.dt : dt;  // (the account keeps the step it was measured with)
  open_energy_account(s, dt);
  keep_work_positions(s);
  predict_and_add_elastic_forces(s);           // eq. (7), essential positions, R(u_{n+1})
  correct(s);                                  // F_{n+1}, eqs. (8)-(10), then (9)
  ContactSums contact = apply_contact(s, dt);  // section 5.1
  essential_mv2_delta_ = essential_ma2_delta_ = 0;
  if (!model_.essential.empty()) {
    enter(Pass::Essential);
    apply_essential_rates(s, cur_t1_, dt);
    leave(Pass::Essential);
  }
  if (body_contact_.active()) {  // after the held nodes' velocities are set: they move as prescribed
    enter(Pass::BodyContact);
    const ContactSums between = body_contact_.apply(s, dt, dt_before);
    s.work_contact += between.work;
    contact.mv2_delta += between.mv2_delta;
    contact.ma2_delta += between.ma2_delta;
    leave(Pass::BodyContact);
  }
  enter(Pass::Guard);
  close_energy_account(s, dt, contact);
  const Fault fault = check_step(s);
  leave(Pass::Guard);
  return fault;
}

// The energy account at t_n (core/energy_ledger.hpp): on the first step (or
// after a fault) the reference it is checked against, from an acceleration
// consistent with the forces; on a change of step, the discrete term restated.
template <class Real>
void Stepper<Real>::open_energy_account(State<Real>& s, double dt) {
  if (s.energy.open) {
    restate_energy_account(s, dt);
    return;
  }
  size_t c = 0;  // loads at t_n for the work trapezoid
  for (const LoadSet& load : model_.loads) {
    const double scale = load.spec.scale ? compute_profile(*load.spec.scale, s.t).s : 1.0;
    for (size_t k = 0; k < load.nodes.size(); ++k, ++c)
      s.energy.load_force[c] = load.spec.force * (scale * load.weight[k]);
  }
  apply_initial_acceleration(s);
  contact_.start(s);
  cur_dt_ = Real(dt);
  tactile::open_energy_account(s, compute_energy(s), dt);
}

// Positions at t_n of the nodes whose work is accounted, in the order
// apply_essential_rates and apply_loads read them: set by set, not sorted.
template <class Real>
void Stepper<Real>::keep_work_positions(const State<Real>& s) {
  const size_t nc = model_.constrained.size();
  size_t held = 0;
  for (const EssentialSet& set : model_.essential) {
    for (int32_t i : set.nodes) {
      const size_t j = 3 * size_t(i);
      u_before_[held++] = Vec3(double(s.u[j]), double(s.u[j + 1]), double(s.u[j + 2]));
    }
  }
  for (size_t c = 0; c < loaded_.size(); ++c) {
    const size_t j = 3 * size_t(loaded_[c]);
    u_before_[nc + c] = Vec3(double(s.u[j]), double(s.u[j + 1]), double(s.u[j + 2]));
  }
}

template <class Real>
void Stepper<Real>::predict_and_add_elastic_forces(State<Real>& s) {
  if (n_parts_ == 1) {
    enter(Pass::Predict);
    run_parts(&Stepper::predict_part, this);  // eq. (7)
    leave(Pass::Predict);
    if (!model_.essential.empty()) {
      enter(Pass::Essential);
      apply_essential_positions(s, cur_t1_, 0, plan_.essential_entries.size());
      leave(Pass::Essential);
    }
    enter(Pass::Elastic);
    run_elastic();  // R(u_{n+1})
    leave(Pass::Elastic);
    return;
  }
  // Split over threads, one job per part predicts its nodes (eq. 7), sets
  // its essential positions, adds its elements' forces and, without loads,
  // corrects its nodes (eqs. 8-10), waiting only for what each of those
  // reads (see elastic_part): one hand-off, not one per pass.
  ++epoch_;
  fused_ = true;
  fused_correct_ = model_.loads.empty();  // loads go into the force arrays between the two
  enter(Pass::Elastic);
  run_elastic();
  leave(Pass::Elastic);
  fused_ = false;
}

// The loads and the corrector, unless the element pass corrected already.
template <class Real>
void Stepper<Real>::correct(State<Real>& s) {
  if (!fused_correct_) {
    if (!model_.loads.empty()) {
      enter(Pass::Loads);
      apply_loads(s, cur_t1_);  // F_{n+1}
      leave(Pass::Loads);
    }
    enter(Pass::Correct);
    run_parts(&Stepper::correct_part, this);  // eqs. (8)-(10), then (9)
    leave(Pass::Correct);
  }
  fused_correct_ = false;
}

template <class Real>
ContactSums Stepper<Real>::apply_contact(State<Real>& s, double dt) {
  if (model_.proxies.empty()) return {};
  enter(Pass::Contact);
  const ContactSums sums = contact_.apply(s, s.t, cur_t1_, dt);
  s.work_contact += sums.work;
  s.energy.proxy_given += sums.proxy_work;
  leave(Pass::Contact);
  return sums;
}

// The energies at t_{n+1} from the sums the passes made, and the state's time.
template <class Real>
void Stepper<Real>::close_energy_account(State<Real>& s, double dt, const ContactSums& contact) {
  ElasticSums el;
  CorrectSums co;
  for (const ElasticSums& e : elastic_) {  // in region order, whichever thread filled each
    el.energy += e.energy;
    el.inverted += e.inverted;
  }
  for (int32_t p = 0; p < n_parts_; ++p) {
    co.abs_a += correct_sums_[size_t(p)].abs_a;
    co.mv2 += correct_sums_[size_t(p)].mv2;
    co.mgu += correct_sums_[size_t(p)].mgu;
    co.ma2 += correct_sums_[size_t(p)].ma2;
  }
  step_sums_ = {el, co};
  s.t = cur_t1_;
  ++s.step;
  // The corrector's sums saw the constrained and pushed nodes before the
  // essential BCs and contact changed them; their passes kept the differences.
  StepEnergySums sums;
  sums.elastic = el.energy;
  sums.mv2 = co.mv2 + essential_mv2_delta_ + contact.mv2_delta;
  sums.ma2 = co.ma2 + essential_ma2_delta_ + contact.ma2_delta;
  sums.mgu = co.mgu;
  tactile::close_energy_account(s, sums, dt, model_.effects.damping ? model_.effects.alpha : 0.0);
}

// The guard: non-finite values, inverted elements a model cannot take, and
// energy growth beyond the work done (or a runaway past the critical step).
template <class Real>
Fault Stepper<Real>::check_step(State<Real>& s) {
  const ElasticSums& el = step_sums_.elastic;
  const CorrectSums& co = step_sums_.correct;
  Fault fault;
  if (!std::isfinite(co.abs_a) || !std::isfinite(el.energy)) {
    fault = make_fault(Fault::Kind::NonFinite, s, "non-finite acceleration or energy", find_nonfinite_elements(s));
  } else if (el.inverted > 0) {
    std::vector<int32_t> ids = find_inverted_elements(s);
    // The message first: an argument std::move(ids) may be evaluated before list_ids(ids).
    std::string msg = std::to_string(el.inverted) + " element(s) inverted (det F <= 0), which their material (" +
                      std::string(ids.empty() ? "stvk" : to_string(model_.tet_model[size_t(ids.front())])) +
                      ") cannot recover from: ids " + list_ids(ids);
    fault = make_fault(Fault::Kind::Inverted, s, std::move(msg), std::move(ids));
  } else {
    const EnergyCheck check =
        check_energy_account(s, model_.integrator.energy_tolerance, energy_floor_, model_.integrator.energy_window);
    if (check.verdict != EnergyCheck::Verdict::Ok) {
      std::vector<int32_t> ids = find_top_energy_elements(s, 10);
      std::ostringstream msg;
      if (check.verdict == EnergyCheck::Verdict::Runaway)
        msg << "kinetic + elastic energy grew by " << check.growth - s.energy.latest.discrete << " J, over "
            << EnergyCheck::kRunaway << " times the " << check.given
            << " J the body was given: the step exceeds the critical step; highest strain energy in elements "
            << list_ids(ids);
      else
        msg << "energy grew by " << check.growth << " J beyond the work done (allowed " << check.allowed
            << " J); highest strain energy in elements " << list_ids(ids);
      fault = make_fault(Fault::Kind::EnergyGrowth, s, msg.str(), std::move(ids));
    }
  }
  return fault;
}

template <class Real>
Fault Stepper<Real>::make_fault(Fault::Kind kind, State<Real>& s, std::string message, std::vector<int32_t> elements) {
  s.fault.kind = kind;
  s.fault.step = s.step;
  s.fault.t = s.t;
  s.fault.message = std::move(message);
  s.fault.elements = std::move(elements);
  return s.fault;
}

template <class Real>
void Stepper<Real>::clear_fault(State<Real>& s) const {
  s.fault = Fault{};
  s.energy.open = false;
  s.critical.refreshed_at = -1;
  s.critical.collapsed_since = -1;
}

// Elements squashed nearly flat (a held node driven into a proxy, say) make
// the critical step fall without bound, and advance() would split each
// interval into ever more steps: a run that never ends rather than a fault.
// Below a hundredth of the step at rest for longer than a strike's crush
// lasts, or below a thousandth at all, it is a fault.
template <class Real>
Fault Stepper<Real>::check_collapse(State<Real>& s, double dt_critical) {
  if (!(dt_critical < kCollapsedStep * model_.dt_rest)) {
    s.critical.collapsed_since = -1;
    return {};
  }
  if (s.critical.collapsed_since < 0) s.critical.collapsed_since = s.t;
  const double lasted = s.t - s.critical.collapsed_since;
  if (dt_critical >= kCrushedStep * model_.dt_rest && lasted <= kCollapseGrace) return {};
  std::ostringstream msg;
  msg << "the critical step fell to " << dt_critical << " s, under ";
  if (dt_critical < kCrushedStep * model_.dt_rest)
    msg << kCrushedStep << " of its " << model_.dt_rest << " s at rest";
  else
    msg << kCollapsedStep << " of its " << model_.dt_rest << " s at rest for " << lasted << " s";
  msg << ": elements are squashed nearly flat (a prescribed motion driving the body into a proxy or another body, or "
         "a load it cannot bear?)";
  return make_fault(Fault::Kind::StepTooLarge, s, msg.str(), {});
}

template <class Real>
AdvanceReport Stepper<Real>::advance(State<Real>& s, double frame_dt, const std::function<bool()>& interrupt) {
  AdvanceReport report;
  if (s.fault) {
    report.fault = s.fault;
    return report;
  }
  if (!(frame_dt > 0) || !std::isfinite(frame_dt)) {
    report.fault = make_fault(Fault::Kind::StepTooLarge, s, "frame interval must be finite and > 0", {});
    return report;
  }
  critical_.refresh(s);  // a sixteenth of the body, and the elements contact pushed
  report.dt_critical = s.critical.dt;
  if (Fault f = check_collapse(s, s.critical.dt)) {
    report.fault = std::move(f);
    return report;
  }
  const double fixed = model_.integrator.dt;
  int64_t n = 1;
  if (fixed > 0) {
    n = std::max<int64_t>(1, std::llround(frame_dt / fixed));
    if (frame_dt / double(n) > s.critical.dt) {
      if (model_.integrator.unstable == UnstablePolicy::Refuse) {
        std::ostringstream msg;
        msg << "integrator.dt = " << fixed << " s exceeds the critical step " << s.critical.dt
            << " s of the current configuration; refused (set integrator.unstable to \"subdivide\" to split it)";
        report.fault = make_fault(Fault::Kind::StepTooLarge, s, msg.str(), {});
        return report;
      }
      n = static_cast<int64_t>(std::ceil(frame_dt / (model_.integrator.safety * s.critical.dt)));
      report.subdivided = true;
    }
  } else {
    n = static_cast<int64_t>(std::ceil(frame_dt / (model_.integrator.safety * s.critical.dt)));
  }
  double dt = frame_dt / double(n);
  report.dt = dt;
  double covered = 0;
  for (int64_t k = 0; k < n; ++k) {
    if (Fault f = step(s, dt)) {
      report.fault = std::move(f);
      break;
    }
    ++report.substeps;
    covered += dt;
    if (k + 1 < n && interrupt && interrupt()) {
      report.interrupted = true;
      break;
    }
    // A proxy that squashes the elements under it within the interval: the
    // rest of the interval is split again at their new critical step. (After
    // the last step the next advance() looks, before it plans its steps.)
    if (k + 1 == n || !critical_.contact_pushed(s)) continue;
    const double dc = critical_.compute_contact(s);
    if (dc >= s.critical.dt) continue;
    s.critical.dt = report.dt_critical = dc;
    if (Fault f = check_collapse(s, dc)) {
      report.fault = std::move(f);
      break;
    }
    if (dt <= model_.integrator.safety * dc) continue;
    if (fixed > 0 && model_.integrator.unstable == UnstablePolicy::Refuse) {
      std::ostringstream msg;
      msg << "integrator.dt = " << fixed << " s exceeds the critical step " << dc
          << " s of the elements a proxy squashes; refused (set integrator.unstable to \"subdivide\" to split it)";
      report.fault = make_fault(Fault::Kind::StepTooLarge, s, msg.str(), {});
      break;
    }
    const double rest = frame_dt - covered;
    const int64_t m = static_cast<int64_t>(std::ceil(rest / (model_.integrator.safety * dc)));
    dt = rest / double(m);
    n = k + 1 + m;
    report.dt = std::min(report.dt, dt);
    report.subdivided = report.subdivided || fixed > 0;
  }
  return report;
}

template <class Real>
std::vector<double> Stepper<Real>::compute_element_energy(const State<Real>& s) const {
  std::vector<double> out(size_t(model_.n_tets), 0.0);
  if (model_.mesh.quadratic()) {
    // Element by element in double (core/quadratic.hpp): this is for
    // output and fault reports, not the step, whose kernel sums the energy.
    for (size_t e = 0; e < out.size(); ++e) {
      const P2Element el = make_p2_element(p2_rest_nodes(model_.mesh, e));
      std::array<Vec3, kP2Nodes> x;
      for (int a = 0; a < kP2Nodes; ++a) {
        const auto i = size_t(model_.mesh.node(e, a));
        x[size_t(a)] = model_.mesh.X[i] + Vec3(double(s.u[3 * i]), double(s.u[3 * i + 1]), double(s.u[3 * i + 2]));
      }
      out[e] = compute_p2_forces(el, x, model_.tet_model[e], model_.tet_lambda[e], model_.tet_mu[e], nullptr);
    }
    return out;
  }
  std::vector<double> lane(size_t(kLanes<Real>));
  for (const ElementGroup& g : model_.groups) {
    for (int32_t b = g.begin; b < g.end; ++b) {
      kernels_.energy[int(g.model)](model_.blocks.data(), b, b + 1, Real(g.lambda), Real(g.mu), s.u.data(), lane.data(),
                                    nullptr);
      for (int l = 0; l < kLanes<Real>; ++l) {
        const int32_t e = model_.lane_tet[size_t(b) * kLanes<Real> + size_t(l)];
        if (e >= 0) out[size_t(e)] = lane[size_t(l)];
      }
    }
  }
  return out;
}

template <class Real>
Energy Stepper<Real>::compute_energy(const State<Real>& s) const {
  Energy e;
  for (double x : compute_element_energy(s)) e.elastic += x;
  for (size_t i = 0; i < size_t(model_.n_nodes); ++i) {
    double v2 = 0, gu = 0;
    for (size_t d = 0; d < 3; ++d) {
      v2 += double(s.v[3 * i + d]) * double(s.v[3 * i + d]);
      gu += model_.effects.g[int(d)] * double(s.u[3 * i + d]);
    }
    e.kinetic += 0.5 * double(model_.m[i]) * v2;
    if (model_.effects.gravity) e.gravity -= double(model_.m[i]) * gu;
  }
  e.work_loads = s.work_loads;
  e.work_essential = s.work_essential;
  e.work_contact = s.work_contact;
  e.dissipated = s.dissipated;
  return e;
}

template <class Real>
std::vector<int32_t> Stepper<Real>::find_nonfinite_elements(const State<Real>& s) const {
  // A non-finite value spreads in one step from its node's u to the forces,
  // accelerations and velocities of all its neighbours: the elements with a
  // non-finite corner position are where it entered; failing those (the
  // forces overflowed first), any non-finite corner value.
  std::vector<int32_t> out;
  for (const bool positions_only : {true, false}) {
    for (size_t e = 0; e < size_t(model_.n_tets) && out.size() < 50; ++e) {
      for (int k = 0; k < model_.mesh.nodes_per_tet(); ++k) {
        const int32_t i = model_.mesh.node(e, k);
        bool bad = false;
        for (size_t d = 0; d < 3; ++d) {
          const size_t j = 3 * size_t(i) + d;
          bad |= !std::isfinite(double(s.u[j]));
          if (!positions_only) bad |= !std::isfinite(double(s.v[j])) || !std::isfinite(double(s.a[j]));
        }
        if (bad) {
          out.push_back(int32_t(e));
          break;
        }
      }
    }
    if (!out.empty()) break;
  }
  return out;
}

template <class Real>
std::vector<int32_t> Stepper<Real>::find_inverted_elements(const State<Real>& s) const {
  std::vector<int32_t> out;
  const TetMesh& mesh = model_.mesh;
  for (size_t e = 0; e < size_t(model_.n_tets) && out.size() < 50; ++e) {
    if (can_invert(model_.tet_model[e])) continue;
    if (mesh.quadratic()) {  // det F <= 0 at a quadrature point, as the kernel counts it
      std::array<Vec3, kP2Nodes> x;
      for (int a = 0; a < kP2Nodes; ++a) {
        const auto i = size_t(mesh.node(e, a));
        x[size_t(a)] = mesh.X[i] + Vec3(double(s.u[3 * i]), double(s.u[3 * i + 1]), double(s.u[3 * i + 2]));
      }
      if (!(make_p2_element(x).min_det > 0)) out.push_back(int32_t(e));
      continue;
    }
    const Tet& t = mesh.tets[e];
    Vec3 x[4];
    for (int c = 0; c < 4; ++c) {
      const size_t i = size_t(t[size_t(c)]);
      x[c] = mesh.X[i] + Vec3(double(s.u[3 * i]), double(s.u[3 * i + 1]), double(s.u[3 * i + 2]));
    }
    if (compute_tet_volume(x[0], x[1], x[2], x[3]) <= 0) out.push_back(int32_t(e));
  }
  return out;
}

template <class Real>
std::vector<int32_t> Stepper<Real>::find_top_energy_elements(const State<Real>& s, size_t count) const {
  const std::vector<double> energy = compute_element_energy(s);
  std::vector<int32_t> ids(energy.size());
  std::iota(ids.begin(), ids.end(), 0);
  count = std::min(count, ids.size());
  std::partial_sort(ids.begin(), ids.begin() + long(count), ids.end(), [&](int32_t a, int32_t b) {
    return energy[size_t(a)] / model_.tet_volume[size_t(a)] > energy[size_t(b)] / model_.tet_volume[size_t(b)];
  });
  ids.resize(count);
  return ids;
}

template class Stepper<float>;
template class Stepper<double>;

}  // namespace tactile
