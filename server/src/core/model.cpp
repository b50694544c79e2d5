#include "core/model.hpp"

#include "core/model_build.hpp"
#include "core/symmetric_eigen.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <sstream>
#include <type_traits>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>
#include <glm/vec4.hpp>
#include <glm/vector_relational.hpp>

namespace tactile {

namespace {

std::string list_ids(const std::vector<int32_t>& ids, size_t max = 10) {
  std::ostringstream out;
  for (size_t i = 0; i < ids.size() && i < max; ++i) out << (i ? ", " : "") << ids[i];
  if (ids.size() > max) out << ", ... (" << ids.size() << " in all)";
  return out.str();
}

// Smallest altitude of a tet [m]: 3 V / (largest face area).
double compute_min_altitude(const Vec3& x0, const Vec3& x1, const Vec3& x2, const Vec3& x3) {
  const double V = std::fabs(compute_tet_volume(x0, x1, x2, x3));
  const double a0 = glm::length(glm::cross(x2 - x1, x3 - x1));
  const double a1 = glm::length(glm::cross(x2 - x0, x3 - x0));
  const double a2 = glm::length(glm::cross(x1 - x0, x3 - x0));
  const double a3 = glm::length(glm::cross(x1 - x0, x2 - x0));
  const double amax = std::max({a0, a1, a2, a3}) * 0.5;
  return amax > 0 ? 3.0 * V / amax : 0.0;
}

}  // namespace

double compute_element_critical_dt(const Vec3& X0, const Vec3& X1, const Vec3& X2, const Vec3& X3, double lambda,
                                   double mu, double rho) {
  // K_e = V B^T C B (12 x 12). Its nonzero eigenvalues are those of the 6 x 6
  // matrix V L^T (B B^T) L, with C = L L^T, which Jacobi solves exactly.
  const glm::dmat3 Dm(X1 - X0, X2 - X0, X3 - X0);  // columns
  const double V = std::fabs(glm::determinant(Dm)) / 6.0;
  const glm::dmat3 Dinv = glm::inverse(Dm);
  // Shape function gradients: grad N_a = row (a-1) of Dm^-1 for a = 1..3.
  Vec3 g[4];
  for (int a = 0; a < 3; ++a) g[a + 1] = Vec3(Dinv[0][a], Dinv[1][a], Dinv[2][a]);
  g[0] = -(g[1] + g[2] + g[3]);
  // Voigt strain rows (xx, yy, zz, xy, yz, zx; engineering shear) of B for node a.
  double G[36] = {};
  for (int a = 0; a < 4; ++a) {
    const double Ba[6][3] = {{g[a].x, 0, 0},      {0, g[a].y, 0},      {0, 0, g[a].z},
                             {g[a].y, g[a].x, 0}, {0, g[a].z, g[a].y}, {g[a].z, 0, g[a].x}};
    for (int r = 0; r < 6; ++r)
      for (int s = 0; s < 6; ++s) G[6 * r + s] += Ba[r][0] * Ba[s][0] + Ba[r][1] * Ba[s][1] + Ba[r][2] * Ba[s][2];
  }
  double C[36] = {};
  for (int r = 0; r < 3; ++r)
    for (int s = 0; s < 3; ++s) C[6 * r + s] = lambda + (r == s ? 2 * mu : 0);
  for (int r = 3; r < 6; ++r) C[6 * r + r] = mu;
  double L[36] = {};  // Cholesky C = L L^T
  for (int i = 0; i < 6; ++i) {
    for (int j = 0; j <= i; ++j) {
      double sum = C[6 * i + j];
      for (int k = 0; k < j; ++k) sum -= L[6 * i + k] * L[6 * j + k];
      L[6 * i + j] = i == j ? std::sqrt(std::max(sum, 0.0)) : (L[6 * j + j] > 0 ? sum / L[6 * j + j] : 0.0);
    }
  }
  double S[36];  // L^T G L
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) {
      double sum = 0;
      for (int k = 0; k < 6; ++k)
        for (int l = 0; l < 6; ++l) sum += L[6 * k + i] * G[6 * k + l] * L[6 * l + j];
      S[6 * i + j] = sum;
    }
  const double k_max = V * compute_max_eigenvalue_symmetric(S, 6);
  const double m_node = rho * V / 4.0;
  if (!(k_max > 0) || !(m_node > 0)) return 0.0;
  return 2.0 / std::sqrt(k_max / m_node);
}

// ---- the stages (core/model_build.hpp) ----------------------------------------------------

void check_materials(const std::vector<MaterialSpec>& materials) {
  for (size_t r = 0; r < materials.size(); ++r) {
    const MaterialSpec& mat = materials[r];
    const std::string where = "materials[" + std::to_string(r) + "]";
    if (!(mat.E > 0) || !std::isfinite(mat.E))
      throw ModelError(where + ".E must be > 0 Pa, got " + std::to_string(mat.E));
    if (!(mat.nu > -1.0 && mat.nu < 0.5))
      throw ModelError(where + ".nu must lie in (-1, 0.5), got " + std::to_string(mat.nu));
    if (!(mat.rho > 0) || !std::isfinite(mat.rho))
      throw ModelError(where + ".rho must be > 0 kg/m^3, got " + std::to_string(mat.rho));
  }
}

namespace {

const MaterialSpec& material_of(const TetMesh& mesh, const std::vector<MaterialSpec>& materials, size_t e) {
  const int32_t r = mesh.region_of(int32_t(e));
  if (r < 0 || size_t(r) >= materials.size())
    throw ModelError("tet " + std::to_string(e) + " is in region " + std::to_string(r) + " but materials has " +
                     std::to_string(materials.size()) + " entries");
  return materials[size_t(r)];
}

}  // namespace

