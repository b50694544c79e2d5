// What a scene asks of the core, in core terms: mesh, materials, boundary
// conditions, loads, effects and integrator settings. Plain data, in double,
// SI units. The scene loader (src/scene/) fills it from JSON; tests fill it
// directly. A Model is built from it once (core/model.hpp).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/coupling.hpp"
#include "core/embedding.hpp"
#include "core/material.hpp"
#include "core/mesh.hpp"
#include "core/proxy.hpp"

namespace tactile {

struct MaterialSpec {
  MaterialModel model = MaterialModel::StVK;
  double E = 1e5;     // Young's modulus [Pa]
  double nu = 0.3;    // Poisson's ratio [-]
  double rho = 1000;  // density [kg/m^3]
};

// Which nodes a boundary condition or load applies to (rest positions).
struct NodeSelector {
  enum class Kind : uint8_t { Box, Plane, Nodes };
  Kind kind = Kind::Box;
  Vec3 lo{0.0}, hi{0.0};       // Box: inclusive corners [m]
  Vec3 point{0.0};             // Plane: a point on it [m]
  Vec3 normal{0.0, 1.0, 0.0};  // Plane: its normal (any length)
  double tolerance = 1e-9;     // Plane: max distance [m]; Box: slack [m]
  std::vector<int32_t> nodes;  // Nodes: explicit ids, counted from `first`
  // The nodes it may pick: ids [first, first + count), one body's in a scene
  // of several (count < 0: every node from first on).
  int32_t first = 0;
  int32_t count = -1;
};

// A scalar s(t) with its first two derivatives, used as an angle [rad] or a
// displacement [m] along a direction. Ramp eases in and out (cycloidal: zero
// velocity and acceleration at both ends) from 0 to `target` over
// [start, start + duration], then holds. ConstantRate turns at `rate`, its
// rate eased in over [start, start + duration] the same way (0: at once).
struct MotionProfile {
  enum class Kind : uint8_t { Ramp, ConstantRate };
  Kind kind = Kind::Ramp;
  double start = 0.0;     // [s]
  double duration = 0.0;  // Ramp; ConstantRate: its spin-up [s]
  double target = 0.0;    // Ramp: final value
  double rate = 0.0;      // ConstantRate: value per second
};
struct ProfileValue {
  double s, ds, dds;
};
ProfileValue compute_profile(const MotionProfile& p, double t);

// Essential boundary condition: the selected nodes follow a rigid motion
// x(t) = c + Rot(axis, angle(t)) (X - c) + direction * shift(t).
// With neither rotation nor shift, the nodes are fixed.
struct EssentialBc {
  std::string name;
  NodeSelector where;
  Vec3 centre{0.0};
  Vec3 axis{0.0, 1.0, 0.0};
  std::optional<MotionProfile> angle;  // rotation about axis through centre [rad]
  Vec3 direction{0.0};
  std::optional<MotionProfile> shift;  // translation along direction [m]
};

// Natural boundary condition: a total force spread over the selected nodes in
// proportion to their lumped mass, scaled by an optional profile (0..1).
struct NaturalLoad {
  std::string name;
  NodeSelector where;
  Vec3 force{0.0};  // total [N]
  std::optional<MotionProfile> scale;
};

// A rigid proxy (paper section 5.1) bound to one device channel: the forces
// it feels go to that channel only. A proxy in a hand moves rigidly with the
// hand, which one device drives: finger tips and segments pressed and
// turned together, their forces summed for that device.
struct ProxySpec {
  std::string name;
  std::string device;  // device channel that drives it and receives its force ("" in a hand: the hand's)
  std::string hand;    // hand it belongs to ("" = none)
  ProxyGeometry geometry;
  Pose pose;            // at t = 0 (world)
  double friction = 0;  // Coulomb coefficient mu (used when effects.friction)
  Coupling coupling;    // when a device drives it alone through a coupling (core/coupling.hpp)
};

struct HandSpec {
  std::string name;
  std::string device;  // device channel that drives the hand
  Pose pose;           // at t = 0 (world): its proxies keep their offsets from it
  Coupling coupling;   // when its device drives it through a coupling (core/coupling.hpp)
};

struct Effects {
  bool friction = false;  // Coulomb friction at proxy contacts (contact itself: any proxy)
  bool gravity = false;
  Vec3 g{0.0, -9.81, 0.0};  // [m/s^2]
  bool damping = false;
  double alpha = 0.0;  // Rayleigh mass damping D = alpha M [1/s], eq. (10)
  // Contact between bodies, and of a body with itself (core/contact/body_contact.hpp).
  bool body_contact = false;
  bool self_contact = false;
  double body_friction = 0.0;  // Coulomb mu at those contacts
  // How deep [m] a vertex may be bound for by the next step before the
  // contact acts ahead of it (its speculative points); 0: 1 % of the
  // shortest surface edge. Larger costs less where surfaces rest together.
  double body_depth_tolerance = 0.0;
};

enum class Precision : uint8_t { Float, Double };
enum class UnstablePolicy : uint8_t { Subdivide, Refuse };

struct IntegratorSpec {
  Precision precision = Precision::Double;
  double dt = 0.0;                                      // fixed step [s]; 0 = chosen from the critical step
  double safety = 0.9;                                  // auto step = safety * critical step
  UnstablePolicy unstable = UnstablePolicy::Subdivide;  // fixed dt above the critical step
  int32_t threads = 1;                                  // element and node passes split this many ways
  double energy_tolerance = 0.05;                       // energy growth allowed beyond the work done, relative
  // The energy balance is checked over windows of this much simulated time [s]: the quadrature errors of
  // the work sums (second order per step) add up without bound over a live session of hours, and the
  // guard is there for blow-ups, which grow within milliseconds.
  double energy_window = 1.0;
  // Selective mass scaling, as explicit FEM codes offer it (a target time
  // increment): each element whose critical step at rest is under this [s]
  // is made denser by (this / its step)^2, which brings its step up to this;
  // the others are left as they are. 0: none. A mesh's few slivers set its
  // step; their added mass is reported (Model::added_mass).
  double mass_scaling_dt = 0.0;
};

// One body of a scene of several. The spec's mesh holds them all, one after
// another: a body's nodes and tets are ranges of it, each in its own mesh's
// order (so that node first + i is the body's node i), and its fine surface's
// vertices and triangles ranges of the spec's surface (empty ranges when the
// scene has none). A body's tets use its nodes only.
struct BodySpec {
  std::string name;
  int32_t node_begin = 0, node_end = 0;
  int32_t tet_begin = 0, tet_end = 0;
  int32_t fine_vertex_begin = 0, fine_vertex_end = 0;
  int32_t fine_triangle_begin = 0, fine_triangle_end = 0;
  int32_t material_begin = 0, material_end = 0;  // its materials in ModelSpec::materials (its region ids, offset)
};

struct ModelSpec {
  TetMesh mesh;
  // Empty: one body, the whole mesh (and surface), named "body".
  std::vector<BodySpec> bodies;
  // A fine surface carried by the mesh (core/embedding.hpp), shown and
  // touched instead of the mesh's own boundary; null when the scene has none.
  std::shared_ptr<const EmbeddedSurface> surface;
  std::vector<MaterialSpec> materials;  // indexed by mesh region id
  std::vector<EssentialBc> essential;
  std::vector<NaturalLoad> loads;
  std::vector<ProxySpec> proxies;
  std::vector<HandSpec> hands;
  Effects effects;
  IntegratorSpec integrator;
};

// Ids of the nodes a selector picks, sorted. Pure.
std::vector<int32_t> select_nodes(const TetMesh& mesh, const NodeSelector& s);

}  // namespace tactile
