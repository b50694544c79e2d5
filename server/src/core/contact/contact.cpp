#include "core/contact/contact.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <utility>

#include <glm/geometric.hpp>
#include <glm/matrix.hpp>

namespace tactile {

namespace {

constexpr int32_t kClusterItems = 32;  // nodes or faces in a cluster (one group)

template <class Real>
Vec3 position(const State<Real>& s, const Vec3& X, int32_t node) {
  const size_t j = 3 * size_t(node);
  return X + Vec3(double(s.u[j]), double(s.u[j + 1]), double(s.u[j + 2]));
}

}  // namespace

template <class Real>
Contact<Real>::Contact(const Model<Real>& model) : model_(model) {
  const size_t n_proxies = model.proxies.size();
  pose0_.resize(n_proxies);
  pose1_.resize(n_proxies);
  velocity_.resize(n_proxies);
  spin_.resize(n_proxies);
  lo_.resize(n_proxies);
  hi_.resize(n_proxies);
  alpha_ = model.effects.damping ? model.effects.alpha : 0.0;
  friction_ = model.effects.friction;
  if (n_proxies == 0) return;

  // Surface nodes that move freely, clustered in Morton order of rest positions
  // (with an embedded surface: the nodes its vertices follow, interior ones too).
  std::vector<int32_t> nodes;
  if (model.embedded) {
    for (const Tet& t : model.embedded_nodes) nodes.insert(nodes.end(), t.begin(), t.end());
    std::sort(nodes.begin(), nodes.end());
    nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  } else {
    nodes = compute_boundary_nodes(model.surface);
  }
  std::vector<int32_t> free, held;
  std::set_difference(nodes.begin(), nodes.end(), model.constrained.begin(), model.constrained.end(),
                      std::back_inserter(free));
  std::set_intersection(nodes.begin(), nodes.end(), model.constrained.begin(), model.constrained.end(),
                        std::back_inserter(held));
  const Aabb box = compute_aabb(model.mesh.X);
  const auto order = [&](const std::vector<Vec3>& points) { return morton_order(points, box); };
  std::vector<Vec3> rest(free.size());
  for (size_t k = 0; k < free.size(); ++k) rest[k] = model.mesh.X[size_t(free[k])];
  free_nodes_.reserve(free.size());
  for (size_t k : order(rest)) free_nodes_.push_back(free[k]);
  slot_node_ = free_nodes_;
  slot_node_.insert(slot_node_.end(), held.begin(), held.end());
  std::vector<int32_t> slot_of(model.mesh.X.size(), -1);
  for (size_t k = 0; k < slot_node_.size(); ++k) slot_of[size_t(slot_node_[k])] = int32_t(k);
  if (model.embedded)
    build_embedded(slot_of, order);
  else
    build_boundary(slot_of, order);

  x_now_.assign(slot_node_.size(), Vec3(0.0));
  f_now_.assign(free_nodes_.size(), Vec3(0.0));
  touched_now_.reserve(free_nodes_.size());
  points_.reserve((free_nodes_.size() + faces_.size() + emb_slot_.size() + emb_faces_.size()) * n_proxies);
  // Solve groups: one per proxy, then one per coupled body (at most one per proxy and hand).
  solve_.reserve(free_nodes_.size(), 2 * n_proxies + model.hands.size(), points_.capacity());
  slot_v_.assign(free_nodes_.size(), Vec3(0.0));
  slot_m_.resize(free_nodes_.size());
  for (size_t k = 0; k < free_nodes_.size(); ++k) slot_m_[k] = double(model.m[size_t(free_nodes_[k])]);
}

template <class Real>
std::vector<typename Contact<Real>::Face> Contact<Real>::claim_edges(const std::vector<Tri>& tris,
                                                                     const std::vector<size_t>& order) {
  std::vector<Face> faces;
  faces.reserve(order.size());
  std::set<std::pair<int32_t, int32_t>> claimed;
  for (size_t k : order) {
    Face f{tris[k], 0};
    for (int c = 0; c < 3; ++c) {
      const int32_t a = f.slot[size_t((c + 1) % 3)], b = f.slot[size_t((c + 2) % 3)];
      if (claimed.insert({std::min(a, b), std::max(a, b)}).second) f.owns_edge = uint8_t(f.owns_edge | (1u << c));
    }
    faces.push_back(f);
  }
  return faces;
}

template <class Real>
template <class Order>
void Contact<Real>::build_embedded(const std::vector<int32_t>& slot_of, const Order& morton_order) {
  // The vertices in Morton order of their rest positions, each with its four slots.
  const EmbeddedSurface& e = *model_.embedded;
  std::vector<int32_t> index_of(e.rest.vertices.size());
  for (size_t v : morton_order(e.rest.vertices)) {
    const Tet& t = model_.embedded_nodes[v];
    index_of[v] = int32_t(emb_slot_.size());
    emb_slot_.push_back({slot_of[size_t(t[0])], slot_of[size_t(t[1])], slot_of[size_t(t[2])], slot_of[size_t(t[3])]});
    emb_w_.push_back(e.weights[v]);
  }
  // A refit when the slots have drifted half a percent of the body's size.
  const Aabb box = compute_aabb(model_.mesh.X);
  refit_drift_ = 0.005 * glm::length(box.size());
  emb_x_.resize(emb_slot_.size());
  emb_stamp_.assign(emb_slot_.size(), 0u);
  emb_vertices_ = ClusterSet::build(int32_t(emb_slot_.size()), kEmbeddedClusterItems, kGroupItems,
                                    [&](int32_t v, std::vector<int32_t>& vertices) { vertices.push_back(v); });
  emb_vertex_gain_ = embedded_gain(emb_vertices_);

  // The triangles, in Morton order of their rest centroids; an edge's
  // contacts belong to the first that has it. One whose vertices all follow
  // held nodes only has nothing to push.
  std::vector<Tri> tris, t_of;  // (as the vertices here, and as the surface's)
  std::vector<Vec3> centroids;
  for (const Tri& t : e.rest.triangles) {
    const Tri v{index_of[size_t(t[0])], index_of[size_t(t[1])], index_of[size_t(t[2])]};
    bool free = false;
    for (int32_t i : v)
      for (int32_t k : emb_slot_[size_t(i)]) free = free || size_t(k) < free_nodes_.size();
    if (!free) continue;
    tris.push_back(v);
    t_of.push_back(t);
    centroids.push_back(
        (e.rest.vertices[size_t(t[0])] + e.rest.vertices[size_t(t[1])] + e.rest.vertices[size_t(t[2])]) / 3.0);
  }
  const std::vector<size_t> order = morton_order(centroids);
  emb_faces_ = claim_edges(tris, order);
  for (size_t k : order) {
    double longest = 0;
    for (int c = 0; c < 3; ++c)
      longest = std::max(longest, glm::length(e.rest.vertices[size_t(t_of[k][size_t(c)])] -
                                              e.rest.vertices[size_t(t_of[k][size_t((c + 1) % 3)])]));
    emb_face_slack_.push_back(kEmbeddedFaceSlack * longest);
  }
  emb_face_clusters_ = ClusterSet::build(
      int32_t(emb_faces_.size()), kEmbeddedClusterItems, kGroupItems, [&](int32_t f, std::vector<int32_t>& vertices) {
        vertices.insert(vertices.end(), emb_faces_[size_t(f)].slot.begin(), emb_faces_[size_t(f)].slot.end());
      });
  emb_face_gain_ = embedded_gain(emb_face_clusters_);
}

template <class Real>
std::vector<double> Contact<Real>::embedded_gain(const ClusterSet& set) const {
  std::vector<double> gain(set.clusters(), 0.0);
  for (size_t c = 0; c < set.clusters(); ++c)
    for (int32_t m = set.vertex_begin[size_t(set.group_begin[c])]; m < set.vertex_begin[size_t(set.group_begin[c + 1])];
         ++m) {
      double sum = 0;
      for (double w : emb_w_[size_t(set.vertices[size_t(m)])]) sum += std::fabs(w);
      gain[c] = std::max(gain[c], sum);
    }
  return gain;
}

template <class Real>
void Contact<Real>::sweep_embedded(ClusterSet& ec, const std::vector<double>& gain, ContactState& cs, size_t first,
                                   size_t first_group) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  const size_t n_proxies = model_.proxies.size();
  for (size_t j = 0; j < ec.clusters(); ++j) {
    Vec3& lo = cs.embedded_lo[first + j];
    Vec3& hi = cs.embedded_hi[first + j];
    double& at = cs.embedded_refit_at[first + j];
    // A vertex moves at most sum_k |w_k| times as far as its nodes.
    double grow = gain[j] * (cs.embedded_drift - at);
    if (!(cs.embedded_drift - at <= refit_drift_)) {
      bool near = false;
      for (size_t p = 0; p < n_proxies && !near; ++p)
        near = boxes_meet(lo - Vec3(grow), hi + Vec3(grow), lo_[p], hi_[p]);
      if (near) {  // refitted to both ends of this step
        at = cs.embedded_drift;
        grow = 0;
        lo = Vec3(inf);
        hi = Vec3(-inf);
        for (int32_t g = ec.group_begin[j]; g < ec.group_begin[j + 1]; ++g) {
          Vec3& glo = cs.embedded_group_lo[first_group + size_t(g)];
          Vec3& ghi = cs.embedded_group_hi[first_group + size_t(g)];
          glo = Vec3(inf);
          ghi = Vec3(-inf);
          for (int32_t m = ec.vertex_begin[size_t(g)]; m < ec.vertex_begin[size_t(g) + 1]; ++m) {
            const std::array<Vec3, 2>& x = embedded_position(cs, size_t(ec.vertices[size_t(m)]));
            glo = glm::min(glo, glm::min(x[0], x[1]));
            ghi = glm::max(ghi, glm::max(x[0], x[1]));
          }
          lo = glm::min(lo, glo);
          hi = glm::max(hi, ghi);
        }
      }
    }
    ec.lo[j] = lo - Vec3(grow);
    ec.hi[j] = hi + Vec3(grow);
    ec.grow[j] = grow;
  }
}

