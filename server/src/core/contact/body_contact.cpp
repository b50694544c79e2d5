#include "core/contact/body_contact.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/geometric.hpp>

namespace tactile {

namespace {

constexpr int32_t kClusterItems = 32, kGroupItems = 8;
// How deep behind a triangle a vertex that did not cross it this step still
// counts as touching it, in its longest edge: a resting contact sinks a
// fraction of a step's travel; a vertex deeper than this is in the body
// beyond the triangle's reach (its far side).
constexpr double kBand = 0.25;
constexpr double kSolveTolerance = 1e-3;
// Or until no velocity changes by more than would move a vertex this part of
// the slop over a step: points that share nodes both ways (a vertex on a
// face whose corner is on the vertex's faces) converge slowly, and what is
// left then is far below any depth the contact allows. (Ten times it left
// organ_bed.json's organ ringing on its bed,
// Simulation.TheOrganSettlesOnItsBedWithoutRinging.)
constexpr double kSweepDepth = 0.001;
// The least depth, in the shortest edge of any surface, that a vertex
// ahead of a face must be bound for by the next step to be given a point
// now.
constexpr double kAheadSlop = 0.01;
// A surface vertex is smooth when each of its triangles' normals at rest is
// within this cosine of their area-weighted mean (about 20 degrees): a
// vertex of a face's interior, or of a gently curved surface, not of an edge
// or a corner.
constexpr double kSmoothCos = 0.94;
// A second face across a rim from the one a vertex touches gets a point of
// its own when their normals differ by more than this cosine (about 10
// degrees): a sharp corner held on one face of a faceted surface would
// otherwise slide along it into the next. (Nearly flush faces: the one point
// holds it.)
constexpr double kRimCos = 0.985;
// Two bodies' surfaces whose mean edges differ by less than this fraction
// are alike: the one of the lower index is then the slave.
constexpr double kAlikeEdges = 0.05;
// The least nodes, listed vertices or candidate pairs a part of a pass split
// over threads takes.
constexpr size_t kPartItems = 256;

}  // namespace

template <class Real>
BodyContact<Real>::BodyContact(const Model<Real>& model, ParallelFor* parallel) : model_(model) {
  between_ = model.effects.body_contact && model.bodies.size() > 1;
  self_ = model.effects.self_contact;
  active_ = between_ || self_;
  mu_ = model.effects.body_friction;
  if (model.effects.body_depth_tolerance > 0) slop_ = model.effects.body_depth_tolerance;
  alpha_ = model.effects.damping ? model.effects.alpha : 0.0;
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
    const std::vector<size_t> order = morton_order(rest, compute_aabb(rest));
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
    for (size_t k : morton_order(centroids, compute_aabb(centroids))) {
      const Tri& t = ts[k];
      triangles_.push_back(t);
      tri_body_.push_back(int32_t(b));
      double longest = 0;
      for (int c = 0; c < 3; ++c) {
        const double edge =
            glm::length(vertices_[size_t(t[size_t(c)])].X - vertices_[size_t(t[size_t((c + 1) % 3)])].X);
        longest = std::max(longest, edge);
        if (edge > 0 && !(model.effects.body_depth_tolerance > 0)) slop_ = std::min(slop_, kAheadSlop * edge);
      }
      tri_band_.push_back(kBand * longest);
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
  node_x1_.assign(size_t(model.n_nodes), Vec3(0.0));  // (sparse: only nodes_ are written)
  node_x0_.assign(size_t(model.n_nodes), Vec3(0.0));
  node_x2_.assign(size_t(model.n_nodes), Vec3(0.0));
  x_.assign(vertices_.size(), {Vec3(0.0), Vec3(0.0), Vec3(0.0)});
  vertex_stamp_.assign(vertices_.size(), 0u);
  tri_stamp_.assign(triangles_.size(), 0u);
  frame_stamp_.assign(triangles_.size(), 0u);
  vertex_listed_.assign(vertices_.size(), 0u);
  tri_listed_.assign(triangles_.size(), 0u);
  frames_.assign(triangles_.size(), Frame{});
  for (int32_t n : nodes_) nodes_body_.push_back(model.node_body[size_t(n)]);
  const size_t n_bodies = vertex_sets_.size();
  move_.assign(n_bodies, 0.0);
  ahead_.assign(n_bodies, 0.0);
  drift_.assign(n_bodies, 0.0);
  node_lo_.assign(n_bodies, Vec3(0.0));
  node_hi_.assign(n_bodies, Vec3(0.0));
  gain_max_.assign(n_bodies, 1.0);
  const auto gains = [&](const ClusterSet& set) {
    std::vector<double> gain(set.clusters(), 0.0);
    for (size_t c = 0; c < set.clusters(); ++c)
      for (int32_t m = set.vertex_begin[size_t(set.group_begin[c])];
           m < set.vertex_begin[size_t(set.group_begin[c + 1])]; ++m) {
        double sum = 0;
        for (double w : vertices_[size_t(set.vertices[size_t(m)])].w) sum += std::fabs(w);
        gain[c] = std::max(gain[c], sum);
      }
    return gain;
  };
  for (size_t b = 0; b < n_bodies; ++b) {
    vertex_gain_.push_back(gains(vertex_sets_[b]));
    tri_gain_.push_back(gains(tri_sets_[b]));
    for (double g : vertex_gain_[b]) gain_max_[b] = std::max(gain_max_[b], g);
    std::vector<double> band(tri_sets_[b].clusters(), 0.0);  // the most of its triangles'
    for (size_t c = 0; c < band.size(); ++c)
      for (int32_t g = tri_sets_[b].group_begin[c]; g < tri_sets_[b].group_begin[c + 1]; ++g)
        for (int32_t i = tri_sets_[b].group_items[size_t(g)][0]; i < tri_sets_[b].group_items[size_t(g)][1]; ++i)
          band[c] = std::max(band[c], tri_band_[size_t(tri_first_[b] + i)]);
    band_max_.push_back(band.empty() ? 0.0 : *std::max_element(band.begin(), band.end()));
    tri_band_of_.push_back(std::move(band));
    vertex_refit_.emplace_back(vertex_sets_[b].clusters(), -std::numeric_limits<double>::infinity());
    tri_refit_.emplace_back(tri_sets_[b].clusters(), -std::numeric_limits<double>::infinity());
    std::vector<Vec3> rest;
    for (int32_t v = vertex_first_[b]; v < (b + 1 < n_bodies ? vertex_first_[b + 1] : int32_t(vertices_.size())); ++v)
      rest.push_back(vertices_[size_t(v)].X);
    refit_drift_.push_back(0.005 * glm::length(compute_aabb(rest).size()));
  }
  // The smooth vertices and each body's mean edge at rest, for the pass
  // that tests a pair of bodies one way across their smooth patches (master_).
  std::vector<Vec3> normal_sum(vertices_.size(), Vec3(0.0));
  std::vector<double> edge_sum(n_bodies, 0.0);
  std::vector<int64_t> edges(n_bodies, 0);
  for (size_t t = 0; t < triangles_.size(); ++t) {
    const Tri& tri = triangles_[t];
    const Vec3 a = vertices_[size_t(tri[0])].X, b = vertices_[size_t(tri[1])].X, c = vertices_[size_t(tri[2])].X;
    const Vec3 area2 = glm::cross(b - a, c - a);
    for (int32_t v : tri) normal_sum[size_t(v)] += area2;
    edge_sum[size_t(tri_body_[t])] += glm::length(b - a) + glm::length(c - b) + glm::length(a - c);
    edges[size_t(tri_body_[t])] += 3;
  }
  smooth_.assign(vertices_.size(), 1);
  for (size_t t = 0; t < triangles_.size(); ++t) {
    const Tri& tri = triangles_[t];
    const Vec3 a = vertices_[size_t(tri[0])].X;
    const Vec3 area2 = glm::cross(vertices_[size_t(tri[1])].X - a, vertices_[size_t(tri[2])].X - a);
    const double len = glm::length(area2);
    for (int32_t v : tri) {
      const double mean = glm::length(normal_sum[size_t(v)]);
      if (!(len > 0 && mean > 0 && glm::dot(area2, normal_sum[size_t(v)]) >= kSmoothCos * len * mean))
        smooth_[size_t(v)] = 0;
    }
  }
  master_.assign(n_bodies * n_bodies, 0);
  for (size_t a = 0; a < n_bodies; ++a)
    for (size_t b = 0; b < n_bodies; ++b) {
      if (a == b || edges[a] == 0 || edges[b] == 0) continue;
      const double ea = edge_sum[a] / double(edges[a]), eb = edge_sum[b] / double(edges[b]);
      master_[a * n_bodies + b] = ea > (1 + kAlikeEdges) * eb || (ea >= (1 - kAlikeEdges) * eb && a > b) ? 1 : 0;
    }
  best_.assign(vertices_.size(), Best{});
  second_.assign(vertices_.size(), Best{});
  tri_lo_.assign(triangles_.size(), Vec3(0.0));
  body_lo_.assign(vertex_sets_.size(), Vec3(0.0));
  margin_ = *std::min_element(refit_drift_.begin(), refit_drift_.end());
  node_listed_.assign(nodes_.size(), Vec3(0.0));
  body_hi_ = body_lo_;
  tri_hi_.assign(triangles_.size(), Vec3(0.0));
  slot_of_.assign(size_t(model.n_nodes), -1);
  held_.assign(size_t(model.n_nodes), 0);
  for (int32_t n : model.constrained) held_[size_t(n)] = 1;
  solve_.reserve(nodes_.size(), 1, vertices_.size());
  // Threads only where a part has enough to do to pay for the hand-off.
  if (parallel && parallel->workers() > 1 && nodes_.size() >= 2 * kPartItems) {
    parallel_ = parallel;
    node_parts_ = int32_t(std::min<size_t>(size_t(parallel->workers()), nodes_.size() / kPartItems));
  }
  node_sums_.resize(size_t(node_parts_));
  for (NodeSums& sums : node_sums_) {
    sums.move.assign(n_bodies, 0.0);
    sums.ahead = sums.listed = sums.jump = sums.move;
    sums.lo.assign(n_bodies, Vec3(0.0));
    sums.hi = sums.lo;
  }
}

template <class Real>
bool BodyContact<Real>::over(int32_t t, size_t end, const Vec3& p, double depth, Vec3& b, double* off) const {
  const Tri& tri = triangles_[size_t(t)];
  const Vec3& a = x_[size_t(tri[0])][end];
  const Vec3 e1 = x_[size_t(tri[1])][end] - a, e2 = x_[size_t(tri[2])][end] - a;
  const Vec3 q = p - a;
  const double d00 = glm::dot(e1, e1), d01 = glm::dot(e1, e2), d11 = glm::dot(e2, e2);
  const double d20 = glm::dot(q, e1), d21 = glm::dot(q, e2);
  const double den = d00 * d11 - d01 * d01;
  if (!(den > 0)) return false;
  b[1] = (d11 * d20 - d01 * d21) / den;
  b[2] = (d00 * d21 - d01 * d20) / den;
  b[0] = 1.0 - b[1] - b[2];
  if (off) *off = 0;
  if (b[0] >= 0 && b[1] >= 0 && b[2] >= 0) return true;
  // Out of it by no more than the depth: behind a corner or an edge where
  // the surface bends (a dent, a rim, two bodies' nodes meeting), the
  // projection falls between the faces that meet there, out of each by
  // about the depth times the bend, and the vertex must still count. Its
  // point is then the triangle's nearest (the coordinates clamped).
  const Vec3 n = glm::cross(e1, e2);
  const double len = glm::length(n);
  const Vec3 c[3] = {a, a + e1, a + e2};
  double out = 0;
  for (int k = 0; k < 3; ++k) {  // in the plane, out of each edge (outward normal edge x n)
    const Vec3 edge = c[(k + 1) % 3] - c[k];
    out = std::max(out, glm::dot(p - c[k], glm::cross(edge, n)) / (glm::length(edge) * len));
  }
  if (out > depth) return false;
  if (off) *off = out;
  b = glm::max(b, Vec3(0.0));
  b /= b[0] + b[1] + b[2];
  return true;
}

template <class Real>
bool BodyContact<Real>::comes_behind(int32_t v, int32_t t, Vec3& b) const {
  const Tri& tri = triangles_[size_t(t)];
  const Vec3& a = x_[size_t(tri[0])][2];
  const Vec3 n2 = glm::cross(x_[size_t(tri[1])][2] - a, x_[size_t(tri[2])][2] - a);
  const double len = glm::length(n2);
  if (!(len > 0)) return false;
  const Vec3& p2 = x_[size_t(v)][2];
  const double depth = -glm::dot(p2 - a, n2) / len;
  // (Not for a sink far under the surface's accuracy: a resting vertex's
  // step of weight, which the paper's rule takes up the step after; points
  // for those would cost most of the solve and change nothing one can see.)
  return depth > slop_ && over(t, 2, p2, depth, b);
}

template <class Real>
double BodyContact<Real>::outside_edges(const Vec3& p, int32_t t) const {
  const Frame& f = frames_[size_t(t)];
  if (!f.valid) return 0.0;
  double out = -std::numeric_limits<double>::infinity();
  for (size_t k = 0; k < 3; ++k) out = std::max(out, (glm::dot(p, f.m[k]) - f.mo[k]) / glm::length(f.m[k]));
  return out;
}

template <class Real>
bool BodyContact<Real>::over_now(int32_t t, const Vec3& p, double depth, Vec3& b, double& off) const {
  // over() at t_{n+1}, from the frame: the corner across edge k is k + 2,
  // its coordinate the area p makes with the edge over the triangle's.
  const Frame& f = frames_[size_t(t)];
  if (!f.valid) return false;
  for (size_t k = 0; k < 3; ++k) b[int((k + 2) % 3)] = (f.mo[k] - glm::dot(p, f.m[k])) * f.inv_area2;
  off = 0;
  if (b[0] >= 0 && b[1] >= 0 && b[2] >= 0) return true;
  for (size_t k = 0; k < 3; ++k) off = std::max(off, (glm::dot(p, f.m[k]) - f.mo[k]) / glm::length(f.m[k]));
  if (off > depth) return false;
  b = glm::max(b, Vec3(0.0));
  b /= b[0] + b[1] + b[2];
  return true;
}

template <class Real>
bool BodyContact<Real>::near_at_rest(int32_t v, int32_t t) const {
  // Self contact: not within the triangle's own neighbourhood at rest,
  // twice its longest edge.
  const double reach = 2.0 * tri_band_[size_t(t)] / kBand;
  for (int32_t c : triangles_[size_t(t)])
    if (glm::length(vertices_[size_t(c)].X - vertices_[size_t(v)].X) < reach) return true;
  return false;
}

template <class Real>
const typename BodyContact<Real>::Frame& BodyContact<Real>::frame(int32_t t) {
  if (frame_stamp_[size_t(t)] != stamp_) {
    for (int32_t c : triangles_[size_t(t)]) vertex_at(c);
    make_frame(t);
  }
  return frames_[size_t(t)];
}

template <class Real>
void BodyContact<Real>::make_frame(int32_t t) {
  frame_stamp_[size_t(t)] = stamp_;
  Frame& f = frames_[size_t(t)];
  const Tri& tri = triangles_[size_t(t)];
  const Vec3& a = x_[size_t(tri[0])][1];
  const Vec3& b = x_[size_t(tri[1])][1];
  const Vec3& c = x_[size_t(tri[2])][1];
  const Vec3 nn = glm::cross(b - a, c - a);
  const double len2 = glm::dot(nn, nn);
  f.valid = len2 > 0;
  if (!f.valid) return;
  f.inv_area2 = 1.0 / std::sqrt(len2);
  f.n = nn * f.inv_area2;
  f.off = glm::dot(f.n, a);
  // Out of the body is n; the corners run counter-clockwise about it, so
  // edge x n points out of the triangle, |edge| long.
  f.m[0] = glm::cross(b - a, f.n);
  f.m[1] = glm::cross(c - b, f.n);
  f.m[2] = glm::cross(a - c, f.n);
  f.mo[0] = glm::dot(f.m[0], a);
  f.mo[1] = glm::dot(f.m[1], b);
  f.mo[2] = glm::dot(f.m[2], c);
}

template <class Real>
const std::array<Vec3, 3>& BodyContact<Real>::vertex_at(int32_t v) {
  if (vertex_stamp_[size_t(v)] != stamp_) {
    vertex_stamp_[size_t(v)] = stamp_;
    const Vertex& vx = vertices_[size_t(v)];
    Vec3 x0(0.0), x1(0.0), x2(0.0);
    for (size_t c = 0; c < 4 && vx.node[c] >= 0; ++c) {
      x0 += vx.w[c] * node_x0_[size_t(vx.node[c])];
      x1 += vx.w[c] * node_x1_[size_t(vx.node[c])];
      x2 += vx.w[c] * node_x2_[size_t(vx.node[c])];
    }
    x_[size_t(v)] = {x0, x1, x2};
  }
  return x_[size_t(v)];
}

template <class Real>
void BodyContact<Real>::keep_boxes(ClusterSet& set, std::vector<double>& refit_at, const std::vector<double>& gain,
                                   const std::vector<double>& band, size_t body) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  const double drift = drift_[body];
  for (size_t c = 0; c < set.clusters(); ++c) {
    // A vertex moves at most sum_k |w_k| times as far as its nodes.
    double grow = gain[c] * (drift - refit_at[c]);
    if (!(drift - refit_at[c] <= refit_drift_[body])) {
      bool near = false;
      for (size_t o = 0; o < vertex_sets_.size() && !near; ++o)
        if (o == body ? self_ : between_)
          near = boxes_meet(set.lo[c] - Vec3(grow), set.hi[c] + Vec3(grow), body_lo_[o], body_hi_[o]);
      if (near) {  // refitted to its vertices at both ends of this step
        refit_at[c] = drift;
        grow = 0;
        set.lo[c] = Vec3(inf);
        set.hi[c] = Vec3(-inf);
        for (int32_t g = set.group_begin[c]; g < set.group_begin[c + 1]; ++g) {
          Vec3 glo(inf), ghi(-inf);
          for (int32_t m = set.vertex_begin[size_t(g)]; m < set.vertex_begin[size_t(g) + 1]; ++m) {
            const std::array<Vec3, 3>& x = vertex_at(set.vertices[size_t(m)]);
            glo = glm::min(glo, glm::min(x[0], x[1]));
            ghi = glm::max(ghi, glm::max(x[0], x[1]));
          }
          set.group_lo[size_t(g)] = glo;
          set.group_hi[size_t(g)] = ghi;
          set.lo[c] = glm::min(set.lo[c], glo);
          set.hi[c] = glm::max(set.hi[c], ghi);
        }
      }
    }
    set.grow[c] = grow + (band.empty() ? 0.0 : band[c] + margin_ + ahead_listed_);
  }
}

template <class Real>
void BodyContact<Real>::place_nodes(int32_t p) {
  // Nodes [k0, k1): where each is at both ends of the step and where the
  // next takes it, and the part's per-body largest moves and box.
  const size_t k0 = nodes_.size() * size_t(p) / size_t(node_parts_);
  const size_t k1 = nodes_.size() * size_t(p + 1) / size_t(node_parts_);
  const Real* u = cur_->u.data();
  const Real* vel = cur_->v.data();
  const Real* acc = cur_->a.data();
  const double dt = cur_dt_;
  NodeSums& sums = node_sums_[size_t(p)];
  std::fill(sums.move.begin(), sums.move.end(), 0.0);
  std::fill(sums.ahead.begin(), sums.ahead.end(), 0.0);
  std::fill(sums.listed.begin(), sums.listed.end(), 0.0);
  std::fill(sums.jump.begin(), sums.jump.end(), 0.0);
  std::fill(sums.lo.begin(), sums.lo.end(), Vec3(std::numeric_limits<double>::infinity()));
  std::fill(sums.hi.begin(), sums.hi.end(), Vec3(-std::numeric_limits<double>::infinity()));
  for (size_t k = k0; k < k1; ++k) {
    const int32_t n = nodes_[k];
    const size_t b = size_t(nodes_body_[k]), j = 3 * size_t(n);
    const Vec3 x1 = model_.mesh.X[size_t(n)] + Vec3(double(u[j]), double(u[j + 1]), double(u[j + 2]));
    const Vec3 v1(double(vel[j]), double(vel[j + 1]), double(vel[j + 2]));
    const Vec3 a1(double(acc[j]), double(acc[j + 1]), double(acc[j + 2]));
    const Vec3 x0 = x1 - dt * (v1 - (0.5 * dt) * a1);
    // Where the next step takes it under this one's velocity and forces, as
    // eq. (7) will over a step of the horizon h (apply()): x_{n+2} = x_{n+1}
    // + h v_{n+1} + h^2/2 a_{n+1}.
    const Vec3 x2 = x1 + horizon_ * v1 + (0.5 * horizon_ * horizon_) * a1;
    // (Where the step before ended: x0 to rounding, unless the state was
    // reset or replaced since; the kept boxes grow by that jump too.)
    // (Squares, their roots taken once per body: the largest move plus the
    // largest jump bounds any node's sum.)
    const Vec3 jump = x0 - node_x1_[size_t(n)], step = x1 - x0, next = x2 - x1;
    const Vec3 from_listed1 = x1 - node_listed_[k], from_listed0 = x0 - node_listed_[k];
    node_x1_[size_t(n)] = x1;
    node_x0_[size_t(n)] = x0;
    node_x2_[size_t(n)] = x2;
    sums.ahead[b] = std::max(sums.ahead[b], glm::dot(next, next));
    sums.move[b] = std::max(sums.move[b], glm::dot(step, step));
    sums.jump[b] = std::max(sums.jump[b], glm::dot(jump, jump));
    sums.listed[b] =
        std::max({sums.listed[b], glm::dot(from_listed1, from_listed1), glm::dot(from_listed0, from_listed0)});
    sums.lo[b] = glm::min(sums.lo[b], glm::min(x0, x1));
    sums.hi[b] = glm::max(sums.hi[b], glm::max(x0, x1));
  }
}

template <class Real>
void BodyContact<Real>::place_listed(int32_t p) {
  const size_t n = listed_vertices_.size();
  for (size_t k = n * size_t(p) / size_t(node_parts_); k < n * size_t(p + 1) / size_t(node_parts_); ++k)
    vertex_at(listed_vertices_[k]);
}

template <class Real>
void BodyContact<Real>::frame_listed(int32_t p) {
  const size_t n = listed_tris_.size();
  for (size_t k = n * size_t(p) / size_t(node_parts_); k < n * size_t(p + 1) / size_t(node_parts_); ++k)
    make_frame(listed_tris_[k]);  // (its corners are listed vertices, placed: this writes the frame alone)
}

template <class Real>
void BodyContact<Real>::find(const State<Real>& s, double dt) {
  const size_t n_bodies = vertex_sets_.size();
  cur_ = &s;
  cur_dt_ = dt;
  // The nodes at both ends of the step, each body's largest move since the
  // step before (over it, and any jump between them) and a box around all
  // its vertices (its nodes' box, widened by the largest sum_k |w_k| of its
  // vertices about its centre).
  run_parallel(
      parallel_, node_parts_, [](void* self, int32_t p) { static_cast<BodyContact*>(self)->place_nodes(p); }, this);
  std::fill(move_.begin(), move_.end(), 0.0);
  std::fill(ahead_.begin(), ahead_.end(), 0.0);
  std::vector<double>& listed_move = node_sums_[0].listed;  // (gathered into part 0's)
  for (size_t b = 0; b < n_bodies; ++b) {
    node_lo_[b] = node_sums_[0].lo[b];
    node_hi_[b] = node_sums_[0].hi[b];
    double jump = 0;
    for (const NodeSums& part : node_sums_) {
      move_[b] = std::max(move_[b], part.move[b]);
      jump = std::max(jump, part.jump[b]);
      ahead_[b] = std::max(ahead_[b], part.ahead[b]);
      listed_move[b] = std::max(listed_move[b], part.listed[b]);
      node_lo_[b] = glm::min(node_lo_[b], part.lo[b]);
      node_hi_[b] = glm::max(node_hi_[b], part.hi[b]);
    }
    move_[b] = std::sqrt(move_[b]) + std::sqrt(jump);
    ahead_[b] = std::sqrt(ahead_[b]);
    listed_move[b] = std::sqrt(listed_move[b]);
  }
  // How far a vertex may come towards a triangle over the next step: what
  // the pairs are listed ahead for (twice the fastest body's, by either side).
  double ahead = 0;
  for (size_t b = 0; b < n_bodies; ++b) {
    drift_[b] += move_[b];
    ahead = std::max(ahead, 2.0 * gain_max_[b] * ahead_[b]);
  }
  if (++stamp_ == 0) {  // (wrapped: no vertex or triangle may keep a stamp that looks current)
    std::fill(vertex_stamp_.begin(), vertex_stamp_.end(), 0u);
    std::fill(tri_stamp_.begin(), tri_stamp_.end(), 0u);
    std::fill(frame_stamp_.begin(), frame_stamp_.end(), 0u);
    std::fill(vertex_listed_.begin(), vertex_listed_.end(), 0u);
    std::fill(tri_listed_.begin(), tri_listed_.end(), 0u);
    stamp_ = 1;
  }
  // The candidate pairs, kept while no vertex and no triangle can have moved
  // by half the margin since they were listed: a pair left out then was
  // farther apart than the margin, so it cannot touch yet.
  // (How far each node is from where it was then: an oscillation does not
  // add up, as the drift of the kept boxes does.)
  bool rebuild = !listed_;
  for (size_t b = 0; b < n_bodies; ++b) rebuild = rebuild || 2.0 * gain_max_[b] * listed_move[b] >= margin_;
  // (And while they were listed far enough ahead for this step's speeds.)
  rebuild = rebuild || ahead > ahead_listed_;
  if (rebuild) {
    // Half as far again ahead as now needs, and never less than half the
    // margin: a body speeding up, or at rest and trembling, renews them once
    // in a while, not each step.
    ahead_listed_ = 1.5 * ahead;
    for (size_t b = 0; b < n_bodies; ++b) {
      const Vec3 c = 0.5 * (node_lo_[b] + node_hi_[b]), half = 0.5 * (node_hi_[b] - node_lo_[b]);
      const Vec3 reach(band_max_[b] + margin_ + ahead_listed_);
      body_lo_[b] = c - gain_max_[b] * half - reach;
      body_hi_[b] = c + gain_max_[b] * half + reach;
    }
    list_candidates();
    std::sort(candidates_.begin(), candidates_.end());
    for (size_t k = 0; k < nodes_.size(); ++k) node_listed_[k] = node_x1_[size_t(nodes_[k])];
    listed_ = true;
    // What the pairs read each step, and the parts they are tested in: about
    // kPartItems pairs each, four a thread so that uneven parts even out.
    // (Each once: marked with the listing's stamp, which no other listing has.)
    listed_vertices_.clear();
    listed_tris_.clear();
    const auto list_once = [&](std::vector<uint32_t>& mark, std::vector<int32_t>& list, int32_t i) {
      if (mark[size_t(i)] == stamp_) return;
      mark[size_t(i)] = stamp_;
      list.push_back(i);
    };
    for (const auto& [v, t] : candidates_) {
      list_once(vertex_listed_, listed_vertices_, v);
      if (tri_listed_[size_t(t)] == stamp_) continue;
      list_once(tri_listed_, listed_tris_, t);
      for (int32_t c : triangles_[size_t(t)]) list_once(vertex_listed_, listed_vertices_, c);
    }
    const size_t parts =
        parallel_ ? std::clamp<size_t>(candidates_.size() / kPartItems, 1, 4 * size_t(parallel_->workers())) : 1;
    narrow_begin_.assign(1, 0);
    for (size_t p = 1; p < parts; ++p) {
      auto k = int32_t(candidates_.size() * p / parts);
      while (k > narrow_begin_.back() && k < int32_t(candidates_.size()) &&
             candidates_[size_t(k)][0] == candidates_[size_t(k) - 1][0])
        ++k;
      if (k > narrow_begin_.back() && k < int32_t(candidates_.size())) narrow_begin_.push_back(k);
    }
    narrow_begin_.push_back(int32_t(candidates_.size()));
    narrow_touched_.resize(narrow_begin_.size() - 1);
  }
  // The listed pairs' vertices placed and their triangles framed, then the
  // pairs tested vertex by vertex, each part on its own vertices.
  run_parallel(
      parallel_, node_parts_, [](void* self, int32_t p) { static_cast<BodyContact*>(self)->place_listed(p); }, this);
  run_parallel(
      parallel_, node_parts_, [](void* self, int32_t p) { static_cast<BodyContact*>(self)->frame_listed(p); }, this);
  run_parallel(
      parallel_, int32_t(narrow_touched_.size()),
      [](void* self, int32_t p) { static_cast<BodyContact*>(self)->narrow(p); }, this);
  for (const std::vector<int32_t>& part : narrow_touched_) touched_.insert(touched_.end(), part.begin(), part.end());
}

template <class Real>
void BodyContact<Real>::narrow(int32_t p) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  const auto neighbours = [&](int32_t t, int32_t u) {
    for (int32_t a : triangles_[size_t(t)])
      for (int32_t b : triangles_[size_t(u)])
        if (a == b) return true;
    return false;
  };
  std::vector<int32_t>& touched = narrow_touched_[size_t(p)];
  touched.clear();
  // The listed pairs, vertex by vertex. Of the faces whose projection holds
  // the vertex, the nearest says where it is: behind it, the vertex is in
  // the body and touches it (eq. 11); in front of it, the vertex is
  // outside, whatever faces meeting that one at a rim it is also behind, and
  // can only come to touch a face it is in front of: the nearest that the
  // next step, as this one's velocities and forces have it, takes it behind,
  // its projection over the face then (speculative contact). A face it is
  // behind by more than its band, not having crossed it this step, is the
  // body's far side and says nothing.
  const auto end = size_t(narrow_begin_[size_t(p) + 1]);
  for (auto i = size_t(narrow_begin_[size_t(p)]); i < end;) {
    const int32_t v = candidates_[i][0];
    const std::array<Vec3, 3>& x = x_[size_t(v)];
    const size_t first = i;
    while (i < end && candidates_[i][0] == v) ++i;
    // Where it is: the nearest face that holds it (none nearer than its
    // plane). In front of every plane, it is outside whichever holds it.
    const auto gap = [&](size_t k) {
      const Frame& f = frames_[size_t(candidates_[k][1])];
      return f.valid ? glm::dot(x[1], f.n) - f.off : inf;
    };
    bool behind_some = false;
    for (size_t k = first; k < i && !behind_some; ++k) behind_some = gap(k) < 0;
    Best nearest;
    double nearest_distance = inf;
    for (size_t k = first; k < i && behind_some; ++k) {
      const int32_t t = candidates_[k][1];
      const double d1 = gap(k);
      if (d1 > ahead_listed_ || std::fabs(d1) >= nearest_distance) continue;
      if (-d1 > tri_band_[size_t(t)]) {  // deep: only a vertex that crossed the face this step
        const Tri& tri = triangles_[size_t(t)];
        const Vec3& a0 = x_[size_t(tri[0])][0];
        const Vec3 n0 = glm::cross(x_[size_t(tri[1])][0] - a0, x_[size_t(tri[2])][0] - a0);
        if (!(glm::dot(x[0] - a0, n0) >= 0)) continue;
      }
      Vec3 b(0.0);
      double off = 0;
      if (!over_now(t, x[1], std::fabs(d1), b, off)) continue;
      // (How far from the face itself, not its plane: the face of a rim
      // that holds the vertex only by the rim's allowance is farther.)
      const double distance = off > 0 ? std::hypot(d1, off) : std::fabs(d1);
      if (distance < nearest_distance) {
        nearest = {t, d1, b, frames_[size_t(t)].n};
        nearest_distance = distance;
      }
    }
    if (nearest.t >= 0 && nearest.gap < 0) {
      touched.push_back(v);
      best_[size_t(v)] = nearest;
      // Across a rim of it (a face that shares a corner with it, its normal
      // differing by more than kRimCos): the nearest other face it is in
      // front of and the next step takes it behind by more than the slop, as
      // it slides over the rim. (Not one it is behind already: near a convex
      // rim that is every vertex under the face, and a point there would
      // push it sideways.)
      Best across;
      double across_distance = inf;
      for (size_t k = first; k < i; ++k) {
        const int32_t t = candidates_[k][1];
        const Frame& f = frames_[size_t(t)];
        if (t == nearest.t || !f.valid || glm::dot(f.n, nearest.n) > kRimCos || !neighbours(t, nearest.t)) continue;
        const double d1 = gap(k);
        if (d1 < 0 || d1 >= across_distance || d1 > ahead_listed_) continue;
        Vec3 b(0.0);
        if (comes_behind(v, t, b)) {
          across = {t, d1, b, f.n};
          across_distance = d1;
        }
      }
      second_[size_t(v)] = across;
      continue;
    }
    // Outside: the nearest face it is in front of that the next step takes
    // it behind by more than the slop. (Not one farther than the vertex and
    // the face's body can come together in the step, twice over for the
    // face's tilt.)
    const double reach = glm::length(x[2] - x[1]);
    Best coming;
    for (size_t k = first; k < i; ++k) {
      const int32_t t = candidates_[k][1];
      const double d1 = gap(k);
      if (d1 < 0 || d1 > ahead_listed_ || (coming.t >= 0 && d1 >= coming.gap)) continue;
      const auto tb = size_t(tri_body_[size_t(t)]);
      if (2.0 * (reach + gain_max_[tb] * ahead_[tb]) - d1 <= slop_) continue;
      Vec3 b(0.0);
      if (comes_behind(v, t, b)) coming = {t, d1, b, frames_[size_t(t)].n};
    }
    if (coming.t < 0) continue;
    touched.push_back(v);
    best_[size_t(v)] = coming;
  }
}

