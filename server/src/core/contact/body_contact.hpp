// Contact between bodies, and of a body with itself: the proxies' velocity
// projection (section 5.1, eq. (11)) with both sides deformable. A surface
// vertex of one body that is inside another's surface at t_{n+1}, moving
// into it, has its normal motion relative to the point of the other surface
// it is nearest taken away, by an impulse J n on the vertex's nodes and -J n
// on the triangle's, shared by their effective masses: one contact point
// whose carriers are the vertex's nodes with weights w_k and the triangle's
// with weights -b_j w_jk, whose velocity is the relative one and whose
// inverse mass is sum w^2 / m over both (ImpulseSolve, with no proxy). Since
// each side's weights sum to one, the momentum one body gains the other
// loses, exactly; the accelerations follow by eq. (9) as for proxies.
// Coulomb friction, when asked, acts in the same impulse.
//
// What is taken away is the relative motion over the next step, the travel
// u = v_{n+1} + dt a_{n+1} / 2 = (x_{n+2} - x_{n+1}) / dt, not v_{n+1}
// itself as for the proxies. A velocity change dv moves u by 2 dv (once
// directly, once through eq. (9)'s 2 dv / dt on a), so zeroing v_{n+1}
// reverses u: the vertex leaves at the speed it came (restitution one over
// the next step), and a resting underside patters, each vertex struck, sent
// off and struck again (BodyContact.ARestingUndersideStaysOnWhatItRestsOn).
// The solve runs on u with each node's half mass, which gives the same
// impulses J and a change 2 dv. It is inelastic in u, and a resting vertex
// stays where it is: its point persists from step to step, so the solve
// starts from the step before's impulses (ContactState::body_impulses,
// scaled by ImpulseSolve::warm_scale) and settles in a few sweeps. (The
// next step is taken as long as the longer of this one and the one before;
// apply() says why.)
//
// Why vertex-face on the surfaces contact meets (the fine surfaces, else
// the boundaries): it is what SOFA's and Bridson et al.'s (2002) deformable
// contact start from, the fine surface is what the user sees touch, and it
// costs one test per vertex near a triangle. Between two bodies it is
// tested both ways at edges and corners, and one way across smooth patches:
// the finer surface's vertices (the slave's) against the coarser's
// triangles (the master's), the master's smooth vertices only where the
// slave's have let them in deeper than the slop (now, or by the end of the
// next step as eq. (7) takes them). Both ways everywhere (the two-pass
// node-to-segment method) over-constrains a resting patch, each point
// nearly a combination of the reverse ones (Puso & Laursen 2004), and the
// projection's sweeps stall there (BodyContact.ARestingPatchSettles-
// WithinItsSweeps; contact_bench --bodies times it). A corner or an edge of
// the master can enter the slave's surface between its vertices, and keeps
// its points. Self contact is tested both ways. Edge-edge contact is left
// out: with both surfaces' edge vertices tested against the other's faces,
// two convex edges can cross between vertices by at most the surfaces'
// cell size.
//
// Found without tunnelling: a vertex counts when it is behind the
// triangle's plane at t_{n+1} over the triangle (its projection inside it)
// and either was in front of it at t_n (it crossed the triangle this step,
// at any depth: a thin body hit fast) or is no deeper than a quarter of the
// triangle's longest edge (it is resting in contact). Positions at t_n
// need no memory: the step's half-step velocity gives them,
// x_n = x_{n+1} - dt (v_{n+1} - dt/2 a_{n+1}), which the velocity
// projection leaves unchanged (it moves a by 2 dv / dt). Of the triangles
// whose projection holds a vertex (or misses it by no more than its depth,
// behind a corner or a rim), the nearest says whether it is inside; one
// outside gets a point only ahead of the crossing (below). A vertex inside
// may get a second point, against a face across a rim of its own (sharing
// a corner, bent by more than about 10 degrees) that the next step would
// take it behind: held on one face only, the sharp corner of one body
// slides along it into the next facet of the other (the stability suite's
// ball_3m_s on quadratic tets guards it).
//
// Stopped short (speculative contact, as rigid-body engines use it): a
// vertex in front of a triangle that the next step, eq. (7) from this
// step's velocity and acceleration, would take behind it by more than the
// slop (effects.body_depth_tolerance, or 1 % of the shortest surface edge)
// is slowed now to arrive at the triangle's plane. It only slows an
// approach, so it adds no energy. A vertex found deeper than the slop is
// sent back toward it, no faster than it came in (apply()); the stability
// suite's body cases (study/stability.hpp) measure the depths left.
//
// Self contact excludes a vertex's own neighbourhood: a triangle of its own
// body whose rest distance from the vertex is under twice its longest edge
// (a face never touches its neighbours, which it meets by construction).
//
// Broad phase: per body, the vertices in Morton order in clusters of 32 and
// the triangles likewise (ClusterSet), in groups of 8. Their boxes are kept
// between steps as the proxies' embedded surface's are (contact.hpp): grown
// each step by how far any vertex can have moved (its body's nodes' largest
// move times the cluster's largest sum_k |w_k|), and refitted to their
// vertices at both ends of the step when they have grown by half a percent
// of the body's size and meet a body they may touch; a vertex's position is
// worked out only there. The pairs are listed with a margin and kept, as
// molecular dynamics keeps its Verlet lists, until a vertex can have moved
// half the margin from where it was then; each step tests the listed pairs
// only. Per pair of bodies, the clusters of each that meet the other's
// whole box are swept and pruned along x, and only the vertex-triangle
// cluster pairs whose boxes meet are tested, group by group, then item by
// item against each triangle's box.
//
// Split over threads (a ParallelFor, as the elastic pass): the nodes' places
// over the step, then the listed vertices' places and triangles' frames,
// then the listed pairs vertex by vertex, each part writing only its own
// vertices' results, gathered in vertex order so that any split gives the
// same points. The listing and the solve stay on one thread.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <vector>

