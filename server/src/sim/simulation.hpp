// One body in motion, whatever its precision: owns the Model, the Stepper and
// the State of a ModelSpec, in float or double as the spec's integrator asks,
// and hands out positions and energies in double.
//
// Every node id and per-node array here is in the numbering of the spec's
// mesh, as the scene's file gave it; the model's own numbering (core/model.hpp,
// ordered for its element pass, and different for another precision or set of
// materials) stays below this API. Tets keep their ids throughout.
//
// The core is templated on the scalar; the application layer picks it once,
// here, from the scene, so nothing above this file is a template.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/fields.hpp"
#include "core/spec.hpp"
#include "core/state.hpp"
#include "core/stepper.hpp"

namespace tactile {

class Simulation {
 public:
  // Builds the model (throws ModelError for a spec the core refuses) and its
  // rest state; a thread pool when spec.integrator.threads > 1.
  explicit Simulation(const ModelSpec& spec);
  ~Simulation();
  Simulation(Simulation&&) noexcept;
  Simulation& operator=(Simulation&&) noexcept;

  Precision precision() const;
  const TetMesh& mesh() const;  // the spec's rest mesh
  // The fine surface the body carries (core/embedding.hpp); null when none.
  const std::shared_ptr<const EmbeddedSurface>& surface() const { return surface_; }
  // The bodies (one for a scene of one): their ranges of the spec's mesh and
  // surface (BodySpec), and of the model's boundary faces.
  const std::vector<ModelBody>& bodies() const;
  int32_t n_nodes() const;
  int32_t n_tets() const;
  double total_mass() const;                      // [kg], with what mass scaling added
  double added_mass() const;                      // what mass scaling added [kg] (integrator.mass_scaling_dt)
  int32_t mass_scaled_tets() const;               // the tets it made denser
  const std::vector<double>& tet_volume() const;  // rest volumes [m^3] (n_tets)
  double dt_rest() const;                         // critical step at rest [s]
  int32_t parts() const;                          // ways each pass is split (threads in use)

  double time() const;  // simulated [s]
  int64_t steps() const;

  // Covers frame_dt [s] with as many sub-steps as stability needs
  // (Stepper::advance); `interrupt`, asked between steps, may stop it there.
  AdvanceReport advance(double frame_dt, const std::function<bool()>& interrupt = {});
  double compute_critical_dt() const;  // of the current configuration [s]

  const Energy& energy() const;                        // as of the latest step
  Energy compute_energy() const;                       // full pass
  std::vector<double> compute_element_energy() const;  // V psi per tet [J] (n_tets)
  // Stress and strain per tet, only those asked for, of every tet or of those
  // listed (core/fields.hpp).
  ElementFields compute_element_fields(const ElementFieldRequest& ask, std::span<const int32_t> tets = {}) const;
  // Per node: 0 free, 1 held in place, 2 moved by a prescribed motion (an
  // essential BC) (n_nodes).
  std::vector<uint8_t> node_constraint() const;

  void copy_positions(std::vector<double>& x) const;     // X + u [m] (n_nodes x 3)
  void copy_displacement(std::vector<double>& u) const;  // [m] (n_nodes x 3)
  void copy_velocity(std::vector<double>& v) const;      // [m/s] (n_nodes x 3)
  Vec3 displacement(int32_t node) const;                 // [m]
  // For the listed nodes only, in one pass: positions X + u [m] (n x 3) and
  // |u| [m] (n; not written when null), in float.
  void gather(std::span<const uint32_t> nodes, float* positions, float* displacement_norm) const;