template <class Real>
template <class Order>
void Contact<Real>::build_boundary(const std::vector<int32_t>& slot_of, const Order& morton_order) {
  const Model<Real>& model = model_;
  const auto n = static_cast<int32_t>(free_nodes_.size());
  node_clusters_ = ClusterSet::build(n, kClusterItems, kClusterItems,
                                     [](int32_t k, std::vector<int32_t>& slots) { slots.push_back(k); });

  // Faces with a free corner, in Morton order of their rest centroids; an
  // edge's contacts belong to the first face (in that order) that has it.
  std::vector<Tri> tris;
  std::vector<Vec3> centroids;
  for (const Tri& t : model.surface) {
    const std::array<int32_t, 3> sl{slot_of[size_t(t[0])], slot_of[size_t(t[1])], slot_of[size_t(t[2])]};
    if (sl[0] >= n && sl[1] >= n && sl[2] >= n) continue;  // all its corners held: nothing to push
    tris.push_back(sl);
    centroids.push_back((model.mesh.X[size_t(t[0])] + model.mesh.X[size_t(t[1])] + model.mesh.X[size_t(t[2])]) / 3.0);
  }
  faces_ = claim_edges(tris, morton_order(centroids));
  // Each face cluster's box is its corners'.
  face_clusters_ = ClusterSet::build(
      int32_t(faces_.size()), kClusterItems, kClusterItems, [&](int32_t f, std::vector<int32_t>& slots) {
        slots.insert(slots.end(), faces_[size_t(f)].slot.begin(), faces_[size_t(f)].slot.end());
      });
}

