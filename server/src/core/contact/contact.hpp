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
// The impulses: per proxy, by projected Gauss-Seidel (ImpulseSolve,
// core/contact/impulse_solve.hpp), so that points sharing nodes (a face and
// its corner) push no more than they need; one proxy's contacts can always be
// met together. The stiffness each proxy and device feels is fitted to the
// forces of the latest steps (core/contact/stiffness_fit.hpp).
//
// An embedded surface (core/embedding.hpp), when the model has one, is what
// proxies meet instead of the boundary: each of its vertices inside a proxy
// is a contact point x = sum w_k x_k over the four nodes of its tet (interior
// nodes too), given its impulse by the same rule as a face's point, dv_k =
// w_k J / m_k, and its opposite summed back to the proxy. A tool smaller than
// a coarse cell then stops at the surface the user sees. Its triangles are
// tested as the boundary's are, at their deepest point in the proxy (where a
// vertex is inside too: deeper than it by a tenth of their size): a small tool
// pressed deep stretches the triangles around it (on quadratic tets, several
// times their rest size) and would pass between their vertices. Such a point
// is sum_j b_j x_j over the triangle's vertices, so sum_j b_j w_jk over up to
// twelve nodes (kPointCarriers), each node once.
//
// Broad phase (ClusterSet, core/contact/cluster_set.hpp): surface nodes in
// clusters of 32 (Morton order of rest positions), each with a box around its
// nodes' motion over the step; only
// clusters whose box meets a proxy's swept bounding box are examined node by
// node; surface triangles likewise, in clusters of 32 by their rest
// centroids. A proxy far from the body costs one box test per cluster. An
// embedded surface's vertices and triangles are in clusters of 128, each in
// groups of 8, whose boxes are kept between steps in the ContactState: grown
// each step by the largest move of any node, refitted to their vertices
// when they have grown by half a percent of the body's size and meet a proxy.
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

#include "core/contact/cluster_set.hpp"
#include "core/contact/impulse_solve.hpp"
#include "core/contact/stiffness_fit.hpp"
#include "core/coupling.hpp"
#include "core/model.hpp"
#include "core/proxy.hpp"
#include "core/state.hpp"

namespace tactile {

// What the contact pass changed, for the stepper's energy accounting.
struct ContactSums {
  double work = 0;        // work of the contact forces on the body over the step [J]
  double mv2_delta = 0;   // change of sum m |v|^2 over the nodes it touched
  double ma2_delta = 0;   // and of sum m |a|^2
  double proxy_work = 0;  // sum over proxies of |work they did| in the step [J]
};

// The contact pass. It holds what it derives from the model (the surface
// slots, their clusters, the faces) and a per-step workspace; all it carries
// from one step to the next is in the State's ContactState, which its
// methods take.
template <class Real>
class Contact {
 public:
  explicit Contact(const Model<Real>& model);

  // Sizes a new state's contact part: every proxy and hand held at its
  // scene pose, no body coupled, no memory.
  void init(ContactState& cs) const;

  int32_t proxies() const { return static_cast<int32_t>(model_.proxies.size()); }
  // A proxy's motion over the coming steps. For a proxy in a hand, prefer
  // set_hand_motion: this moves it alone.
  void set_motion(State<Real>& s, int32_t proxy, const ProxyMotion& m) const { s.contact.motion[size_t(proxy)] = m; }
  // Moves a hand's proxies rigidly with it: each keeps its offset from the hand.
  void set_hand_motion(State<Real>& s, int32_t hand, const ProxyMotion& m) const;

