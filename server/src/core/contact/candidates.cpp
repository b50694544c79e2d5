// Contact's candidate points (core/contact/contact.hpp): where a surface
// node, a boundary face, or an embedded surface's vertex or triangle is
// inside a proxy at t_{n+1}, the point the impulse solve then stops, with
// the normal it left the proxy by (a node's path over the step, a memory of
// the side it entered from) and the nodes it moves.
#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/geometric.hpp>

#include "core/contact/contact.hpp"

namespace tactile {

template <class Real>
Vec3 Contact<Real>::outward(const ProxyGeometry& g, const Vec3& q0, const Vec3& q1, const SurfacePoint& at1,
                            Memory& mem, int32_t proxy) const {
  Vec3 n_local;
  if (locate(g, q0).phi > 0) {
    // Crossed the surface during the step: the normal where it crossed.
    double a = 0.0, b = 1.0;
    for (int it = 0; it < 20; ++it) {
      const double m = 0.5 * (a + b);
      (locate(g, q0 + m * (q1 - q0)).phi > 0 ? a : b) = m;
    }
    n_local = locate(g, q0 + b * (q1 - q0)).n;
  } else if (mem.proxy == proxy && -at1.phi > trust_depth(g)) {
    n_local = mem.normal;  // too deep to trust the nearest surface: the way it came in
  } else {
    n_local = at1.n;
  }
  mem.proxy = proxy;
  mem.normal = n_local;
  return n_local;
}

template <class Real>
void Contact<Real>::find_node_contact(ContactState& cs, int32_t k, int32_t proxy, const Pose& p0, const Pose& p1) {
  const ProxySpec& spec = model_.proxies[size_t(proxy)];
  const ProxyGeometry& g = spec.geometry;
  Memory& mem = cs.memory[size_t(k)];
  const Vec3 x1 = x_now_[size_t(k)];
  const Vec3 q1 = p1.to_local(x1);
  const SurfacePoint at1 = locate(g, q1);
  if (at1.phi > 0) {
    if (mem.proxy == proxy) mem.proxy = -1;
    return;
  }
  // Inside at t_{n+1}: which way is out?
  Point c = empty_point(proxy, cs.proxy_body[size_t(proxy)]);
  c.slot[0] = k;
  c.w[0] = 1;
  c.x = x1;
  c.n = p1.orientation * outward(g, p0.to_local(cs.x_prev[size_t(k)]), q1, at1, mem, proxy);
  c.vp = velocity_[size_t(proxy)] + glm::cross(spin_[size_t(proxy)], x1 - p1.position);
  c.r = c.body >= 0 ? x1 - cs.bodies[size_t(c.body)].next.pose.position : Vec3(0.0);
  c.v_held = Vec3(0.0);
  c.inv_mass = 1.0 / double(model_.m[size_t(free_nodes_[size_t(k)])]);
  c.mu = friction_ ? spec.friction : 0.0;
  points_.push_back(c);
  ++node_contacts_;
}

template <class Real>
bool Contact<Real>::triangle_point(const ProxyGeometry& g, const std::array<Vec3, 3>& q,
                                   const std::array<double, 3>& phi, uint8_t owns_edge, Memory& mem, int32_t proxy,
                                   TrianglePoint& out) {
  // Cheap ways out first. A triangle whose corners are all inside lies inside
  // (the shape is convex): its corners' contacts hold it. A box whose slab
  // (with its rounding) leaves all three corners on one side cannot reach it.
  if (phi[0] <= 0 && phi[1] <= 0 && phi[2] <= 0) return false;
  if (g.shape == ProxyShape::Box)
    for (int k = 0; k < 3; ++k) {
      const double reach = g.half_extents[k] + g.radius;
      if (std::min({q[0][k], q[1][k], q[2][k]}) > reach || std::max({q[0][k], q[1][k], q[2][k]}) < -reach) {
        if (mem.proxy == proxy) mem.proxy = -1;
        return false;
      }
    }
  out.b = deepest_on_triangle(g, q[0], q[1], q[2]);
  const Vec3& b = out.b;
  const int zeros = int(b.x == 0) + int(b.y == 0) + int(b.z == 0);
  out.q = b.x * q[0] + b.y * q[1] + b.z * q[2];
  out.at = locate(g, out.q);
  if (out.at.phi > 0 || zeros >= 2) {  // outside, or deepest at a corner: the corner's own contact
    if (mem.proxy == proxy) mem.proxy = -1;
    return false;
  }
  return zeros == 0 || (owns_edge & (1u << (b.x == 0 ? 0 : b.y == 0 ? 1 : 2)));  // else its edge's other triangle's
}

template <class Real>
void Contact<Real>::find_face_contact(ContactState& cs, int32_t f, int32_t proxy, const Pose& p0, const Pose& p1,
                                      double dt) {
  const ProxySpec& spec = model_.proxies[size_t(proxy)];
  const ProxyGeometry& g = spec.geometry;
  const Face& face = faces_[size_t(f)];
  Memory& mem = cs.face_memory[size_t(f)];
  std::array<Vec3, 3> q;
  std::array<double, 3> phi;
  for (size_t c = 0; c < 3; ++c) {
    q[c] = p1.to_local(x_now_[size_t(face.slot[c])]);
    phi[c] = locate(g, q[c]).phi;
  }
  TrianglePoint tp;
  if (!triangle_point(g, q, phi, face.owns_edge, mem, proxy, tp)) return;
  const Vec3& w = tp.b;
  const Vec3& q1 = tp.q;
  const SurfacePoint& at1 = tp.at;
  Point c = empty_point(proxy, cs.proxy_body[size_t(proxy)]);
  Vec3 x0(0.0);
  int free = 0;
  for (size_t j = 0; j < 3; ++j) {
    const auto k = size_t(face.slot[j]);
    const double wj = w[int(j)];
    if (wj == 0) continue;
    x0 += wj * cs.x_prev[k];
    c.x += wj * x_now_[k];
    add_corner(cs, c, free, k, wj, dt);
  }
  if (!(c.inv_mass > 0)) return;
  c.n = p1.orientation * outward(g, p0.to_local(x0), q1, at1, mem, proxy);
  c.vp = velocity_[size_t(proxy)] + glm::cross(spin_[size_t(proxy)], c.x - p1.position);
  c.r = c.body >= 0 ? c.x - cs.bodies[size_t(c.body)].next.pose.position : Vec3(0.0);
  c.mu = friction_ ? spec.friction : 0.0;
  points_.push_back(c);
  ++face_contacts_;
}

template <class Real>
typename Contact<Real>::Point Contact<Real>::empty_point(int32_t proxy, int32_t body) {
  Point c;
  c.proxy = proxy;
  c.body = body;
  c.slot.fill(-1);
  c.w.fill(0);
  c.x = Vec3(0.0);
  c.v_held = Vec3(0.0);
  c.inv_mass = 0;
  return c;
}

template <class Real>
void Contact<Real>::add_corner(const ContactState& cs, Point& c, int& free, size_t slot, double w, double dt) const {
  if (slot < free_nodes_.size()) {
    c.slot[size_t(free)] = int32_t(slot);
    c.w[size_t(free++)] = w;
    c.inv_mass += w * w / double(model_.m[size_t(free_nodes_[slot])]);
  } else {
    c.v_held += w * (x_now_[slot] - cs.x_prev[slot]) / dt;  // held: as prescribed over the step
  }
}

template <class Real>
void Contact<Real>::find_embedded_contact(ContactState& cs, int32_t e, int32_t proxy, const Pose& p0, const Pose& p1,
                                          double dt) {
  const ProxySpec& spec = model_.proxies[size_t(proxy)];
  const ProxyGeometry& g = spec.geometry;
  Memory& mem = cs.embedded_memory[size_t(e)];
  const std::array<int32_t, 4>& slots = emb_slot_[size_t(e)];
  const std::array<double, 4>& w = emb_w_[size_t(e)];
  const auto& [x0, x1] = embedded_position(cs, size_t(e));
  // The vertex's own path over the step against the proxy's swept box, then the proxy itself.
  if (!boxes_meet(glm::min(x0, x1), glm::max(x0, x1), lo_[size_t(proxy)], hi_[size_t(proxy)])) {
    if (mem.proxy == proxy) mem.proxy = -1;
    return;
  }
  const Vec3 q1 = p1.to_local(x1);
  const SurfacePoint at1 = locate(g, q1);
  if (at1.phi > 0) {
    if (mem.proxy == proxy) mem.proxy = -1;
    return;
  }
  Point c = empty_point(proxy, cs.proxy_body[size_t(proxy)]);
  c.x = x1;
  int free = 0;
  for (size_t k = 0; k < 4; ++k)
    if (w[k] != 0) add_corner(cs, c, free, size_t(slots[k]), w[k], dt);
  if (!(c.inv_mass > 0)) return;
  c.n = p1.orientation * outward(g, p0.to_local(x0), q1, at1, mem, proxy);
  c.vp = velocity_[size_t(proxy)] + glm::cross(spin_[size_t(proxy)], x1 - p1.position);
  c.r = c.body >= 0 ? x1 - cs.bodies[size_t(c.body)].next.pose.position : Vec3(0.0);
  c.mu = friction_ ? spec.friction : 0.0;
  points_.push_back(c);
  ++embedded_contacts_;
}

template <class Real>
void Contact<Real>::find_embedded_face_contact(ContactState& cs, int32_t f, int32_t proxy, const Pose& p0,
                                               const Pose& p1, double dt) {
  const ProxySpec& spec = model_.proxies[size_t(proxy)];
  const ProxyGeometry& g = spec.geometry;
  const Face& face = emb_faces_[size_t(f)];
  Memory& mem = cs.embedded_face_memory[size_t(f)];
  std::array<Vec3, 3> x0, x1, q;
  Vec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
  for (size_t j = 0; j < 3; ++j) {
    const std::array<Vec3, 2>& x = embedded_position(cs, size_t(face.slot[j]));
    x0[j] = x[0];
    x1[j] = x[1];
    lo = glm::min(lo, glm::min(x0[j], x1[j]));
    hi = glm::max(hi, glm::max(x0[j], x1[j]));
  }
  // As a boundary face (find_face_contact): one all inside is held by its
  // vertices' contacts, one deepest at a vertex is that vertex's.
  if (!boxes_meet(lo, hi, lo_[size_t(proxy)], hi_[size_t(proxy)])) {
    if (mem.proxy == proxy) mem.proxy = -1;
    return;
  }
  std::array<double, 3> phi;
  for (size_t j = 0; j < 3; ++j) {
    q[j] = p1.to_local(x1[j]);
    phi[j] = locate(g, q[j]).phi;
  }
  TrianglePoint tp;
  if (!triangle_point(g, q, phi, face.owns_edge, mem, proxy, tp)) return;
  // Within its slack of a vertex inside the proxy, that vertex's contact holds it.
  const double held = std::max({-phi[0], -phi[1], -phi[2]});
  if (held >= 0 && -tp.at.phi <= held + emb_face_slack_[size_t(f)]) return;
  const Vec3& b = tp.b;
  const Vec3& q1 = tp.q;
  const SurfacePoint& at1 = tp.at;
  // Its nodes, each once: a node two vertices follow takes the sum of their weights.
  std::array<int32_t, kPointCarriers> slot;
  std::array<double, kPointCarriers> w{};
  size_t n = 0;
  for (size_t j = 0; j < 3; ++j) {
    const auto v = size_t(face.slot[j]);
    if (b[int(j)] == 0) continue;
    for (size_t k = 0; k < 4; ++k) {
      const int32_t s = emb_slot_[v][k];
      size_t m = 0;
      while (m < n && slot[m] != s) ++m;
      if (m == n) {
        slot[n] = s;
        w[n++] = 0;
      }
      w[m] += b[int(j)] * emb_w_[v][k];
    }
  }
  Point c = empty_point(proxy, cs.proxy_body[size_t(proxy)]);
  int free = 0;
  for (size_t m = 0; m < n; ++m)
    if (w[m] != 0) add_corner(cs, c, free, size_t(slot[m]), w[m], dt);
  if (!(c.inv_mass > 0)) return;
  c.x = b.x * x1[0] + b.y * x1[1] + b.z * x1[2];
  c.n = p1.orientation * outward(g, p0.to_local(b.x * x0[0] + b.y * x0[1] + b.z * x0[2]), q1, at1, mem, proxy);
  c.vp = velocity_[size_t(proxy)] + glm::cross(spin_[size_t(proxy)], c.x - p1.position);
  c.r = c.body >= 0 ? c.x - cs.bodies[size_t(c.body)].next.pose.position : Vec3(0.0);
  c.mu = friction_ ? spec.friction : 0.0;
  points_.push_back(c);
  ++embedded_contacts_;
}

// The members defined here, for both precisions (contact.cpp instantiates the rest).
#define TACTILE_CONTACT_CANDIDATES(Real)                                                                             \
  template Vec3 Contact<Real>::outward(const ProxyGeometry&, const Vec3&, const Vec3&, const SurfacePoint&,          \
                                       ContactMemory&, int32_t) const;                                               \
  template void Contact<Real>::find_node_contact(ContactState&, int32_t, int32_t, const Pose&, const Pose&);         \
  template bool Contact<Real>::triangle_point(const ProxyGeometry&, const std::array<Vec3, 3>&,                      \
                                              const std::array<double, 3>&, uint8_t, ContactMemory&, int32_t,        \
                                              TrianglePoint&);                                                       \
  template void Contact<Real>::find_face_contact(ContactState&, int32_t, int32_t, const Pose&, const Pose&, double); \
  template ContactPoint Contact<Real>::empty_point(int32_t, int32_t);                                                \
  template void Contact<Real>::add_corner(const ContactState&, ContactPoint&, int&, size_t, double, double) const;   \
  template void Contact<Real>::find_embedded_contact(ContactState&, int32_t, int32_t, const Pose&, const Pose&,      \
                                                     double);                                                        \
  template void Contact<Real>::find_embedded_face_contact(ContactState&, int32_t, int32_t, const Pose&, const Pose&, \
                                                          double);
TACTILE_CONTACT_CANDIDATES(float)
TACTILE_CONTACT_CANDIDATES(double)
#undef TACTILE_CONTACT_CANDIDATES

}  // namespace tactile
