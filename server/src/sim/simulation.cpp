#include "sim/simulation.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include "core/carry.hpp"
#include "core/model.hpp"

#include "parallel/thread_pool.hpp"

namespace tactile {

struct Simulation::Engine {
  virtual ~Engine() = default;
  virtual Carried carry_out() const = 0;
  virtual void carry_in(const Carried& c) = 0;
  virtual void set_initial_state(const std::vector<double>& u, const std::vector<double>& v) = 0;
  virtual const TetMesh& mesh() const = 0;
  virtual int32_t n_nodes() const = 0;
  virtual int32_t n_tets() const = 0;
  virtual double total_mass() const = 0;
  virtual const std::vector<double>& tet_volume() const = 0;
  virtual double dt_rest() const = 0;
  virtual int32_t parts() const = 0;
  virtual double time() const = 0;
  virtual int64_t steps() const = 0;
  virtual AdvanceReport advance(double frame_dt, const std::function<bool()>& interrupt) = 0;
  virtual double compute_critical_dt() const = 0;
  virtual const Energy& energy() const = 0;
  virtual Energy compute_energy() const = 0;
  virtual std::vector<double> compute_element_energy() const = 0;
  virtual ElementFields compute_element_fields(const ElementFieldRequest& ask, std::span<const int32_t> tets) const = 0;
  virtual std::vector<uint8_t> node_constraint() const = 0;
  virtual void track_contact_forces(bool on) = 0;
  virtual double take_contact_impulses(std::vector<double>& impulse) = 0;
  virtual void copy_displacement(std::vector<double>& u) const = 0;
  virtual void copy_velocity(std::vector<double>& v) const = 0;
  virtual Vec3 displacement(int32_t node) const = 0;
  virtual void gather(std::span<const uint32_t> nodes, float* positions, float* norm) const = 0;
  virtual const std::vector<ProxySpec>& proxies() const = 0;
  virtual const std::vector<HandSpec>& hands() const = 0;
  virtual const std::vector<std::string>& devices() const = 0;
  virtual const std::vector<int32_t>& proxy_device() const = 0;
  virtual void set_proxy_motion(int32_t proxy, const ProxyMotion& m) = 0;
  virtual void set_hand_motion(int32_t hand, const ProxyMotion& m) = 0;
  virtual Pose proxy_pose(int32_t proxy) const = 0;
  virtual Pose hand_pose(int32_t hand) const = 0;
  virtual void couple_device(int32_t device, const DeviceLimits* limits) = 0;
  virtual void release_device(int32_t device) = 0;
  virtual bool device_coupled(int32_t device) const = 0;
  virtual const std::vector<ProxyReport>& proxy_reports() const = 0;
  virtual const std::vector<DeviceReport>& device_reports() const = 0;
  virtual void clear_impulses() = 0;
  virtual const Fault& fault() const = 0;
  virtual void set_probe(StepProbe* probe) = 0;
};

namespace {

template <class Real>
class EngineOf final : public Simulation::Engine {
 public:
  EngineOf(const ModelSpec& spec, ParallelFor* pool)
      : mesh_(spec.mesh),
        model_(std::make_unique<Model<Real>>(build_model<Real>(spec))),
        stepper_(*model_, pool),
        state_(stepper_.make_state()),
        node_model_(model_->node_model) {}

  Carried carry_out() const override { return tactile::carry_out(state_, model_->node_given); }
  void carry_in(const Carried& c) override {
    if (c.u.size() != state_.u.size() || c.proxy.size() != model_->proxies.size() ||
        c.hand.size() != model_->hands.size())
      throw std::invalid_argument("continue_from: the other simulation has " + std::to_string(c.u.size() / 3) +
                                  " nodes, " + std::to_string(c.proxy.size()) + " proxies and " +
                                  std::to_string(c.hand.size()) + " hands; this one " +
                                  std::to_string(state_.u.size() / 3) + ", " + std::to_string(model_->proxies.size()) +
                                  " and " + std::to_string(model_->hands.size()));
    tactile::carry_in(c, model_->node_given, state_);
    stepper_.contact().take_bodies(state_, c.bodies);
  }

