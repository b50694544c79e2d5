// Proxy contact, the paper's way (section 5.1): no penalty springs. A
// surface node inside a proxy whose velocity relative to the proxy points
// into it has that normal relative velocity set to zero,
//   v^_{n+1} = v^ - (v^ . n) n
// (eq. (11) is printed with a `+`; its text and eq. (13) need this sign),
// and its acceleration follows from eq. (9), a_{n+1} = 2 (v_{n+1} - v_half) / dt,
// so that the node's normal offset two steps on equals the one before
// contact (eq. 13): penetration stops growing within two steps. The change of
// acceleration times q = m (1 + alpha dt / 2), eq. (10), is the equivalent
// force on the node; its opposite, summed per proxy, is the force and the
// torque the proxy (and the hand holding it) feels. Bouncing, sticking and
// sliding contacts all take this one path. Coulomb friction, when the scene
// asks for it, uses the same impulse: the tangential relative velocity is
// removed if that takes at most mu times the normal impulse (stick), and
// reduced by mu times it otherwise (slide).
//
// Fast motion: each node is tested along its path relative to the proxy
// over the step (its proxy-frame positions at t_n and t_{n+1}), and a node
// that crossed the surface takes the normal where it crossed. A node deep
// inside keeps the normal it entered with, so a fast proxy never pushes a
// node out through its far side. This costs the same at any speed, where
// sub-stepping would multiply the FEM steps by the speed.
//
// Faces: a proxy smaller than the mesh's cells can press between surface
// nodes with none of them inside it (a thin ball on a coarse plate). Each
// surface triangle near a proxy is tested at its deepest point in the proxy
// (deepest_on_triangle); a point inside, not at a vertex (the node's own
// contact) and on an edge only once (its first triangle's), is an embedded
// contact point x = sum w_i x_i. The same rule holds for it: its normal
// relative velocity is set to zero, by the impulse J = dv / sum_i (w_i^2 / m_i)
// shared out as dv_i = w_i J / m_i over the triangle's free nodes (a node
// under an essential BC takes none: it moves as prescribed). Its momentum
// change is J, and the forces and the proxy's reaction follow as for nodes.
//
// The impulses: per proxy, by projected Gauss-Seidel (Contact::solve), so
// that points sharing nodes (a face and its corner) push no more than they
// need; one proxy's contacts can always be met together.
//
// Broad phase: surface nodes in clusters of 32 (Morton order of rest
// positions), each with a box around its nodes' motion over the step; only
// clusters whose box meets a proxy's swept bounding box are examined node by
// node; surface triangles likewise, in clusters of 32 by their rest
// centroids. A proxy far from the body costs one box test per cluster.
//
// Coupled proxies (core/coupling.hpp): a device's proxy, or its hand, may be
// a rigid body of its own that the device's pose pulls through a spring. Its
// points then take the impulse with the body's mass and inertia in series
// with the nodes' (J = dv / (sum w^2/m + 1/M + |r x n|^2 / I)), the body
// gets -J at the point, and all the points of one body are solved together,
// since each changes the body's velocity that the others see.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include <glm/mat3x3.hpp>

#include "core/coupling.hpp"
#include "core/model.hpp"
#include "core/proxy.hpp"
#include "core/state.hpp"

namespace tactile {

// What a proxy, or a device channel, felt over the latest step. A device's
// report is the sum over the proxies it drives (one proxy, or a hand's),
// never another device's; its torque is about its reference point (its
// hand's or its proxy's position), a proxy's about the proxy's position.
struct ContactReport {
  Vec3 force{0.0};    // on the proxy or device [N] (the reaction of the contact impulses)
  Vec3 torque{0.0};   // [N m]
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
  bool saturated = false;  // the coupling was at its force or torque limit
  Pose target;             // the device's pose the coupling pulled toward at t_{n+1}
  Pose body;               // where its body (hand, or first proxy) was at t_{n+1}
  double coupling_stiffness = 0;  // [N/m]
  double max_force = 0;           // the coupling's saturation [N]
  double max_torque = 0;          // [N m]
};

// What the contact pass changed, for the stepper's energy accounting.
struct ContactSums {
  double work = 0;       // work of the contact forces on the body over the step [J]
  double mv2_delta = 0;  // change of sum m |v|^2 over the nodes it touched
  double ma2_delta = 0;  // and of sum m |a|^2
  double proxy_work = 0; // sum over proxies of |work they did| in the step [J]
};

template <class Real>
class Contact {
 public:
  explicit Contact(const Model<Real>& model);

