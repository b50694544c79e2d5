// The stages of build_model (core/model.hpp), in order, each a function of
// plain data that returns plain data, with its own tests
// (server/tests/core/model_build_test.cpp). build_model runs them and moves
// what they return into the Model:
//
//   check_materials            every material's E, nu and rho in range
//   compute_element_constants  per tet: rest volume (inverted and flat tets
//                              refused, by id), material, Lame parameters,
//                              smallest altitude, critical step at rest
//   scale_element_masses       selective mass scaling: the tets whose
//                              critical step is under the integrator's
//                              mass_scaling_dt made denser to reach it
//   compute_lumped_masses      per node: its share of its tets' mass (a node
//                              in no tet refused)
//   compute_element_order      the sweep the element pass follows, cut into
//                              parts for threads, grouped by material in each
//   make_lane_blocks           the lane blocks, in strips, with their groups
//                              and the maps between tets and lanes
//   compute_node_numbering     the model's node ids: the order the blocks
//                              first touch the nodes, and each part's range
//   compute_boundary_sets      essential sets and loads, in model ids
//   check_proxies              the proxies, their hands and devices
//   check_settings             damping and the integrator's settings
//   compute_embedded_nodes     a fine surface's nodes, in model ids
//   check_bodies               the bodies tile the mesh and surface, none
//                              uses another's nodes or lies inside another
//
// A ModelError names what is refused.
#pragma once

#include <cstdint>
#include <vector>

#include "core/model.hpp"
#include "core/quadratic.hpp"

namespace tactile {

void check_materials(const std::vector<MaterialSpec>& materials);

// Per tet (n_tets each), in the mesh's tet ids.
struct ElementConstants {
  std::vector<MaterialModel> model;
  std::vector<double> volume;  // rest volume [m^3]
  std::vector<double> lambda;  // Lame parameters [Pa]
  std::vector<double> mu;
  std::vector<double> altitude;  // smallest rest altitude [m]
  std::vector<double> dt;        // critical step at rest, exact per element [s]
  bool any_non_invertible = false;
};
// A quadratic mesh's tets take their quadratic element's step
// (compute_p2_critical_dt), not the linear tet's, and one whose edge nodes
// fold it (det J <= 0 at a quadrature point) is refused as inverted.
ElementConstants compute_element_constants(const TetMesh& mesh, const std::vector<MaterialSpec>& materials);

// Selective mass scaling to `target_dt` [s] (IntegratorSpec::mass_scaling_dt):
// per tet, the factor its density is scaled by, (target_dt / dt)^2 where its
// critical step dt is under target_dt, else 1, and that step raised to
// target_dt in `elements` (a step goes as the square root of the density).
// All ones for target_dt 0.
std::vector<double> scale_element_masses(ElementConstants& elements, double target_dt);

// Row-sum lumping, section 4.1: each tet gives a quarter of its mass to each
// corner [kg] (n_nodes, the mesh's ids); a quadratic mesh, HRZ lumping
// (compute_quadratic_lumped_masses). `density_scale` (per tet, optional):
// each tet's density times it.
std::vector<double> compute_lumped_masses(const TetMesh& mesh, const std::vector<MaterialSpec>& materials,
                                          const std::vector<double>& volume,
                                          const std::vector<double>& density_scale = {});

// The tets in the element pass's order (a permutation of the tet ids), the
// part each falls in (by tet id), and how many parts: `threads` at most, and
// kMinPartElements tets a part at least.
struct ElementOrder {
  std::vector<int32_t> order;
  std::vector<int32_t> part_of;
  int32_t n_parts = 1;
};
inline constexpr size_t kMinPartElements = 4096;
ElementOrder compute_element_order(const TetMesh& mesh, const std::vector<double>& volume, int threads);

// The lane blocks with the mesh's node ids (compute_node_numbering renumbers
// them), one run per part and material, in strips (model.hpp); a part's first
// block (-1 for a part without one). lane_tet, lane_dt and tet_lane as in
// Model. Block: ElementBlock<Real> (linear tets) or QuadraticBlock<Real>.
template <class Block>
struct LaneLayout {
  std::vector<Block> blocks;
  std::vector<ElementGroup> groups;
  std::vector<int32_t> lane_tet;
  std::vector<double> lane_dt;
  std::vector<int32_t> tet_lane;
  std::vector<int32_t> first_block;  // per part
};
template <class Real>
using LaneBlocks = LaneLayout<ElementBlock<Real>>;
template <class Real>
using QuadraticLaneBlocks = LaneLayout<QuadraticBlock<Real>>;

template <class Real>
LaneBlocks<Real> make_lane_blocks(const TetMesh& mesh, const ElementConstants& elements, const ElementOrder& order);
// A quadratic mesh's tets, as straight quadratic ones: each lane's ten nodes
// (the corners, then the edge nodes).
template <class Real>
QuadraticLaneBlocks<Real> make_quadratic_lane_blocks(const TetMesh& mesh, const ElementConstants& elements,
                                                     const ElementOrder& order);

// The model's node ids: node_model[given] and node_given[model], numbered in
// the order the blocks first touch them (all of a lane's nodes: the corners,
// and a quadratic tet's edge nodes); cut[p] where part p's node range starts
// (a multiple of 16 but the last, n_parts + 1 entries).
struct NodeNumbering {
  std::vector<int32_t> node_model, node_given, cut;
};
template <class Block>
NodeNumbering compute_node_numbering(const LaneLayout<Block>& lanes, int32_t n_parts, int32_t n_nodes);

// The essential sets (nodes held by two of them refused) and the loads, each
// load's weights by the nodes' masses; in model ids. `mesh` in the spec's ids,
// `mass` in the model's.
struct BoundarySets {
  std::vector<EssentialSet> essential;
  std::vector<int32_t> constrained;  // sorted unique
  std::vector<LoadSet> loads;
};
BoundarySets compute_boundary_sets(const ModelSpec& spec, const std::vector<int32_t>& node_model,
                                   const std::vector<double>& mass);

struct ProxySetup {
  std::vector<ProxySpec> proxies;  // device filled in from the hand for hand proxies
  std::vector<HandSpec> hands;
  std::vector<int32_t> proxy_hand;    // hand index per proxy, -1 if none
  std::vector<Pose> proxy_offset;     // pose in its hand's frame (identity if no hand)
  std::vector<std::string> devices;   // distinct device channels, in order of first use
  std::vector<int32_t> proxy_device;  // device index per proxy
};
ProxySetup check_proxies(const std::vector<ProxySpec>& proxies, const std::vector<HandSpec>& hands);

void check_settings(const Effects& effects, const IntegratorSpec& integrator);

// The four nodes each vertex of a fine surface follows, in model ids.
std::vector<Tet> compute_embedded_nodes(const EmbeddedSurface& surface, const std::vector<int32_t>& node_model);

// The spec's bodies (one covering everything when it names none), checked:
// their node, tet and fine-surface ranges tile the mesh and surface in order,
// a body's tets and fine vertices use its own nodes only, names are unique,
// and no body's boundary node lies inside another body's tet at rest (two
// bodies may touch, not overlap). The ModelError names the body.
std::vector<BodySpec> check_bodies(const ModelSpec& spec);

}  // namespace tactile