  void set_initial_state(const std::vector<double>& u, const std::vector<double>& v) override {
    if (state_.step != 0)
      throw std::logic_error("set_initial_state: the simulation has taken " + std::to_string(state_.step) +
                             " steps; an initial state is set before the first");
    if (u.size() != state_.u.size() || v.size() != state_.v.size())
      throw std::invalid_argument("set_initial_state: " + std::to_string(u.size() / 3) + " displacements and " +
                                  std::to_string(v.size() / 3) + " velocities for " +
                                  std::to_string(state_.u.size() / 3) + " nodes");
    for (size_t k = 0; k < u.size(); ++k)
      if (!std::isfinite(u[k]) || !std::isfinite(v[k]))
        throw std::invalid_argument("set_initial_state: node " + std::to_string(k / 3) + " has a non-finite value");
    for (size_t g = 0; g < node_model_.size(); ++g)
      for (size_t d = 0; d < 3; ++d) {
        state_.u[3 * size_t(node_model_[g]) + d] = Real(u[3 * g + d]);
        state_.v[3 * size_t(node_model_[g]) + d] = Real(v[3 * g + d]);
      }
  }

  const TetMesh& mesh() const override { return mesh_; }
  int32_t n_nodes() const override { return model_->n_nodes; }
  int32_t n_tets() const override { return model_->n_tets; }
  double total_mass() const override { return model_->total_mass; }
  const std::vector<double>& tet_volume() const override { return model_->tet_volume; }
  double dt_rest() const override { return model_->dt_rest; }
  int32_t parts() const override { return stepper_.parts(); }
  double time() const override { return state_.t; }
  int64_t steps() const override { return state_.step; }
  AdvanceReport advance(double frame_dt, const std::function<bool()>& interrupt) override {
    return stepper_.advance(state_, frame_dt, interrupt);
  }
  double compute_critical_dt() const override { return stepper_.compute_critical_dt(state_); }
  const Energy& energy() const override { return state_.energy.latest; }
  Energy compute_energy() const override { return stepper_.compute_energy(state_); }
  std::vector<double> compute_element_energy() const override { return stepper_.compute_element_energy(state_); }
  ElementFields compute_element_fields(const ElementFieldRequest& ask, std::span<const int32_t> tets) const override {
    return tactile::compute_element_fields(*model_, state_, ask, tets);
  }
  std::vector<uint8_t> node_constraint() const override {
    std::vector<uint8_t> out(size_t(model_->n_nodes), 0);
    for (const EssentialSet& set : model_->essential)
      for (int32_t i : set.nodes) {
        uint8_t& c = out[size_t(model_->node_given[size_t(i)])];
        c = std::max<uint8_t>(c, set.moving ? 2 : 1);
      }
    return out;
  }
  void track_contact_forces(bool on) override { stepper_.contact().track_node_impulses(state_, on); }
  double take_contact_impulses(std::vector<double>& impulse) override {
    impulses_.assign(state_.u.size(), 0.0);
    const double span = stepper_.contact().take_node_impulses(state_, impulses_);
    copy_given(impulses_.data(), impulse);
    return span;
  }
  void copy_displacement(std::vector<double>& u) const override { copy_given(state_.u.data(), u); }
  void copy_velocity(std::vector<double>& v) const override { copy_given(state_.v.data(), v); }
  Vec3 displacement(int32_t node) const override {
    const size_t j = 3 * size_t(node_model_.at(size_t(node)));
    return {double(state_.u[j]), double(state_.u[j + 1]), double(state_.u[j + 2])};
  }
  void gather(std::span<const uint32_t> nodes, float* positions, float* norm) const override {
    const std::vector<Vec3>& X = mesh_.X;
    const Real* u = state_.u.data();
    for (size_t k = 0; k < nodes.size(); ++k) {
      const size_t g = nodes[k], i = size_t(node_model_[g]);
      const double ux = double(u[3 * i]), uy = double(u[3 * i + 1]), uz = double(u[3 * i + 2]);
      positions[3 * k] = float(X[g].x + ux);
      positions[3 * k + 1] = float(X[g].y + uy);
      positions[3 * k + 2] = float(X[g].z + uz);
      if (norm) norm[k] = float(std::sqrt(ux * ux + uy * uy + uz * uz));
    }
  }
  const std::vector<ProxySpec>& proxies() const override { return model_->proxies; }
  const std::vector<HandSpec>& hands() const override { return model_->hands; }
  const std::vector<std::string>& devices() const override { return model_->devices; }
  const std::vector<int32_t>& proxy_device() const override { return model_->proxy_device; }
  void set_proxy_motion(int32_t proxy, const ProxyMotion& m) override {
    stepper_.contact().set_motion(state_, proxy, m);
  }
  void set_hand_motion(int32_t hand, const ProxyMotion& m) override {
    stepper_.contact().set_hand_motion(state_, hand, m);
  }
  Pose proxy_pose(int32_t proxy) const override { return stepper_.contact().proxy_pose(state_, proxy); }
  Pose hand_pose(int32_t hand) const override { return stepper_.contact().hand_pose(state_, hand); }
  void couple_device(int32_t device, const DeviceLimits* limits) override {
    stepper_.contact().couple(state_, device, limits);
  }
  void release_device(int32_t device) override { stepper_.contact().release(state_, device); }
  bool device_coupled(int32_t device) const override { return state_.contact.coupled(device); }
  const std::vector<ProxyReport>& proxy_reports() const override { return state_.contact.reports; }
  const std::vector<DeviceReport>& device_reports() const override { return state_.contact.device_reports; }
  void clear_impulses() override { state_.contact.clear_impulses(); }
  const Fault& fault() const override { return state_.fault; }
  void set_probe(StepProbe* probe) override { stepper_.set_probe(probe); }