  int32_t proxies() const { return static_cast<int32_t>(motion_.size()); }
  // A proxy's motion over the coming steps. For a proxy in a hand, prefer
  // set_hand_motion: this moves it alone.
  void set_motion(int32_t proxy, const ProxyMotion& m) { motion_[size_t(proxy)] = m; }
  // Moves a hand's proxies rigidly with it: each keeps its offset from the hand.
  void set_hand_motion(int32_t hand, const ProxyMotion& m);
  const std::vector<DeviceReport>& device_reports() const { return device_reports_; }
  // Starts the impulse sums of every proxy and device report again.
  void clear_impulses();
  const ProxyMotion& motion(int32_t proxy) const { return motion_[size_t(proxy)]; }
  const ProxyMotion& hand_motion(int32_t hand) const { return hand_motion_[size_t(hand)]; }
  const std::vector<ProxyReport>& reports() const { return reports_; }

  // Virtual coupling (core/coupling.hpp). From now on the motion set for the
  // bodies device `device` drives (its hand, or each of its proxies alone) is
  // the device's pose, which pulls each through the coupling resolved from
  // the scene's spec and `limits` (nullptr: the device gives none). A body
  // newly coupled starts where its motion has it at time t, moving with it;
  // coupling a coupled device again changes its coupling only.
  void couple(int32_t device, const DeviceLimits* limits, double t);
  // Back to kinematic: its bodies follow their motion again.
  void release(int32_t device);
  bool coupled(int32_t device) const;
  // The coupling a coupled device's first body runs (nullptr when kinematic).
  const Coupling* coupling(int32_t device) const;
  // Where a proxy or hand is at time t (the latest step's end, for a coupled
  // one, whatever t): its body's pose when coupled, else its motion's.
  Pose proxy_pose(int32_t proxy, double t) const;
  Pose hand_pose(int32_t hand, double t) const;
  // Total momentum of the coupled bodies [N s].
  Vec3 body_momentum() const;
  // A coupled body as another Contact of the same scene can take it over
  // (a model rebuilt with other parameters): its device, the limits it was
  // coupled with, and its motion.
  struct CoupledBody {
    int32_t device, hand, proxy;
    bool has_limits;
    DeviceLimits limits;
    BodyState state;
  };
  std::vector<CoupledBody> coupled_bodies() const;
  // Couples each as it was, at time t, and takes over its motion.
  void take_bodies(const std::vector<CoupledBody>& bodies, double t);

  // Forgets the previous positions and contacts (a new or reset state).
  void start(const State<Real>& s);
  // The contact pass of the step [t0, t1]: after the corrector has written
  // v_{n+1} and a_{n+1}, before the essential BCs overwrite theirs. Returns
  // the work the contact forces did on the body over the step (trapezoid on
  // the nodes' displacements, like the natural loads').
  ContactSums apply(State<Real>& s, double t0, double t1, double dt);
  // Surface nodes the latest apply() pushed (ids into surface_nodes()).
  const std::vector<int32_t>& pushed() const { return touched_prev_; }
  // The free surface nodes contact tests, as node ids.
  const std::vector<int32_t>& surface_nodes() const { return free_nodes_; }
  // Contact points inside proxies in the latest apply(): on surface nodes, and on faces between them.
  int32_t node_contacts() const { return node_contacts_; }
  int32_t face_contacts() const { return face_contacts_; }

  // Per-node contact force for an output that asks (VTU point data), summed
  // only while tracking is on: the impulse q dv each free surface node took
  // (the force of eq. (10) times the step), and the time it was summed over.
  void track_node_impulses(bool on);
  bool tracks_node_impulses() const { return track_nodes_; }
  // Adds the sums since the last take to `impulse` [N s] (n_nodes x 3, model
  // numbering), clears them and returns the time they cover [s].
  double take_node_impulses(std::vector<double>& impulse);