  // Virtual coupling (core/coupling.hpp). From now on the motion set for the
  // bodies device `device` drives (its hand, or each of its proxies alone) is
  // the device's pose, which pulls each through the coupling resolved from
  // the scene's spec and `limits` (nullptr: the device gives none). A body
  // newly coupled starts where its motion has it at s.t, moving with it;
  // coupling a coupled device again changes its coupling only.
  void couple(State<Real>& s, int32_t device, const DeviceLimits* limits) const;
  // Back to kinematic: its bodies follow their motion again.
  void release(State<Real>& s, int32_t device) const;
  // Where a proxy or hand is at s.t (the latest step's end, for a coupled
  // one): its body's pose when coupled, else its motion's.
  Pose proxy_pose(const State<Real>& s, int32_t proxy) const;
  Pose hand_pose(const State<Real>& s, int32_t hand) const;
  // Couples each body as another state of the same scene had it (a model
  // rebuilt with other parameters): its coupling resolved again from this
  // model's scene, its motion taken over.
  void take_bodies(State<Real>& s, const std::vector<CoupledBodyState>& bodies) const;

  // Forgets the previous positions and contacts (a new or reset state).
  void start(State<Real>& s) const;
  // The contact pass of the step [t0, t1]: after the corrector has written
  // v_{n+1} and a_{n+1}, before the essential BCs overwrite theirs. Returns
  // the work the contact forces did on the body over the step (trapezoid on
  // the nodes' displacements, like the natural loads').
  ContactSums apply(State<Real>& s, double t0, double t1, double dt);
  // The free surface nodes contact tests, as node ids; s.contact.pushed
  // holds indices into it.
  const std::vector<int32_t>& surface_nodes() const { return free_nodes_; }
  // Contact points inside proxies in the latest apply(): on surface nodes, and on faces between them.
  int32_t node_contacts() const { return node_contacts_; }
  int32_t face_contacts() const { return face_contacts_; }
  int32_t embedded_contacts() const { return embedded_contacts_; }  // on the embedded surface's vertices and triangles

  // Per-node contact force for an output that asks (VTU point data), summed
  // only while tracking is on: the impulse q dv each free surface node took
  // (the force of eq. (10) times the step), and the time it was summed over.
  void track_node_impulses(State<Real>& s, bool on) const;
  // Adds the sums since the last take to `impulse` [N s] (n_nodes x 3, model
  // numbering), clears them and returns the time they cover [s].
  double take_node_impulses(State<Real>& s, std::vector<double>& impulse) const;

