#include "live/frames.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/geometric.hpp>

#include "core/proxy.hpp"
#include "tactile_generated.h"

namespace tactile {

namespace fb = flatbuffers;
namespace wire = proto;

Surface extract_surface(const Simulation& sim) {
  const TetMesh& mesh = sim.mesh();
  const std::vector<Tri> faces = compute_boundary_faces(mesh);
  const std::vector<int32_t> boundary = compute_boundary_nodes(faces);  // sorted
  const std::shared_ptr<const EmbeddedSurface>& e = sim.surface();
  Surface s;
  std::vector<int32_t> vertex_of(size_t(mesh.n_nodes()), -1);
  // Body by body: its boundary nodes, then the interior nodes its fine
  // surface follows, each in the order of the scene's mesh: two runs of one
  // mesh send the same vertex in the same place, as a re-simulation compares them.
  for (const ModelBody& mb : sim.bodies()) {
    const BodySpec& body = mb.spec;
    Surface::Body out;
    out.name = body.name;
    out.node_begin = uint32_t(body.node_begin);
    out.vertex_begin = uint32_t(s.nodes.size());
    for (int32_t n : boundary)
      if (n >= body.node_begin && n < body.node_end) {
        vertex_of[size_t(n)] = int32_t(s.nodes.size());
        s.nodes.push_back(uint32_t(n));
      }
    if (e) {
      std::vector<int32_t> interior;
      for (int32_t v = body.fine_vertex_begin; v < body.fine_vertex_end; ++v)
        for (int32_t n : e->nodes[size_t(v)])
          if (vertex_of[size_t(n)] == -1) {
            vertex_of[size_t(n)] = -2;  // listed
            interior.push_back(n);
          }
      std::sort(interior.begin(), interior.end());
      for (int32_t n : interior) {
        vertex_of[size_t(n)] = int32_t(s.nodes.size());
        s.nodes.push_back(uint32_t(n));
      }
    }
    out.vertex_end = uint32_t(s.nodes.size());
    out.triangle_begin = uint32_t(s.triangles.size() / 3);
    for (const Tri& f : faces)
      if (f[0] >= body.node_begin && f[0] < body.node_end)
        for (int32_t i : f) s.triangles.push_back(uint32_t(vertex_of[size_t(i)]));
    out.triangle_end = uint32_t(s.triangles.size() / 3);
    out.fine_vertex_begin = uint32_t(body.fine_vertex_begin);
    out.fine_vertex_end = uint32_t(body.fine_vertex_end);
    out.fine_triangle_begin = uint32_t(body.fine_triangle_begin);
    out.fine_triangle_end = uint32_t(body.fine_triangle_end);
    s.bodies.push_back(out);
  }
  if (e) {
    s.carriers.reserve(4 * e->nodes.size());
    s.weights.reserve(4 * e->nodes.size());
    for (size_t v = 0; v < e->nodes.size(); ++v)
      for (int k = 0; k < 4; ++k) {
        s.carriers.push_back(uint32_t(vertex_of[size_t(e->nodes[v][size_t(k)])]));
        s.weights.push_back(float(e->weights[v][size_t(k)]));
      }
  }
  return s;
}

int32_t compute_device_hand(const Simulation& sim, int32_t device) {
  const std::string& name = sim.devices()[size_t(device)];
  for (size_t h = 0; h < sim.hands().size(); ++h)
    if (sim.hands()[h].device == name) return int32_t(h);
  return -1;
}

namespace {

// A coupled channel whose target stands farther than this off its device's
// path is sent no stiffness (haptic_frame) [m].
constexpr double kMaxOffsetForStiffness = 1e-3;
// A coupled channel whose proxy has touched nothing for this long is free
// and sent no stiffness (haptic_frame) [s].
constexpr double kFreeAfter = 2e-3;
// A device's local model (DeviceModel) holds within half its smallest
// proxy's bounding radius, where the contact's points and normal change
// little, and within these bounds [m]: past a centimetre the server's next
// frames know better than any extrapolation.
constexpr double kModelRadiusMin = 1e-3;
constexpr double kModelRadiusMax = 1e-2;

wire::Vec3f to_wire(const Vec3& v) { return {float(v.x), float(v.y), float(v.z)}; }
wire::Quatf to_wire(const Quat& q) { return {float(q.w), float(q.x), float(q.y), float(q.z)}; }
wire::Mat3f to_wire(const glm::dmat3& m) {  // glm is column-major: m[col][row]
  return {float(m[0][0]), float(m[1][0]), float(m[2][0]), float(m[0][1]), float(m[1][1]),
          float(m[2][1]), float(m[0][2]), float(m[1][2]), float(m[2][2])};
}

wire::ProxyShape to_wire(ProxyShape s) {
  switch (s) {
    case ProxyShape::Sphere: return wire::ProxyShape::Sphere;
    case ProxyShape::Capsule: return wire::ProxyShape::Capsule;
    case ProxyShape::Box: return wire::ProxyShape::Box;
    case ProxyShape::Plane: return wire::ProxyShape::Plane;
  }
  return wire::ProxyShape::Sphere;
}

// A coupled channel's local model (proto DeviceModel) from its report, the
// stiffness K it is sent (negative semidefinite, zero while free) and the
// contact force on its proxies (a window's mean). The normal is the contact
// force's direction, not the coupling's: a proxy that lags a lifting hand
// pulls it toward the body through the coupling while the contact still
// pushes the proxy out. The damping is the coupling's damper as the device
// feels it through the contact in series: the felt stiffness times the
// coupling's time constant c/k (the coupling's own damper against a rigid
// body). The release plane is where the model's force along the normal,
// F0.n + n.K n (x - x0).n, falls to zero (behind x0 where the coupling
// already pulls the device in: the contact is letting go).
wire::DeviceModel local_model(const DeviceReport& r, const glm::dmat3& K, const Vec3& contact_force, double radius) {
  const double c = glm::length(contact_force);
  const Vec3 n = c > 0 ? contact_force / c : Vec3(0.0);
  const double k_n = -glm::dot(n, K * n);
  if (k_n <= 0) {  // no contact, or no stiffness along it: the force alone
    return wire::DeviceModel(to_wire(glm::dmat3(0.0)), to_wire(r.target_velocity), wire::Vec3f(0, 0, 0), 0.0f,
                             float(radius));
  }
  const double tau = r.coupling_stiffness > 0 ? r.coupling_damping / r.coupling_stiffness : 0.0;
  return wire::DeviceModel(to_wire(-tau * K), to_wire(r.target_velocity), to_wire(n), float(glm::dot(r.force, n) / k_n),
                           float(radius));
}

template <class T>
std::span<const uint8_t> seal(fb::FlatBufferBuilder& b, wire::Message type, fb::Offset<T> body) {
  b.Finish(wire::CreateEnvelope(b, type, body.Union()), wire::EnvelopeIdentifier());
  return std::span<const uint8_t>(b.GetBufferPointer(), b.GetSize());
}

}  // namespace

FrameEncoder::FrameEncoder(const Simulation& sim, std::string scene_name, uint32_t scene_id, double dt,
                           double force_window)
    : sim_(sim), scene_name_(std::move(scene_name)), scene_id_(scene_id), dt_(dt), surface_(extract_surface(sim)) {
  positions_.resize(3 * surface_.nodes.size());
  poses_.resize(sim.proxies().size());
  forces_.resize(sim.proxies().size());
  proxy_haptics_.resize(sim.proxies().size());
  device_haptics_.resize(sim.devices().size());
  device_poses_.resize(sim.devices().size());
  state_device_poses_.resize(sim.devices().size());
  device_couplings_.resize(sim.devices().size());
  device_models_.resize(sim.devices().size());
  model_radius_.assign(sim.devices().size(), kModelRadiusMax);
  for (size_t j = 0; j < sim.proxies().size(); ++j) {
    const double r = bounding_radius(sim.proxies()[j].geometry);  // infinite for a plane
    double& m = model_radius_[size_t(sim.proxy_device()[j])];
    if (std::isfinite(r)) m = std::min(m, std::max(kModelRadiusMin, 0.5 * r));
  }
  contacts_proxy_.assign(sim.proxies().size(), 0);
  contacts_device_.assign(sim.devices().size(), 0);
  touched_.assign(sim.devices().size(), -std::numeric_limits<double>::infinity());
  input_sequences_.resize(sim.devices().size());
  device_hand_.resize(sim.devices().size());
  device_proxy_.assign(sim.devices().size(), -1);
  for (size_t d = 0; d < sim.devices().size(); ++d) device_hand_[d] = compute_device_hand(sim, int32_t(d));
  // (Every channel has a proxy: the model makes its channels from them.)
  for (size_t j = sim.proxies().size(); j-- > 0;) device_proxy_[size_t(sim.proxy_device()[j])] = int32_t(j);
  // An even number of steps: a resting contact's bounce often pulses every
  // other step, which an odd window would turn into a frame-to-frame flicker.
  window_steps_ = size_t(std::max(1.0, std::round(force_window / (dt > 0 ? dt : 0.7 * sim.dt_rest()))));
  window_steps_ += window_steps_ % 2;
  window_proxy_.resize(window_steps_ * sim.proxies().size());
  window_device_.resize(window_steps_ * sim.devices().size());
  sum_proxy_.resize(sim.proxies().size());
  sum_device_.resize(sim.devices().size());
}

std::span<const uint8_t> FrameEncoder::scene_description(std::span<const Parameter> parameters,
                                                         std::span<const std::string> scenes) {
  fb::FlatBufferBuilder& b = scene_builder_;
  b.Clear();
  const TetMesh& mesh = sim_.mesh();
  std::vector<float> rest(3 * surface_.nodes.size());
  for (size_t k = 0; k < surface_.nodes.size(); ++k)
    for (int c = 0; c < 3; ++c) rest[3 * k + size_t(c)] = float(mesh.X[surface_.nodes[k]][c]);
  std::vector<fb::Offset<wire::ProxyInfo>> proxies;
  for (const ProxySpec& p : sim_.proxies()) {
    const wire::Vec3f half = to_wire(p.geometry.half_extents);
    proxies.push_back(wire::CreateProxyInfoDirect(b, p.name.c_str(), p.device.c_str(), p.hand.c_str(),
                                                  to_wire(p.geometry.shape), float(p.geometry.radius),
                                                  float(p.geometry.half_length), &half, float(p.friction)));
  }
  std::vector<fb::Offset<fb::String>> devices;
  for (const std::string& d : sim_.devices()) devices.push_back(b.CreateString(d));
  std::vector<fb::Offset<wire::Parameter>> params;
  for (const Parameter& p : parameters)
    params.push_back(wire::CreateParameterDirect(b, p.name.c_str(), p.value, p.min, p.max, p.unit.c_str()));
  std::vector<fb::Offset<fb::String>> names;
  for (const std::string& s : scenes) names.push_back(b.CreateString(s));
  fb::Offset<wire::EmbeddedSurface> embedded;
  if (const auto& e = sim_.surface()) {
    std::vector<float> fine_rest(3 * e->rest.vertices.size());
    for (size_t v = 0; v < e->rest.vertices.size(); ++v)
      for (int c = 0; c < 3; ++c) fine_rest[3 * v + size_t(c)] = float(e->rest.vertices[v][c]);
    std::vector<uint32_t> fine_triangles;
    fine_triangles.reserve(3 * e->rest.triangles.size());
    for (const Tri& t : e->rest.triangles)
      for (int32_t v : t) fine_triangles.push_back(uint32_t(v));
    embedded = wire::CreateEmbeddedSurfaceDirect(b, &fine_rest, &fine_triangles, &surface_.carriers, &surface_.weights);
  }
  std::vector<fb::Offset<wire::FieldInfo>> fields;
  for (int k = 0; k < kViewFieldCount; ++k) {
    const ViewFieldInfo& f = view_field_info(ViewField(k));
    fields.push_back(wire::CreateFieldInfoDirect(b, f.name, f.unit, f.description));
  }
  std::vector<fb::Offset<wire::BodyInfo>> bodies;
  for (const Surface::Body& body : surface_.bodies)
    bodies.push_back(wire::CreateBodyInfoDirect(b, body.name.c_str(), body.vertex_begin, body.vertex_end,
                                                body.triangle_begin, body.triangle_end, body.fine_vertex_begin,
                                                body.fine_vertex_end, body.fine_triangle_begin, body.fine_triangle_end,
                                                body.node_begin));
  return seal(b, wire::Message::SceneDescription,
              wire::CreateSceneDescriptionDirect(b, scene_name_.c_str(), scene_id_, dt_, &rest, &surface_.triangles,
                                                 &surface_.nodes, "", &proxies, &devices, &params, &names, embedded,
                                                 &fields, &bodies));
}

void FrameEncoder::build_field_map() {
  const TetMesh& mesh = sim_.mesh();
  const std::vector<double>& volume = sim_.tet_volume();
  std::vector<int32_t> vertex_of(size_t(mesh.n_nodes()), -1);
  for (size_t k = 0; k < surface_.nodes.size(); ++k) vertex_of[surface_.nodes[k]] = int32_t(k);
  // Per vertex, its tets: counted, then filled (CSR).
  field_start_.assign(surface_.nodes.size() + 1, 0);
  for (size_t e = 0; e < mesh.tets.size(); ++e) {
    bool touches = false;
    for (int k = 0; k < mesh.nodes_per_tet(); ++k)
      if (const int32_t n = mesh.node(e, k); vertex_of[size_t(n)] >= 0) {
        ++field_start_[size_t(vertex_of[size_t(n)]) + 1];
        touches = true;
      }
    if (touches) field_tets_.push_back(int32_t(e));
  }
  for (size_t k = 0; k < surface_.nodes.size(); ++k) field_start_[k + 1] += field_start_[k];
  field_entry_.resize(field_start_.back());
  field_weight_.resize(field_start_.back());
  std::vector<uint32_t> next(field_start_.begin(), field_start_.end() - 1);
  std::vector<double> total(surface_.nodes.size(), 0.0);
  for (size_t i = 0; i < field_tets_.size(); ++i)
    for (int k = 0; k < mesh.nodes_per_tet(); ++k)
      if (const int32_t v = vertex_of[size_t(mesh.node(size_t(field_tets_[i]), k))]; v >= 0) {
        field_entry_[next[size_t(v)]] = uint32_t(i);
        field_weight_[next[size_t(v)]++] = float(volume[size_t(field_tets_[i])]);
        total[size_t(v)] += volume[size_t(field_tets_[i])];
      }
  for (size_t v = 0; v < surface_.nodes.size(); ++v)
    for (uint32_t j = field_start_[v]; j < field_start_[v + 1]; ++j)
      field_weight_[j] = float(field_weight_[j] / total[v]);
}

std::span<const uint8_t> FrameEncoder::state_frame(int64_t server_time_ns, ViewFieldMask fields) {
  sim_.gather(surface_.nodes, positions_.data(), nullptr);  // the frame's vertices only: not every node
  fb::FlatBufferBuilder& b = state_builder_;
  b.Clear();
  const auto positions = b.CreateVector(positions_);
  fb::Offset<fb::Vector<fb::Offset<wire::FrameField>>> field_vec;
  if (fields) {
    // Per tet around the frame's vertices only, then their volume-weighted
    // mean at each vertex (as ParaView's Cell Data to Point Data).
    if (field_start_.empty()) build_field_map();
    const ElementFields per_tet = sim_.compute_element_fields(element_request(fields), field_tets_);
    std::vector<fb::Offset<wire::FrameField>> out;
    for (int k = 0; k < kViewFieldCount; ++k) {
      if (!(fields & view_field_bit(ViewField(k)))) continue;
      const double* values = nullptr;
      size_t stride = 1;
      switch (ViewField(k)) {
        case ViewField::VonMises: values = per_tet.von_mises.data(); break;
        case ViewField::EnergyDensity: values = per_tet.energy_density.data(); break;
        case ViewField::StretchMax: values = per_tet.principal_stretches.data(), stride = 3; break;
        case ViewField::StretchMin: values = per_tet.principal_stretches.data() + 2, stride = 3; break;
      }
      std::vector<float>& v = field_values_[k];
      v.assign(surface_.nodes.size(), 0.0f);
      for (size_t i = 0; i < v.size(); ++i) {
        double sum = 0;
        for (uint32_t j = field_start_[i]; j < field_start_[i + 1]; ++j)
          sum += double(field_weight_[j]) * values[stride * field_entry_[j]];
        v[i] = float(sum);
      }
      out.push_back(wire::CreateFrameFieldDirect(b, view_field_info(ViewField(k)).name, &v));
    }
    field_vec = b.CreateVector(out);
  }
  // (CreateVectorOfStructs, not the uninitialized variant: flatbuffers 2.0.8
  // aligns that one to the struct's size, which is wrong for these.)
  const std::vector<ProxyReport>& reports = sim_.proxy_reports();
  for (size_t j = 0; j < reports.size(); ++j) {
    const Pose p = sim_.proxy_pose(int32_t(j));
    poses_[j] = wire::ProxyPose(to_wire(p.position), to_wire(p.orientation));
    forces_[j] = to_wire(reports[j].force);
  }
  const auto pose_vec = b.CreateVectorOfStructs(poses_.data(), reports.size());
  const auto force_vec = b.CreateVectorOfStructs(forces_.data(), reports.size());
  // Where each channel's device is: a coupled channel's device pose (which
  // its proxy or hand is pulled toward, and may lag behind); else its hand's
  // or first proxy's, which follow it.
  const std::vector<DeviceReport>& dr = sim_.device_reports();
  for (size_t d = 0; d < dr.size(); ++d) {
    const Pose p = dr[d].coupled          ? dr[d].target
                   : device_hand_[d] >= 0 ? sim_.hand_pose(device_hand_[d])
                                          : sim_.proxy_pose(device_proxy_[d]);
    state_device_poses_[d] = wire::ProxyPose(to_wire(p.position), to_wire(p.orientation));
  }
  const auto device_vec = b.CreateVectorOfStructs(state_device_poses_.data(), dr.size());
  wire::StateFrameBuilder f(b);
  f.add_scene_id(scene_id_);
  f.add_step(uint64_t(sim_.steps()));
  f.add_sim_time(sim_.time());
  f.add_server_time_ns(server_time_ns);
  f.add_positions(positions);
  f.add_proxies(pose_vec);
  f.add_contact_forces(force_vec);
  const Energy& e = sim_.energy();
  const wire::Energies energies(e.kinetic, e.elastic, e.gravity, e.work_loads, e.work_essential, e.work_contact,
                                e.dissipated, e.discrete, e.restated);
  f.add_energies(&energies);
  if (fields) f.add_fields(field_vec);
  f.add_device_poses(device_vec);
  return seal(b, wire::Message::StateFrame, f.Finish());
}

void FrameEncoder::add_step_forces() {
  // The force over the last force window (a millisecond by default): the
  // mean of the per-step contact forces, which is what changed the body's
  // momentum over it. A resting contact pushes its nodes back only every few
  // steps (the paper's projection bounces a node back to where it was, eq.
  // 13), so the force at one step flickers between 0 and several times its
  // mean; its mean over the window does not.
  // Each entry is the mean over the latest advance, its impulse over its
  // time: an advance the stepper split into sub-steps counts all of them (the
  // force of its last sub-step alone would alias with the bounce, which often
  // comes every other step).
  const std::vector<ProxyReport>& pr = sim_.proxy_reports();
  const std::vector<DeviceReport>& dr = sim_.device_reports();
  const auto mean = [](const ContactReport& r) {
    return r.elapsed > 0 ? Wrench{r.impulse / r.elapsed, r.angular_impulse / r.elapsed} : Wrench{r.force, r.torque};
  };
  const size_t slot = window_next_;
  window_next_ = (window_next_ + 1) % window_steps_;
  window_filled_ = std::min(window_filled_ + 1, window_steps_);
  for (size_t j = 0; j < pr.size(); ++j) {
    contacts_proxy_[j] = std::max(contacts_proxy_[j], pr[j].contacts_peak);
    Wrench& old = window_proxy_[slot * pr.size() + j];
    const Wrench now = mean(pr[j]);
    sum_proxy_[j].force += now.force - old.force;
    sum_proxy_[j].torque += now.torque - old.torque;
    old = now;
  }
  for (size_t d = 0; d < dr.size(); ++d) {
    // A node resting on a proxy is pushed every other step or so (eq. 13):
    // a frame counts the contacts of its busiest step (sub-steps of an
    // advance included) since the previous one.
    contacts_device_[d] = std::max(contacts_device_[d], dr[d].contacts_peak);
    if (dr[d].contacts_peak > 0) touched_[d] = sim_.time();
    Wrench& old = window_device_[slot * dr.size() + d];
    const Wrench now = mean(dr[d]);
    sum_device_[d].force += now.force - old.force;
    sum_device_[d].torque += now.torque - old.torque;
    old = now;
  }
}

std::span<const uint8_t> FrameEncoder::haptic_frame(int64_t server_time_ns, uint64_t last_input_sequence,
                                                    std::span<const uint64_t> input_sequences,
                                                    std::span<const Vec3> device_offsets) {
  fb::FlatBufferBuilder& b = haptic_builder_;
  b.Clear();
  const std::vector<ProxyReport>& pr = sim_.proxy_reports();
  const std::vector<DeviceReport>& dr = sim_.device_reports();
  const double inv = 1.0 / double(std::max<size_t>(window_filled_, 1));
  for (size_t j = 0; j < pr.size(); ++j) {
    const Pose p = sim_.proxy_pose(int32_t(j));
    proxy_haptics_[j] = wire::ProxyHaptics(to_wire(inv * sum_proxy_[j].force), to_wire(inv * sum_proxy_[j].torque),
                                           wire::ProxyPose(to_wire(p.position), to_wire(p.orientation)),
                                           to_wire(pr[j].stiffness), uint32_t(contacts_proxy_[j]));
  }
  for (size_t d = 0; d < dr.size(); ++d) {
    input_sequences_[d] = d < input_sequences.size() ? input_sequences[d] : 0;
    if (dr[d].coupled) {
      // The coupling's force at the step, not a window's mean: a spring's
      // force does not flicker with the contact's bounce, and the device
      // adds its own motion since the step to it (stiffness times the
      // motion from device_poses), which a mean over a window would blur.
      // The pose is the coupling's target, which the force is about. While
      // the target still glides onto the device's path (the loop's
      // approach, after a jump or a stall) the device's motion since the
      // step says nothing of the force's: no stiffness then, so that the
      // device shows the force alone (K times a gap of centimetres would
      // pull the hand with newtons in free space). Nor while the proxy
      // touches nothing: a free proxy follows the hand within the display's
      // few milliseconds, and the fit of the device's force to its motion,
      // still that of the press it left, would pull a lifting hand back.
      // (Free: untouched for kFreeAfter, as a resting proxy is pushed only
      // every other step or so.)
      const DeviceReport& r = dr[d];
      const bool gliding = d < device_offsets.size() && glm::dot(device_offsets[d], device_offsets[d]) >
                                                            kMaxOffsetForStiffness * kMaxOffsetForStiffness;
      const bool free = sim_.time() - touched_[d] > kFreeAfter;
      const glm::dmat3 K = gliding || free ? glm::dmat3(0.0) : r.stiffness;
      device_haptics_[d] =
          wire::DeviceHaptics(to_wire(r.force), to_wire(r.torque), to_wire(K), uint32_t(contacts_device_[d]));
      Vec3 contact_force(0.0);
      for (size_t j = 0; j < pr.size(); ++j) {
        if (size_t(sim_.proxy_device()[j]) == d) contact_force += inv * sum_proxy_[j].force;
      }
      device_models_[d] = local_model(r, K, contact_force, model_radius_[d]);
      device_poses_[d] = wire::ProxyPose(to_wire(r.target.position), to_wire(r.target.orientation));
      device_couplings_[d] =
          wire::DeviceCoupling(wire::ProxyPose(to_wire(r.body.position), to_wire(r.body.orientation)),
                               float(r.coupling_stiffness), float(r.max_force), float(r.max_torque), true, r.saturated);
      continue;
    }
    device_couplings_[d] = wire::DeviceCoupling();
    device_models_[d] = wire::DeviceModel();
    device_haptics_[d] = wire::DeviceHaptics(to_wire(inv * sum_device_[d].force), to_wire(inv * sum_device_[d].torque),
                                             to_wire(dr[d].stiffness), uint32_t(contacts_device_[d]));
    // A lone proxy's pose is the one just staged for it; a hand's is its own.
    if (device_hand_[d] >= 0) {
      const Pose p = sim_.hand_pose(device_hand_[d]);
      device_poses_[d] = wire::ProxyPose(to_wire(p.position), to_wire(p.orientation));
    } else {
      device_poses_[d] = proxy_haptics_[size_t(device_proxy_[d])].pose();
    }
  }
  const auto proxies = b.CreateVectorOfStructs(proxy_haptics_.data(), pr.size());
  const auto devices = b.CreateVectorOfStructs(device_haptics_.data(), dr.size());
  const auto device_poses = b.CreateVectorOfStructs(device_poses_.data(), dr.size());
  const auto sequences = b.CreateVector(input_sequences_.data(), dr.size());
  const auto couplings = b.CreateVectorOfStructs(device_couplings_.data(), dr.size());
  const auto models = b.CreateVectorOfStructs(device_models_.data(), dr.size());
  std::fill(contacts_proxy_.begin(), contacts_proxy_.end(), 0);
  std::fill(contacts_device_.begin(), contacts_device_.end(), 0);
  wire::HapticFrameBuilder f(b);
  f.add_scene_id(scene_id_);
  f.add_step(uint64_t(sim_.steps()));
  f.add_sim_time(sim_.time());
  f.add_server_time_ns(server_time_ns);
  f.add_last_input_sequence(last_input_sequence);
  f.add_proxies(proxies);
  f.add_devices(devices);
  f.add_device_poses(device_poses);
  f.add_device_input_sequences(sequences);
  f.add_device_couplings(couplings);
  f.add_device_models(models);
  return seal(b, wire::Message::HapticFrame, f.Finish());
}

}  // namespace tactile