 private:
  struct Memory {
    int32_t proxy = -1;  // proxy it is inside, or -1
    Vec3 normal{0.0};    // outward normal it is pushed along (proxy frame)
  };
  struct Cluster {
    int32_t begin, end;  // range in free_nodes_ (node clusters) or faces_ (face clusters)
    Vec3 lo, hi;         // box around its nodes' motion over the step
  };
  struct Face {
    std::array<int32_t, 3> slot;  // its corners, as slots (below)
    uint8_t owns_edge = 0;        // bit c: the contacts on the edge opposite corner c are this face's
  };
  // A contact point inside a proxy at t_{n+1}: a free surface node, or a
  // point of a face, x = sum w_c x_c over its corners.
  struct Point {
    int32_t proxy;
    int32_t body;                 // its proxy's coupled body, -1 for a kinematic proxy
    Vec3 r;                       // from the body's origin to x (coupled) [m]
    std::array<int32_t, 3> slot;  // its free corners' slots, -1 for none (a node: slot[0] alone, weight 1)
    Vec3 w;                       // their weights
    Vec3 x;                       // world position [m]
    Vec3 n;                       // outward normal (world)
    Vec3 vp;                      // the proxy's velocity at x [m/s]
    Vec3 v_held;                  // velocity its held corners give it (sum w_c v_c) [m/s]
    double inv_mass;              // sum w_c^2 / m_c over its free corners [1/kg]
    double mu;                    // Coulomb friction coefficient, 0 without
    double jn = 0;                // normal impulse given so far [N s] (never negative)
    Vec3 jt{0.0};                 // tangential impulse so far (|jt| <= mu jn)
  };
  void find_node_contact(int32_t k, int32_t proxy, const Pose& p0, const Pose& p1);
  void find_face_contact(int32_t f, int32_t proxy, const Pose& p0, const Pose& p1, double dt);
  // Which way is out of the proxy, for a point at q1 (proxy frame at t_{n+1}) that was at q0 (at t_n).
  Vec3 outward(const ProxyGeometry& g, const Vec3& q0, const Vec3& q1, const SurfacePoint& at1, Memory& mem,
               int32_t proxy) const;
  // Projected Gauss-Seidel over the points: the impulses that leave no
  // point moving into its proxy, with friction bounded by mu times the
  // normal impulse, as velocity changes per free slot (dv_).
  void solve(const State<Real>& s);
  Vec3 point_velocity(const State<Real>& s, const Point& c) const;
  void give(Point& c, const Vec3& J);
  // A coupled body: a hand (hand >= 0) or one proxy.
  struct Body {
    int32_t device = -1, hand = -1, proxy = -1;
    bool has_limits = false;
    DeviceLimits limits;         // what its device said (when has_limits)
    Coupling c;
    BodyState now, next;         // at t_n, and over the step under way
    Vec3 v_free{0.0}, w_free{0.0};  // next's velocities before contact
    CouplingWrench wrench;       // the coupling on the body at t_{n+1}
    CouplingWrench previous;     // and at t_n
    Pose target;                 // the device's pose at t_{n+1}
    Vec3 previous_target{0.0};   // its position at t_n [m]
  };
  // The proxy's velocity at c.x: its body's, as the solve has it so far, or its motion's.
  Vec3 proxy_velocity(const Point& c) const;
  // A hand's or a proxy's pose composed with a proxy's offset in it.
  Pose body_proxy_pose(const Body& b, const Pose& body_pose, int32_t proxy) const;