ElementConstants compute_element_constants(const TetMesh& mesh, const std::vector<MaterialSpec>& materials) {
  const auto nt = size_t(mesh.n_tets());
  ElementConstants out;
  out.volume.resize(nt);
  std::vector<int32_t> inverted, flat;
  for (size_t e = 0; e < nt; ++e) {
    const Tet& t = mesh.tets[e];
    const Vec3 &x0 = mesh.X[size_t(t[0])], &x1 = mesh.X[size_t(t[1])], &x2 = mesh.X[size_t(t[2])],
               &x3 = mesh.X[size_t(t[3])];
    const double V = compute_tet_volume(x0, x1, x2, x3);
    const double L = std::max({glm::length(x1 - x0), glm::length(x2 - x0), glm::length(x3 - x0), glm::length(x2 - x1),
                               glm::length(x3 - x1), glm::length(x3 - x2)});
    if (V < 0)
      inverted.push_back(int32_t(e));
    else if (V <= 1e-9 * L * L * L)
      flat.push_back(int32_t(e));
    else if (mesh.quadratic() && !(make_p2_element(p2_rest_nodes(mesh, e)).min_det > 1e-9 * L * L * L))
      inverted.push_back(int32_t(e));  // an edge node so far off its edge that the map folds
    out.volume[e] = V;
  }
  if (!inverted.empty() || !flat.empty()) {
    std::string msg = "mesh refused:";
    if (!inverted.empty())
      msg += " " + std::to_string(inverted.size()) + " inverted tet(s) (ids " + list_ids(inverted) + ")";
    if (!flat.empty())
      msg += std::string(inverted.empty() ? "" : ";") + " " + std::to_string(flat.size()) + " degenerate tet(s) (ids " +
             list_ids(flat) + ")";
    throw ModelError(msg);
  }
  out.model.resize(nt);
  out.lambda.resize(nt);
  out.mu.resize(nt);
  out.altitude.resize(nt);
  out.dt.resize(nt);
  for (size_t e = 0; e < nt; ++e) {
    const MaterialSpec& mat = material_of(mesh, materials, e);
    const Lame lame = compute_lame(mat.E, mat.nu);
    out.model[e] = mat.model;
    out.lambda[e] = lame.lambda;
    out.mu[e] = lame.mu;
    if (!can_invert(mat.model)) out.any_non_invertible = true;
    const Tet& t = mesh.tets[e];
    const Vec3 &x0 = mesh.X[size_t(t[0])], &x1 = mesh.X[size_t(t[1])], &x2 = mesh.X[size_t(t[2])],
               &x3 = mesh.X[size_t(t[3])];
    out.altitude[e] = compute_min_altitude(x0, x1, x2, x3);
    if (mesh.quadratic()) {
      out.dt[e] = compute_p2_critical_dt(p2_rest_nodes(mesh, e), lame.lambda, lame.mu, mat.rho);
    } else {
      out.dt[e] = compute_element_critical_dt(x0, x1, x2, x3, lame.lambda, lame.mu, mat.rho);
    }
  }
  return out;
}

std::vector<double> scale_element_masses(ElementConstants& elements, double target_dt) {
  std::vector<double> scale(elements.dt.size(), 1.0);
  if (!(target_dt > 0)) return scale;
  for (size_t e = 0; e < scale.size(); ++e)
    if (elements.dt[e] < target_dt) {
      const double r = target_dt / elements.dt[e];
      scale[e] = r * r;
      elements.dt[e] = target_dt;
    }
  return scale;
}

std::vector<double> compute_lumped_masses(const TetMesh& mesh, const std::vector<MaterialSpec>& materials,
                                          const std::vector<double>& volume, const std::vector<double>& density_scale) {
  std::vector<double> mass(size_t(mesh.n_nodes()), 0.0);
  const auto rho = [&](size_t e) {
    return material_of(mesh, materials, e).rho * (density_scale.empty() ? 1.0 : density_scale[e]);
  };
  if (mesh.quadratic()) {
    std::vector<double> rhos(mesh.tets.size());
    for (size_t e = 0; e < mesh.tets.size(); ++e) rhos[e] = rho(e);
    mass = compute_quadratic_lumped_masses(mesh, rhos, volume);
  } else {
    for (size_t e = 0; e < mesh.tets.size(); ++e) {
      const double m4 = rho(e) * volume[e] / 4.0;  // section 4.1: lump by rows
      for (int32_t id : mesh.tets[e]) mass[size_t(id)] += m4;
    }
  }
  std::vector<int32_t> unreferenced;
  for (size_t i = 0; i < mass.size(); ++i)
    if (!(mass[i] > 0)) unreferenced.push_back(int32_t(i));
  if (!unreferenced.empty())
    throw ModelError("mesh has " + std::to_string(unreferenced.size()) + " node(s) in no tet (ids " +
                     list_ids(unreferenced) + "); compact the mesh first");
  return mass;
}

