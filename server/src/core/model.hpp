// The FEM model: everything about the body that does not change while it
// moves. Built once from a ModelSpec, immutable after; a State is plain data
// (core/state.hpp) and the Stepper (core/stepper.hpp) reads the model and
// writes the state.
#pragma once

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/kernels/kernels.hpp"
#include "core/spec.hpp"

namespace tactile {

// A spec the core cannot build (bad material, degenerate element, empty
// selection...). The message names the field or element at fault.
struct ModelError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Lane blocks [begin, end) whose elements share one material model, so the
// kernel for that model runs over them with no per-element branch.
struct ElementGroup {
  MaterialModel model;
  int32_t begin, end;
  double lambda, mu;  // Lame parameters [Pa] of every element of the group
};

// Blocks per strip. A group's blocks come in strips (the last may be
// shorter): within a strip of kStripBlocks blocks, lane l takes the l-th run
// of the strip's elements, so that elements that share nodes sit in one lane
// of consecutive blocks rather than side by side in one block: a block's
// corner-force adds seldom hit the same node back to back (a store-to-load
// forwarding chain), while each strip stays compact in space. A range of
// blocks that cuts a strip touches the nodes of the whole strip, so threads
// share work in whole strips (stepper.cpp): 16 blocks, for fine shares.
// Guarded by fem_bench --only=passes and --large --only=passes (the elastic
// column; docs/perf.md, Element and node order).
inline constexpr int32_t kStripBlocks = 16;

// A share of the step's work for one thread: the lane blocks [block_begin,
// block_end) of one slab of the body, and the nodes [node_begin, node_end)
// for the node passes, those the slab's blocks number first (see
// build_model). The parts tile both ranges in order; a part's elements also
// touch a layer of the previous part's nodes.
struct ModelPart {
  int32_t block_begin, block_end;
  int32_t node_begin, node_end;
};

// Nodes held by one essential boundary condition.
struct EssentialSet {
  EssentialBc spec;
  std::vector<int32_t> nodes;  // node ids (n_set)
  bool moving;                 // false: fixed in place
};

// Nodes loaded by one natural boundary condition, with their share of it.
struct LoadSet {
  NaturalLoad spec;
  std::vector<int32_t> nodes;  // node ids (n_set)
  std::vector<double> weight;  // share of the total force, sums to 1 (n_set)
};

// A body of the model (BodySpec): its ranges of the spec's mesh and fine
// surface (given numbering), and of the model's boundary faces.
struct ModelBody {
  BodySpec spec;
  int32_t face_begin = 0, face_end = 0;  // Model::surface, grouped by body
};

template <class Real>
struct Model {
  static constexpr int W = kLanes<Real>;

  // The rest mesh (double), linear or quadratic (core/mesh.hpp), its nodes
  // numbered for the element pass: in the order the blocks first touch them. Tets keep their ids. Every node id the
  // model holds or a State indexes is in this numbering; node sets in a spec
  // name nodes as the spec's mesh gives them, and these two translate.
  TetMesh mesh;
  std::vector<int32_t> node_model;  // model id of each given node (n_nodes)
  std::vector<int32_t> node_given;  // given id of each model node (n_nodes)
  std::vector<Tri> surface;         // boundary triangles, outward, body by body (n_faces x 3)
  std::vector<ModelBody> bodies;    // at least one; the spec's order
  std::vector<int32_t> node_body;   // body of each model node (n_nodes)
  // A fine surface the body carries (core/embedding.hpp): contact then
  // meets its vertices, not the boundary's. Null when the spec has none.
  std::shared_ptr<const EmbeddedSurface> embedded;
  std::vector<Tet> embedded_nodes;  // its vertices' four nodes, in this numbering (n_fine)
  int32_t n_nodes = 0;
  int32_t n_tets = 0;

  std::vector<Real> m;      // lumped mass [kg] (n_nodes), section 4.1
  std::vector<Real> inv_m;  // 1 / m [1/kg] (n_nodes)
  double total_mass = 0;    // [kg], with what mass scaling added
  // Selective mass scaling (IntegratorSpec::mass_scaling_dt): the mass it
  // added [kg] and the tets it made denser.
  double added_mass = 0;
  int32_t mass_scaled_tets = 0;

  std::vector<ElementBlock<Real>> blocks;  // lane-blocked elements (n_blocks); a quadratic mesh's corners
  // A quadratic mesh (mesh.quadratic()): its tets as quadratic blocks, in
  // the same lanes as `blocks` (n_blocks); empty for a linear mesh.
  std::vector<QuadraticBlock<Real>> quadratic_blocks;
  std::vector<ElementGroup> groups;  // ranges of blocks of one material model, per part
  std::vector<ModelPart> parts;      // how the step splits over threads (integrator.threads at most)
  std::vector<int32_t> lane_tet;     // tet id of block lane b*W+l, -1 for padding (n_blocks x W)
  std::vector<double> lane_dt;       // tet_dt of block lane b*W+l [s], +inf for padding (n_blocks x W)
  std::vector<int32_t> tet_lane;     // block lane b*W+l of each tet (n_tets)

  std::vector<MaterialModel> tet_model;    // material model per tet (n_tets)
  std::vector<double> tet_volume;          // rest volume [m^3] (n_tets)
  std::vector<double> tet_lambda, tet_mu;  // Lame parameters [Pa] (n_tets)
  std::vector<double> tet_altitude;        // smallest rest altitude [m] (n_tets)
  std::vector<double> tet_dt;              // critical step at rest, exact per element [s] (n_tets)
  double dt_rest = 0;                      // min of tet_dt [s]
  bool any_non_invertible = false;         // some element uses a model that cannot invert

  std::vector<EssentialSet> essential;
  std::vector<int32_t> constrained;  // all nodes under an essential BC, sorted unique
  std::vector<LoadSet> loads;
  std::vector<ProxySpec> proxies;  // device filled in from the hand for hand proxies
  std::vector<HandSpec> hands;
  std::vector<int32_t> proxy_hand;    // hand index per proxy, -1 if none (n_proxies)
  std::vector<Pose> proxy_offset;     // pose in its hand's frame (n_proxies; identity if no hand)
  std::vector<std::string> devices;   // distinct device channels, in order of first use
  std::vector<int32_t> proxy_device;  // device index per proxy (n_proxies)
  Effects effects;
  IntegratorSpec integrator;
};

template <class Real>
Model<Real> build_model(const ModelSpec& spec);

// Critical time step of one element at rest [s]: 2 / omega_max of its
// stiffness against its lumped mass. By Irons' element eigenvalue theorem the
// assembled system's critical step is at least the smallest of these.
double compute_element_critical_dt(const Vec3& X0, const Vec3& X1, const Vec3& X2, const Vec3& X3, double lambda,
                                   double mu, double rho);

}  // namespace tactile
