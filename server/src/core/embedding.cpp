#include "core/embedding.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <string>
#include <utility>

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>

namespace tactile {
namespace {

// Tets by the cells of a uniform grid their bounding boxes overlap (CSR).
struct TetGrid {
  Vec3 lo{0.0};
  double h = 1;
  std::array<int32_t, 3> n{1, 1, 1};
  std::vector<int32_t> start, items;

  int32_t clamp_cell(double v, int d) const {
    return std::clamp(static_cast<int32_t>(std::floor((v - lo[d]) / h)), 0, n[size_t(d)] - 1);
  }
  int32_t index(int32_t i, int32_t j, int32_t k) const { return (k * n[1] + j) * n[0] + i; }
};

TetGrid build_grid(const TetMesh& mesh) {
  TetGrid g;
  const Aabb box = compute_aabb(mesh.X);
  const Vec3 size = box.size();
  const double volume = std::max(size.x * size.y * size.z, 1e-30);
  // About two tets per cell along each axis: few candidates per query, few cells per tet.
  g.h = std::max(1.5 * std::cbrt(volume / std::max(mesh.n_tets(), 1)), 1e-9 * glm::length(size) + 1e-12);
  for (int d = 0; d < 3; ++d) g.n[size_t(d)] = std::clamp(static_cast<int32_t>(std::ceil(size[d] / g.h)), 1, 256);
  g.lo = box.lo;
  const size_t cells = size_t(g.n[0]) * size_t(g.n[1]) * size_t(g.n[2]);
  std::vector<std::array<int32_t, 6>> range(mesh.tets.size());
  std::vector<int32_t> count(cells + 1, 0);
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    Vec3 lo = mesh.X[size_t(mesh.tets[e][0])], hi = lo;
    for (int32_t v : mesh.tets[e]) {
      lo = glm::min(lo, mesh.X[size_t(v)]);
      hi = glm::max(hi, mesh.X[size_t(v)]);
    }
    auto& r = range[e];
    for (int d = 0; d < 3; ++d) {
      r[size_t(d)] = g.clamp_cell(lo[d], d);
      r[size_t(d) + 3] = g.clamp_cell(hi[d], d);
    }
    for (int32_t k = r[2]; k <= r[5]; ++k)
      for (int32_t j = r[1]; j <= r[4]; ++j)
        for (int32_t i = r[0]; i <= r[3]; ++i) ++count[size_t(g.index(i, j, k)) + 1];
  }
  for (size_t c = 0; c < cells; ++c) count[c + 1] += count[c];
  g.start = count;
  g.items.resize(size_t(count[cells]));
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    const auto& r = range[e];
    for (int32_t k = r[2]; k <= r[5]; ++k)
      for (int32_t j = r[1]; j <= r[4]; ++j)
        for (int32_t i = r[0]; i <= r[3]; ++i) g.items[size_t(count[size_t(g.index(i, j, k))]++)] = int32_t(e);
  }
  return g;
}

// Barycentric coordinates of p in tet e (rest positions).
std::array<double, 4> barycentric(const TetMesh& mesh, const std::vector<glm::dmat3>& inverse, int32_t e,
                                  const Vec3& p) {
  const Vec3 l = inverse[size_t(e)] * (p - mesh.X[size_t(mesh.tets[size_t(e)][0])]);
  return {1.0 - l.x - l.y - l.z, l.x, l.y, l.z};
}

// Distance from p to the tet of corners x (0 inside), given p's barycentric coordinates there.
double distance_to_tet(const std::array<Vec3, 4>& x, const Vec3& p, const std::array<double, 4>& w) {
  if (*std::min_element(w.begin(), w.end()) >= 0) return 0;
  static constexpr int kFaces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  double best = std::numeric_limits<double>::infinity();
  for (const auto& f : kFaces) {
    const Vec3 q = compute_closest_on_triangle(p, x[size_t(f[0])], x[size_t(f[1])], x[size_t(f[2])]);
    best = std::min(best, glm::length(p - q));
  }
  return best;
}
double distance_to_tet(const TetMesh& mesh, int32_t e, const Vec3& p, const std::array<double, 4>& w) {
  const Tet& t = mesh.tets[size_t(e)];
  return distance_to_tet({mesh.X[size_t(t[0])], mesh.X[size_t(t[1])], mesh.X[size_t(t[2])], mesh.X[size_t(t[3])]}, p,
                         w);
}

