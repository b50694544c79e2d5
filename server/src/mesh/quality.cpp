#include "mesh/quality.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>

#include <glm/geometric.hpp>

#include "mesh/mesh_error.hpp"

namespace tactile {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

std::string format_g(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

// "2 inverted tets (ids 4, 17)", at most `shown` ids listed.
std::string describe_ids(const std::vector<int32_t>& ids, const char* what, size_t shown) {
  std::string s = std::to_string(ids.size()) + " " + what + (ids.size() == 1 ? " tet (id " : " tets (ids ");
  for (size_t i = 0; i < ids.size() && i < shown; ++i) s += (i ? ", " : "") + std::to_string(ids[i]);
  if (ids.size() > shown) s += ", and " + std::to_string(ids.size() - shown) + " more";
  return s + ")";
}

}  // namespace

MeshQuality compute_quality(const TetMesh& mesh, const QualityThresholds& t) {
  MeshQuality q;
  q.n_tets = mesh.n_tets();
  q.n_nodes = mesh.n_nodes();
  double min_dihedral = kInf, max_dihedral = -kInf, max_aspect = -kInf;
  double min_volume = kInf, max_volume = -kInf, min_edge = kInf, max_edge = -kInf;
  std::vector<char> referenced(mesh.X.size(), 0);
  // Faces opposite nodes 3, 2, 1, 0, wound outwards for a positive tet (as in core/mesh.cpp).
  static constexpr int kFace[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  static constexpr int kEdge[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

  for (int32_t e = 0; e < mesh.n_tets(); ++e) {
    const Tet& tet = mesh.tets[size_t(e)];
    bool ids_ok = true;
    for (int32_t id : tet) ids_ok = ids_ok && id >= 0 && id < mesh.n_nodes();
    if (!ids_ok) {
      q.degenerate.push_back(e);
      continue;
    }
    for (int32_t id : tet) referenced[size_t(id)] = 1;
    std::array<Vec3, 4> x;
    for (size_t k = 0; k < 4; ++k) x[k] = mesh.X[size_t(tet[k])];

    double l_max = 0.0;
    for (const auto& [a, b] : kEdge) {
      const double l = glm::length(x[size_t(b)] - x[size_t(a)]);
      l_max = std::max(l_max, l);
      min_edge = std::min(min_edge, l);
      max_edge = std::max(max_edge, l);
    }
    const double V = compute_tet_volume(x[0], x[1], x[2], x[3]);
    min_volume = std::min(min_volume, V);
    max_volume = std::max(max_volume, V);
    if (!(std::abs(V) > std::max(t.min_volume, t.degenerate_volume_ratio * l_max * l_max * l_max))) {
      q.degenerate.push_back(e);
      continue;
    }
    if (V < 0.0) q.inverted.push_back(e);

    // Area vectors of the faces; the interior dihedral angle between two faces
    // is pi minus the angle between their outward normals. Flipping all four
    // (an inverted tet) leaves it unchanged.
    std::array<Vec3, 4> n;
    double area_sum = 0.0;
    for (size_t f = 0; f < 4; ++f) {
      const Vec3 &a = x[size_t(kFace[f][0])], &b = x[size_t(kFace[f][1])], &c = x[size_t(kFace[f][2])];
      n[f] = 0.5 * glm::cross(b - a, c - a);
      area_sum += glm::length(n[f]);
    }
    double tet_min = kInf, tet_max = -kInf;
    for (size_t f = 0; f < 4; ++f)
      for (size_t g = f + 1; g < 4; ++g) {
        const double c = -glm::dot(n[f], n[g]) / (glm::length(n[f]) * glm::length(n[g]));
        const double angle = std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / std::numbers::pi;
        tet_min = std::min(tet_min, angle);
        tet_max = std::max(tet_max, angle);
      }
    // Inradius r = 3|V| / (total face area); aspect = L_max / (2 sqrt(6) r).
    const double r_in = 3.0 * std::abs(V) / area_sum;
    const double aspect = l_max / (2.0 * std::sqrt(6.0) * r_in);
    min_dihedral = std::min(min_dihedral, tet_min);
    max_dihedral = std::max(max_dihedral, tet_max);
    max_aspect = std::max(max_aspect, aspect);
    if (V > 0.0 &&
        (tet_min < t.poor_min_dihedral_deg || tet_max > t.poor_max_dihedral_deg || aspect > t.poor_aspect_ratio))
      q.poor.push_back(e);
  }

  auto or_zero = [](double v) { return std::isfinite(v) ? v : 0.0; };
  q.min_dihedral_deg = or_zero(min_dihedral);
  q.max_dihedral_deg = or_zero(max_dihedral);
  q.max_aspect_ratio = or_zero(max_aspect);
  q.min_volume = or_zero(min_volume);
  q.max_volume = or_zero(max_volume);
  q.min_edge = or_zero(min_edge);
  q.max_edge = or_zero(max_edge);
  for (const TetEdges& edges : mesh.edges)  // a quadratic mesh's edge nodes are its tets' too
    for (int32_t id : edges)
      if (id >= 0 && id < mesh.n_nodes()) referenced[size_t(id)] = 1;
  for (int32_t i = 0; i < mesh.n_nodes(); ++i)
    if (!referenced[size_t(i)]) q.unreferenced.push_back(i);
  return q;
}

std::string MeshQuality::summary() const {
  std::string s = std::to_string(n_tets) + " tets, " + std::to_string(n_nodes) + " nodes; volume " +
                  format_g(min_volume) + ".." + format_g(max_volume) + " m^3; edge " + format_g(min_edge) + ".." +
                  format_g(max_edge) + " m; dihedral " + format_g(min_dihedral_deg) + ".." +
                  format_g(max_dihedral_deg) + " deg; aspect ratio <= " + format_g(max_aspect_ratio) + "\n";
  s += std::to_string(inverted.size()) + " inverted, " + std::to_string(degenerate.size()) + " degenerate, " +
       std::to_string(poor.size()) + " poor tets; " + std::to_string(unreferenced.size()) + " unreferenced nodes";
  if (!poor.empty()) s += "\nwarning: " + describe_ids(poor, "poor", 10);
  if (!unreferenced.empty()) s += "\nwarning: unreferenced nodes get no mass; drop them with compute_compacted";
  return s;
}

void check_mesh_or_throw(const TetMesh& mesh, const MeshQuality& q) {
  if (const std::string fault = check_mesh_structure(mesh); !fault.empty()) throw MeshError("mesh refused: " + fault);
  if (q.n_tets != mesh.n_tets() || q.n_nodes != mesh.n_nodes())
    throw MeshError("check_mesh_or_throw: the quality report is for another mesh (" + std::to_string(q.n_tets) +
                    " tets, " + std::to_string(q.n_nodes) + " nodes; the mesh has " + std::to_string(mesh.n_tets()) +
                    ", " + std::to_string(mesh.n_nodes()) + ")");
  if (q.inverted.empty() && q.degenerate.empty()) return;
  std::string msg = "mesh refused: ";
  if (!q.inverted.empty()) msg += describe_ids(q.inverted, "inverted", 10);
  if (!q.inverted.empty() && !q.degenerate.empty()) msg += "; ";
  if (!q.degenerate.empty()) msg += describe_ids(q.degenerate, "degenerate", 10);
  throw MeshError(msg);
}

TetMesh compute_compacted(const TetMesh& mesh) {
  std::vector<int32_t> new_id(mesh.X.size(), -1);
  for (int32_t e = 0; e < mesh.n_tets(); ++e)
    for (int32_t id : mesh.tets[size_t(e)]) {
      if (id < 0 || id >= mesh.n_nodes())
        throw MeshError("compute_compacted: tet " + std::to_string(e) + " refers to node " + std::to_string(id) +
                        ", outside 0.." + std::to_string(mesh.n_nodes() - 1));
      new_id[size_t(id)] = 0;
    }
  TetMesh out;
  for (size_t i = 0; i < mesh.X.size(); ++i) {
    if (new_id[i] < 0) continue;
    new_id[i] = out.n_nodes();
    out.X.push_back(mesh.X[i]);
  }
  out.tets.reserve(mesh.tets.size());
  for (const Tet& t : mesh.tets)
    out.tets.push_back({new_id[size_t(t[0])], new_id[size_t(t[1])], new_id[size_t(t[2])], new_id[size_t(t[3])]});
  out.region = mesh.region;
  return out;
}

}  // namespace tactile