// Element order: a sweep of the body in layers across its longest axis,
// rows across its next longest, and along the shortest within a row, on a
// grid of cells the size of the elements. Threads take consecutive slabs of
// the sweep (integrator.threads parts, cut at equal element counts), so two
// parts meet on one layer of nodes. At least kMinPartElements per part:
// below that the hand-offs between threads cost more than the split saves
// (fem_bench --only=threads; docs/perf.md, Threads).
//
// A sweep, not a space-filling curve: the elements around a node follow
// one another within a layer or two, so the node arrays stream through
// the cache once a step, where a Morton curve comes back to a node's
// neighbours half the body later (fem_bench --large --only=passes, the
// elastic column at 1 M tets; docs/perf.md, Element and node order).
ElementOrder compute_element_order(const TetMesh& mesh, const std::vector<double>& volume, int threads) {
  const auto nt = size_t(mesh.n_tets());
  ElementOrder out;
  out.n_parts = static_cast<int32_t>(std::clamp<size_t>(nt / kMinPartElements, 1, size_t(std::max(1, threads))));
  std::vector<int32_t>& order = out.order;
  order.resize(nt);
  std::iota(order.begin(), order.end(), 0);
  {
    double total = 0;
    for (double V : volume) total += V;
    const Aabb box = compute_aabb(mesh.X);
    const Vec3 extent = box.size();
    const double cell = std::cbrt(6.0 * total / double(nt));  // a cube of 6 tets of the mean volume
    std::array<int, 3> axis{0, 1, 2};                         // slowest first
    std::stable_sort(axis.begin(), axis.end(), [&](int a, int b) { return extent[a] > extent[b]; });
    std::vector<std::array<int32_t, 3>> key(nt);
    for (size_t e = 0; e < nt; ++e) {
      const Tet& t = mesh.tets[e];
      const Vec3 c = (mesh.X[size_t(t[0])] + mesh.X[size_t(t[1])] + mesh.X[size_t(t[2])] + mesh.X[size_t(t[3])]) * 0.25;
      for (int k = 0; k < 3; ++k) key[e][size_t(k)] = int32_t((c[axis[size_t(k)]] - box.lo[axis[size_t(k)]]) / cell);
    }
    std::stable_sort(order.begin(), order.end(), [&](int32_t a, int32_t b) { return key[size_t(a)] < key[size_t(b)]; });
  }
  out.part_of.resize(nt);
  for (size_t k = 0; k < nt; ++k) out.part_of[size_t(order[k])] = int32_t(k * size_t(out.n_parts) / nt);
  // Within a part, elements grouped by material (model and Lame parameters:
  // a group's kernel takes them once), each group in sweep order.
  std::stable_sort(order.begin(), order.end(), [&](int32_t a, int32_t b) {
    if (out.part_of[size_t(a)] != out.part_of[size_t(b)]) return out.part_of[size_t(a)] < out.part_of[size_t(b)];
    return mesh.region_of(a) < mesh.region_of(b);
  });
  return out;
}

namespace {

// Lane blocks, one run per part and material, in strips of kStripBlocks
// blocks (see model.hpp): fill(B, l, e) puts tet e in lane l of block B,
// pad(B, l) makes lane l padding.
template <class Block, class Fill, class Pad>
LaneLayout<Block> lay_out_lanes(const TetMesh& mesh, const ElementConstants& elements, const ElementOrder& eo,
                                Fill fill, Pad pad) {
  constexpr int W = Block::W;
  const auto nt = size_t(mesh.n_tets());
  const std::vector<int32_t>& order = eo.order;
  LaneLayout<Block> out;
  out.first_block.assign(size_t(eo.n_parts), -1);
  for (size_t i = 0; i < nt;) {
    const int32_t part = eo.part_of[size_t(order[i])];
    const int32_t region = mesh.region_of(order[i]);
    size_t j = i;
    while (j < nt && eo.part_of[size_t(order[j])] == part && mesh.region_of(order[j]) == region) ++j;
    if (out.first_block[size_t(part)] < 0) out.first_block[size_t(part)] = int32_t(out.blocks.size());
    const auto e0 = size_t(order[i]);
    ElementGroup group{elements.model[e0], int32_t(out.blocks.size()), 0, elements.lambda[e0], elements.mu[e0]};
    for (size_t k = i; k < j; k += W * size_t(kStripBlocks)) {
      const size_t count = std::min(j - k, W * size_t(kStripBlocks));  // elements in this chunk
      const size_t n_blocks = (count + W - 1) / W;
      for (size_t b = 0; b < n_blocks; ++b) {
        Block B{};
        for (int l = 0; l < W; ++l) {
          const size_t slot = size_t(l) * n_blocks + b;  // position in the chunk
          if (slot >= count) {                           // padding lane (lane 0 never is)
            pad(B, l);
            out.lane_tet.push_back(-1);
            out.lane_dt.push_back(std::numeric_limits<double>::infinity());
            continue;
          }
          const auto e = size_t(order[k + slot]);
          fill(B, l, e);
          out.lane_tet.push_back(int32_t(e));
          out.lane_dt.push_back(elements.dt[e]);
        }
        out.blocks.push_back(B);
      }
    }
    group.end = int32_t(out.blocks.size());
    out.groups.push_back(group);
    i = j;
  }
  out.tet_lane.assign(nt, -1);
  for (size_t k = 0; k < out.lane_tet.size(); ++k)
    if (out.lane_tet[k] >= 0) out.tet_lane[size_t(out.lane_tet[k])] = int32_t(k);
  return out;
}

// A lane's shape: the corners' Dm^-1 (row-major) and the rest volume.
template <class Block>
void fill_shape(Block& B, int l, const TetMesh& mesh, const ElementConstants& elements, size_t e) {
  using Real = std::remove_reference_t<decltype(B.V[0])>;
  const Tet& t = mesh.tets[e];
  const Vec3& X0 = mesh.X[size_t(t[0])];
  const glm::dmat3 Dm(mesh.X[size_t(t[1])] - X0, mesh.X[size_t(t[2])] - X0, mesh.X[size_t(t[3])] - X0);
  const glm::dmat3 Dinv = glm::inverse(Dm);  // glm is column-major: Dinv[col][row]
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) B.Dinv[3 * r + c][l] = Real(Dinv[c][r]);
  B.V[l] = Real(elements.volume[e]);
}