template <class Real>
void Contact<Real>::init(ContactState& cs) const {
  const size_t n_proxies = model_.proxies.size();
  cs = ContactState{};
  cs.motion.resize(n_proxies);
  for (size_t j = 0; j < n_proxies; ++j) cs.motion[j] = hold(model_.proxies[j].pose);
  cs.hand_motion.resize(model_.hands.size());
  for (size_t h = 0; h < model_.hands.size(); ++h) cs.hand_motion[h] = hold(model_.hands[h].pose);
  cs.reports.resize(n_proxies);
  cs.device_reports.resize(model_.devices.size());
  cs.proxy_body.assign(n_proxies, -1);
  cs.x_prev.assign(slot_node_.size(), Vec3(0.0));
  cs.f_prev.assign(free_nodes_.size(), Vec3(0.0));
  cs.pushed.reserve(free_nodes_.size());
  cs.memory.assign(free_nodes_.size(), Memory{});
  cs.face_memory.assign(faces_.size(), Memory{});
  cs.embedded_memory.assign(emb_slot_.size(), Memory{});
  cs.embedded_face_memory.assign(emb_faces_.size(), Memory{});
  cs.embedded_lo.assign(emb_vertices_.clusters() + emb_face_clusters_.clusters(), Vec3(0.0));
  cs.embedded_hi = cs.embedded_lo;
  cs.embedded_group_lo.assign(emb_vertices_.groups() + emb_face_clusters_.groups(), Vec3(0.0));
  cs.embedded_group_hi = cs.embedded_group_lo;
  cs.embedded_refit_at.assign(cs.embedded_lo.size(), -std::numeric_limits<double>::infinity());
  cs.embedded_drift = 0;
  cs.fit.resize(n_proxies);
  cs.device_fit.resize(model_.devices.size());
  cs.device_felt.assign(model_.devices.size(), glm::dmat3(0.0));
}