template <class Real>
void BodyContact<Real>::list_candidates() {
  const size_t n_bodies = vertex_sets_.size();
  candidates_.clear();
  // The clusters' boxes, kept between steps: grown each step by how far
  // their vertices can have moved, and refitted when they have grown by
  // half a percent of their body's size and meet a body they may touch.
  for (size_t b = 0; b < n_bodies; ++b) {
    keep_boxes(vertex_sets_[b], vertex_refit_[b], vertex_gain_[b], {}, b);
    keep_boxes(tri_sets_[b], tri_refit_[b], tri_gain_[b], tri_band_of_[b], b);
  }
  // Per pair of a body's vertices and a body's triangles (two bodies, or one
  // with self contact): the clusters of each that meet the other's whole box,
  // swept and pruned along x; each vertex cluster and triangle cluster whose
  // boxes meet is tested group by group, then item by item.
  for (size_t a = 0; a < n_bodies; ++a)
    for (size_t b = 0; b < n_bodies; ++b) {
      if (a == b ? !self_ : !between_) continue;
      const ClusterSet& vs = vertex_sets_[a];
      const ClusterSet& ts = tri_sets_[b];
      boxes_.clear();
      for (size_t c = 0; c < vs.clusters(); ++c) {
        const Vec3 g(vs.grow[c]);
        if (a == b || boxes_meet(vs.lo[c] - g, vs.hi[c] + g, body_lo_[b], body_hi_[b]))
          boxes_.push_back({vs.lo[c].x - g.x, vs.hi[c].x + g.x, int32_t(c), true});
      }
      if (boxes_.empty()) continue;
      const size_t n_vertex_boxes = boxes_.size();
      for (size_t c = 0; c < ts.clusters(); ++c) {
        const Vec3 g(ts.grow[c]);
        if (a == b || boxes_meet(ts.lo[c] - g, ts.hi[c] + g, body_lo_[a], body_hi_[a]))
          boxes_.push_back({ts.lo[c].x - g.x, ts.hi[c].x + g.x, int32_t(c), false});
      }
      if (boxes_.size() == n_vertex_boxes) continue;
      std::sort(boxes_.begin(), boxes_.end(), [](const Box& x, const Box& y) { return x.lo_x < y.lo_x; });
      for (size_t i = 0; i < boxes_.size(); ++i)
        for (size_t j = i + 1; j < boxes_.size() && boxes_[j].lo_x <= boxes_[i].hi_x; ++j) {
          if (boxes_[i].vertices == boxes_[j].vertices) continue;
          const auto vc = size_t(boxes_[i].vertices ? boxes_[i].c : boxes_[j].c);
          const auto tc = size_t(boxes_[i].vertices ? boxes_[j].c : boxes_[i].c);
          const Vec3 gv(vs.grow[vc]), gt(ts.grow[tc]);
          if (boxes_meet(vs.lo[vc] - gv, vs.hi[vc] + gv, ts.lo[tc] - gt, ts.hi[tc] + gt)) list_pairs(a, vc, b, tc);
        }
    }
}