// A quadratic tet's eight linear sub-tets over its ten nodes (core/mesh.hpp's
// order): the four at its corners, and the inner octahedron of its edge
// nodes cut along its shortest diagonal (between two opposite edges' nodes)
// into four around it.
std::array<Tet, 8> make_sub_tets(const TetMesh& mesh, size_t e) {
  std::array<Tet, 8> out{Tet{0, 4, 6, 7}, Tet{4, 1, 5, 8}, Tet{6, 5, 2, 9}, Tet{7, 8, 9, 3}};
  constexpr int kDiagonals[3][2] = {{4, 9}, {6, 8}, {7, 5}};  // 01-23, 02-13, 03-12
  int best = 0;
  double shortest = std::numeric_limits<double>::infinity();
  for (int d = 0; d < 3; ++d) {
    const double l =
        glm::length(mesh.X[size_t(mesh.node(e, kDiagonals[d][0]))] - mesh.X[size_t(mesh.node(e, kDiagonals[d][1]))]);
    if (l < shortest) {
      shortest = l;
      best = d;
    }
  }
  const int p = kDiagonals[best][0], q = kDiagonals[best][1];
  // The other four edge nodes in a ring: neighbours share a corner.
  std::array<int, 4> ring{};
  int n = 0;
  for (int a = 4; a < 10; ++a)
    if (a != p && a != q) ring[size_t(n++)] = a;
  auto share = [](int a, int b) {
    const int* ea = kTetEdges[a - 4];
    const int* eb = kTetEdges[b - 4];
    return ea[0] == eb[0] || ea[0] == eb[1] || ea[1] == eb[0] || ea[1] == eb[1];
  };
  if (!share(ring[0], ring[1])) std::swap(ring[1], ring[2]);
  if (!share(ring[1], ring[2])) std::swap(ring[2], ring[3]);
  for (size_t k = 0; k < 4; ++k) out[4 + k] = Tet{p, q, ring[k], ring[(k + 1) % 4]};
  return out;
}

// The sub-tet of quadratic tet e that holds the point of barycentric
// coordinates L in e (the one it is deepest in), and the point's barycentric
// coordinates there: its nodes (local, 0..9) and weights.
std::pair<Tet, std::array<double, 4>> locate_in_sub_tet(const TetMesh& mesh, size_t e, const std::array<double, 4>& L) {
  auto node_L = [](int a) {  // a node's barycentric coordinates in its tet
    std::array<double, 4> b{};
    if (a < 4) {
      b[size_t(a)] = 1;
    } else {
      b[size_t(kTetEdges[a - 4][0])] = b[size_t(kTetEdges[a - 4][1])] = 0.5;
    }
    return b;
  };
  std::pair<Tet, std::array<double, 4>> best{};
  double best_min = -std::numeric_limits<double>::infinity();
  for (const Tet& sub : make_sub_tets(mesh, e)) {
    // Solve L = sum_k lambda_k B_k with sum lambda = 1, in L1..L3: B_0 + [B_k - B_0] lambda_(1..3).
    const std::array<double, 4> b0 = node_L(sub[0]);
    glm::dmat3 A;
    for (int k = 1; k < 4; ++k) {
      const std::array<double, 4> bk = node_L(sub[size_t(k)]);
      A[k - 1] = Vec3(bk[1] - b0[1], bk[2] - b0[2], bk[3] - b0[3]);
    }
    const Vec3 l = glm::inverse(A) * Vec3(L[1] - b0[1], L[2] - b0[2], L[3] - b0[3]);
    const std::array<double, 4> lambda{1.0 - l.x - l.y - l.z, l.x, l.y, l.z};
    const double lowest = *std::min_element(lambda.begin(), lambda.end());
    if (lowest > best_min) {
      best_min = lowest;
      best = {sub, lambda};
    }
  }
  return best;
}