  const Model<Real>& model_;
  std::vector<ProxyMotion> motion_;
  std::vector<ProxyReport> reports_;
  std::vector<DeviceReport> device_reports_;
  std::vector<ProxyMotion> hand_motion_;  // per hand (its position is the torque reference)
  // Slots: the surface nodes, the free ones first (in Morton order; slot k
  // of a free node is its index in free_nodes_), then those under an
  // essential BC (faces' corners, never pushed).
  std::vector<int32_t> slot_node_;  // node id per slot
  std::vector<int32_t> free_nodes_; // the first free_count slots' nodes
  std::vector<Cluster> clusters_;   // of free nodes
  std::vector<Face> faces_;         // surface triangles with a free corner, in Morton order of rest centroids
  std::vector<Cluster> face_clusters_;
  std::vector<int32_t> face_cluster_slots_, face_cluster_slot_begin_;  // each face cluster's corners, once each
  std::vector<Vec3> x_prev_;      // world position at t_n per slot [m]
  std::vector<Vec3> x_now_;       // and at t_{n+1}
  std::vector<Vec3> f_prev_;      // contact force on the free node over the previous step [N]
  std::vector<Vec3> f_now_;       // and over this one
  std::vector<int32_t> touched_prev_, touched_now_;  // free slots with a force in those steps
  std::vector<Point> points_;        // this step's contact points
  std::vector<int32_t> point_order_; // their indices, by proxy
  std::vector<int32_t> proxy_begin_, proxy_fill_;  // per proxy: its range in point_order_
  std::vector<Vec3> dv_;             // velocity change per free slot, this step [m/s]
  std::vector<int32_t> moved_;       // free slots given a dv_ this step
  std::vector<uint8_t> moved_flag_;  // per free slot: in moved_
  std::vector<Memory> memory_;       // per free node
  std::vector<Memory> face_memory_;  // per face
  int32_t node_contacts_ = 0, face_contacts_ = 0;
  std::vector<Pose> pose0_, pose1_;  // per proxy at t_n and t_{n+1}
  std::vector<Vec3> velocity_, spin_;  // per proxy over the step: velocity [m/s], angular velocity [rad/s]
  std::vector<Vec3> lo_, hi_;        // per proxy: box its bounding sphere sweeps over the step
  // Secant fit of the stiffness per proxy: exponentially weighted sums of
  // dF dx^T and dx dx^T over the steps the proxy moved in contact.
  // The stiffness fit works on segments of an even number of steps over
  // which the proxy moved a little (kFitMinMotion): their mean force and
  // mean position. Per step, the force pulses with the contact's bounce
  // (often every other step) while the proxy moves micrometres, and dF/dx
  // from single steps is that noise over nearly nothing.
  struct Fit {
    glm::dmat3 fx{0.0}, xx{0.0};
    Vec3 last_position{0.0}, last_force{0.0};  // the latest closed segment's means
    bool has_last = false;
    Vec3 seg_impulse{0.0}, seg_moment{0.0}, seg_start{0.0};  // the open segment: sum F dt, sum x dt, x at its start
    double seg_time = 0;
    int32_t seg_steps = 0;
    int32_t idle = 0;  // steps since the proxy last touched
  };
  // Adds one step (the proxy or device at `position`, under `force`) to the
  // fit; where a segment closes with motion, sets `stiffness` to the fit.
  enum class FitWindow { Proxy, Device };  // segments of kFitMinMotion; of kDeviceFitMinTime and kDeviceFitMinMotion
  static void fit_stiffness(Fit& f, FitWindow window, const Vec3& position, const Vec3& force, double dt,
                            glm::dmat3& stiffness);
  std::vector<Fit> fit_;
  // Per device: the fit of a coupled device's force against its own pose,
  // and the stiffness it gives (kept between steps: the device feels it
  // whether or not its proxy touches at this step).
  std::vector<Fit> device_fit_;
  std::vector<glm::dmat3> device_felt_;
  std::vector<Body> bodies_;
  std::vector<int32_t> proxy_body_;  // per proxy: its body in bodies_, -1 when kinematic (n_proxies)
  double alpha_ = 0;  // Rayleigh mass damping [1/s], for q = m (1 + alpha dt / 2)
  bool friction_ = false;
  bool track_nodes_ = false;
  std::vector<Vec3> node_impulse_;      // per free slot, while tracking [N s]
  std::vector<int32_t> impulse_slots_;  // free slots with a nonzero node_impulse_
  double node_elapsed_ = 0;             // [s]
};

}  // namespace tactile
