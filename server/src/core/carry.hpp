// What a body in motion carries into a model rebuilt from the same mesh (a
// controller changed a material, the damping, the precision...): the State's
// fields one by one, each carried or named here as one the new model starts
// afresh, with the reason. In the mesh's node numbering (a model numbers its
// nodes by its element blocks, so two models of one mesh may differ) and in
// double (the two models may differ in precision).
//
// Every field of State and of its ContactState is bound by name below: a
// field added to either fails to compile here until it is carried or said not
// to be (server/tests/core/carry_test.cpp fills every carried field and reads
// it back through a model of the other precision).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/state.hpp"

namespace tactile {

struct Carried {
  std::vector<double> u, v;  // displacement [m], velocity [m/s], mesh order (n_nodes x 3)
  double t = 0;              // simulated time [s]
  int64_t step = 0;
  double work_loads = 0, work_essential = 0, work_contact = 0, dissipated = 0;  // [J]
  std::vector<ProxyMotion> proxy, hand;  // the motions set for them (n_proxies), (n_hands)
  std::vector<CoupledBodyState> bodies;  // the coupled devices' bodies, re-coupled by the new model
};

// `node_given`: the mesh's id of each model node (Model::node_given).
template <class Real>
Carried carry_out(const State<Real>& s, std::span<const int32_t> node_given) {
  [[maybe_unused]] const auto& [u, v, a, t, step, work_loads, work_essential, work_contact, dissipated, reaction,
                                contact, energy, critical, fault] = s;
  // Not carried: a (the first step computes it from u and v), reaction (the
  // first step's), energy (the guard opens a new account: the new model's
  // elastic energy is another), critical (the new model's own estimate),
  // fault (a body at fault is not carried: live/director.cpp starts anew).
  [[maybe_unused]] const auto& [motion, hand_motion, reports, device_reports, bodies, proxy_body, x_prev, f_prev,
                                pushed, memory, face_memory, embedded_memory, embedded_face_memory, embedded_lo,
                                embedded_hi, embedded_group_lo, embedded_group_hi, embedded_refit_at, embedded_drift,
                                fit, device_fit, device_felt, track_nodes, node_impulse, impulse_slots, node_elapsed,
                                body_pushed, body_impulses] = s.contact;
  // Carried: the motions set for the proxies and hands, and the coupled
  // bodies (Contact::take_bodies re-couples them). Not carried: reports and
  // fits (the next step's), proxy_body (made by coupling), the contact
  // memory and previous positions per surface slot (in the old model's slot
  // numbering; a body in contact finds it again in one step), the per-node
  // impulse tracking (an output's, asked again), the forces and impulses
  // between bodies (the new model's first step has none, and starts its
  // solve cold).
  Carried c;
  c.u.resize(u.size());
  c.v.resize(v.size());
  for (size_t i = 0; i < node_given.size(); ++i)
    for (size_t d = 0; d < 3; ++d) {
      c.u[3 * size_t(node_given[i]) + d] = double(u[3 * i + d]);
      c.v[3 * size_t(node_given[i]) + d] = double(v[3 * i + d]);
    }
  c.t = t;
  c.step = step;
  c.work_loads = work_loads;
  c.work_essential = work_essential;
  c.work_contact = work_contact;
  c.dissipated = dissipated;
  c.proxy = motion;
  c.hand = hand_motion;
  c.bodies = bodies;
  return c;
}

// Into a state of the new model (its node count, proxies and hands checked by
// the caller); the bodies are left to Contact::take_bodies.
template <class Real>
void carry_in(const Carried& c, std::span<const int32_t> node_given, State<Real>& s) {
  for (size_t i = 0; i < node_given.size(); ++i)
    for (size_t d = 0; d < 3; ++d) {
      s.u[3 * i + d] = Real(c.u[3 * size_t(node_given[i]) + d]);
      s.v[3 * i + d] = Real(c.v[3 * size_t(node_given[i]) + d]);
    }
  s.t = c.t;
  s.step = c.step;
  s.work_loads = c.work_loads;
  s.work_essential = c.work_essential;
  s.work_contact = c.work_contact;
  s.dissipated = c.dissipated;
  s.contact.motion = c.proxy;
  s.contact.hand_motion = c.hand;
}

}  // namespace tactile