template <class Real>
void Contact<Real>::set_hand_motion(State<Real>& s, int32_t hand, const ProxyMotion& m) const {
  ContactState& cs = s.contact;
  cs.hand_motion[size_t(hand)] = m;
  for (size_t j = 0; j < cs.motion.size(); ++j) {
    if (model_.proxy_hand[j] != hand) continue;
    const Pose& offset = model_.proxy_offset[j];
    ProxyMotion& pm = cs.motion[j];
    pm.t0 = m.t0;
    pm.t1 = m.t1;
    pm.from = {m.from.to_world(offset.position), m.from.orientation * offset.orientation};
    pm.to = {m.to.to_world(offset.position), m.to.orientation * offset.orientation};
  }
}

template <class Real>
void Contact<Real>::start(State<Real>& s) const {
  ContactState& cs = s.contact;
  for (size_t k = 0; k < slot_node_.size(); ++k)
    cs.x_prev[k] = position(s, model_.mesh.X[size_t(slot_node_[k])], slot_node_[k]);
  std::fill(cs.f_prev.begin(), cs.f_prev.end(), Vec3(0.0));
  cs.pushed.clear();
  cs.body_pushed.clear();
  cs.body_impulses.clear();
  std::fill(cs.memory.begin(), cs.memory.end(), Memory{});
  std::fill(cs.face_memory.begin(), cs.face_memory.end(), Memory{});
  std::fill(cs.embedded_memory.begin(), cs.embedded_memory.end(), Memory{});
  std::fill(cs.embedded_face_memory.begin(), cs.embedded_face_memory.end(), Memory{});
  std::fill(cs.embedded_refit_at.begin(), cs.embedded_refit_at.end(), -std::numeric_limits<double>::infinity());
  for (Fit& f : cs.fit) f = Fit{};
  for (Fit& f : cs.device_fit) f = Fit{};
  std::fill(cs.device_felt.begin(), cs.device_felt.end(), glm::dmat3(0.0));
  for (ProxyReport& r : cs.reports) r = ProxyReport{};
  for (DeviceReport& d : cs.device_reports) d = DeviceReport{};
  // (Coupled bodies keep their motion: couple() placed them.)
}

template <class Real>
Pose Contact<Real>::body_proxy_pose(const Body& b, const Pose& body_pose, int32_t proxy) const {
  if (b.hand < 0) return body_pose;
  const Pose& offset = model_.proxy_offset[size_t(proxy)];
  return {body_pose.to_world(offset.position), body_pose.orientation * offset.orientation};
}

