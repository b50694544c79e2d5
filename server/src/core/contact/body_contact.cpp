#include "core/contact/body_contact.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <glm/geometric.hpp>

namespace tactile {

namespace {

constexpr int32_t kClusterItems = 32, kGroupItems = 8;

// The order of `points` by Morton code within their box.
std::vector<size_t> morton_order(const std::vector<Vec3>& points) {
  const Aabb box = compute_aabb(points);
  const Vec3 extent = glm::max(box.size(), Vec3(1e-30));
  std::vector<uint32_t> key(points.size());
  for (size_t k = 0; k < points.size(); ++k) key[k] = compute_morton_code((points[k] - box.lo) / extent);
  std::vector<size_t> order(points.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return key[a] < key[b]; });
  return order;
}

}  // namespace

template <class Real>
BodyContact<Real>::BodyContact(const Model<Real>& model) : model_(model) {
  between_ = model.effects.body_contact && model.bodies.size() > 1;
  self_ = model.effects.self_contact;
  active_ = between_ || self_;
  mu_ = model.effects.body_friction;
  if (!active_) return;
  // Each body's surface contact meets: its fine surface's vertices and
  // triangles, else its boundary's nodes and faces; vertices in Morton order.
  for (size_t b = 0; b < model.bodies.size(); ++b) {
    const ModelBody& body = model.bodies[b];
    std::vector<Vertex> vs;
    std::vector<Tri> ts;
    if (model.embedded) {
      const EmbeddedSurface& e = *model.embedded;
      const int32_t v0 = body.spec.fine_vertex_begin;
      for (int32_t v = v0; v < body.spec.fine_vertex_end; ++v)
        vs.push_back({model.embedded_nodes[size_t(v)], e.weights[size_t(v)], int32_t(b), e.rest.vertices[size_t(v)]});
      for (int32_t t = body.spec.fine_triangle_begin; t < body.spec.fine_triangle_end; ++t) {
        const Tri& tri = e.rest.triangles[size_t(t)];
        ts.push_back({tri[0] - v0, tri[1] - v0, tri[2] - v0});
      }
    } else {
      const std::vector<Tri> faces(model.surface.begin() + body.face_begin, model.surface.begin() + body.face_end);
      const std::vector<int32_t> nodes = compute_boundary_nodes(faces);
      std::vector<int32_t> index(size_t(model.n_nodes), -1);
      for (int32_t n : nodes) {
        index[size_t(n)] = int32_t(vs.size());
        vs.push_back({{n, -1, -1, -1}, {1.0, 0.0, 0.0, 0.0}, int32_t(b), model.mesh.X[size_t(n)]});
      }
      for (const Tri& f : faces) ts.push_back({index[size_t(f[0])], index[size_t(f[1])], index[size_t(f[2])]});
    }
    std::vector<Vec3> rest(vs.size());
    for (size_t k = 0; k < vs.size(); ++k) rest[k] = vs[k].X;
    const std::vector<size_t> order = morton_order(rest);
    std::vector<int32_t> renumber(vs.size());
    const auto first = int32_t(vertices_.size());
    for (size_t k = 0; k < order.size(); ++k) {
      renumber[order[k]] = first + int32_t(k);
      vertices_.push_back(vs[order[k]]);
    }
    std::vector<Vec3> centroids;
    for (Tri& t : ts) {
      for (int32_t& v : t) v = renumber[size_t(v)];
      centroids.push_back((vertices_[size_t(t[0])].X + vertices_[size_t(t[1])].X + vertices_[size_t(t[2])].X) / 3.0);
    }
    const auto tri_first = int32_t(triangles_.size());
    for (size_t k : morton_order(centroids)) {
      const Tri& t = ts[k];
      triangles_.push_back(t);
      tri_body_.push_back(int32_t(b));
      double longest = 0;
      for (int c = 0; c < 3; ++c)
        longest = std::max(
            longest, glm::length(vertices_[size_t(t[size_t(c)])].X - vertices_[size_t(t[size_t((c + 1) % 3)])].X));
      tri_edge_.push_back(longest);
    }
    vertex_first_.push_back(first);
    tri_first_.push_back(tri_first);
    vertex_sets_.push_back(ClusterSet::build(int32_t(vs.size()), kClusterItems, kGroupItems,
                                             [&](int32_t i, std::vector<int32_t>& out) { out.push_back(first + i); }));
    tri_sets_.push_back(
        ClusterSet::build(int32_t(ts.size()), kClusterItems, kGroupItems, [&](int32_t i, std::vector<int32_t>& out) {
          const Tri& t = triangles_[size_t(tri_first + i)];
          out.insert(out.end(), t.begin(), t.end());
        }));
  }
  for (const Vertex& v : vertices_)
    for (int32_t n : v.node)
      if (n >= 0) nodes_.push_back(n);
  std::sort(nodes_.begin(), nodes_.end());
  nodes_.erase(std::unique(nodes_.begin(), nodes_.end()), nodes_.end());
  node_x1_.assign(size_t(model.n_nodes), Vec3(0.0));
  node_x0_.assign(size_t(model.n_nodes), Vec3(0.0));
  x1_.assign(vertices_.size(), Vec3(0.0));
  x0_.assign(vertices_.size(), Vec3(0.0));
  best_.assign(vertices_.size(), Best{});
  slot_of_.assign(size_t(model.n_nodes), -1);
  solve_.reserve(nodes_.size(), 1, vertices_.size());
}