// A padding lane: zero stiffness, identity shape, every node at lane 0's
// first (F = I whatever u, and a node the block touches anyway).
template <class Block>
void pad_lane(Block& B, int l) {
  using Real = std::remove_reference_t<decltype(B.V[0])>;
  for (auto& ids : B.node4) ids[l] = B.node4[0][0];
  for (int q = 0; q < 9; ++q) B.Dinv[q][l] = (q % 4 == 0) ? Real(1) : Real(0);
  B.V[l] = Real(0);
}

}  // namespace

template <class Real>
LaneBlocks<Real> make_lane_blocks(const TetMesh& mesh, const ElementConstants& elements, const ElementOrder& eo) {
  return lay_out_lanes<ElementBlock<Real>>(
      mesh, elements, eo,
      [&](ElementBlock<Real>& B, int l, size_t e) {
        for (int c = 0; c < 4; ++c) B.node4[c][l] = mesh.tets[e][size_t(c)];  // the given id until renumbered
        fill_shape(B, l, mesh, elements, e);
      },
      pad_lane<ElementBlock<Real>>);
}

template <class Real>
QuadraticLaneBlocks<Real> make_quadratic_lane_blocks(const TetMesh& mesh, const ElementConstants& elements,
                                                     const ElementOrder& eo) {
  return lay_out_lanes<QuadraticBlock<Real>>(
      mesh, elements, eo,
      [&](QuadraticBlock<Real>& B, int l, size_t e) {
        for (int a = 0; a < kP2Nodes; ++a) B.node4[a][l] = mesh.node(e, a);
        fill_shape(B, l, mesh, elements, e);
      },
      pad_lane<QuadraticBlock<Real>>);
}

// Nodes renumbered in the order the blocks first touch them, so that the
// element pass reads and adds into the node arrays nearly in sequence, a
// few new cache lines a block: a stream the hardware prefetcher follows
// with no prefetches in software (fem_bench --large --only=passes;
// docs/perf.md, Element and node order).
template <class Block>
NodeNumbering compute_node_numbering(const LaneLayout<Block>& lanes, int32_t n_parts, int32_t n_nodes) {
  constexpr int W = Block::W;
  constexpr int C = int(std::extent_v<decltype(Block::node4)>);  // nodes a lane: 4, or 10 for a quadratic tet
  const auto nn = size_t(n_nodes);
  NodeNumbering out;
  out.cut.assign(size_t(n_parts) + 1, 0);
  out.node_model.assign(nn, -1);
  out.node_given.assign(nn, -1);
  int32_t next = 0;
  for (int32_t p = 0; p < n_parts; ++p) {
    // A part's node-pass range starts where its blocks start numbering,
    // rounded to 16 nodes so that no cache line of a node array holds two
    // parts' nodes.
    if (p > 0) out.cut[size_t(p)] = std::max(out.cut[size_t(p) - 1], std::min(n_nodes, (next + 8) / 16 * 16));
    if (lanes.first_block[size_t(p)] < 0) continue;
    const int32_t b1 = p + 1 < n_parts ? lanes.first_block[size_t(p) + 1] : int32_t(lanes.blocks.size());
    for (int32_t b = lanes.first_block[size_t(p)]; b < b1; ++b)
      for (int c = 0; c < C; ++c)
        for (int l = 0; l < W; ++l) {
          int32_t& id = out.node_model[size_t(lanes.blocks[size_t(b)].node4[c][l])];
          if (id < 0) id = next++;
        }
  }
  out.cut[size_t(n_parts)] = n_nodes;
  for (size_t i = 0; i < nn; ++i) out.node_given[size_t(out.node_model[i])] = int32_t(i);
  return out;
}

BoundarySets compute_boundary_sets(const ModelSpec& spec, const std::vector<int32_t>& node_model,
                                   const std::vector<double>& mass) {
  // A node set names nodes as the mesh gave them.
  auto select = [&](const NodeSelector& where) {
    std::vector<int32_t> nodes = select_nodes(spec.mesh, where);
    for (int32_t& i : nodes) i = node_model[size_t(i)];
    std::sort(nodes.begin(), nodes.end());
    return nodes;
  };
  BoundarySets out;
  for (size_t k = 0; k < spec.essential.size(); ++k) {
    const EssentialBc& bc = spec.essential[k];
    EssentialSet set{bc, select(bc.where), bc.angle.has_value() || bc.shift.has_value()};
    if (set.nodes.empty())
      throw ModelError("boundary condition " + std::to_string(k) + (bc.name.empty() ? "" : " ('" + bc.name + "')") +
                       " selects no node");
    if (bc.angle && !(glm::length(bc.axis) > 0))
      throw ModelError("boundary condition " + std::to_string(k) + " rotates about a zero axis");
    out.constrained.insert(out.constrained.end(), set.nodes.begin(), set.nodes.end());
    out.essential.push_back(std::move(set));
  }
  std::sort(out.constrained.begin(), out.constrained.end());
  const size_t before = out.constrained.size();
  out.constrained.erase(std::unique(out.constrained.begin(), out.constrained.end()), out.constrained.end());
  if (out.constrained.size() != before) throw ModelError("boundary conditions overlap: a node is held by two of them");

  for (size_t k = 0; k < spec.loads.size(); ++k) {
    const NaturalLoad& load = spec.loads[k];
    LoadSet set{load, select(load.where), {}};
    if (set.nodes.empty())
      throw ModelError("load " + std::to_string(k) + (load.name.empty() ? "" : " ('" + load.name + "')") +
                       " selects no node");
    double sum = 0;
    for (int32_t i : set.nodes) sum += mass[size_t(i)];
    for (int32_t i : set.nodes) set.weight.push_back(mass[size_t(i)] / sum);
    out.loads.push_back(std::move(set));
  }
  return out;
}