template <class Real>
void Contact<Real>::couple(State<Real>& s, int32_t device, const DeviceLimits* limits) const {
  ContactState& cs = s.contact;
  const double t = s.t;
  const auto bounding = [&](int32_t j) {
    const double r = bounding_radius(model_.proxies[size_t(j)].geometry);
    return std::isfinite(r) ? r : 0.1;  // a plane: a body of a tenth of a metre
  };
  const auto add = [&](int32_t hand, int32_t proxy, const Coupling& spec, double radius) {
    Body* b = nullptr;
    for (Body& existing : cs.bodies)
      if (existing.hand == hand && existing.proxy == proxy) b = &existing;
    const Coupling c = fit_to_step(resolve_coupling(spec, limits, radius), model_.dt_rest);
    if (b) {  // coupled already: the new coupling only
      b->c = c;
      b->has_limits = limits != nullptr;
      b->limits = limits ? *limits : DeviceLimits{};
      return;
    }
    Body nb;
    nb.has_limits = limits != nullptr;
    nb.limits = limits ? *limits : DeviceLimits{};
    nb.device = device;
    nb.hand = hand;
    nb.proxy = proxy;
    nb.c = c;
    const ProxyMotion& m = hand >= 0 ? cs.hand_motion[size_t(hand)] : cs.motion[size_t(proxy)];
    nb.now.pose = m.at(t);
    if (t >= m.t0 && t < m.t1) {
      nb.now.v = m.velocity();
      nb.now.w = m.angular_velocity();
    }
    nb.target = nb.now.pose;
    cs.bodies.push_back(nb);
  };
  cs.device_fit[size_t(device)] = Fit{};
  cs.device_felt[size_t(device)] = glm::dmat3(0.0);
  for (size_t h = 0; h < model_.hands.size(); ++h) {
    if (model_.devices[size_t(device)] != model_.hands[h].device) continue;
    double radius = 0;
    for (size_t j = 0; j < model_.proxies.size(); ++j)
      if (model_.proxy_hand[j] == int32_t(h))
        radius = std::max(radius, glm::length(model_.proxy_offset[j].position) + bounding(int32_t(j)));
    add(int32_t(h), -1, model_.hands[h].coupling, radius);
  }
  for (size_t j = 0; j < model_.proxies.size(); ++j)
    if (model_.proxy_device[j] == device && model_.proxy_hand[j] < 0)
      add(-1, int32_t(j), model_.proxies[j].coupling, bounding(int32_t(j)));
  index_bodies(cs);
}

template <class Real>
void Contact<Real>::index_bodies(ContactState& cs) const {
  std::fill(cs.proxy_body.begin(), cs.proxy_body.end(), -1);
  for (size_t b = 0; b < cs.bodies.size(); ++b)
    for (size_t j = 0; j < model_.proxies.size(); ++j)
      if (cs.bodies[b].hand >= 0 ? model_.proxy_hand[j] == cs.bodies[b].hand : int32_t(j) == cs.bodies[b].proxy)
        cs.proxy_body[j] = int32_t(b);
}

template <class Real>
void Contact<Real>::release(State<Real>& s, int32_t device) const {
  ContactState& cs = s.contact;
  cs.bodies.erase(std::remove_if(cs.bodies.begin(), cs.bodies.end(), [&](const Body& b) { return b.device == device; }),
                  cs.bodies.end());
  index_bodies(cs);
  cs.device_reports[size_t(device)].coupled = false;
  cs.device_fit[size_t(device)] = Fit{};
  cs.device_felt[size_t(device)] = glm::dmat3(0.0);
}

template <class Real>
Pose Contact<Real>::proxy_pose(const State<Real>& s, int32_t proxy) const {
  const ContactState& cs = s.contact;
  const double t = s.t;
  const int32_t b = cs.proxy_body[size_t(proxy)];
  if (b < 0) return cs.motion[size_t(proxy)].at(t);
  return body_proxy_pose(cs.bodies[size_t(b)], cs.bodies[size_t(b)].now.pose, proxy);
}

template <class Real>
Pose Contact<Real>::hand_pose(const State<Real>& s, int32_t hand) const {
  const ContactState& cs = s.contact;
  const double t = s.t;
  for (const Body& b : cs.bodies)
    if (b.hand == hand) return b.now.pose;
  return cs.hand_motion[size_t(hand)].at(t);
}

template <class Real>
void Contact<Real>::take_bodies(State<Real>& s, const std::vector<CoupledBodyState>& bodies) const {
  for (const CoupledBodyState& taken : bodies) {
    couple(s, taken.device, taken.has_limits ? &taken.limits : nullptr);
    for (Body& b : s.contact.bodies)
      if (b.hand == taken.hand && b.proxy == taken.proxy) b.now = taken.now;
  }
}