 private:
  // A per-node array of the model's numbering, in the mesh's (n_nodes x 3).
  template <class T>
  void copy_given(const T* model_order, std::vector<double>& out) const {
    out.resize(3 * node_model_.size());
    for (size_t g = 0; g < node_model_.size(); ++g)
      for (size_t d = 0; d < 3; ++d) out[3 * g + d] = double(model_order[3 * size_t(node_model_[g]) + d]);
  }

  TetMesh mesh_;                        // the spec's, in its own numbering
  std::unique_ptr<Model<Real>> model_;  // the stepper keeps a reference: the model must not move
  Stepper<Real> stepper_;
  State<Real> state_;
  std::vector<int32_t> node_model_;  // the model's id of each mesh node
  std::vector<double> impulses_;     // take_contact_impulses' model-ordered scratch
};

}  // namespace

Simulation::Simulation(const ModelSpec& spec) {
  if (spec.integrator.threads > 1) pool_ = std::make_unique<ThreadPool>(spec.integrator.threads);
  if (spec.integrator.precision == Precision::Float)
    engine_ = std::make_unique<EngineOf<float>>(spec, pool_.get());
  else
    engine_ = std::make_unique<EngineOf<double>>(spec, pool_.get());
  precision_ = spec.integrator.precision;
  surface_ = spec.surface;
}

Simulation::~Simulation() = default;
Simulation::Simulation(Simulation&&) noexcept = default;
Simulation& Simulation::operator=(Simulation&&) noexcept = default;

Precision Simulation::precision() const { return precision_; }
const TetMesh& Simulation::mesh() const { return engine_->mesh(); }
int32_t Simulation::n_nodes() const { return engine_->n_nodes(); }
int32_t Simulation::n_tets() const { return engine_->n_tets(); }
double Simulation::total_mass() const { return engine_->total_mass(); }
const std::vector<double>& Simulation::tet_volume() const { return engine_->tet_volume(); }
double Simulation::dt_rest() const { return engine_->dt_rest(); }
int32_t Simulation::parts() const { return engine_->parts(); }
double Simulation::time() const { return engine_->time(); }
int64_t Simulation::steps() const { return engine_->steps(); }
AdvanceReport Simulation::advance(double frame_dt, const std::function<bool()>& interrupt) {
  return engine_->advance(frame_dt, interrupt);
}
double Simulation::compute_critical_dt() const { return engine_->compute_critical_dt(); }
const Energy& Simulation::energy() const { return engine_->energy(); }
Energy Simulation::compute_energy() const { return engine_->compute_energy(); }
std::vector<double> Simulation::compute_element_energy() const { return engine_->compute_element_energy(); }
ElementFields Simulation::compute_element_fields(const ElementFieldRequest& ask, std::span<const int32_t> tets) const {
  return engine_->compute_element_fields(ask, tets);
}
std::vector<uint8_t> Simulation::node_constraint() const { return engine_->node_constraint(); }
void Simulation::track_contact_forces(bool on) { engine_->track_contact_forces(on); }
double Simulation::take_contact_impulses(std::vector<double>& impulse) {
  return engine_->take_contact_impulses(impulse);
}
void Simulation::copy_positions(std::vector<double>& x) const {
  engine_->copy_displacement(x);
  const TetMesh& m = mesh();
  for (size_t i = 0; i < m.X.size(); ++i)
    for (size_t d = 0; d < 3; ++d) x[3 * i + d] += m.X[i][int(d)];
}
void Simulation::copy_displacement(std::vector<double>& u) const { engine_->copy_displacement(u); }
void Simulation::copy_velocity(std::vector<double>& v) const { engine_->copy_velocity(v); }
Vec3 Simulation::displacement(int32_t node) const { return engine_->displacement(node); }
void Simulation::gather(std::span<const uint32_t> nodes, float* positions, float* displacement_norm) const {
  engine_->gather(nodes, positions, displacement_norm);
}
const std::vector<ProxySpec>& Simulation::proxies() const { return engine_->proxies(); }
const std::vector<HandSpec>& Simulation::hands() const { return engine_->hands(); }
const std::vector<std::string>& Simulation::devices() const { return engine_->devices(); }
const std::vector<int32_t>& Simulation::proxy_device() const { return engine_->proxy_device(); }
void Simulation::set_proxy_motion(int32_t proxy, const ProxyMotion& m) { engine_->set_proxy_motion(proxy, m); }
void Simulation::set_hand_motion(int32_t hand, const ProxyMotion& m) { engine_->set_hand_motion(hand, m); }
Pose Simulation::proxy_pose(int32_t proxy) const { return engine_->proxy_pose(proxy); }
Pose Simulation::hand_pose(int32_t hand) const { return engine_->hand_pose(hand); }
void Simulation::couple_device(int32_t device, const DeviceLimits* limits) {
  if (limits)
    for (const auto& [name, value] :
         {std::pair{"max_force", limits->max_force}, std::pair{"max_torque", limits->max_torque},
          std::pair{"stiffness", limits->stiffness}})
      if (!std::isfinite(value) || value < 0)
        throw std::invalid_argument(std::string("device limits: ") + name +
                                    " must be finite and >= 0 (0: not given), got " + std::to_string(value));
  engine_->couple_device(device, limits);
}
void Simulation::release_device(int32_t device) { engine_->release_device(device); }
bool Simulation::device_coupled(int32_t device) const { return engine_->device_coupled(device); }
const std::vector<ProxyReport>& Simulation::proxy_reports() const { return engine_->proxy_reports(); }
const std::vector<DeviceReport>& Simulation::device_reports() const { return engine_->device_reports(); }
void Simulation::clear_impulses() { engine_->clear_impulses(); }
void Simulation::continue_from(const Simulation& other) { engine_->carry_in(other.engine_->carry_out()); }
void Simulation::set_initial_state(const std::vector<double>& u, const std::vector<double>& v) {
  engine_->set_initial_state(u, v);
}
const Fault& Simulation::fault() const { return engine_->fault(); }
void Simulation::set_probe(StepProbe* probe) { engine_->set_probe(probe); }

}  // namespace tactile