ProxySetup check_proxies(const std::vector<ProxySpec>& proxies, const std::vector<HandSpec>& hands) {
  ProxySetup out;
  for (size_t j = 0; j < proxies.size(); ++j) {
    const ProxySpec& proxy = proxies[j];
    const std::string where = "proxy " + std::to_string(j) + (proxy.name.empty() ? "" : " ('" + proxy.name + "')");
    const ProxyGeometry& g = proxy.geometry;
    auto positive = [&](double value, const char* field) {
      if (!(value > 0) || !std::isfinite(value))
        throw ModelError(where + ": " + field + " must be finite and > 0 m, got " + std::to_string(value));
    };
    if (g.shape == ProxyShape::Sphere || g.shape == ProxyShape::Capsule) positive(g.radius, "radius");
    if (g.shape == ProxyShape::Capsule) positive(g.half_length, "half_length");
    if (g.shape == ProxyShape::Box) {
      positive(g.half_extents.x, "half_extents.x");
      positive(g.half_extents.y, "half_extents.y");
      positive(g.half_extents.z, "half_extents.z");
      if (!(g.radius >= 0)) throw ModelError(where + ": radius must be >= 0 m");
    }
    if (!(proxy.friction >= 0) || !std::isfinite(proxy.friction))
      throw ModelError(where + ": friction must be finite and >= 0, got " + std::to_string(proxy.friction));
    const double qn = glm::length(glm::dvec4(proxy.pose.orientation.x, proxy.pose.orientation.y,
                                             proxy.pose.orientation.z, proxy.pose.orientation.w));
    if (!(std::fabs(qn - 1.0) < 1e-6))
      throw ModelError(where + ": orientation must be a unit quaternion, |q| = " + std::to_string(qn));
    if (!std::isfinite(glm::length(proxy.pose.position))) throw ModelError(where + ": position must be finite");
    for (size_t k = 0; k < j; ++k)
      if (!proxy.name.empty() && proxies[k].name == proxy.name)
        throw ModelError(where + ": name used twice (also proxy " + std::to_string(k) + ")");
    ProxySpec kept = proxy;
    int32_t hand = -1;
    Pose offset;
    if (!proxy.hand.empty()) {
      for (size_t h = 0; h < hands.size(); ++h)
        if (hands[h].name == proxy.hand) hand = int32_t(h);
      if (hand < 0) throw ModelError(where + ": hand '" + proxy.hand + "' is not among the hands");
      const HandSpec& hs = hands[size_t(hand)];
      if (!proxy.device.empty() && proxy.device != hs.device)
        throw ModelError(where + ": device '" + proxy.device + "' differs from its hand's ('" + hs.device +
                         "'); a hand's proxies go to the hand's device");
      kept.device = hs.device;
      offset.orientation = glm::conjugate(hs.pose.orientation) * proxy.pose.orientation;
      offset.position = hs.pose.to_local(proxy.pose.position);
    }
    if (kept.device.empty()) throw ModelError(where + ": device must name the channel that drives it");
    int32_t device = -1;
    for (size_t d = 0; d < out.devices.size(); ++d)
      if (out.devices[d] == kept.device) device = int32_t(d);
    if (device < 0) {
      device = int32_t(out.devices.size());
      out.devices.push_back(kept.device);
    }
    out.proxies.push_back(kept);
    out.proxy_hand.push_back(hand);
    out.proxy_offset.push_back(offset);
    out.proxy_device.push_back(device);
  }
  for (size_t h = 0; h < hands.size(); ++h) {
    const HandSpec& hs = hands[h];
    const std::string where = "hand " + std::to_string(h) + (hs.name.empty() ? "" : " ('" + hs.name + "')");
    if (hs.name.empty()) throw ModelError(where + ": name must not be empty");
    if (hs.device.empty()) throw ModelError(where + ": device must name the channel that drives it");
    const glm::dquat& q = hs.pose.orientation;
    if (!(std::fabs(std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z) - 1.0) < 1e-6))
      throw ModelError(where + ": orientation must be a unit quaternion");
    for (size_t k = 0; k < h; ++k)
      if (hands[k].name == hs.name) throw ModelError(where + ": name used twice (also hand " + std::to_string(k) + ")");
    if (std::find(out.proxy_hand.begin(), out.proxy_hand.end(), int32_t(h)) == out.proxy_hand.end())
      throw ModelError(where + ": no proxy belongs to it");
    out.hands.push_back(hs);
  }
  return out;
}

void check_settings(const Effects& effects, const IntegratorSpec& integrator) {
  if (effects.damping && !(effects.alpha >= 0))
    throw ModelError("damping alpha must be >= 0 1/s, got " + std::to_string(effects.alpha));
  if (!(effects.body_friction >= 0 && std::isfinite(effects.body_friction)))
    throw ModelError("body contact friction must be finite and >= 0, got " + std::to_string(effects.body_friction));
  if (!(effects.body_depth_tolerance >= 0 && std::isfinite(effects.body_depth_tolerance)))
    throw ModelError("body contact depth tolerance must be finite and >= 0, got " +
                     std::to_string(effects.body_depth_tolerance));
  if (!(integrator.safety > 0 && integrator.safety <= 1))
    throw ModelError("integrator.safety must lie in (0, 1], got " + std::to_string(integrator.safety));
  if (integrator.dt < 0) throw ModelError("integrator.dt must be >= 0 s");
  if (integrator.threads < 1) throw ModelError("integrator.threads must be >= 1");
}

std::vector<Tet> compute_embedded_nodes(const EmbeddedSurface& surface, const std::vector<int32_t>& node_model) {
  std::vector<Tet> out;
  out.reserve(surface.nodes.size());
  for (size_t v = 0; v < surface.nodes.size(); ++v) {
    Tet t;
    for (size_t k = 0; k < 4; ++k) {
      const int32_t n = surface.nodes[v][k];
      if (n < 0 || size_t(n) >= node_model.size())
        throw ModelError("surface vertex " + std::to_string(v) + " follows node " + std::to_string(n) +
                         ", which the mesh lacks (bound to another mesh)");
      t[k] = node_model[size_t(n)];
    }
    out.push_back(t);
  }
  return out;
}