#include "core/contact/cluster_set.hpp"
#include "core/contact/contact.hpp"
#include "core/contact/impulse_solve.hpp"
#include "core/model.hpp"
#include "core/parallel_for.hpp"
#include "core/state.hpp"

namespace tactile {

// Normal impulses summed with their points' positions: sum jn, sum jn x and
// sum jn x x^T (xx, yy, zz, xy, xz, yz) [N s, N s m, N s m^2]. Their ratios
// give a contact's centre of pressure and its spread about it, which, unlike
// the nodes inside the patch, do not come in steps of the surface's spacing
// (the Hertz study reads the contact radius off them).
struct ContactMoments {
  double weight = 0;
  Vec3 first{0.0};
  std::array<double, 6> second{};
  void add(double jn, const Vec3& x) {
    weight += jn;
    first += jn * x;
    const std::array<double, 6> xx = {x.x * x.x, x.y * x.y, x.z * x.z, x.x * x.y, x.x * x.z, x.y * x.z};
    for (size_t i = 0; i < 6; ++i) second[i] += jn * xx[i];
  }
  void add(const ContactMoments& o) {
    weight += o.weight;
    first += o.first;
    for (size_t i = 0; i < 6; ++i) second[i] += o.second[i];
  }
};

template <class Real>
class BodyContact {
 public:
  // Inactive (apply() does nothing) unless the model's effects ask for body
  // or self contact. `parallel` (optional) splits the per-step passes.
  explicit BodyContact(const Model<Real>& model, ParallelFor* parallel = nullptr);
  bool active() const { return active_; }
  // The effect its pass is, as costs name it: body_contact, self_contact, or
  // body_and_self_contact (one pass does both; its cost is not split).
  const char* effect_name() const {
    return between_ && self_ ? "body_and_self_contact" : self_ ? "self_contact" : "body_contact";
  }

