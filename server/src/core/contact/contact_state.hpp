// What contact carries from one step to the next, as plain data in the State
// (core/state.hpp): the proxies' and hands' motions, the coupled bodies, each
// surface node's and face's memory of the proxy it is inside, the previous
// step's positions and forces for the work trapezoid, the stiffness fits,
// and the reports with their impulse sums. The Contact pass (core/contact/contact.hpp)
// owns only what it derives from the model and its per-step workspace, so
// copying a State copies all a step depends on.
#pragma once

#include <algorithm>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include <glm/mat3x3.hpp>

#include "core/coupling.hpp"
#include "core/proxy.hpp"

namespace tactile {

// What a proxy, or a device channel, felt over the latest step. A device's
// report is the sum over the proxies it drives (one proxy, or a hand's),
// never another device's; its torque is about its reference point (its
// hand's or its proxy's position), a proxy's about the proxy's position.
struct ContactReport {
  Vec3 force{0.0};       // on the proxy or device [N] (the reaction of the contact impulses)
  Vec3 torque{0.0};      // [N m]
  int32_t contacts = 0;  // contact points inside its proxies: surface nodes, and face points between them
  // Local contact stiffness dF/dx of the force with the position [N/m]: per
  // proxy a secant estimate fitted to the latest steps' changes (zero out of
  // contact, and in directions the proxy has not moved along), made
  // symmetric and negative semidefinite, as a passive contact's is (the
  // fit's noise, on a stiff body that rings, is not); per device the sum
  // over its proxies (the hand translated as one).
  glm::dmat3 stiffness{0.0};
  // Sums over the steps since the last clear_impulses(): the mean force over
  // an interval longer than a step (a device tick, an output frame) is
  // impulse / elapsed.
  Vec3 impulse{0.0};          // [N s]
  Vec3 angular_impulse{0.0};  // [N m s]
  double elapsed = 0;         // [s]
  // The most contact points of one step since then: a node resting on a
  // proxy is pushed every other step or so (eq. 13), so the latest step
  // alone may have none.
  int32_t contacts_peak = 0;

  void add_step(double dt) {
    impulse += force * dt;
    angular_impulse += torque * dt;
    elapsed += dt;
    contacts_peak = std::max(contacts_peak, contacts);
  }
  void clear_impulses() {
    impulse = angular_impulse = Vec3(0.0);
    elapsed = 0;
    contacts_peak = 0;
  }
};

struct ProxyReport : ContactReport {
  double work = 0;  // work the proxy has done on the body since the start [J]
};

// A device channel's report. For a coupled device, force and torque are the
// coupling's on the device (what it should display), and stiffness is what
// the device feels through the coupling: dF/dx of that force against the
// device's own position, fitted as a proxy's is (over a few milliseconds:
// between the coupling's alone while the proxy has not yet moved, and the
// coupling in series with the contact once it has).
struct DeviceReport : ContactReport {
  bool coupled = false;
  bool saturated = false;         // the coupling was at its force or torque limit
  Pose target;                    // the device's pose the coupling pulled toward at t_{n+1}
  Pose body;                      // where its body (hand, or first proxy) was at t_{n+1}
  Vec3 target_velocity{0.0};      // the device's velocity the coupling's damper used [m/s]
  double coupling_stiffness = 0;  // [N/m]
  double coupling_damping = 0;    // [N s/m]
  double max_force = 0;           // the coupling's saturation [N]
  double max_torque = 0;          // [N m]
};

// The stiffness fit of a proxy or a coupled device: exponentially weighted
// sums of dF dx^T and dx dx^T over segments of an even number of steps over
// which it moved a little, their mean force and mean position. Per step, the
// force pulses with the contact's bounce (often every other step) while the
// proxy moves micrometres, and dF/dx from single steps is that noise over
// nearly nothing.
struct StiffnessFit {
  glm::dmat3 fx{0.0}, xx{0.0};
  Vec3 last_position{0.0}, last_force{0.0};  // the latest closed segment's means
  bool has_last = false;
  Vec3 seg_impulse{0.0}, seg_moment{0.0}, seg_start{0.0};  // the open segment: sum F dt, sum x dt, x at its start
  double seg_time = 0;
  int32_t seg_steps = 0;
  int32_t idle = 0;  // steps since the proxy last touched
};

// A coupled body (core/coupling.hpp): a hand (hand >= 0) or one proxy.
struct CoupledBodyState {
  int32_t device = -1, hand = -1, proxy = -1;
  bool has_limits = false;
  DeviceLimits limits;  // what its device said (when has_limits)
  Coupling c;
  BodyState now, next;            // at t_n, and over the step under way
  Vec3 v_free{0.0}, w_free{0.0};  // next's velocities before contact
  CouplingWrench wrench;          // the coupling on the body at t_{n+1}
  CouplingWrench previous;        // and at t_n
  Pose target;                    // the device's pose at t_{n+1}
  Vec3 target_velocity{0.0};      // its velocity over the step [m/s]
  Vec3 previous_target{0.0};      // its position at t_n [m]
};

// Which proxy a surface point is inside, and the normal it is pushed along.
struct ContactMemory {
  int32_t proxy = -1;  // proxy it is inside, or -1
  Vec3 normal{0.0};    // outward normal it is pushed along (proxy frame)
};

struct ContactState {
  std::vector<ProxyMotion> motion;           // per proxy, over the coming steps (n_proxies)
  std::vector<ProxyMotion> hand_motion;      // per hand (its position is the torque reference) (n_hands)
  std::vector<ProxyReport> reports;          // what each proxy felt (n_proxies)
  std::vector<DeviceReport> device_reports;  // what each device channel felt (n_devices)
  std::vector<CoupledBodyState> bodies;      // the coupled devices' bodies
  std::vector<int32_t> proxy_body;           // per proxy: its body in `bodies`, -1 when kinematic (n_proxies)