template <class Real>
ContactSums Contact<Real>::apply(State<Real>& s, double t0, double t1, double dt) {
  ContactSums sums;
  if (s.contact.motion.empty()) return sums;
  begin_reports(s.contact, dt);
  const double largest_move = sweep_slots(s);
  move_proxies(s.contact, t0, t1, dt);
  find_points(s.contact, largest_move, dt);
  // The impulses, then the velocity changes they make: by eq. (9),
  // v_{n+1} = v_half + dt/2 a_{n+1}, so a moves by 2 dv / dt; by eq. (10)
  // that is the force q 2 dv / dt on a node, q = m (1 + alpha dt / 2).
  solve(s);
  apply_impulses(s, dt, sums);
  close_step(s.contact, sums);
  report(s.contact, t1, dt);
  return sums;
}

template <class Real>
double Contact<Real>::sweep_slots(const State<Real>& s) {
  const ContactState& cs = s.contact;
  // Positions at t_{n+1}, and boxes around each cluster's motion over the step.
  // With an embedded surface, also the largest move of any slot over the step.
  double move2 = 0;
  for (size_t k = 0; k < slot_node_.size(); ++k) {
    x_now_[k] = position(s, model_.mesh.X[size_t(slot_node_[k])], slot_node_[k]);
    if (!emb_vertices_.empty()) move2 = std::max(move2, glm::dot(x_now_[k] - cs.x_prev[k], x_now_[k] - cs.x_prev[k]));
  }
  node_clusters_.fit(cs.x_prev, x_now_);
  face_clusters_.fit(cs.x_prev, x_now_);
  return std::sqrt(move2);
}

template <class Real>
void Contact<Real>::move_proxies(ContactState& cs, double t0, double t1, double dt) {
  const size_t n_proxies = cs.motion.size();
  // The coupled bodies' prediction and coupling (core/coupling.hpp): their
  // motion is the device's.
  for (Body& b : cs.bodies) {
    const ProxyMotion& m = b.hand >= 0 ? cs.hand_motion[size_t(b.hand)] : cs.motion[size_t(b.proxy)];
    b.previous = b.wrench;
    b.previous_target = b.target.position;
    b.target = m.at(t1);
    const bool moving = t1 > m.t0 && t0 < m.t1;
    b.target_velocity = moving ? m.velocity() : Vec3(0.0);
    b.wrench = step_coupled_body(b.c, b.now, b.target, b.target_velocity, moving ? m.angular_velocity() : Vec3(0.0), dt,
                                 b.next);
    b.v_free = b.next.v;
    b.w_free = b.next.w;
  }
  // Each proxy's poses and the box its bounding sphere sweeps over the step.
  for (size_t j = 0; j < n_proxies; ++j) {
    if (const int32_t bi = cs.proxy_body[j]; bi >= 0) {
      const Body& b = cs.bodies[size_t(bi)];
      pose0_[j] = body_proxy_pose(b, b.now.pose, int32_t(j));
      pose1_[j] = body_proxy_pose(b, b.next.pose, int32_t(j));
      spin_[j] = b.next.w;
      velocity_[j] = b.next.v + glm::cross(b.next.w, pose1_[j].position - b.next.pose.position);
    } else {
      pose0_[j] = cs.motion[j].at(t0);
      pose1_[j] = cs.motion[j].at(t1);
      velocity_[j] = cs.motion[j].velocity();
      spin_[j] = cs.motion[j].angular_velocity();
    }
    const Aabb b0 = world_bounds(model_.proxies[j].geometry, pose0_[j]);
    const Aabb b1 = world_bounds(model_.proxies[j].geometry, pose1_[j]);
    lo_[j] = glm::min(b0.lo, b1.lo);
    hi_[j] = glm::max(b0.hi, b1.hi);
  }
}