template <class Real>
void BodyContact<Real>::list_pairs(size_t a, size_t vc, size_t b, size_t tc) {
  const ClusterSet& vs = vertex_sets_[a];
  const ClusterSet& ts = tri_sets_[b];
  const Vec3 grow_v(vs.grow[vc]), grow_t(ts.grow[tc]);
  for (int32_t gv = vs.group_begin[vc]; gv < vs.group_begin[vc + 1]; ++gv) {
    const Vec3 vlo = vs.group_lo[size_t(gv)] - grow_v, vhi = vs.group_hi[size_t(gv)] + grow_v;
    for (int32_t gt = ts.group_begin[tc]; gt < ts.group_begin[tc + 1]; ++gt) {
      const Vec3 tlo = ts.group_lo[size_t(gt)] - grow_t, thi = ts.group_hi[size_t(gt)] + grow_t;
      if (!boxes_meet(vlo, vhi, tlo, thi)) continue;
      // Vertex by vertex against the group's box, then each triangle's
      // own (its corners over the step): most pairs end here.
      for (int32_t iv = vs.group_items[size_t(gv)][0]; iv < vs.group_items[size_t(gv)][1]; ++iv) {
        const int32_t v = vertex_first_[a] + iv;
        const std::array<Vec3, 3>& x = vertex_at(v);
        const Vec3 plo = glm::min(x[0], x[1]), phi = glm::max(x[0], x[1]);
        if (!boxes_meet(plo, phi, tlo, thi)) continue;
        for (int32_t it = ts.group_items[size_t(gt)][0]; it < ts.group_items[size_t(gt)][1]; ++it) {
          const int32_t t = tri_first_[b] + it;
          if (tri_stamp_[size_t(t)] != stamp_) {
            tri_stamp_[size_t(t)] = stamp_;
            const Tri& tri = triangles_[size_t(t)];
            Vec3 lo(std::numeric_limits<double>::infinity()), hi(-std::numeric_limits<double>::infinity());
            for (int32_t c : tri) {
              const std::array<Vec3, 3>& y = vertex_at(c);
              lo = glm::min(lo, glm::min(y[0], y[1]));
              hi = glm::max(hi, glm::max(y[0], y[1]));
            }
            const Vec3 reach(tri_band_[size_t(t)] + margin_ + ahead_listed_);
            tri_lo_[size_t(t)] = lo - reach;
            tri_hi_[size_t(t)] = hi + reach;
          }
          if (!boxes_meet(plo, phi, tri_lo_[size_t(t)], tri_hi_[size_t(t)])) continue;
          // Only a vertex near the triangle's plane at either end of the
          // step: in front by at most the margin, behind by at most its
          // band and the margin (until the list is renewed each moves less
          // than that towards the other).
          const Frame& pl = frame(t);
          if (!pl.valid) continue;
          const Tri& tri = triangles_[size_t(t)];
          const Vec3& a0 = x_[size_t(tri[0])][0];
          const Vec3 n0 = glm::cross(x_[size_t(tri[1])][0] - a0, x_[size_t(tri[2])][0] - a0);
          const double len0 = glm::length(n0);
          const double d0 = len0 > 0 ? glm::dot(x[0] - a0, n0) / len0 : 0.0;
          const double d1 = glm::dot(x[1], pl.n) - pl.off;
          if (std::min(d0, d1) > margin_ + ahead_listed_ || std::max(d0, d1) < -(tri_band_[size_t(t)] + margin_))
            continue;
          // And over the triangle at t_{n+1}: its projection no farther out
          // of any edge than the two margins and its distance from the plane
          // (what the vertex and the triangle's tilt can still change).
          if (outside_edges(x[1], t) > 2.0 * margin_ + ahead_listed_ + std::fabs(d1)) continue;
          if (tri_body_[size_t(t)] == int32_t(a) && near_at_rest(v, t)) continue;
          candidates_.push_back({v, t});
        }
      }
    }
  }
}