namespace {

std::string body_name(const std::vector<BodySpec>& bodies, size_t b) {
  return "body " + std::to_string(b) + " ('" + bodies[b].name + "')";
}

// The barycentric coordinates of p in tet t (corners), or false for a flat tet.
bool barycentric(const TetMesh& mesh, const Tet& t, const Vec3& p, std::array<double, 4>& w) {
  const Vec3 &x0 = mesh.X[size_t(t[0])], &x1 = mesh.X[size_t(t[1])], &x2 = mesh.X[size_t(t[2])],
             &x3 = mesh.X[size_t(t[3])];
  const double V = compute_tet_volume(x0, x1, x2, x3);
  if (!(V > 0)) return false;
  w = {compute_tet_volume(p, x1, x2, x3) / V, compute_tet_volume(x0, p, x2, x3) / V,
       compute_tet_volume(x0, x1, p, x3) / V, compute_tet_volume(x0, x1, x2, p) / V};
  return true;
}

std::array<int32_t, 3> face_key(const Tet& t, int skip) {
  std::array<int32_t, 3> k{};
  for (int c = 0, i = 0; c < 4; ++c)
    if (c != skip) k[size_t(i++)] = t[size_t(c)];
  std::sort(k.begin(), k.end());
  return k;
}

// The first boundary node of body a inside body b, or -1. Inside: in one of
// b's tets (to rounding) and on none of b's boundary faces, so that bodies
// that touch are not caught. b's tets are binned in a grid of about one tet
// a cell.
int32_t find_node_inside(const TetMesh& mesh, const BodySpec& a, const std::vector<int32_t>& boundary,
                         const BodySpec& b) {
  std::map<std::array<int32_t, 3>, int> face_count;  // b's corner faces, boundary ones counted once
  std::vector<Vec3> corners;
  for (int32_t e = b.tet_begin; e < b.tet_end; ++e) {
    for (int c = 0; c < 4; ++c) ++face_count[face_key(mesh.tets[size_t(e)], c)];
    for (int32_t n : mesh.tets[size_t(e)]) corners.push_back(mesh.X[size_t(n)]);
  }
  const Aabb box = compute_aabb(corners);
  const Vec3 size = glm::max(box.size(), Vec3(1e-12));
  const double cell = std::cbrt(size.x * size.y * size.z / double(b.tet_end - b.tet_begin));
  const glm::ivec3 cells = glm::clamp(glm::ivec3(glm::ceil(size / cell)), glm::ivec3(1), glm::ivec3(256));
  const auto cell_of = [&](const Vec3& p) {
    return glm::clamp(glm::ivec3((p - box.lo) / size * Vec3(cells)), glm::ivec3(0), cells - 1);
  };
  std::vector<std::vector<int32_t>> grid(size_t(cells.x) * size_t(cells.y) * size_t(cells.z));
  for (int32_t e = b.tet_begin; e < b.tet_end; ++e) {
    Vec3 lo(std::numeric_limits<double>::infinity()), hi(-std::numeric_limits<double>::infinity());
    for (int32_t n : mesh.tets[size_t(e)]) lo = glm::min(lo, mesh.X[size_t(n)]), hi = glm::max(hi, mesh.X[size_t(n)]);
    const glm::ivec3 c0 = cell_of(lo), c1 = cell_of(hi);
    for (int z = c0.z; z <= c1.z; ++z)
      for (int y = c0.y; y <= c1.y; ++y)
        for (int x = c0.x; x <= c1.x; ++x) grid[size_t((z * cells.y + y) * cells.x + x)].push_back(e);
  }
  const double margin = 1e-6;  // of a tet's size: on a face
  for (int32_t n : boundary) {
    if (n < a.node_begin || n >= a.node_end) continue;
    const Vec3& p = mesh.X[size_t(n)];
    if (glm::any(glm::lessThan(p, box.lo)) || glm::any(glm::greaterThan(p, box.hi))) continue;
    const glm::ivec3 c = cell_of(p);
    bool in = false, on_boundary = false;
    for (int32_t e : grid[size_t((c.z * cells.y + c.y) * cells.x + c.x)]) {
      const Tet& t = mesh.tets[size_t(e)];
      std::array<double, 4> w{};
      if (!barycentric(mesh, t, p, w) || *std::min_element(w.begin(), w.end()) < -margin) continue;
      in = true;
      for (int k = 0; k < 4; ++k)
        if (w[size_t(k)] <= margin && face_count[face_key(t, k)] == 1) on_boundary = true;
    }
    if (in && !on_boundary) return n;
  }
  return -1;
}

}  // namespace