 private:
  struct Face {
    std::array<int32_t, 3> slot;  // its corners, as slots (below)
    uint8_t owns_edge = 0;        // bit c: the contacts on the edge opposite corner c are this face's
  };
  // A contact point (core/contact/impulse_solve.hpp); its slots are this pass's.
  using Point = ContactPoint;
  using Body = CoupledBodyState;
  using Memory = ContactMemory;
  using Fit = StiffnessFit;
  void find_node_contact(ContactState& cs, int32_t k, int32_t proxy, const Pose& p0, const Pose& p1);
  void find_face_contact(ContactState& cs, int32_t f, int32_t proxy, const Pose& p0, const Pose& p1, double dt);
  void find_embedded_contact(ContactState& cs, int32_t e, int32_t proxy, const Pose& p0, const Pose& p1, double dt);
  void find_embedded_face_contact(ContactState& cs, int32_t f, int32_t proxy, const Pose& p0, const Pose& p1,
                                  double dt);
  // A point with no corners yet.
  static Point empty_point(int32_t proxy, int32_t body);
  // Where a triangle (corners q in the proxy's frame at t_{n+1}, phi their
  // distances out of it) is deepest in the proxy: its barycentric
  // coordinates b, the point q and its place on the proxy. False where the
  // triangle needs no point of its own (all inside, deepest at a corner, or
  // on an edge another triangle owns) or misses the proxy (then its memory
  // of this proxy is dropped). For the boundary's faces and an embedded
  // surface's triangles alike.
  struct TrianglePoint {
    Vec3 b, q;
    SurfacePoint at;
  };
  static bool triangle_point(const ProxyGeometry& g, const std::array<Vec3, 3>& q, const std::array<double, 3>& phi,
                             uint8_t owns_edge, Memory& mem, int32_t proxy, TrianglePoint& out);
  // A corner of a face's or an embedded vertex's point, of weight w: a free
  // node takes its share of the impulse, a held one moves as prescribed.
  void add_corner(const ContactState& cs, Point& c, int& free, size_t slot, double w, double dt) const;
  // Triangles (as slots or embedded vertices) as faces, in `order`: an edge's
  // contacts belong to the first face in that order that has it.
  static std::vector<Face> claim_edges(const std::vector<Tri>& tris, const std::vector<size_t>& order);
  // The constructor's two ways: the embedded surface's vertices, or the boundary's nodes and faces.
  template <class Order>
  void build_embedded(const std::vector<int32_t>& slot_of, const Order& morton_order);
  template <class Order>
  void build_boundary(const std::vector<int32_t>& slot_of, const Order& morton_order);
  // Which way is out of the proxy, for a point at q1 (proxy frame at t_{n+1}) that was at q0 (at t_n).
  Vec3 outward(const ProxyGeometry& g, const Vec3& q0, const Vec3& q1, const SurfacePoint& at1, Memory& mem,
               int32_t proxy) const;
  // apply()'s passes, in order. Clears the proxies' and devices' reports of
  // the step before (a device keeps its impulse sums).
  void begin_reports(ContactState& cs, double dt);
  // Each slot's position at t_{n+1} (x_now_) and the boxes around the node
  // and face clusters' motion over the step; returns the largest move of any
  // slot (with an embedded surface, else 0) [m].
  double sweep_slots(const State<Real>& s);
  // The coupled bodies' prediction and coupling, then each proxy's poses at
  // t_n and t_{n+1}, velocity, and the box it sweeps (pose0_, pose1_, lo_, hi_).
  void move_proxies(ContactState& cs, double t0, double t1, double dt);
  // The step's contact points (points_): the nodes' and faces' near each
  // proxy, or the embedded surface's vertices' and triangles'.
  void find_points(ContactState& cs, double largest_move, double dt);
  // Their impulses (ImpulseSolve) on the free slots' velocities and masses:
  // solve_.moved() and solve_.dv() hold the velocity changes.
  void solve(State<Real>& s);
  // The changes into the nodes' velocities and accelerations (eq. 9) and the
  // bodies', and the contact forces into the proxies' reports.
  void apply_impulses(State<Real>& s, double dt, ContactSums& sums);
  // The contact forces' work over the step (trapezoid); this step's
  // positions and forces become the previous.
  void close_step(ContactState& cs, ContactSums& sums);
  // The proxies' and devices' reports: stiffness fits, and per device its
  // proxies' sums or its coupling's force.
  void report(ContactState& cs, double t1, double dt);
  // A hand's or a proxy's pose composed with a proxy's offset in it.
  Pose body_proxy_pose(const Body& b, const Pose& body_pose, int32_t proxy) const;
  // Which body each proxy belongs to, after `bodies` changed.
  void index_bodies(ContactState& cs) const;