  // The pass for the step ending at s.t + dt: after the essential BCs have
  // set their nodes' velocities (held nodes take no impulse; they move as
  // prescribed). Changes v_{n+1} and a_{n+1} of the nodes it pushes; returns
  // what it changed for the energy account and the work of its forces on
  // the bodies over the step (the trapezoid, as the proxies'; the forces of
  // this step are kept in s.contact.body_pushed for the next).
  //
  // `horizon` (>= dt): the step the travel it sets is for, the next one as
  // the stepper expects it (the longer of this step and the one before: a
  // sliver of a step, as an interval ending a hair past a whole number of
  // steps leaves, is followed by a full one). A travel change du over a
  // horizon H is the acceleration change 2 du / (dt + H), which by eq. (9)
  // changes v_{n+1} by dt du / (dt + H): for H = dt, du / dt and du / 2. (Set
  // for a step of dt alone, a sliver's du became an acceleration du / sliver
  // that the full step after it integrated.)
  ContactSums apply(State<Real>& s, double dt, double horizon);
  // Contact points in the latest apply(): between bodies, and within one.
  int32_t body_contacts() const { return body_contacts_; }
  int32_t self_contacts() const { return self_contacts_; }
  // The impulse the latest apply() gave between bodies, to the body of the
  // lower index of each pair, the other taking its opposite [N s]. (By eq.
  // (9) it acts once more through the accelerations it set, over the next
  // half step.)
  const Vec3& exchanged() const { return exchanged_; }
  // The momentum the latest apply() gave each body, sum m dv over its nodes
  // [N s] (per body). Between free nodes these sum to zero to rounding: each
  // point's weights on the two sides sum to one each.
  const std::vector<Vec3>& given() const { return given_; }
  // What the held nodes of the latest apply()'s points would have taken
  // (sum J times their weights) [N s]: the constraint holding them takes it,
  // and given() sums to its opposite.
  const Vec3& held_given() const { return held_given_; }
  // Whether the latest apply()'s projection settled within its sweeps
  // (ImpulseSolve::settled).
  bool settled() const { return solve_.settled(); }
  // The sum of the latest apply()'s points' |J| [N s].
  double impulse_sum() const { return impulse_sum_; }
  // Where the normal impulses between bodies landed since the last take
  // (ContactMoments).
  ContactMoments take_moments() {
    const ContactMoments m = moments_;
    moments_ = ContactMoments{};
    return m;
  }

 private:
  struct Vertex {
    std::array<int32_t, 4> node;  // model ids; -1 past the last
    std::array<double, 4> w;
    int32_t body;
    Vec3 X;  // at rest
  };
  void find(const State<Real>& s, double dt);
  // The per-step passes find() splits over threads, part `p` of each.
  void place_nodes(int32_t p);
  void place_listed(int32_t p);
  void frame_listed(int32_t p);
  void narrow(int32_t p);
  const std::array<Vec3, 3>& vertex_at(int32_t v);
  // A triangle at t_{n+1} (stamped per step): its unit normal n, n . x = off
  // on its plane; per edge k (corner k to k+1) its outward normal in the
  // plane m[k], as long as the edge, m[k] . x = mo[k] along it; one over
  // twice its area. A point's projection is out of edge k by (m[k] . p -
  // mo[k]) / |m[k]|, and its barycentric coordinate of the corner across
  // is (mo[k] - m[k] . p) * inv_area2.
  struct Frame {
    Vec3 n{0.0};
    double off = 0;
    std::array<Vec3, 3> m{};
    std::array<double, 3> mo{};
    double inv_area2 = 0;
    bool valid = false;  // not degenerate
  };
  const Frame& frame(int32_t t);  // placing its corners first
  void make_frame(int32_t t);     // its corners placed
  // How far p's projection on triangle t's plane (at t_{n+1}) lies out of
  // its farthest edge [m]; negative inside (its frame placed).
  double outside_edges(const Vec3& p, int32_t t) const;
  // Whether p's projection on triangle t's plane at t_{n+1} is over the
  // triangle, or out of it by no more than `depth`: over(), from its frame.
  bool over_now(int32_t t, const Vec3& p, double depth, Vec3& b, double& off) const;
  // Whether vertex v lies within triangle t's own neighbourhood at rest (self contact skips it).
  bool near_at_rest(int32_t v, int32_t t) const;
  // A set's kept boxes for this step: grown by how far its vertices can have
  // moved, refitted where that is much and it is near a body it may touch.
  // A triangle set's boxes are grown by its triangles' band as well (`band`,
  // per cluster; empty for vertices).
  void keep_boxes(ClusterSet& set, std::vector<double>& refit_at, const std::vector<double>& gain,
                  const std::vector<double>& band, size_t body);
  // The broad phase: every vertex and triangle whose boxes, the triangle's
  // grown by its band and the margin, meet (candidates_).
  void list_candidates();
  // Lists the candidate pairs of vertex cluster vc of body a and triangle
  // cluster tc of body b.
  void list_pairs(size_t a, size_t vc, size_t b, size_t tc);