std::vector<BodySpec> check_bodies(const ModelSpec& spec) {
  const TetMesh& mesh = spec.mesh;
  const int32_t n_fine = spec.surface ? spec.surface->n_vertices() : 0;
  const int32_t n_fine_tris = spec.surface ? int32_t(spec.surface->rest.triangles.size()) : 0;
  if (spec.bodies.empty())
    return {BodySpec{"body", 0, mesh.n_nodes(), 0, mesh.n_tets(), 0, n_fine, 0, n_fine_tris, 0,
                     int32_t(spec.materials.size())}};
  const std::vector<BodySpec>& bodies = spec.bodies;
  BodySpec end{};  // where the previous body ended
  for (size_t b = 0; b < bodies.size(); ++b) {
    const BodySpec& body = bodies[b];
    const std::string name = body_name(bodies, b);
    if (body.name.empty()) throw ModelError("body " + std::to_string(b) + " has no name");
    for (size_t c = 0; c < b; ++c)
      if (bodies[c].name == body.name) throw ModelError(name + ": the name is also body " + std::to_string(c) + "'s");
    if (body.node_begin != end.node_end || body.node_end <= body.node_begin || body.tet_begin != end.tet_end ||
        body.tet_end <= body.tet_begin || body.fine_vertex_begin != end.fine_vertex_end ||
        body.fine_vertex_end < body.fine_vertex_begin || body.fine_triangle_begin != end.fine_triangle_end ||
        body.fine_triangle_end < body.fine_triangle_begin)
      throw ModelError(name + ": its nodes, tets and surface must follow the previous body's, and be some");
    end = body;
    for (int32_t e = body.tet_begin; e < body.tet_end && e < mesh.n_tets(); ++e)
      for (int k = 0; k < mesh.nodes_per_tet(); ++k) {
        const int32_t n = mesh.node(size_t(e), k);
        if (n < body.node_begin || n >= body.node_end)
          throw ModelError(name + ": tet " + std::to_string(e) + " uses node " + std::to_string(n) +
                           ", which is not the body's");
      }
    for (int32_t v = body.fine_vertex_begin; v < body.fine_vertex_end && v < n_fine; ++v)
      for (int32_t n : spec.surface->nodes[size_t(v)])
        if (n < body.node_begin || n >= body.node_end)
          throw ModelError(name + ": surface vertex " + std::to_string(v) + " follows node " + std::to_string(n) +
                           ", which is not the body's");
    for (int32_t t = body.fine_triangle_begin; t < body.fine_triangle_end && t < n_fine_tris; ++t)
      for (int32_t v : spec.surface->rest.triangles[size_t(t)])
        if (v < body.fine_vertex_begin || v >= body.fine_vertex_end)
          throw ModelError(name + ": surface triangle " + std::to_string(t) + " uses vertex " + std::to_string(v) +
                           ", which is not the body's");
  }
  if (end.node_end != mesh.n_nodes() || end.tet_end != mesh.n_tets() || end.fine_vertex_end != n_fine ||
      end.fine_triangle_end != n_fine_tris)
    throw ModelError("the bodies hold " + std::to_string(end.node_end) + " nodes and " + std::to_string(end.tet_end) +
                     " tets of the mesh's " + std::to_string(mesh.n_nodes()) + " and " + std::to_string(mesh.n_tets()) +
                     " (and their surfaces " + std::to_string(end.fine_vertex_end) + " of " + std::to_string(n_fine) +
                     " fine vertices)");
  if (bodies.size() > 1) {
    const std::vector<int32_t> boundary = compute_boundary_nodes(compute_boundary_faces(mesh));
    for (size_t a = 0; a < bodies.size(); ++a)
      for (size_t b = 0; b < bodies.size(); ++b) {
        if (a == b) continue;
        const int32_t n = find_node_inside(mesh, bodies[a], boundary, bodies[b]);
        if (n >= 0) {
          const Vec3& p = mesh.X[size_t(n)];
          throw ModelError(body_name(bodies, a) + " overlaps " + body_name(bodies, b) + " at rest: its node " +
                           std::to_string(n - bodies[a].node_begin) + " (" + std::to_string(p.x) + ", " +
                           std::to_string(p.y) + ", " + std::to_string(p.z) + ") is inside it");
        }
      }
  }
  return bodies;
}

// ---- the model -------------------------------------------------------------------------------