template <class Real>
void Contact<Real>::find_points(ContactState& cs, double largest_move, double dt) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  const size_t n_proxies = cs.motion.size();
  // The embedded surface's clusters: each slot is in several, so exact
  // boxes every step would cost most of the embedding's step. A cluster's
  // box is grown each step by the largest move of any slot (so that no
  // vertex can have left it), and refitted to its vertices when it has grown
  // by refit_drift_ and meets a proxy's box.
  if (++stamp_ == 0) {  // (wrapped: no vertex may keep a stamp that looks current)
    std::fill(emb_stamp_.begin(), emb_stamp_.end(), 0u);
    stamp_ = 1;
  }
  if (!emb_vertices_.empty()) {
    cs.embedded_drift += largest_move;
    sweep_embedded(emb_vertices_, emb_vertex_gain_, cs, 0, 0);
    sweep_embedded(emb_face_clusters_, emb_face_gain_, cs, emb_vertices_.clusters(), emb_vertices_.groups());
  }
  node_contacts_ = face_contacts_ = embedded_contacts_ = 0;
  points_.clear();
  // The nodes, cluster by cluster, each near a proxy then tested along its own path over the step.
  const ClusterSet& nc = node_clusters_;
  for (size_t c = 0; c < nc.clusters(); ++c)
    for (size_t j = 0; j < n_proxies; ++j)
      nc.visit_cluster(c, nc.group_lo.data(), nc.group_hi.data(), lo_[j], hi_[j], [&](int32_t k) {
        const Vec3& x = x_now_[size_t(k)];
        const Vec3& xp = cs.x_prev[size_t(k)];
        if (!boxes_meet(glm::min(x, xp), glm::max(x, xp), lo_[j], hi_[j])) {
          Memory& mem = cs.memory[size_t(k)];
          if (mem.proxy == int32_t(j)) mem.proxy = -1;
          return;
        }
        find_node_contact(cs, k, int32_t(j), pose0_[j], pose1_[j]);
      });
  // Then the faces. A plane meets a triangle deepest at a corner: its nodes are all it needs.
  const ClusterSet& fc = face_clusters_;
  for (size_t c = 0; c < fc.clusters(); ++c)
    for (size_t j = 0; j < n_proxies; ++j) {
      if (model_.proxies[j].geometry.shape == ProxyShape::Plane) continue;
      fc.visit_cluster(c, fc.group_lo.data(), fc.group_hi.data(), lo_[j], hi_[j], [&](int32_t f) {
        Vec3 lo(inf), hi(-inf);
        for (int32_t k : faces_[size_t(f)].slot) {
          lo = glm::min(lo, glm::min(x_now_[size_t(k)], cs.x_prev[size_t(k)]));
          hi = glm::max(hi, glm::max(x_now_[size_t(k)], cs.x_prev[size_t(k)]));
        }
        if (!boxes_meet(lo, hi, lo_[j], hi_[j])) {
          Memory& mem = cs.face_memory[size_t(f)];
          if (mem.proxy == int32_t(j)) mem.proxy = -1;
          return;
        }
        find_face_contact(cs, f, int32_t(j), pose0_[j], pose1_[j], dt);
      });
    }

  // The embedded surface's vertices and triangles (in place of the nodes and faces above, which it then has none
  // of), their groups' boxes kept in the state: the vertices' clusters', then the triangles'.
  const ClusterSet& ev = emb_vertices_;
  const ClusterSet& ef = emb_face_clusters_;
  const Vec3* ef_lo = cs.embedded_group_lo.data() + ev.groups();
  const Vec3* ef_hi = cs.embedded_group_hi.data() + ev.groups();
  for (size_t j = 0; j < n_proxies; ++j) {
    for (size_t c = 0; c < ev.clusters(); ++c)
      ev.visit_cluster(c, cs.embedded_group_lo.data(), cs.embedded_group_hi.data(), lo_[j], hi_[j],
                       [&](int32_t e) { find_embedded_contact(cs, e, int32_t(j), pose0_[j], pose1_[j], dt); });
    if (model_.proxies[j].geometry.shape == ProxyShape::Plane) continue;  // (deepest at a vertex)
    for (size_t c = 0; c < ef.clusters(); ++c)
      ef.visit_cluster(c, ef_lo, ef_hi, lo_[j], hi_[j],
                       [&](int32_t f) { find_embedded_face_contact(cs, f, int32_t(j), pose0_[j], pose1_[j], dt); });
  }
}