template <class Real>
ContactSums BodyContact<Real>::apply(State<Real>& s, double dt, double horizon) {
  ContactSums sums;
  body_contacts_ = self_contacts_ = 0;
  exchanged_ = Vec3(0.0);
  if (!active_) return sums;
  given_.assign(model_.bodies.size(), Vec3(0.0));
  held_given_ = Vec3(0.0);
  impulse_sum_ = 0;
  horizon_ = std::max(dt, horizon);
  find(s, dt);
  // The work of the forces between bodies over the step, by the trapezoid
  // as the proxies' (contact.cpp): the previous step's forces on this
  // step's displacements now, this step's below.
  std::vector<std::pair<int32_t, Vec3>>& pushed = s.contact.body_pushed;
  for (const auto& [n, f] : pushed) sums.work += 0.5 * glm::dot(f, node_x1_[size_t(n)] - node_x0_[size_t(n)]);
  pushed.clear();
  if (touched_.empty()) {
    s.contact.body_impulses.clear();
    return sums;
  }
  // In vertex order, whatever order the candidates were listed in: the
  // solve's sweeps (and so its last digits) see the same points the same way.
  std::sort(touched_.begin(), touched_.end());

  // The points: the vertex's nodes (+w) against the triangle's (-b_j w_jk),
  // each node once; a held node adds its prescribed motion. The solve is
  // over the next step's travel (body_contact.hpp): each slot's velocity is
  // u = v + H a / 2 (H the horizon) and its mass half the node's, so that
  // over steps of one length its impulses are the real ones and its changes
  // 2 dv.
  points_.clear();
  point_sign_.clear();
  point_held_.clear();
  point_key_.clear();
  slot_node_.clear();
  slot_v_.clear();
  slot_m_.clear();
  const auto velocity = [&](int32_t n) {
    const size_t j = 3 * size_t(n);
    return Vec3(double(s.v[j]), double(s.v[j + 1]), double(s.v[j + 2]));
  };
  const auto acceleration = [&](int32_t n) {
    const size_t j = 3 * size_t(n);
    return Vec3(double(s.a[j]), double(s.a[j + 1]), double(s.a[j + 2]));
  };
  const auto travel = [&](int32_t n) { return velocity(n) + (0.5 * horizon_) * acceleration(n); };
  // One point: vertex v against its face `best`, its key 2 v + `which`.
  const auto make_point = [&](int32_t v, Best& best, int32_t which) {
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
    // The vertex's normal travel relative to the triangle (its gap after
    // the next step is g + h un, h the horizon), where a master's smooth
    // vertex or one in contact needs it (below).
    const bool master =
        smooth_[size_t(v)] && master_[size_t(vx.body) * vertex_sets_.size() + size_t(tri_body_[size_t(best.t)])];
    double un = 0;
    if (master || best.gap < 0) {
      Vec3 rel_u(0.0);
      for (size_t k = 0; k < count; ++k) rel_u += w[k] * travel(node[k]);
      un = glm::dot(rel_u, best.n);
    }
    // A master's smooth vertex only where the slave's vertices let it in
    // deeper than the slop, now or by the end of the next step (master_).
    if (master) {
      if (std::min(best.gap, best.gap + horizon_ * un) > -slop_) {
        best = Best{};
        return;
      }
    }
    ContactPoint& p = points_.emplace_back();  // (dropped below if it moves no free node)
    p.proxy = 0;
    p.body = -1;
    p.r = Vec3(0.0);
    p.slot.fill(-1);
    p.w.fill(0);
    p.x = x_[size_t(v)][1];
    p.n = best.n;
    p.v_held = Vec3(0.0);
    p.inv_mass = 0;
    p.mu = mu_;
    // The least relative normal travel the point may keep over the next
    // step, its gap then g + h u (h the horizon): ahead of the triangle
    // (speculative contact, as rigid-body engines use it), what brings it to the
    // triangle's plane and no farther; in contact none (it stays where it
    // is), or, deeper than the slop, back out toward it (what the sweeps
    // leave and the surfaces' turning let in would otherwise add up), no
    // faster than it came in: never more than the paper's own rule gives
    // back (restitution one over the next step), and the only push that can
    // add kinetic energy.
    const double least = best.gap >= 0 ? -best.gap / horizon_
                                       : std::min(std::max(0.0, -(best.gap + slop_) / horizon_), std::max(0.0, -un));
    p.vp = least * p.n;
    size_t free = 0;
    double held_w = 0;
    for (size_t k = 0; k < count; ++k) {
      if (w[k] == 0) continue;
      if (held_[size_t(node[k])]) {
        p.v_held += w[k] * travel(node[k]);
        held_w += w[k];
        continue;
      }
      int32_t& slot = slot_of_[size_t(node[k])];
      if (slot < 0) {
        slot = int32_t(slot_node_.size());
        slot_node_.push_back(node[k]);
        slot_v_.push_back(travel(node[k]));
        slot_m_.push_back(0.5 * double(model_.m[size_t(node[k])]));
      }
      p.slot[free] = slot;
      p.w[free++] = w[k];
      p.inv_mass += w[k] * w[k] / slot_m_[size_t(slot)];
    }
    if (!(p.inv_mass > 0)) {
      points_.pop_back();
    } else {
      const int32_t tb = tri_body_[size_t(best.t)];
      (vx.body == tb ? self_contacts_ : body_contacts_) += 1;
      point_sign_.push_back(vx.body == tb ? 0.0 : vx.body < tb ? 1.0 : -1.0);
      point_held_.push_back(held_w);
      point_key_.push_back(2 * v + which);
    }
    best = Best{};
  };
  for (int32_t v : touched_) {
    make_point(v, best_[size_t(v)], 0);
    if (second_[size_t(v)].t >= 0) make_point(v, second_[size_t(v)], 1);
  }
  touched_.clear();

  // Warm: a point (a vertex, on its first or second face) that was there
  // in the step before starts from its impulses (its normal one along today's normal, its friction in today's
  // tangent plane), all scaled by the factor that lowers the solve's
  // objective most (ImpulseSolve::warm_scale). A resting patch's points
  // persist, and its sweeps then start near their end.
  std::vector<ContactState::BodyImpulse>& before = s.contact.body_impulses;
  for (size_t k = 0, b = 0; k < points_.size() && b < before.size(); ++k) {
    while (b < before.size() && before[b].key < point_key_[k]) ++b;
    if (b == before.size() || before[b].key != point_key_[k]) continue;
    ContactPoint& c = points_[k];
    c.jn = before[b].jn;
    c.jt = before[b].jt - glm::dot(before[b].jt, c.n) * c.n;
  }
  const double warm = solve_.warm_scale(points_, slot_v_, slot_m_);
  for (ContactPoint& c : points_) {
    c.jn *= warm;
    c.jt *= warm;
  }
  // To a thousandth of the first sweep's change (a resting contact's
  // impulses are a step's weight, and a thousandth of that is far below
  // what moves a vertex by a rounding of its position), or to kSweepDepth of
  // the slop a step. Each sweep only lowers the kinetic energy of the
  // points' travel from where the guess left it, no higher than none does,
  // so stopping early adds none.
  solve_.solve(points_, 1, no_bodies_, slot_v_, slot_m_, kSolveTolerance, 2.0 * kSweepDepth * slop_ / horizon_);
  before.clear();
  for (size_t k = 0; k < points_.size(); ++k)
    if (points_[k].jn > 0) before.push_back({point_key_[k], points_[k].jn, points_[k].jt});
  // A travel change du: the acceleration change 2 du / (dt + H) and, by eq.
  // (9), the velocity change dt du / (dt + H) (apply()); its force over the
  // step by eq. (10), m q da, q = 1 + alpha dt / 2.
  const double to_a = 2.0 / (dt + horizon_), to_v = dt / (dt + horizon_), q = 1.0 + 0.5 * alpha_ * dt;
  for (int32_t k : solve_.moved()) {
    const int32_t n = slot_node_[size_t(k)];
    const Vec3 du = solve_.dv(k), dv = to_v * du, da = to_a * du;
    const double m = double(model_.m[size_t(n)]);
    const Vec3 f = (m * q) * da;
    given_[size_t(model_.node_body[size_t(n)])] += m * dv;
    sums.work += 0.5 * glm::dot(f, node_x1_[size_t(n)] - node_x0_[size_t(n)]);
    pushed.emplace_back(n, f);
    const size_t j = 3 * size_t(n);
    for (size_t d = 0; d < 3; ++d) {
      const double v0 = double(s.v[j + d]), a0 = double(s.a[j + d]);
      const auto v1 = Real(v0 + dv[int(d)]), a1 = Real(a0 + da[int(d)]);  // eq. (9)
      s.v[j + d] = v1;
      s.a[j + d] = a1;
      sums.mv2_delta += m * (double(v1) * double(v1) - v0 * v0);
      sums.ma2_delta += m * (double(a1) * double(a1) - a0 * a0);
    }
  }
  for (size_t k = 0; k < points_.size(); ++k) {
    const Vec3 J = points_[k].jn * points_[k].n + points_[k].jt;
    exchanged_ += point_sign_[k] * J;
    held_given_ += point_held_[k] * J;
    impulse_sum_ += glm::length(J);
    if (point_sign_[k] != 0) moments_.add(points_[k].jn, points_[k].x);
  }
  solve_.clear();
  for (int32_t n : slot_node_) slot_of_[size_t(n)] = -1;
  return sums;
}

template class BodyContact<float>;
template class BodyContact<double>;

}  // namespace tactile