template <class Real>
void BodyContact<Real>::test(int32_t v, int32_t t, double dt) {
  (void)dt;
  const Vertex& vx = vertices_[size_t(v)];
  const Tri& tri = triangles_[size_t(t)];
  if (tri_body_[size_t(t)] == vx.body) {
    // Self contact: not within the triangle's own neighbourhood at rest.
    const double reach = 2.0 * tri_edge_[size_t(t)];
    for (int32_t c : tri)
      if (glm::length(vertices_[size_t(c)].X - vx.X) < reach) return;
  }
  const Vec3 &a = x1_[size_t(tri[0])], &b = x1_[size_t(tri[1])], &c = x1_[size_t(tri[2])];
  const Vec3 e1 = b - a, e2 = c - a;
  const Vec3 nn = glm::cross(e1, e2);
  const double area2 = glm::length(nn);
  if (!(area2 > 0)) return;
  const Vec3 n = nn / area2;
  const Vec3 p = x1_[size_t(v)];
  const double d1 = glm::dot(p - a, n);
  if (!(d1 < 0)) return;
  // Barycentric coordinates of p's projection on the triangle.
  const Vec3 q = p - a;
  const double d00 = glm::dot(e1, e1), d01 = glm::dot(e1, e2), d11 = glm::dot(e2, e2);
  const double d20 = glm::dot(q, e1), d21 = glm::dot(q, e2);
  const double den = d00 * d11 - d01 * d01;
  const double bb = (d11 * d20 - d01 * d21) / den, bc = (d00 * d21 - d01 * d20) / den, ba = 1.0 - bb - bc;
  constexpr double eps = -1e-9;
  if (ba < eps || bb < eps || bc < eps) return;
  const double depth = -d1;
  if (depth > 0.5 * tri_edge_[size_t(t)]) {
    // Deep: only a vertex that crossed the triangle this step.
    const Vec3 &a0 = x0_[size_t(tri[0])], &b0 = x0_[size_t(tri[1])], &c0 = x0_[size_t(tri[2])];
    const Vec3 n0 = glm::cross(b0 - a0, c0 - a0);
    if (!(glm::dot(x0_[size_t(v)] - a0, n0) >= 0)) return;
  }
  Best& best = best_[size_t(v)];
  if (best.t >= 0 && best.depth <= depth) return;
  if (best.t < 0) touched_.push_back(v);
  best = {t, depth, Vec3(ba, bb, bc), n};
}