  const Model<Real>& model_;
  // Slots: the surface nodes, the free ones first (in Morton order; slot k
  // of a free node is its index in free_nodes_), then those under an
  // essential BC (faces' corners, never pushed).
  std::vector<int32_t> slot_node_;   // node id per slot
  std::vector<int32_t> free_nodes_;  // the first free_count slots' nodes
  ClusterSet node_clusters_;         // of free slots, 32 a cluster (one group), their boxes fitted each step
  std::vector<Face> faces_;          // surface triangles with a free corner, in Morton order of rest centroids
  ClusterSet face_clusters_;         // of faces, likewise, over their corners
  // Items of the embedded surface (vertices, or triangles) in clusters of
  // 128, each in groups of 8: a cluster's box is its groups', a group's its
  // items' vertices'. A cluster near a proxy has its groups tested, a group
  // near it its items.
  static constexpr int32_t kEmbeddedClusterItems = 128, kGroupItems = 8;
  // Per cluster of an embedded set: the most sum_k |w_k| of its vertices,
  // how much farther than a node a vertex can move.
  std::vector<double> embedded_gain(const ClusterSet& set) const;
  // Sets each cluster's box for the step: its box at its last refit (first,
  // first_group: its clusters' and groups' indices in cs.embedded_lo and
  // cs.embedded_group_lo), grown by the drift since; refits one that has
  // drifted refit_drift_ and meets a proxy's box.
  void sweep_embedded(ClusterSet& ec, const std::vector<double>& gain, ContactState& cs, size_t first,
                      size_t first_group);
  // The embedded surface's vertices (instead of nodes and faces), in Morton
  // order of their rest positions: each one's four slots and weights; its
  // triangles in Morton order of their rest centroids, as those vertices,
  // with the edges whose contacts are theirs (Face::owns_edge).
  std::vector<std::array<int32_t, 4>> emb_slot_;
  std::vector<std::array<double, 4>> emb_w_;
  ClusterSet emb_vertices_;
  std::vector<double> emb_vertex_gain_;
  std::vector<Face> emb_faces_;  // (slot: its vertices, in emb_slot_'s order)
  // A triangle with a vertex inside the proxy has its point added where it
  // is deeper than that vertex by more than this fraction of its longest
  // edge at rest: short of that, the vertex's contact holds it within a
  // tenth of its size (as the vertices alone did), and a point on every
  // triangle of a held press would only slow the solve, each sharing its
  // nodes with its vertices' points.
  static constexpr double kEmbeddedFaceSlack = 0.1;
  std::vector<double> emb_face_slack_;  // per triangle [m]
  ClusterSet emb_face_clusters_;
  std::vector<double> emb_face_gain_;
  // Each vertex's positions at t_n and t_{n+1}, worked out once in a step
  // (when emb_stamp_ is the step's) for its own test and its triangles'.
  std::vector<std::array<Vec3, 2>> emb_x_;
  std::vector<uint32_t> emb_stamp_;
  uint32_t stamp_ = 0;
  // The drift past which a cluster's box is refitted [m]: each step grows
  // the boxes by the largest move of any slot, so that they need their
  // vertices only now and then, and only near a proxy (embedding_bench
  // guards this).
  double refit_drift_ = 0;
  const std::array<Vec3, 2>& embedded_position(const ContactState& cs, size_t v);
  // Workspace of one step.
  std::vector<Vec3> x_now_;           // world position at t_{n+1} per slot [m]
  std::vector<Vec3> f_now_;           // contact force on each free slot over this step [N]
  std::vector<int32_t> touched_now_;  // free slots with a force in this step
  std::vector<Point> points_;         // this step's contact points
  ImpulseSolve solve_;                // their impulses
  std::vector<Vec3> slot_v_;          // per free slot: its velocity before contact [m/s]
  std::vector<double> slot_m_;        // and its mass [kg], the model's
  int32_t node_contacts_ = 0, face_contacts_ = 0, embedded_contacts_ = 0;
  std::vector<Pose> pose0_, pose1_;    // per proxy at t_n and t_{n+1}
  std::vector<Vec3> velocity_, spin_;  // per proxy over the step: velocity [m/s], angular velocity [rad/s]
  std::vector<Vec3> lo_, hi_;          // per proxy: box its bounding sphere sweeps over the step
  double alpha_ = 0;                   // Rayleigh mass damping [1/s], for q = m (1 + alpha dt / 2)
  bool friction_ = false;
};

// (Here, not in a .cpp: the broad phase's refits and the candidate points
// both call it per vertex.)
template <class Real>
inline const std::array<Vec3, 2>& Contact<Real>::embedded_position(const ContactState& cs, size_t v) {
  std::array<Vec3, 2>& x = emb_x_[v];
  if (emb_stamp_[v] == stamp_) return x;
  emb_stamp_[v] = stamp_;
  x = {Vec3(0.0), Vec3(0.0)};
  for (size_t k = 0; k < 4; ++k) {
    x[0] += emb_w_[v][k] * cs.x_prev[size_t(emb_slot_[v][k])];
    x[1] += emb_w_[v][k] * x_now_[size_t(emb_slot_[v][k])];
  }
  return x;
}

}  // namespace tactile
