#include "sim/simulation.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>
#include <variant>

#include "core/carry.hpp"
#include "core/model.hpp"

#include "parallel/thread_pool.hpp"

namespace tactile {

namespace {

// The precision-specific part: a model, its stepper and its state, of one
// scalar type. Plain members: each Simulation accessor below reads them
// directly through visit(), one place per accessor.
template <class Real>
struct Body {
  Body(const ModelSpec& spec, ParallelFor* pool)
      : mesh(spec.mesh),
        model(std::make_unique<Model<Real>>(build_model<Real>(spec))),
        stepper(*model, pool),
        state(stepper.make_state()) {}

  // A per-node array of the model's numbering, in the mesh's (n_nodes x 3).
  template <class T>
  void copy_given(const T* model_order, std::vector<double>& out) const {
    const std::vector<int32_t>& node_model = model->node_model;
    out.resize(3 * node_model.size());
    for (size_t g = 0; g < node_model.size(); ++g)
      for (size_t d = 0; d < 3; ++d) out[3 * g + d] = double(model_order[3 * size_t(node_model[g]) + d]);
  }

  TetMesh mesh;                        // the spec's, in its own numbering
  std::unique_ptr<Model<Real>> model;  // the stepper keeps a reference: the model must not move
  Stepper<Real> stepper;
  State<Real> state;
  std::vector<double> impulses;  // take_contact_impulses' model-ordered scratch
};

}  // namespace

struct Simulation::Engine {
  std::variant<std::unique_ptr<Body<float>>, std::unique_ptr<Body<double>>> body;
};

// f(body) for the body of this simulation's precision.
template <class F>
decltype(auto) Simulation::visit(F&& f) const {
  return std::visit([&](const auto& b) -> decltype(auto) { return f(std::as_const(*b)); }, engine_->body);
}
template <class F>
decltype(auto) Simulation::visit(F&& f) {
  return std::visit([&](auto& b) -> decltype(auto) { return f(*b); }, engine_->body);
}

Simulation::Simulation(const ModelSpec& spec) : engine_(std::make_unique<Engine>()) {
  if (spec.integrator.threads > 1) pool_ = std::make_unique<ThreadPool>(spec.integrator.threads);
  if (spec.integrator.precision == Precision::Float)
    engine_->body = std::make_unique<Body<float>>(spec, pool_.get());
  else
    engine_->body = std::make_unique<Body<double>>(spec, pool_.get());
  precision_ = spec.integrator.precision;
  surface_ = spec.surface;
}

Simulation::~Simulation() = default;
Simulation::Simulation(Simulation&&) noexcept = default;
Simulation& Simulation::operator=(Simulation&&) noexcept = default;

Precision Simulation::precision() const { return precision_; }
const TetMesh& Simulation::mesh() const {
  return visit([](const auto& b) -> const TetMesh& { return b.mesh; });
}
const std::vector<ModelBody>& Simulation::bodies() const {
  return visit([](const auto& b) -> const std::vector<ModelBody>& { return b.model->bodies; });
}
int32_t Simulation::n_nodes() const {
  return visit([](const auto& b) { return b.model->n_nodes; });
}
int32_t Simulation::n_tets() const {
  return visit([](const auto& b) { return b.model->n_tets; });
}
double Simulation::total_mass() const {
  return visit([](const auto& b) { return b.model->total_mass; });
}
double Simulation::added_mass() const {
  return visit([](const auto& b) { return b.model->added_mass; });
}
int32_t Simulation::mass_scaled_tets() const {
  return visit([](const auto& b) { return b.model->mass_scaled_tets; });
}
const std::vector<double>& Simulation::tet_volume() const {
  return visit([](const auto& b) -> const std::vector<double>& { return b.model->tet_volume; });
}
double Simulation::dt_rest() const {
  return visit([](const auto& b) { return b.model->dt_rest; });
}
int32_t Simulation::parts() const {
  return visit([](const auto& b) { return b.stepper.parts(); });
}
double Simulation::time() const {
  return visit([](const auto& b) { return b.state.t; });
}
int64_t Simulation::steps() const {
  return visit([](const auto& b) { return b.state.step; });
}
AdvanceReport Simulation::advance(double frame_dt, const std::function<bool()>& interrupt) {
  return visit([&](auto& b) { return b.stepper.advance(b.state, frame_dt, interrupt); });
}
double Simulation::compute_critical_dt() const {
  return visit([](const auto& b) { return b.stepper.compute_critical_dt(b.state); });
}
const Energy& Simulation::energy() const {
  return visit([](const auto& b) -> const Energy& { return b.state.energy.latest; });
}
Energy Simulation::compute_energy() const {
  return visit([](const auto& b) { return b.stepper.compute_energy(b.state); });
}
std::vector<double> Simulation::compute_element_energy() const {
  return visit([](const auto& b) { return b.stepper.compute_element_energy(b.state); });
}
ElementFields Simulation::compute_element_fields(const ElementFieldRequest& ask, std::span<const int32_t> tets) const {
  return visit([&](const auto& b) { return tactile::compute_element_fields(*b.model, b.state, ask, tets); });
}
std::vector<uint8_t> Simulation::node_constraint() const {
  return visit([](const auto& b) {
    std::vector<uint8_t> out(size_t(b.model->n_nodes), 0);
    for (const EssentialSet& set : b.model->essential)
      for (int32_t i : set.nodes) {
        uint8_t& c = out[size_t(b.model->node_given[size_t(i)])];
        c = std::max<uint8_t>(c, set.moving ? 2 : 1);
      }
    return out;
  });
}
void Simulation::track_contact_forces(bool on) {
  visit([&](auto& b) { b.stepper.contact().track_node_impulses(b.state, on); });
}
double Simulation::take_contact_impulses(std::vector<double>& impulse) {
  return visit([&](auto& b) {
    b.impulses.assign(b.state.u.size(), 0.0);
    const double span = b.stepper.contact().take_node_impulses(b.state, b.impulses);
    b.copy_given(b.impulses.data(), impulse);
    return span;
  });
}
void Simulation::copy_positions(std::vector<double>& x) const {
  copy_displacement(x);
  const TetMesh& m = mesh();
  for (size_t i = 0; i < m.X.size(); ++i)
    for (size_t d = 0; d < 3; ++d) x[3 * i + d] += m.X[i][int(d)];
}
void Simulation::copy_displacement(std::vector<double>& u) const {
  visit([&](const auto& b) { b.copy_given(b.state.u.data(), u); });
}
void Simulation::copy_velocity(std::vector<double>& v) const {
  visit([&](const auto& b) { b.copy_given(b.state.v.data(), v); });
}
Vec3 Simulation::displacement(int32_t node) const {
  return visit([&](const auto& b) {
    const size_t j = 3 * size_t(b.model->node_model.at(size_t(node)));
    return Vec3(double(b.state.u[j]), double(b.state.u[j + 1]), double(b.state.u[j + 2]));
  });
}
void Simulation::gather(std::span<const uint32_t> nodes, float* positions, float* displacement_norm) const {
  visit([&](const auto& b) {
    const std::vector<Vec3>& X = b.mesh.X;
    const auto* u = b.state.u.data();
    for (size_t k = 0; k < nodes.size(); ++k) {
      const size_t g = nodes[k], i = size_t(b.model->node_model[g]);
      const double ux = double(u[3 * i]), uy = double(u[3 * i + 1]), uz = double(u[3 * i + 2]);
      positions[3 * k] = float(X[g].x + ux);
      positions[3 * k + 1] = float(X[g].y + uy);
      positions[3 * k + 2] = float(X[g].z + uz);
      if (displacement_norm) displacement_norm[k] = float(std::sqrt(ux * ux + uy * uy + uz * uz));
    }
  });
}
const std::vector<ProxySpec>& Simulation::proxies() const {
  return visit([](const auto& b) -> const std::vector<ProxySpec>& { return b.model->proxies; });
}
const std::vector<HandSpec>& Simulation::hands() const {
  return visit([](const auto& b) -> const std::vector<HandSpec>& { return b.model->hands; });
}
const std::vector<std::string>& Simulation::devices() const {
  return visit([](const auto& b) -> const std::vector<std::string>& { return b.model->devices; });
}
const std::vector<int32_t>& Simulation::proxy_device() const {
  return visit([](const auto& b) -> const std::vector<int32_t>& { return b.model->proxy_device; });
}
void Simulation::set_proxy_motion(int32_t proxy, const ProxyMotion& m) {
  visit([&](auto& b) { b.stepper.contact().set_motion(b.state, proxy, m); });
}
void Simulation::set_hand_motion(int32_t hand, const ProxyMotion& m) {
  visit([&](auto& b) { b.stepper.contact().set_hand_motion(b.state, hand, m); });
}
Pose Simulation::proxy_pose(int32_t proxy) const {
  return visit([&](const auto& b) { return b.stepper.contact().proxy_pose(b.state, proxy); });
}
Pose Simulation::hand_pose(int32_t hand) const {
  return visit([&](const auto& b) { return b.stepper.contact().hand_pose(b.state, hand); });
}
void Simulation::couple_device(int32_t device, const DeviceLimits* limits) {
  if (limits)
    for (const auto& [name, value] :
         {std::pair{"max_force", limits->max_force}, std::pair{"max_torque", limits->max_torque},
          std::pair{"stiffness", limits->stiffness}})
      if (!std::isfinite(value) || value < 0)
        throw std::invalid_argument(std::string("device limits: ") + name +
                                    " must be finite and >= 0 (0: not given), got " + std::to_string(value));
  visit([&](auto& b) { b.stepper.contact().couple(b.state, device, limits); });
}
void Simulation::release_device(int32_t device) {
  visit([&](auto& b) { b.stepper.contact().release(b.state, device); });
}
bool Simulation::device_coupled(int32_t device) const {
  return visit([&](const auto& b) { return b.state.contact.coupled(device); });
}
const std::vector<ProxyReport>& Simulation::proxy_reports() const {
  return visit([](const auto& b) -> const std::vector<ProxyReport>& { return b.state.contact.reports; });
}
Simulation::BodyContactReport Simulation::body_contact_report() const {
  return visit([](const auto& b) {
    const auto& c = b.stepper.body_contact();
    BodyContactReport r;
    if (!c.active()) return r;
    r.between = c.body_contacts();
    r.within = c.self_contacts();
    r.given = c.given();
    r.held = c.held_given();
    r.impulses = c.impulse_sum();
    return r;
  });
}
ContactMoments Simulation::take_body_contact_moments() {
  return visit([](auto& b) { return b.stepper.body_contact().take_moments(); });
}
const char* Simulation::pass_name(Pass p) const {
  if (p != Pass::BodyContact) return to_string(p);
  return visit([](const auto& b) { return b.stepper.body_contact().effect_name(); });
}
Vec3 Simulation::held_force(int32_t body) const {
  return visit([&](const auto& b) {
    Vec3 sum(0.0);
    size_t c = 0;  // the reactions run over the sets' nodes in order
    for (const EssentialSet& set : b.model->essential)
      for (int32_t i : set.nodes) {
        if (b.model->node_body[size_t(i)] == body)
          for (int d = 0; d < 3; ++d) sum[d] += double(b.state.reaction[3 * c + size_t(d)]);
        ++c;
      }
    return sum;
  });
}
const std::vector<DeviceReport>& Simulation::device_reports() const {
  return visit([](const auto& b) -> const std::vector<DeviceReport>& { return b.state.contact.device_reports; });
}
void Simulation::clear_impulses() {
  visit([](auto& b) { b.state.contact.clear_impulses(); });
}
void Simulation::continue_from(const Simulation& other) {
  const Carried c = other.visit([](const auto& b) { return carry_out(b.state, b.model->node_given); });
  visit([&](auto& b) {
    if (c.u.size() != b.state.u.size() || c.proxy.size() != b.model->proxies.size() ||
        c.hand.size() != b.model->hands.size())
      throw std::invalid_argument(
          "continue_from: the other simulation has " + std::to_string(c.u.size() / 3) + " nodes, " +
          std::to_string(c.proxy.size()) + " proxies and " + std::to_string(c.hand.size()) + " hands; this one " +
          std::to_string(b.state.u.size() / 3) + ", " + std::to_string(b.model->proxies.size()) + " and " +
          std::to_string(b.model->hands.size()));
    carry_in(c, b.model->node_given, b.state);
    b.stepper.contact().take_bodies(b.state, c.bodies);
  });
}
void Simulation::set_initial_state(const std::vector<double>& u, const std::vector<double>& v) {
  visit([&](auto& b) {
    using Real = typename std::decay_t<decltype(b.state.u)>::value_type;
    if (b.state.step != 0)
      throw std::logic_error("set_initial_state: the simulation has taken " + std::to_string(b.state.step) +
                             " steps; an initial state is set before the first");
    if (u.size() != b.state.u.size() || v.size() != b.state.v.size())
      throw std::invalid_argument("set_initial_state: " + std::to_string(u.size() / 3) + " displacements and " +
                                  std::to_string(v.size() / 3) + " velocities for " +
                                  std::to_string(b.state.u.size() / 3) + " nodes");
    for (size_t k = 0; k < u.size(); ++k)
      if (!std::isfinite(u[k]) || !std::isfinite(v[k]))
        throw std::invalid_argument("set_initial_state: node " + std::to_string(k / 3) + " has a non-finite value");
    const std::vector<int32_t>& node_model = b.model->node_model;
    for (size_t g = 0; g < node_model.size(); ++g)
      for (size_t d = 0; d < 3; ++d) {
        b.state.u[3 * size_t(node_model[g]) + d] = Real(u[3 * g + d]);
        b.state.v[3 * size_t(node_model[g]) + d] = Real(v[3 * g + d]);
      }
  });
}
const Fault& Simulation::fault() const {
  return visit([](const auto& b) -> const Fault& { return b.state.fault; });
}
void Simulation::set_probe(StepProbe* probe) {
  visit([&](auto& b) { b.stepper.set_probe(probe); });
}

}  // namespace tactile