template <class Real>
void BodyContact<Real>::find(const State<Real>& s, double dt) {
  const Real* u = s.u.data();
  const Real* vel = s.v.data();
  const Real* acc = s.a.data();
  for (int32_t n : nodes_) {
    const size_t j = 3 * size_t(n);
    const Vec3 x1 = model_.mesh.X[size_t(n)] + Vec3(double(u[j]), double(u[j + 1]), double(u[j + 2]));
    const Vec3 vh = Vec3(double(vel[j]), double(vel[j + 1]), double(vel[j + 2])) -
                    (0.5 * dt) * Vec3(double(acc[j]), double(acc[j + 1]), double(acc[j + 2]));
    node_x1_[size_t(n)] = x1;
    node_x0_[size_t(n)] = x1 - dt * vh;
  }
  for (size_t k = 0; k < vertices_.size(); ++k) {
    const Vertex& v = vertices_[k];
    Vec3 x1(0.0), x0(0.0);
    for (size_t c = 0; c < 4 && v.node[c] >= 0; ++c) {
      x1 += v.w[c] * node_x1_[size_t(v.node[c])];
      x0 += v.w[c] * node_x0_[size_t(v.node[c])];
    }
    x1_[k] = x1;
    x0_[k] = x0;
  }
  boxes_.clear();
  for (size_t b = 0; b < vertex_sets_.size(); ++b) {
    vertex_sets_[b].fit(x0_, x1_);
    tri_sets_[b].fit(x0_, x1_);
    for (size_t c = 0; c < vertex_sets_[b].clusters(); ++c)
      boxes_.push_back({vertex_sets_[b].lo[c].x, vertex_sets_[b].hi[c].x, int32_t(b), int32_t(c), true});
    for (size_t c = 0; c < tri_sets_[b].clusters(); ++c)
      boxes_.push_back({tri_sets_[b].lo[c].x, tri_sets_[b].hi[c].x, int32_t(b), int32_t(c), false});
  }
  // Sweep and prune along x: each pair of a vertex cluster and a triangle
  // cluster whose boxes meet, of two bodies or (self contact) of one.
  std::sort(boxes_.begin(), boxes_.end(), [](const Box& x, const Box& y) { return x.lo_x < y.lo_x; });
  for (size_t i = 0; i < boxes_.size(); ++i)
    for (size_t j = i + 1; j < boxes_.size() && boxes_[j].lo_x <= boxes_[i].hi_x; ++j) {
      if (boxes_[i].vertices == boxes_[j].vertices) continue;
      const Box& vb = boxes_[i].vertices ? boxes_[i] : boxes_[j];
      const Box& tb = boxes_[i].vertices ? boxes_[j] : boxes_[i];
      if (vb.set == tb.set ? !self_ : !between_) continue;
      const ClusterSet& vs = vertex_sets_[size_t(vb.set)];
      const ClusterSet& ts = tri_sets_[size_t(tb.set)];
      const auto vc = size_t(vb.c), tc = size_t(tb.c);
      if (!boxes_meet(vs.lo[vc], vs.hi[vc], ts.lo[tc], ts.hi[tc])) continue;
      for (int32_t gv = vs.group_begin[vc]; gv < vs.group_begin[vc + 1]; ++gv) {
        const Vec3 &vlo = vs.group_lo[size_t(gv)], &vhi = vs.group_hi[size_t(gv)];
        if (!boxes_meet(vlo, vhi, ts.lo[tc], ts.hi[tc])) continue;
        for (int32_t gt = ts.group_begin[tc]; gt < ts.group_begin[tc + 1]; ++gt) {
          if (!boxes_meet(vlo, vhi, ts.group_lo[size_t(gt)], ts.group_hi[size_t(gt)])) continue;
          for (int32_t iv = vs.group_items[size_t(gv)][0]; iv < vs.group_items[size_t(gv)][1]; ++iv)
            for (int32_t it = ts.group_items[size_t(gt)][0]; it < ts.group_items[size_t(gt)][1]; ++it)
              test(vertex_first_[size_t(vb.set)] + iv, tri_first_[size_t(tb.set)] + it, dt);
        }
      }
    }
}