template <class Real>
void Contact<Real>::apply_impulses(State<Real>& s, double dt, ContactSums& sums) {
  ContactState& cs = s.contact;
  // The bodies: the contact's velocity change raises their acceleration as a
  // node's (eq. 9), and the step's end becomes their present.
  for (Body& b : cs.bodies) {
    b.next.a += (2.0 / dt) * (b.next.v - b.v_free);
    b.next.alpha += (2.0 / dt) * (b.next.w - b.w_free);
    b.now = b.next;
  }
  for (Point& c : points_)
    if (c.body >= 0) c.vp = proxy_velocity(cs.bodies, c);
  const double to_force = (1.0 + 0.5 * alpha_ * dt) * 2.0 / dt;  // from an impulse to its force over the step
  for (int32_t k : solve_.moved()) {
    const Vec3 dv = solve_.dv(k);
    const size_t i = size_t(free_nodes_[size_t(k)]);
    const double m = double(model_.m[i]);
    const Vec3 v(double(s.v[3 * i]), double(s.v[3 * i + 1]), double(s.v[3 * i + 2]));
    const Vec3 a(double(s.a[3 * i]), double(s.a[3 * i + 1]), double(s.a[3 * i + 2]));
    const Vec3 v_new = v + dv, a_new = a + (2.0 / dt) * dv;
    for (int c = 0; c < 3; ++c) {
      s.v[3 * i + size_t(c)] = Real(v_new[c]);
      s.a[3 * i + size_t(c)] = Real(a_new[c]);
    }
    sums.mv2_delta += m * (glm::dot(v_new, v_new) - glm::dot(v, v));
    sums.ma2_delta += m * (glm::dot(a_new, a_new) - glm::dot(a, a));
    f_now_[size_t(k)] = (m * to_force) * dv;
    touched_now_.push_back(k);  // (reserved: never allocates)
    if (cs.track_nodes) {
      if (cs.node_impulse[size_t(k)] == Vec3(0.0)) cs.impulse_slots.push_back(k);  // (reserved)
      cs.node_impulse[size_t(k)] += f_now_[size_t(k)] * dt;
    }
  }
  solve_.clear();
  for (const Point& c : points_) {
    ProxyReport& r = cs.reports[size_t(c.proxy)];
    ++r.contacts;
    const Vec3 fc = to_force * (c.jn * c.n + c.jt);  // on the body
    r.force -= fc;
    r.torque -= glm::cross(c.x - pose1_[size_t(c.proxy)].position, fc);
    const double w = glm::dot(fc, c.vp) * dt;
    r.work += w;
    sums.proxy_work += std::fabs(w);
  }
}

template <class Real>
void Contact<Real>::close_step(ContactState& cs, ContactSums& sums) {
  // Work of the contact forces on the body (trapezoid, as for the loads) and
  // by each proxy; then this step's positions and forces become the previous.
  // Only the nodes pushed in this step or the one before carry a force.
  for (int32_t k : touched_now_)
    sums.work += 0.5 * glm::dot(cs.f_prev[size_t(k)] + f_now_[size_t(k)], x_now_[size_t(k)] - cs.x_prev[size_t(k)]);
  for (int32_t k : cs.pushed) {
    if (f_now_[size_t(k)] != Vec3(0.0)) continue;  // counted above
    sums.work += 0.5 * glm::dot(cs.f_prev[size_t(k)], x_now_[size_t(k)] - cs.x_prev[size_t(k)]);
  }
  for (int32_t k : cs.pushed) cs.f_prev[size_t(k)] = Vec3(0.0);
  for (int32_t k : touched_now_) {
    cs.f_prev[size_t(k)] = f_now_[size_t(k)];
    f_now_[size_t(k)] = Vec3(0.0);
  }
  cs.pushed.assign(touched_now_.begin(), touched_now_.end());  // (the workspace keeps its reserve)
  touched_now_.clear();
  cs.x_prev.swap(x_now_);
}

template <class Real>
void Contact<Real>::solve(State<Real>& s) {
  // The free slots the points move: their velocities, gathered for the solve (their masses are the model's).
  for (const Point& c : points_)
    for (size_t j = 0; j < kPointCarriers && c.slot[j] >= 0; ++j) {
      const auto k = size_t(c.slot[j]);
      const size_t i = size_t(free_nodes_[k]);
      slot_v_[k] = Vec3(double(s.v[3 * i]), double(s.v[3 * i + 1]), double(s.v[3 * i + 2]));
    }
  solve_.solve(points_, s.contact.motion.size(), s.contact.bodies, slot_v_, slot_m_);
}

template class Contact<float>;
template class Contact<double>;

}  // namespace tactile
