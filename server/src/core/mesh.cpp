#include "core/mesh.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include <glm/geometric.hpp>

namespace tactile {

// Closest point of triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5).
Vec3 compute_closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
  const Vec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

double compute_tet_volume(const Vec3& x0, const Vec3& x1, const Vec3& x2, const Vec3& x3) {
  return glm::dot(x1 - x0, glm::cross(x2 - x0, x3 - x0)) / 6.0;
}

std::vector<Tri> compute_boundary_faces(const TetMesh& mesh) {
  // Faces of a positively oriented tet (0,1,2,3) with outward normals.
  static constexpr int kFace[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  struct Seen {
    Tri oriented;
    int count;
    int32_t tet;
  };
  std::map<std::array<int32_t, 3>, Seen> faces;
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    const Tet& t = mesh.tets[e];
    for (const auto& f : kFace) {
      Tri tri{t[static_cast<size_t>(f[0])], t[static_cast<size_t>(f[1])], t[static_cast<size_t>(f[2])]};
      std::array<int32_t, 3> key = tri;
      std::sort(key.begin(), key.end());
      auto [it, inserted] = faces.try_emplace(key, Seen{tri, 0, int32_t(e)});
      ++it->second.count;
    }
  }
  std::vector<Tri> out;
  for (const auto& [key, seen] : faces) {
    if (seen.count != 1) continue;
    if (!mesh.quadratic()) {
      out.push_back(seen.oriented);
      continue;
    }
    // The edge node between corners a and b of the face's tet.
    const auto e = size_t(seen.tet);
    auto mid = [&](int32_t a, int32_t b) {
      int la = 0, lb = 0;
      for (int c = 0; c < 4; ++c) {
        if (mesh.tets[e][size_t(c)] == a) la = c;
        if (mesh.tets[e][size_t(c)] == b) lb = c;
      }
      for (int k = 0; k < 6; ++k)
        if ((kTetEdges[k][0] == la && kTetEdges[k][1] == lb) || (kTetEdges[k][0] == lb && kTetEdges[k][1] == la))
          return mesh.edges[e][size_t(k)];
      return int32_t(-1);  // (unreachable: two corners of a tet share an edge)
    };
    const Tri& t = seen.oriented;
    const int32_t ab = mid(t[0], t[1]), bc = mid(t[1], t[2]), ca = mid(t[2], t[0]);
    out.push_back({t[0], ab, ca});
    out.push_back({ab, t[1], bc});
    out.push_back({ca, bc, t[2]});
    out.push_back({ab, bc, ca});
  }
  return out;
}

std::vector<int32_t> compute_boundary_nodes(const std::vector<Tri>& faces) {
  std::vector<int32_t> nodes;
  nodes.reserve(faces.size() * 3);
  for (const Tri& f : faces) nodes.insert(nodes.end(), f.begin(), f.end());
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  return nodes;
}

Aabb compute_aabb(const std::vector<Vec3>& x) {
  Aabb box;
  if (x.empty()) return box;
  box.lo = box.hi = x[0];
  for (const Vec3& p : x) {
    box.lo = glm::min(box.lo, p);
    box.hi = glm::max(box.hi, p);
  }
  return box;
}

std::string check_mesh_structure(const TetMesh& mesh) {
  if (mesh.X.size() < 4) return "mesh has " + std::to_string(mesh.X.size()) + " nodes; a tet mesh needs at least 4";
  if (mesh.tets.empty()) return "mesh has no tetrahedra";
  if (!mesh.region.empty() && mesh.region.size() != mesh.tets.size())
    return "mesh has " + std::to_string(mesh.region.size()) + " region ids for " + std::to_string(mesh.tets.size()) +
           " tets";
  for (size_t i = 0; i < mesh.X.size(); ++i) {
    const Vec3& p = mesh.X[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
      return "node " + std::to_string(i) + " has a non-finite coordinate";
  }
  const auto n = static_cast<int32_t>(mesh.X.size());
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    const Tet& t = mesh.tets[e];
    for (int32_t id : t) {
      if (id < 0 || id >= n)
        return "tet " + std::to_string(e) + " refers to node " + std::to_string(id) + ", outside 0.." +
               std::to_string(n - 1);
    }
    if (t[0] == t[1] || t[0] == t[2] || t[0] == t[3] || t[1] == t[2] || t[1] == t[3] || t[2] == t[3])
      return "tet " + std::to_string(e) + " repeats a node";
  }
  if (!mesh.quadratic()) return "";
  if (mesh.edges.size() != mesh.tets.size())
    return "mesh has edge nodes for " + std::to_string(mesh.edges.size()) + " tets of " +
           std::to_string(mesh.tets.size());
  std::vector<char> corner(mesh.X.size(), 0);
  for (const Tet& t : mesh.tets)
    for (int32_t id : t) corner[size_t(id)] = 1;
  std::map<std::array<int32_t, 2>, int32_t> edge_node;  // corners (sorted) -> its node
  std::vector<std::array<int32_t, 2>> node_edge(mesh.X.size(), {-1, -1});
  for (size_t e = 0; e < mesh.tets.size(); ++e)
    for (int k = 0; k < 6; ++k) {
      const int32_t id = mesh.edges[e][size_t(k)];
      const std::string where = "tet " + std::to_string(e) + " edge node " + std::to_string(4 + k);
      if (id < 0 || id >= n)
        return where + " refers to node " + std::to_string(id) + ", outside 0.." + std::to_string(n - 1);
      if (corner[size_t(id)]) return where + " is node " + std::to_string(id) + ", a corner";
      const int32_t a = mesh.tets[e][size_t(kTetEdges[k][0])], b = mesh.tets[e][size_t(kTetEdges[k][1])];
      const std::array<int32_t, 2> key{std::min(a, b), std::max(a, b)};
      auto [it, inserted] = edge_node.try_emplace(key, id);
      if (it->second != id)
        return where + " is node " + std::to_string(id) + ", but another tet puts node " + std::to_string(it->second) +
               " on that edge (" + std::to_string(a) + "-" + std::to_string(b) + ")";
      if (node_edge[size_t(id)][0] >= 0 && node_edge[size_t(id)] != key)
        return where + " is node " + std::to_string(id) + ", which another tet puts on another edge";
      node_edge[size_t(id)] = key;
    }
  return "";
}

uint32_t compute_morton_code(const Vec3& p) {
  auto spread = [](uint32_t v) {
    v = (v | (v << 16)) & 0x030000FF;
    v = (v | (v << 8)) & 0x0300F00F;
    v = (v | (v << 4)) & 0x030C30C3;
    v = (v | (v << 2)) & 0x09249249;
    return v;
  };
  auto q = [](double x) { return static_cast<uint32_t>(std::clamp(x, 0.0, 1.0) * 1023.0); };
  return spread(q(p.x)) | (spread(q(p.y)) << 1) | (spread(q(p.z)) << 2);
}

}  // namespace tactile