std::string format_point(const Vec3& p) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "(%.6g, %.6g, %.6g)", p.x, p.y, p.z);
  return buf;
}

}  // namespace

int32_t orient_surface(SurfaceMesh& s) {
  const size_t nt = s.triangles.size();
  // Each undirected edge's triangles, with the direction each runs it in.
  std::map<std::pair<int32_t, int32_t>, std::vector<std::pair<int32_t, bool>>> edges;
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const int32_t a = s.triangles[t][size_t(k)], b = s.triangles[t][size_t((k + 1) % 3)];
      edges[{std::min(a, b), std::max(a, b)}].emplace_back(int32_t(t), a < b);
    }
  std::vector<int8_t> flipped(nt, -1);  // -1: not reached yet
  int32_t flips = 0;
  std::vector<int32_t> queue, component;
  for (size_t seed = 0; seed < nt; ++seed) {
    if (flipped[seed] >= 0) continue;
    flipped[seed] = 0;
    queue.assign(1, int32_t(seed));
    component.clear();
    bool closed = true;
    while (!queue.empty()) {
      const int32_t t = queue.back();
      queue.pop_back();
      component.push_back(t);
      for (int k = 0; k < 3; ++k) {
        const int32_t a = s.triangles[size_t(t)][size_t(k)], b = s.triangles[size_t(t)][size_t((k + 1) % 3)];
        const auto& shared = edges[{std::min(a, b), std::max(a, b)}];
        if (shared.size() != 2) closed = false;
        // This triangle runs the edge a->b once its flip is applied; a consistent neighbour runs it b->a.
        const bool forward = (a < b) != (flipped[size_t(t)] == 1);
        for (const auto& [u, u_forward] : shared) {
          if (u == t || flipped[size_t(u)] >= 0) continue;
          flipped[size_t(u)] = (u_forward == forward) ? 1 : 0;
          queue.push_back(u);
        }
      }
    }
    for (int32_t t : component)
      if (flipped[size_t(t)] == 1) std::swap(s.triangles[size_t(t)][1], s.triangles[size_t(t)][2]);
    if (!closed) continue;
    double volume = 0;  // six times the signed volume enclosed
    for (int32_t t : component) {
      const Tri& f = s.triangles[size_t(t)];
      volume += glm::dot(s.vertices[size_t(f[0])], glm::cross(s.vertices[size_t(f[1])], s.vertices[size_t(f[2])]));
    }
    if (volume < 0)
      for (int32_t t : component) {
        std::swap(s.triangles[size_t(t)][1], s.triangles[size_t(t)][2]);
        flipped[size_t(t)] = int8_t(1 - flipped[size_t(t)]);
      }
  }
  for (int8_t f : flipped) flips += f == 1;
  return flips;
}

