// What contact reports (core/contact/contact.hpp): per proxy and per device
// channel, the force and torque of the step, the contact points, the
// stiffness felt (core/contact/stiffness_fit.hpp), the impulse sums an
// interval longer than a step reads, and per node, for an output that asks,
// the impulses the contact gave.
#include <glm/geometric.hpp>

#include "core/contact/contact.hpp"

namespace tactile {

template <class Real>
void Contact<Real>::track_node_impulses(State<Real>& s, bool on) const {
  ContactState& cs = s.contact;
  cs.track_nodes = on;
  cs.node_impulse.assign(on ? free_nodes_.size() : 0, Vec3(0.0));
  cs.impulse_slots.clear();
  cs.impulse_slots.reserve(on ? free_nodes_.size() : 0);
  cs.node_elapsed = 0;
}

template <class Real>
double Contact<Real>::take_node_impulses(State<Real>& s, std::vector<double>& impulse) const {
  ContactState& cs = s.contact;
  for (int32_t k : cs.impulse_slots) {
    const size_t i = 3 * size_t(free_nodes_[size_t(k)]);
    for (int c = 0; c < 3; ++c) impulse[i + size_t(c)] += cs.node_impulse[size_t(k)][c];
    cs.node_impulse[size_t(k)] = Vec3(0.0);
  }
  cs.impulse_slots.clear();
  const double elapsed = cs.node_elapsed;
  cs.node_elapsed = 0;
  return elapsed;
}

template <class Real>
void Contact<Real>::begin_reports(ContactState& cs, double dt) {
  if (cs.track_nodes) cs.node_elapsed += dt;
  for (ProxyReport& r : cs.reports) {
    r.force = r.torque = Vec3(0.0);
    r.contacts = 0;
  }
  for (DeviceReport& d : cs.device_reports) {
    const DeviceReport kept = d;
    d = DeviceReport{};  // summed from its proxies below, but for the impulse sums
    d.impulse = kept.impulse;
    d.angular_impulse = kept.angular_impulse;
    d.elapsed = kept.elapsed;
    d.contacts_peak = kept.contacts_peak;
  }
}

template <class Real>
void Contact<Real>::report(ContactState& cs, double t1, double dt) {
  const size_t n_proxies = cs.motion.size();
  // A proxy resting on the body is pushed every other step or so (eq. 13):
  // its fit goes on through steps without contact, their force zero, and
  // ends only when it has not touched for kFitIdleSteps.
  for (size_t j = 0; j < n_proxies; ++j) {
    Fit& f = cs.fit[j];
    f.idle = cs.reports[j].contacts > 0 ? 0 : f.idle + 1;
    if (f.idle > kFitIdleSteps) {
      f = Fit{};
      f.idle = kFitIdleSteps + 1;
      cs.reports[j].stiffness = glm::dmat3(0.0);
    } else {
      fit_stiffness(f, FitWindow::Proxy, pose1_[j].position, cs.reports[j].force, dt, cs.reports[j].stiffness);
    }
  }
  // Per device: its proxies' sums, torques moved to the device's reference point.
  for (size_t j = 0; j < n_proxies; ++j) {
    ProxyReport& r = cs.reports[j];
    r.add_step(dt);
    DeviceReport& d = cs.device_reports[size_t(model_.proxy_device[j])];
    d.contacts += r.contacts;
    d.stiffness += r.stiffness;
    if (cs.proxy_body[j] >= 0) continue;  // the coupling's force below
    const int32_t hand = model_.proxy_hand[j];
    const Vec3 reference = hand >= 0 ? cs.hand_motion[size_t(hand)].at(t1).position : pose1_[j].position;
    d.force += r.force;
    d.torque += r.torque + glm::cross(pose1_[j].position - reference, r.force);
  }
  // A coupled device displays its coupling: the opposite of the coupling's
  // force on its bodies (torques about its first body's origin), and the
  // stiffness it feels (fitted below, from that force and its pose). The force is the
  // mean of the latest two steps', about the mean of the two device poses: a
  // proxy resting on the body is pushed every other step, as a node is (eq.
  // 13), and its coupling's damper answers each push, so the force of one
  // step alternates while the pair's mean is steady.
  for (const Body& b : cs.bodies) {
    DeviceReport& d = cs.device_reports[size_t(b.device)];
    const CouplingWrench w{0.5 * (b.wrench.force + b.previous.force), 0.5 * (b.wrench.torque + b.previous.torque),
                           b.wrench.saturated};
    if (!d.coupled) {
      d.coupled = true;
      d.target = b.target;
      d.target.position = 0.5 * (b.target.position + b.previous_target);
      d.body = b.now.pose;
      d.target_velocity = b.target_velocity;
      d.coupling_stiffness = b.c.stiffness;
      d.coupling_damping = b.c.damping;
      d.max_force = b.c.max_force;
      d.max_torque = b.c.max_torque;
    }
    d.saturated = d.saturated || w.saturated;
    d.force -= w.force;
    d.torque -= w.torque + glm::cross(b.now.pose.position - d.body.position, w.force);
  }
  for (size_t i = 0; i < cs.device_reports.size(); ++i) {
    DeviceReport& d = cs.device_reports[i];
    if (!d.coupled) continue;
    fit_stiffness(cs.device_fit[i], FitWindow::Device, d.target.position, d.force, dt, cs.device_felt[i]);
    // A device feels at most its coupling's own spring (the contact in
    // series with it can only soften it); a fit across a contact's onset
    // can read stiffer, and the bridge would render that.
    d.stiffness = nearest_passive(cs.device_felt[i], d.coupling_stiffness);
  }
  for (DeviceReport& d : cs.device_reports) d.add_step(dt);
}

// The members defined here, for both precisions (contact.cpp instantiates the rest).
#define TACTILE_CONTACT_REPORTS(Real)                                                          \
  template void Contact<Real>::track_node_impulses(State<Real>&, bool) const;                  \
  template double Contact<Real>::take_node_impulses(State<Real>&, std::vector<double>&) const; \
  template void Contact<Real>::begin_reports(ContactState&, double);                           \
  template void Contact<Real>::report(ContactState&, double, double);
TACTILE_CONTACT_REPORTS(float)
TACTILE_CONTACT_REPORTS(double)
#undef TACTILE_CONTACT_REPORTS

}  // namespace tactile