  // Per surface slot (Contact's numbering: the free surface nodes in Morton
  // order, then the held ones) and per face with a free corner.
  std::vector<Vec3> x_prev;                         // world position at t_n per slot [m]
  std::vector<Vec3> f_prev;                         // contact force on each free slot over the previous step [N]
  std::vector<int32_t> pushed;                      // free slots with a force in the latest step
  std::vector<ContactMemory> memory;                // per free slot
  std::vector<ContactMemory> face_memory;           // per face
  std::vector<ContactMemory> embedded_memory;       // per embedded surface vertex (contact's order)
  std::vector<ContactMemory> embedded_face_memory;  // per embedded surface triangle (contact's order)
  // The embedded surface's clusters (its vertices', then its triangles'):
  // each one's box at its last refit (its vertices at both ends of that
  // step), its groups' likewise, and the drift then; the drift is the sum of
  // each step's largest move of any slot since the state started [m], so a
  // box has to grow by the difference (-infinity: refit at the next step).
  std::vector<Vec3> embedded_lo, embedded_hi;
  std::vector<Vec3> embedded_group_lo, embedded_group_hi;
  std::vector<double> embedded_refit_at;
  double embedded_drift = 0;

  std::vector<StiffnessFit> fit;  // per proxy
  // Per device: the fit of a coupled device's force against its own pose,
  // and the stiffness it gives (kept between steps: the device feels it
  // whether or not its proxy touches at this step).
  std::vector<StiffnessFit> device_fit;
  std::vector<glm::dmat3> device_felt;

  // Per-node contact force for an output that asks, summed while on.
  bool track_nodes = false;
  std::vector<Vec3> node_impulse;      // per free slot, while tracking [N s]
  std::vector<int32_t> impulse_slots;  // free slots with a nonzero node_impulse
  double node_elapsed = 0;             // [s]

  // Contact between bodies (core/contact/body_contact.hpp): the nodes it
  // pushed in the latest step and the force on each over it [N], for the
  // next step's work trapezoid.
  std::vector<std::pair<int32_t, Vec3>> body_pushed;
  // And its points' impulses, by point key (2 x the surface vertex in
  // BodyContact's order, + 1 for its second face; ascending), for the next
  // step's warm start.
  struct BodyImpulse {
    int32_t key;
    double jn;  // [N s]
    Vec3 jt;    // [N s]
  };
  std::vector<BodyImpulse> body_impulses;

  // Starts the impulse sums of every proxy and device report again.
  void clear_impulses() {
    for (ProxyReport& r : reports) r.clear_impulses();
    for (DeviceReport& d : device_reports) d.clear_impulses();
  }
  // The coupled body device `device` drives first (nullptr when kinematic).
  const CoupledBodyState* body_of(int32_t device) const {
    for (const CoupledBodyState& b : bodies)
      if (b.device == device) return &b;
    return nullptr;
  }
  bool coupled(int32_t device) const { return body_of(device) != nullptr; }
  // Total momentum of the coupled bodies [N s].
  Vec3 body_momentum() const {
    Vec3 p(0.0);
    for (const CoupledBodyState& b : bodies) p += b.c.mass * b.now.v;
    return p;
  }
};

}  // namespace tactile