EmbeddedSurface embed_surface(const TetMesh& mesh, SurfaceMesh surface, double max_outside) {
  if (surface.triangles.empty()) throw EmbeddingError("the surface has no triangles");
  if (mesh.tets.empty()) throw EmbeddingError("the body has no tets to carry the surface");
  const int32_t nv = static_cast<int32_t>(surface.vertices.size());
  for (size_t t = 0; t < surface.triangles.size(); ++t)
    for (int32_t v : surface.triangles[t])
      if (v < 0 || v >= nv)
        throw EmbeddingError("triangle " + std::to_string(t) + " names vertex " + std::to_string(v) + " of " +
                             std::to_string(nv));
  orient_surface(surface);

  std::vector<glm::dmat3> inverse(mesh.tets.size());
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    const Tet& t = mesh.tets[e];
    const Vec3& x0 = mesh.X[size_t(t[0])];
    inverse[e] =
        glm::inverse(glm::dmat3(mesh.X[size_t(t[1])] - x0, mesh.X[size_t(t[2])] - x0, mesh.X[size_t(t[3])] - x0));
  }
  const TetGrid g = build_grid(mesh);

  EmbeddedSurface out;
  out.nodes.resize(size_t(nv));
  out.weights.resize(size_t(nv));
  out.tet.resize(size_t(nv));
  out.outside.resize(size_t(nv));
  const int32_t rings = static_cast<int32_t>(std::ceil(max_outside / g.h)) + 1;
  for (int32_t v = 0; v < nv; ++v) {
    const Vec3& p = surface.vertices[size_t(v)];
    const std::array<int32_t, 3> c{g.clamp_cell(p.x, 0), g.clamp_cell(p.y, 1), g.clamp_cell(p.z, 2)};
    int32_t best = -1;
    double best_distance = std::numeric_limits<double>::infinity(), best_min = -std::numeric_limits<double>::infinity();
    // Rings of cells around p's, nearest first; a tet holding p ends the search. A ring r cells out is at least
    // (r - 1) h away from p (p may sit anywhere in its cell, or outside the grid).
    for (int32_t r = 0; r <= rings; ++r) {
      if (best >= 0 && (best_distance == 0 || (r - 1) * g.h > best_distance)) break;
      for (int32_t k = c[2] - r; k <= c[2] + r; ++k)
        for (int32_t j = c[1] - r; j <= c[1] + r; ++j)
          for (int32_t i = c[0] - r; i <= c[0] + r; ++i) {
            if (std::max({std::abs(i - c[0]), std::abs(j - c[1]), std::abs(k - c[2])}) != r) continue;
            if (i < 0 || j < 0 || k < 0 || i >= g.n[0] || j >= g.n[1] || k >= g.n[2]) continue;
            const int32_t cell = g.index(i, j, k);
            for (int32_t q = g.start[size_t(cell)]; q < g.start[size_t(cell) + 1]; ++q) {
              const int32_t e = g.items[size_t(q)];
              const std::array<double, 4> w = barycentric(mesh, inverse, e, p);
              const double lowest = *std::min_element(w.begin(), w.end());
              // Inside (to round-off): the tet p is deepest in. Outside: the nearest.
              const double d = lowest >= -1e-12 ? 0.0 : distance_to_tet(mesh, e, p, w);
              if (d < best_distance || (d == 0 && best_distance == 0 && lowest > best_min)) {
                best = e;
                best_distance = d;
                best_min = lowest;
              }
            }
          }
    }
    if (best < 0 || best_distance > max_outside) {
      std::string how = best < 0 ? "no tet within " + std::to_string(max_outside) + " m"
                                 : std::to_string(best_distance) + " m from the nearest tet";
      throw EmbeddingError("vertex " + std::to_string(v) + " at " + format_point(p) + " is outside the body: " + how +
                           " (max_outside " + std::to_string(max_outside) + " m)");
    }
    out.tet[size_t(v)] = best;
    out.nodes[size_t(v)] = mesh.tets[size_t(best)];
    out.weights[size_t(v)] = barycentric(mesh, inverse, best, p);
    out.outside[size_t(v)] = best_distance;
    if (mesh.quadratic()) {  // the sub-tet of the ten nodes that holds it
      const auto [sub, lambda] = locate_in_sub_tet(mesh, size_t(best), out.weights[size_t(v)]);
      std::array<Vec3, 4> x;
      for (size_t k = 0; k < 4; ++k) {
        out.nodes[size_t(v)][k] = mesh.node(size_t(best), sub[k]);
        x[k] = mesh.X[size_t(out.nodes[size_t(v)][k])];
      }
      out.weights[size_t(v)] = lambda;
      // (Outside the body, a vertex may stand farther from its sub-tet than from the tet: contact's broad
      // phase pads the nodes' box by this.)
      out.outside[size_t(v)] = distance_to_tet(x, p, lambda);
    }
  }
  out.rest = std::move(surface);
  return out;
}

void compute_embedded_positions(const EmbeddedSurface& e, std::span<const Vec3> x, std::span<Vec3> out) {
  for (size_t v = 0; v < e.nodes.size(); ++v) {
    const Tet& n = e.nodes[v];
    const auto& w = e.weights[v];
    out[v] = w[0] * x[size_t(n[0])] + w[1] * x[size_t(n[1])] + w[2] * x[size_t(n[2])] + w[3] * x[size_t(n[3])];
  }
}

}  // namespace tactile