template <class Real>
ContactSums BodyContact<Real>::apply(State<Real>& s, double dt) {
  ContactSums sums;
  body_contacts_ = self_contacts_ = 0;
  exchanged_ = Vec3(0.0);
  if (!active_) return sums;
  find(s, dt);
  if (touched_.empty()) return sums;

  // The points: the vertex's nodes (+w) against the triangle's (-b_j w_jk),
  // each node once; a held node adds its prescribed velocity.
  points_.clear();
  point_sign_.clear();
  slot_node_.clear();
  slot_v_.clear();
  slot_m_.clear();
  const auto held = [&](int32_t n) {
    return std::binary_search(model_.constrained.begin(), model_.constrained.end(), n);
  };
  const auto velocity = [&](int32_t n) {
    const size_t j = 3 * size_t(n);
    return Vec3(double(s.v[j]), double(s.v[j + 1]), double(s.v[j + 2]));
  };
  for (int32_t v : touched_) {
    Best& best = best_[size_t(v)];
    std::array<int32_t, 16> node{};
    std::array<double, 16> w{};
    size_t count = 0;
    const auto add = [&](int32_t n, double weight) {
      for (size_t k = 0; k < count; ++k)
        if (node[k] == n) {
          w[k] += weight;
          return;
        }
      node[count] = n;
      w[count++] = weight;
    };
    const Vertex& vx = vertices_[size_t(v)];
    for (size_t c = 0; c < 4 && vx.node[c] >= 0; ++c) add(vx.node[c], vx.w[c]);
    const Tri& tri = triangles_[size_t(best.t)];
    for (size_t j = 0; j < 3; ++j) {
      const Vertex& ty = vertices_[size_t(tri[j])];
      for (size_t c = 0; c < 4 && ty.node[c] >= 0; ++c) add(ty.node[c], -best.b[int(j)] * ty.w[c]);
    }
    ContactPoint p;
    p.proxy = 0;
    p.body = -1;
    p.r = Vec3(0.0);
    p.slot.fill(-1);
    p.w.fill(0);
    p.x = x1_[size_t(v)];
    p.n = best.n;
    p.vp = Vec3(0.0);
    p.v_held = Vec3(0.0);
    p.inv_mass = 0;
    p.mu = mu_;
    size_t free = 0;
    for (size_t k = 0; k < count; ++k) {
      if (w[k] == 0) continue;
      if (held(node[k])) {
        p.v_held += w[k] * velocity(node[k]);
        continue;
      }
      int32_t& slot = slot_of_[size_t(node[k])];
      if (slot < 0) {
        slot = int32_t(slot_node_.size());
        slot_node_.push_back(node[k]);
        slot_v_.push_back(velocity(node[k]));
        slot_m_.push_back(double(model_.m[size_t(node[k])]));
      }
      p.slot[free] = slot;
      p.w[free++] = w[k];
      p.inv_mass += w[k] * w[k] / slot_m_[size_t(slot)];
    }
    if (p.inv_mass > 0) {
      points_.push_back(p);
      const int32_t tb = tri_body_[size_t(best.t)];
      (vx.body == tb ? self_contacts_ : body_contacts_) += 1;
      point_sign_.push_back(vx.body == tb ? 0.0 : vx.body < tb ? 1.0 : -1.0);
    }
    best = Best{};
  }
  touched_.clear();

  solve_.solve(points_, 1, no_bodies_, slot_v_, slot_m_);
  for (int32_t k : solve_.moved()) {
    const int32_t n = slot_node_[size_t(k)];
    const Vec3& dv = solve_.dv(k);
    const double m = slot_m_[size_t(k)];
    const size_t j = 3 * size_t(n);
    for (size_t d = 0; d < 3; ++d) {
      const double v0 = double(s.v[j + d]), a0 = double(s.a[j + d]);
      const auto v1 = Real(v0 + dv[int(d)]), a1 = Real(a0 + (2.0 / dt) * dv[int(d)]);  // eq. (9)
      s.v[j + d] = v1;
      s.a[j + d] = a1;
      sums.mv2_delta += m * (double(v1) * double(v1) - v0 * v0);
      sums.ma2_delta += m * (double(a1) * double(a1) - a0 * a0);
    }
  }
  for (size_t k = 0; k < points_.size(); ++k)
    exchanged_ += point_sign_[k] * (points_[k].jn * points_[k].n + points_[k].jt);
  solve_.clear();
  for (int32_t n : slot_node_) slot_of_[size_t(n)] = -1;
  return sums;
}

template class BodyContact<float>;
template class BodyContact<double>;

}  // namespace tactile