  // Rigid proxies (core/contact/contact.hpp) as the model holds them: a hand's
  // proxies carry the hand's device.
  const std::vector<ProxySpec>& proxies() const;     // (n_proxies)
  const std::vector<HandSpec>& hands() const;        // (n_hands)
  const std::vector<std::string>& devices() const;   // device channels, in order of first use (n_devices)
  const std::vector<int32_t>& proxy_device() const;  // index into devices() per proxy (n_proxies)
  // Motion over the coming steps of one proxy (alone) or of a hand (with its proxies).
  void set_proxy_motion(int32_t proxy, const ProxyMotion& m);
  void set_hand_motion(int32_t hand, const ProxyMotion& m);
  Pose proxy_pose(int32_t proxy) const;  // at time(), world
  Pose hand_pose(int32_t hand) const;    // at time(), world
  // Virtual coupling (core/coupling.hpp): the proxies or hand `device` drives
  // become rigid bodies that the motion set for them (the device's pose)
  // pulls through a spring-damper saturated at the device's limits (nullptr:
  // the scene's, or soft defaults). Coupling again changes the coupling;
  // release_device makes them kinematic again. Limits must be finite and
  // >= 0 (0: not given); else std::invalid_argument naming the field.
  void couple_device(int32_t device, const DeviceLimits* limits);
  void release_device(int32_t device);
  bool device_coupled(int32_t device) const;
  // What each proxy and each device channel felt in the latest step, with
  // impulse sums since clear_impulses() (mean force = impulse / elapsed).
  const std::vector<ProxyReport>& proxy_reports() const;    // (n_proxies)
  const std::vector<DeviceReport>& device_reports() const;  // (n_devices)
  void clear_impulses();
  // The contact force on each node, for an output that asks: summed from
  // track_contact_forces(true) on, and taken as impulses [N s] (n_nodes x 3,
  // overwritten) with the time they cover [s] returned; the mean force over
  // it is impulse / time.
  void track_contact_forces(bool on);
  // Contact between bodies and within one in the latest step
  // (core/contact/body_contact.hpp): its points, and the momentum it gave
  // each body [N s] (per body; empty when the scene asks for neither) and
  // the held nodes' constraints [N s]: these sum to zero; and the sum of its
  // points' impulses' sizes [N s].
  struct BodyContactReport {
    int32_t between = 0, within = 0;
    std::vector<Vec3> given;
    Vec3 held{0.0};
    double impulses = 0;
  };
  BodyContactReport body_contact_report() const;
  // Where the normal impulses between bodies landed since the last call
  // (ContactMoments, BodyContact::take_moments); zeros without body contact.
  ContactMoments take_body_contact_moments();
  // A pass's name as its cost is reported: to_string(p), but the body
  // contact pass named by what the scene asks of it (BodyContact::effect_name).
  const char* pass_name(Pass p) const;
  // The force the essential BCs exert on body `body`'s held nodes in the
  // latest step, summed [N] (a body pressed against a held one: the load
  // through their contact, once it is quasi-static).
  Vec3 held_force(int32_t body) const;
  double take_contact_impulses(std::vector<double>& impulse);

  // Takes over another simulation's body and proxies: displacements,
  // velocities, time, step count, energy sums and proxy motions, so that a
  // model rebuilt with other parameters (scene/parameters.hpp) goes on from
  // where the old one was. The accelerations are recomputed from this
  // model's forces at the first step. Both must have the same mesh (node
  // count), proxies and hands; precisions may differ. Throws
  // std::invalid_argument otherwise.
  void continue_from(const Simulation& other);
  // Before the first step: starts from displacement u [m] and velocity v
  // [m/s] (n_nodes x 3) instead of rest (constrained nodes still follow their
  // conditions). Throws std::logic_error after a step, std::invalid_argument
  // on a size mismatch or a non-finite value.
  void set_initial_state(const std::vector<double>& u, const std::vector<double>& v);

  const Fault& fault() const;
  void set_probe(StepProbe* probe);

  struct Engine;  // the body in its precision (a variant of float and double), simulation.cpp

 private:
  // f(body) on the body of this simulation's precision: each accessor is one
  // such call (simulation.cpp), its one place.
  template <class F>
  decltype(auto) visit(F&& f) const;
  template <class F>
  decltype(auto) visit(F&& f);

  std::unique_ptr<ParallelFor> pool_;  // declared first: outlives the stepper that uses it
  std::unique_ptr<Engine> engine_;
  Precision precision_ = Precision::Double;
  std::shared_ptr<const EmbeddedSurface> surface_;
};

}  // namespace tactile