  const Model<Real>& model_;
  bool active_ = false;
  bool self_ = false, between_ = false;
  double mu_ = 0;
  double alpha_ = 0;  // Rayleigh mass damping, for the force of a velocity change (eq. 10)
  std::vector<Vertex> vertices_;
  std::vector<Tri> triangles_;     // vertex ids, outward
  std::vector<int32_t> tri_body_;  // per triangle
  std::vector<double>
      tri_band_;  // per triangle: how deep behind it a vertex touches it [m] (kBand of its longest edge)
  std::vector<ClusterSet> vertex_sets_, tri_sets_;  // per body
  std::vector<int32_t> vertex_first_, tri_first_;   // per body: its first vertex, triangle
  std::vector<int32_t> nodes_;                      // every node a vertex follows
  std::vector<uint8_t> smooth_;                     // per vertex: not on an edge or corner at rest (kSmoothCos)
  // Per pair of bodies (a x n_bodies + b): a is the master of the pair (its
  // surface the coarser), its smooth vertices given points against b's
  // triangles only past the slop.
  std::vector<uint8_t> master_;
  // Per step.
  std::vector<int32_t> nodes_body_;  // body of each of nodes_
  // Per node of nodes_ (indexed like the model's, sparse): at t_{n+1}, t_n,
  // and where the next step takes it without contact.
  std::vector<Vec3> node_x1_, node_x0_, node_x2_;
  // Per vertex, its positions at t_n and t_{n+1}, worked out only near
  // another body (vertex_at): current where its stamp is the step's.
  std::vector<std::array<Vec3, 3>> x_;
  std::vector<uint32_t> vertex_stamp_, tri_stamp_, frame_stamp_;
  std::vector<Frame> frames_;
  uint32_t stamp_ = 0;
  std::vector<Vec3> tri_lo_, tri_hi_;  // per triangle: the box of its corners over the step (stamped)
  // Per body: its nodes' largest move this step, the sum of those since the
  // start (drift_), its nodes' box, the largest sum_k |w_k| of its vertices,
  // the drift after which a kept box is refitted (half a percent of its size).
  std::vector<double> move_, drift_, gain_max_, refit_drift_;
  std::vector<double> ahead_;  // per body: its nodes' largest move over the next step without contact
  double ahead_listed_ = 0;    // how far ahead of a triangle the pairs were listed [m]
  double slop_ = std::numeric_limits<double>::infinity();  // a depth too small for a point ahead [m] (kAheadSlop)
  std::vector<Vec3> node_lo_, node_hi_;
  // Per body, per cluster: sum_k |w_k| at most, and the drift at its last refit.
  std::vector<std::vector<double>> vertex_gain_, tri_gain_, vertex_refit_, tri_refit_;
  std::vector<std::vector<double>> tri_band_of_;  // per body, per triangle cluster: its triangles' largest band
  std::vector<double> band_max_;                  // per body: its largest band
  // The candidate pairs (vertex, triangle), listed with a margin (the
  // smallest body's refit drift) and kept until some vertex can have moved
  // half of it since: a node by more than that over its body's largest sum
  // |w| from where it was then (node_listed_, per node of nodes_).
  std::vector<std::array<int32_t, 2>> candidates_;
  // What the listed pairs read each step: their vertices and the triangles'
  // corners, and their triangles; and the parts the pairs are tested in
  // (first candidate of each, at a vertex's first; one past the last at the end).
  std::vector<int32_t> listed_vertices_, listed_tris_, narrow_begin_;
  std::vector<uint32_t> vertex_listed_, tri_listed_;  // the stamp of the step each was last listed in
  std::vector<Vec3> node_listed_;
  double margin_ = 0;
  bool listed_ = false;
  struct Best {
    int32_t t = -1;
    double gap = 0;  // at t_{n+1} [m]: negative behind the triangle (in contact), else ahead of it
    Vec3 b{0.0}, n{0.0};
  };
  // Per vertex in contact, a second face across a rim of the one it touches
  // (best_): one it is in front of that the next step takes it behind
  // (narrow()). t < 0: none.
  std::vector<Best> second_;
  // Whether p's projection on triangle t's plane at end `end` (0: t_n, 1:
  // t_{n+1}, 2: the next step's) is over the triangle, or out of it by no
  // more than `depth`; its barycentric coordinates (clamped to it) in b, and
  // how far out in *off (0 over it) when off is given.
  bool over(int32_t t, size_t end, const Vec3& p, double depth, Vec3& b, double* off = nullptr) const;
  // Whether the next step, as this one's velocities and forces have it,
  // takes vertex v behind triangle t's plane then, its projection over the
  // triangle there (coordinates in b).
  bool comes_behind(int32_t v, int32_t t, Vec3& b) const;
  std::vector<Best> best_;  // per vertex
  std::vector<int32_t> touched_;
  // The step the passes read (find()), and the threads they split over.
  const State<Real>* cur_ = nullptr;
  double cur_dt_ = 0;
  // The step the travel it sets is for (apply()'s `horizon`).
  double horizon_ = 0;
  ParallelFor* parallel_ = nullptr;
  int32_t node_parts_ = 1;
  // Per part of place_nodes(): per body, its nodes' largest move over the
  // step, jump from the last, move over the next and from where they were
  // listed, and their box; per part of narrow(), the vertices it found touching.
  struct NodeSums {
    std::vector<double> move, jump, ahead, listed;  // (squared)
    std::vector<Vec3> lo, hi;
  };
  std::vector<NodeSums> node_sums_;
  std::vector<std::vector<int32_t>> narrow_touched_;
  struct Box {
    double lo_x, hi_x;
    int32_t c;      // cluster
    bool vertices;  // a vertex cluster (else triangles)
  };
  std::vector<Vec3> body_lo_, body_hi_;  // per body: a box around all its vertices over the step
  std::vector<Box> boxes_;
  std::vector<ContactPoint> points_;
  std::vector<double> point_sign_;  // per point: +1, -1 as exchanged() counts it, 0 within a body
  std::vector<double> point_held_;  // per point: the sum of its held carriers' weights
  std::vector<int32_t> point_key_;  // per point: 2 x its vertex, + 1 for a second face (ascending)
  std::vector<uint8_t> held_;       // per model node: an essential BC holds it
  std::vector<int32_t> slot_of_;    // per model node, -1
  std::vector<int32_t> slot_node_;
  std::vector<Vec3> slot_v_;
  std::vector<double> slot_m_;
  ImpulseSolve solve_;
  std::vector<CoupledBodyState> no_bodies_;
  int32_t body_contacts_ = 0, self_contacts_ = 0;
  Vec3 exchanged_{0.0};
  std::vector<Vec3> given_;
  Vec3 held_given_{0.0};
  double impulse_sum_ = 0;
  ContactMoments moments_;
};

extern template class BodyContact<float>;
extern template class BodyContact<double>;

}  // namespace tactile