template <class Real>
Model<Real> build_model(const ModelSpec& spec) {
  constexpr int W = kLanes<Real>;
  const TetMesh& mesh = spec.mesh;
  if (std::string err = check_mesh_structure(mesh); !err.empty()) throw ModelError("mesh: " + err);
  check_materials(spec.materials);
  const std::vector<BodySpec> bodies = check_bodies(spec);
  ElementConstants elements = compute_element_constants(mesh, spec.materials);
  const std::vector<double> density_scale = scale_element_masses(elements, spec.integrator.mass_scaling_dt);
  const std::vector<double> given_mass = compute_lumped_masses(mesh, spec.materials, elements.volume, density_scale);
  const ElementOrder order = compute_element_order(mesh, elements.volume, spec.integrator.threads);
  LaneBlocks<Real> lanes = make_lane_blocks<Real>(mesh, elements, order);
  // A quadratic mesh: its element pass runs over quadratic blocks laid out
  // as the linear ones (the same tets in the same lanes), whose corners the
  // critical step's estimate reads (core/critical_step.hpp).
  QuadraticLaneBlocks<Real> quadratic;
  if (mesh.quadratic()) quadratic = make_quadratic_lane_blocks<Real>(mesh, elements, order);
  NodeNumbering numbers = mesh.quadratic() ? compute_node_numbering(quadratic, order.n_parts, mesh.n_nodes())
                                           : compute_node_numbering(lanes, order.n_parts, mesh.n_nodes());

  Model<Real> model;
  model.n_nodes = mesh.n_nodes();
  model.n_tets = mesh.n_tets();
  const auto nn = static_cast<size_t>(model.n_nodes);

  // Everything the model holds uses the model's node ids; node_given and node_model translate.
  model.mesh = mesh;
  for (size_t i = 0; i < nn; ++i) model.mesh.X[size_t(numbers.node_model[i])] = mesh.X[i];
  for (Tet& t : model.mesh.tets)
    for (int32_t& id : t) id = numbers.node_model[size_t(id)];
  for (TetEdges& t : model.mesh.edges)
    for (int32_t& id : t) id = numbers.node_model[size_t(id)];
  for (ElementBlock<Real>& B : lanes.blocks)
    for (int c = 0; c < 4; ++c)
      for (int l = 0; l < W; ++l) B.node4[c][l] = 4 * numbers.node_model[size_t(B.node4[c][l])];
  for (QuadraticBlock<Real>& B : quadratic.blocks)
    for (int a = 0; a < kP2Nodes; ++a)
      for (int l = 0; l < W; ++l) B.node4[a][l] = 4 * numbers.node_model[size_t(B.node4[a][l])];
  model.quadratic_blocks = std::move(quadratic.blocks);
  std::vector<double> mass(nn);
  model.m.resize(nn);
  model.inv_m.resize(nn);
  for (size_t i = 0; i < nn; ++i) {
    const auto k = size_t(numbers.node_model[i]);
    mass[k] = given_mass[i];
    model.m[k] = Real(given_mass[i]);
    model.inv_m[k] = Real(1.0 / given_mass[i]);
    model.total_mass += given_mass[i];
  }

  model.tet_model = std::move(elements.model);
  model.tet_volume = std::move(elements.volume);
  model.tet_lambda = std::move(elements.lambda);
  model.tet_mu = std::move(elements.mu);
  model.tet_altitude = std::move(elements.altitude);
  for (size_t e = 0; e < density_scale.size(); ++e)
    if (density_scale[e] != 1.0) {
      model.added_mass += (density_scale[e] - 1.0) * material_of(mesh, spec.materials, e).rho * model.tet_volume[e];
      ++model.mass_scaled_tets;
    }
  model.tet_dt = std::move(elements.dt);
  model.any_non_invertible = elements.any_non_invertible;
  model.dt_rest = *std::min_element(model.tet_dt.begin(), model.tet_dt.end());

  model.blocks = std::move(lanes.blocks);
  model.groups = std::move(lanes.groups);
  model.lane_tet = std::move(lanes.lane_tet);
  model.lane_dt = std::move(lanes.lane_dt);
  model.tet_lane = std::move(lanes.tet_lane);
  const int32_t n_parts = order.n_parts;
  model.parts.resize(size_t(n_parts));
  for (int32_t p = n_parts - 1; p >= 0; --p) {
    ModelPart& part = model.parts[size_t(p)];
    part.block_end = p + 1 < n_parts ? model.parts[size_t(p) + 1].block_begin : int32_t(model.blocks.size());
    part.block_begin = lanes.first_block[size_t(p)] < 0 ? part.block_end : lanes.first_block[size_t(p)];
    part.node_begin = numbers.cut[size_t(p)];
    part.node_end = numbers.cut[size_t(p) + 1];
  }

  BoundarySets boundary = compute_boundary_sets(spec, numbers.node_model, mass);
  model.essential = std::move(boundary.essential);
  model.constrained = std::move(boundary.constrained);
  model.loads = std::move(boundary.loads);

  ProxySetup proxies = check_proxies(spec.proxies, spec.hands);
  model.proxies = std::move(proxies.proxies);
  model.hands = std::move(proxies.hands);
  model.proxy_hand = std::move(proxies.proxy_hand);
  model.proxy_offset = std::move(proxies.proxy_offset);
  model.devices = std::move(proxies.devices);
  model.proxy_device = std::move(proxies.proxy_device);

  check_settings(spec.effects, spec.integrator);
  model.effects = spec.effects;
  model.integrator = spec.integrator;
  model.surface = compute_boundary_faces(model.mesh);
  // The boundary faces body by body, each body's in the order they came.
  model.node_body.assign(nn, 0);
  for (size_t b = 0; b < bodies.size(); ++b)
    for (int32_t n = bodies[b].node_begin; n < bodies[b].node_end; ++n)
      model.node_body[size_t(numbers.node_model[size_t(n)])] = int32_t(b);
  std::stable_sort(model.surface.begin(), model.surface.end(), [&](const Tri& x, const Tri& y) {
    return model.node_body[size_t(x[0])] < model.node_body[size_t(y[0])];
  });
  for (size_t b = 0, f = 0; b < bodies.size(); ++b) {
    ModelBody body{bodies[b], int32_t(f), 0};
    while (f < model.surface.size() && model.node_body[size_t(model.surface[f][0])] == int32_t(b)) ++f;
    body.face_end = int32_t(f);
    model.bodies.push_back(body);
  }
  if (spec.surface) {
    model.embedded = spec.surface;
    model.embedded_nodes = compute_embedded_nodes(*spec.surface, numbers.node_model);
  }
  model.node_model = std::move(numbers.node_model);
  model.node_given = std::move(numbers.node_given);
  return model;
}

template LaneBlocks<float> make_lane_blocks<float>(const TetMesh&, const ElementConstants&, const ElementOrder&);
template LaneBlocks<double> make_lane_blocks<double>(const TetMesh&, const ElementConstants&, const ElementOrder&);
template QuadraticLaneBlocks<float> make_quadratic_lane_blocks<float>(const TetMesh&, const ElementConstants&,
                                                                      const ElementOrder&);
template QuadraticLaneBlocks<double> make_quadratic_lane_blocks<double>(const TetMesh&, const ElementConstants&,
                                                                        const ElementOrder&);
template NodeNumbering compute_node_numbering(const LaneBlocks<float>&, int32_t, int32_t);
template NodeNumbering compute_node_numbering(const LaneBlocks<double>&, int32_t, int32_t);
template NodeNumbering compute_node_numbering(const QuadraticLaneBlocks<float>&, int32_t, int32_t);
template NodeNumbering compute_node_numbering(const QuadraticLaneBlocks<double>&, int32_t, int32_t);
template Model<float> build_model<float>(const ModelSpec&);
template Model<double> build_model<double>(const ModelSpec&);

}  // namespace tactile
