#include "app/headless.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <ostream>
#include <stdexcept>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include "app/progress.hpp"
#include "app/section.hpp"
#include "app/vtu.hpp"
#include "core/kernels/kernels.hpp"
#include "sim/simulation.hpp"

namespace tactile {

namespace {

namespace fs = std::filesystem;
using Json = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

// Time spent in each pass of the step; the core reads no clock, so the app does.
class PassTimer final : public StepProbe {
 public:
  void enter(Pass p) override { start_[size_t(p)] = Clock::now(); }
  void leave(Pass p) override {
    total_[size_t(p)] += std::chrono::duration<double>(Clock::now() - start_[size_t(p)]).count();
  }
  double total(Pass p) const { return total_[size_t(p)]; }

 private:
  std::array<Clock::time_point, kPassCount> start_{};
  std::array<double, kPassCount> total_{};
};

// Running min, max and mean of a per-frame figure.
struct Range {
  double lo = std::numeric_limits<double>::infinity(), hi = -std::numeric_limits<double>::infinity(), sum = 0;
  int64_t n = 0;
  void add(double x) {
    lo = std::min(lo, x);
    hi = std::max(hi, x);
    sum += x;
    ++n;
  }
  Json to_json() const {
    if (n == 0) return Json(nullptr);
    return Json{{"min", lo}, {"max", hi}, {"mean", sum / double(n)}};
  }
};

Json vec(const Vec3& v) { return Json::array({v.x, v.y, v.z}); }

const char* precision_name(Precision p) { return p == Precision::Float ? "float" : "double"; }

std::string frame_name(const std::string& prefix, int32_t frame) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "_%06d.vtu", frame);
  return prefix + buf;
}

// Every term of the energy balance (Energy::balance()), so that the drift a
// table reports is the sum of its own columns: kinetic + discrete - restated
// + elastic + gravity - work_loads - work_essential - work_contact +
// dissipated.
Json energy_json(const Energy& e) {
  return Json{{"kinetic_J", e.kinetic},
              {"elastic_J", e.elastic},
              {"gravity_J", e.gravity},
              {"work_loads_J", e.work_loads},
              {"work_essential_J", e.work_essential},
              {"work_contact_J", e.work_contact},
              {"dissipated_J", e.dissipated},
              {"discrete_J", e.discrete},
              {"restated_J", e.restated},
              {"balance_drift_J", e.balance()}};
}

Json fault_json(const Fault& f) {
  if (!f) return Json(nullptr);
  return Json{{"kind", to_string(f.kind)},
              {"message", f.message},
              {"step", f.step},
              {"sim_time_s", f.t},
              {"elements", f.elements}};
}

void write_text(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw std::runtime_error(path.string() + ": cannot open for writing");
  out << text;
  out.close();
  if (!out) throw std::runtime_error(path.string() + ": write failed");
}

// Appends ",x" with 9 significant digits (appends rather than operator+, which trips GCC 12's -Wrestrict).
void append_number(std::string& csv, double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, ",%.9g", x);
  csv += buf;
}

// Removes the frames, collection and force traces an earlier run left in `dir`, so the folder holds one run.
void clear_old_output(const fs::path& dir) {
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (((name.starts_with("frame_") || name.starts_with("proxy-") || name.starts_with("surface_")) &&
         name.ends_with(".vtu")) ||
        name == "series.pvd" || name == "forces.csv" || name == "devices.csv")
      fs::remove(entry.path(), ec);
  }
}

}  // namespace

namespace {

// One headless run in its stages: set up (the plan of frames and control
// intervals, the outputs' headers), step_frame() per frame, record_frame()
// after each, then write_outputs() and log_summary(). Its members are what
// the stages share.
class HeadlessRun {
 public:
  HeadlessRun(const Scene& scene, const HeadlessOptions& options);
  void run();  // every frame, to the end or a fault
  void write_outputs();
  void log_summary() const;
  HeadlessResult result;

 private:
  AdvanceReport step_frame();
  void record_frame(int32_t frame, const AdvanceReport* report, bool vtu);
  void write_vtu_frame(int32_t frame);
  void drive(double t0, double t1);  // scripted proxies and hands over an interval; the others hold
  void record_contacts();            // after an interval: its mean forces, contacts and positions
  void take(const ContactReport& r, ContactResult& c, double t, std::string& out, bool with_device);
  Json summary_json() const;

  const Clock::time_point started_ = Clock::now();
  const Scene& scene_;
  const HeadlessOptions& options_;
  const RunSettings& run_;
  fs::path dir_;
  Simulation sim_;
  PassTimer timer_;
  int32_t n_frames_ = 0;
  double frame_dt_ = 0;
  bool has_proxies_ = false;
  int32_t per_frame_ = 1;  // control intervals a frame: a whole number, none longer than options.control_interval
  double interval_ = 0;
  std::vector<SectionCut> cuts_;
  std::vector<double> rest_area_;
  std::string csv_;               // frames.csv: one row per frame, frame 0 at rest
  std::string forces_, devices_;  // forces.csv, devices.csv: a row per proxy (device) per control interval
  std::vector<double> u_, v_, density_, contact_;
  std::vector<uint8_t> fixed_;
  double plane_half_size_ = 1;  // a plane proxy is drawn as a square this big about its origin: the body's size
  std::vector<PvdEntry> pvd_;
  Range substeps_, dt_used_, dt_critical_, frame_wall_, max_u_, section_ratio_;
  int64_t subdivided_frames_ = 0;
  double wall_ = 0;  // stepping only, not the outputs [s]
};

HeadlessRun::HeadlessRun(const Scene& scene, const HeadlessOptions& options)
    : scene_(scene), options_(options), run_(scene.run), sim_(scene.spec) {
  result.scene = scene.name;
  result.variant = scene.variant;
  dir_ = fs::path(options.out_dir) / scene.name / (scene.variant.empty() ? "run" : scene.variant);
  result.dir = dir_.string();
  fs::create_directories(dir_);
  clear_old_output(dir_);
  sim_.set_probe(&timer_);
  const TetMesh& mesh = sim_.mesh();
  n_frames_ = int32_t(std::max<int64_t>(1, std::llround(run_.duration * run_.frame_rate)));
  frame_dt_ = run_.duration / double(n_frames_);
  has_proxies_ = !sim_.proxies().empty();
  per_frame_ =
      has_proxies_ ? int32_t(std::max(1.0, std::ceil(frame_dt_ / options.control_interval * (1.0 - 1e-12)))) : 1;
  interval_ = frame_dt_ / double(per_frame_);

  for (const SectionPlane& p : run_.sections) cuts_.push_back(make_section_cut(mesh, p));
  for (const SectionCut& c : cuts_) rest_area_.push_back(compute_section_area(c, mesh, {}));

  csv_ = "frame,sim_time_s,substeps,dt_s";
  for (const TrackedPoint& p : scene.track) csv_ += "," + p.name + "_ux_m," + p.name + "_uy_m," + p.name + "_uz_m";
  for (const SectionPlane& p : run_.sections) csv_ += "," + p.name + "_area_m2";
  csv_ +=
      ",kinetic_J,elastic_J,gravity_J,work_loads_J,work_essential_J,work_contact_J,dissipated_J,discrete_J,"
      "restated_J,balance_drift_J\n";
  forces_ = "sim_time_s,proxy,device,fx_N,fy_N,fz_N,tx_Nm,ty_Nm,tz_Nm,contacts,px_m,py_m,pz_m\n";
  devices_ = "sim_time_s,device,fx_N,fy_N,fz_N,tx_Nm,ty_Nm,tz_Nm,contacts\n";

  fixed_ = sim_.node_constraint();
  if (options.write_vtu && run_.vtu_contact_force) sim_.track_contact_forces(true);
  Vec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
  for (const Vec3& x : mesh.X) lo = glm::min(lo, x), hi = glm::max(hi, x);
  plane_half_size_ = mesh.X.empty() ? 1.0 : glm::length(hi - lo);

  const std::vector<ProxySpec>& proxies = sim_.proxies();
  for (size_t j = 0; j < proxies.size(); ++j)
    result.proxies.push_back({proxies[j].name, proxies[j].device, {}, {}, 0, sim_.proxy_pose(int32_t(j)).position, 0});
  for (const std::string& d : sim_.devices()) result.devices.push_back({d, d, {}, {}, 0, {}, 0});

  if (options.log) {
    *options.log << "running " << scene.name << (scene.variant.empty() ? "" : " [" + scene.variant + "]") << ": "
                 << mesh.n_tets() << " tets, " << mesh.n_nodes() << " nodes, " << precision_name(sim_.precision())
                 << ", " << n_frames_ << " frames of " << frame_dt_ << " s, critical step at rest " << sim_.dt_rest()
                 << " s";
    if (sim_.mass_scaled_tets() > 0)
      *options.log << " (mass scaled: " << sim_.mass_scaled_tets() << " tets, +" << sim_.added_mass() << " kg)";
    *options.log << ", " << sim_.parts() << " thread(s)\n";
  }
}

void HeadlessRun::run() {
  record_frame(0, nullptr, options_.write_vtu);
  ProgressBar bar(stderr, options_.progress, scene_.name + (scene_.variant.empty() ? "" : "/" + scene_.variant));
  char buf[64];
  for (int32_t frame = 1; frame <= n_frames_; ++frame) {
    const AdvanceReport report = step_frame();
    substeps_.add(report.substeps);
    if (report.dt > 0) dt_used_.add(report.dt);
    dt_critical_.add(report.dt_critical);
    subdivided_frames_ += report.subdivided ? 1 : 0;
    const bool last = frame == n_frames_ || bool(report.fault);
    if (!report.fault) result.frames = frame;
    record_frame(frame, &report, options_.write_vtu && (frame % run_.vtu_every == 0 || last));
    std::snprintf(buf, sizeof buf, "t = %.3g / %.3g s", sim_.time(), run_.duration);
    bar.update(double(frame) / double(n_frames_), buf);
    if (report.fault) {
      result.fault = report.fault;
      break;
    }
  }
  bar.finish();
}

// One frame: a single advance without proxies, else its control intervals
// (each driven, stepped and recorded), summed into one report.
AdvanceReport HeadlessRun::step_frame() {
  AdvanceReport report;
  double dt_wall = 0;
  if (!has_proxies_) {
    const Clock::time_point t0 = Clock::now();
    report = sim_.advance(frame_dt_);
    dt_wall = std::chrono::duration<double>(Clock::now() - t0).count();
  } else {
    for (int32_t k = 0; k < per_frame_ && !report.fault; ++k) {
      const double t_start = sim_.time();
      drive(t_start, t_start + interval_);
      const Clock::time_point t0 = Clock::now();
      const AdvanceReport r = sim_.advance(interval_);
      dt_wall += std::chrono::duration<double>(Clock::now() - t0).count();
      record_contacts();
      report.substeps += r.substeps;
      report.dt = r.dt > 0 ? r.dt : report.dt;
      report.dt_critical = r.dt_critical;
      report.subdivided = report.subdivided || r.subdivided;
      report.fault = r.fault;
    }
  }
  wall_ += dt_wall;
  frame_wall_.add(dt_wall);
  return report;
}

void HeadlessRun::record_frame(int32_t frame, const AdvanceReport* report, bool vtu) {
  sim_.copy_displacement(u_);
  const Energy& e = sim_.energy();
  csv_ += std::to_string(frame);
  append_number(csv_, sim_.time());
  append_number(csv_, report ? report->substeps : 0);
  append_number(csv_, report ? report->dt : 0.0);
  for (const TrackedPoint& p : scene_.track) {
    for (size_t d = 0; d < 3; ++d) append_number(csv_, u_[3 * size_t(p.node) + d]);
  }
  for (size_t k = 0; k < cuts_.size(); ++k) {
    const double a = compute_section_area(cuts_[k], sim_.mesh(), u_);
    append_number(csv_, a);
    if (frame > 0) section_ratio_.add(a / rest_area_[k]);
  }
  for (double x : {e.kinetic, e.elastic, e.gravity, e.work_loads, e.work_essential, e.work_contact, e.dissipated,
                   e.discrete, e.restated, e.balance()})
    append_number(csv_, x);
  csv_ += '\n';
  double umax = 0;
  for (size_t i = 0; i < u_.size(); i += 3)
    umax = std::max(umax, std::sqrt(u_[i] * u_[i] + u_[i + 1] * u_[i + 1] + u_[i + 2] * u_[i + 2]));
  if (frame > 0) max_u_.add(umax);
  if (vtu) write_vtu_frame(frame);
}

// The body at rest with its displacement and fields (each body a block of its
// own, in a scene of several), each proxy a block of its own (its surface
// where it is, and what it felt), then the fine surfaces.
void HeadlessRun::write_vtu_frame(int32_t frame) {
  sim_.copy_velocity(v_);
  density_ = sim_.compute_element_energy();
  for (size_t t = 0; t < density_.size(); ++t) density_[t] /= sim_.tet_volume()[t];
  const ElementFields fields = sim_.compute_element_fields(run_.vtu_cells);
  if (run_.vtu_contact_force) {
    const double span = sim_.take_contact_impulses(contact_);
    for (double& x : contact_) x = span > 0 ? x / span : 0.0;
  }
  // A scene of several bodies: each its own block, in its own numbering.
  const std::vector<BodySpec>& bodies = scene_.spec.bodies;
  const size_t n_bodies = std::max<size_t>(1, bodies.size());
  for (size_t b = 0; b < n_bodies; ++b) {
    const BodySpec* body = bodies.empty() ? nullptr : &bodies[b];
    const std::string name = frame_name(body ? "frame-" + body->name : "frame", frame);
    write_vtu((dir_ / name).string(), VtuFrame{&scene_.spec.mesh, &u_, &v_, &fixed_,
                                               run_.vtu_contact_force ? &contact_ : nullptr, &density_, &fields, body});
    pvd_.push_back({sim_.time(), name, int32_t(b), body ? body->name : "body"});
  }
  for (size_t j = 0; j < sim_.proxies().size(); ++j) {
    const ProxySpec& p = sim_.proxies()[j];
    const ProxySurface surface = make_proxy_surface(p.geometry, sim_.proxy_pose(int32_t(j)), plane_half_size_);
    const ContactResult& c = result.proxies[j];
    const std::string proxy_file = frame_name("proxy-" + p.name, frame);
    write_vtu((dir_ / proxy_file).string(), VtuProxy{&surface, c.force, c.torque, c.contacts});
    pvd_.push_back({sim_.time(), proxy_file, int32_t(n_bodies + j), p.name});
  }
  if (sim_.surface()) {
    int32_t part = int32_t(n_bodies + sim_.proxies().size());
    for (size_t b = 0; b < n_bodies; ++b) {
      const BodySpec* body = bodies.empty() ? nullptr : &bodies[b];
      if (body && body->fine_triangle_end == body->fine_triangle_begin) continue;
      const std::string surface_file = frame_name(body ? "surface-" + body->name : "surface", frame);
      write_vtu((dir_ / surface_file).string(), VtuSurface{sim_.surface().get(), &u_, body});
      pvd_.push_back({sim_.time(), surface_file, part++, body ? "surface-" + body->name : "surface"});
    }
  }
}

void HeadlessRun::drive(double t0, double t1) {
  for (size_t j = 0; j < scene_.proxy_script.size(); ++j)
    if (scene_.proxy_script[j]) sim_.set_proxy_motion(int32_t(j), scene_.proxy_script[j]->motion(t0, t1));
  for (size_t h = 0; h < scene_.hand_script.size(); ++h)
    if (scene_.hand_script[h]) sim_.set_hand_motion(int32_t(h), scene_.hand_script[h]->motion(t0, t1));
  sim_.clear_impulses();
}

// One interval's report into a result and a CSV row: t, names, mean force
// and torque over the interval, contacts at its end.
void HeadlessRun::take(const ContactReport& r, ContactResult& c, double t, std::string& out, bool with_device) {
  const double span = r.elapsed;
  c.force = span > 0 ? r.impulse / span : Vec3(0.0);
  c.torque = span > 0 ? r.angular_impulse / span : Vec3(0.0);
  c.contacts = r.contacts;
  c.peak_force = std::max(c.peak_force, glm::length(c.force));
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", t);
  out.append(buf).append(",").append(c.name);
  if (with_device) out.append(",").append(c.device);
  for (double x : {c.force.x, c.force.y, c.force.z, c.torque.x, c.torque.y, c.torque.z}) append_number(out, x);
  out.append(",").append(std::to_string(c.contacts));
}

void HeadlessRun::record_contacts() {
  const double t = sim_.time();
  const std::vector<ProxyReport>& pr = sim_.proxy_reports();
  for (size_t j = 0; j < pr.size(); ++j) {
    ContactResult& c = result.proxies[j];
    take(pr[j], c, t, forces_, true);
    c.position = sim_.proxy_pose(int32_t(j)).position;
    for (double x : {c.position.x, c.position.y, c.position.z}) append_number(forces_, x);
    forces_ += '\n';
  }
  const std::vector<DeviceReport>& dr = sim_.device_reports();
  for (size_t d = 0; d < dr.size(); ++d) {
    take(dr[d], result.devices[d], t, devices_, false);
    devices_ += '\n';
  }
}

void HeadlessRun::write_outputs() {
  result.steps = sim_.steps();
  result.t = sim_.time();
  result.wall_s = wall_;
  result.energy = sim_.energy();
  for (const TrackedPoint& p : scene_.track) result.tracked.push_back({p.name, p.node, p.X, sim_.displacement(p.node)});
  sim_.copy_displacement(u_);
  for (size_t k = 0; k < cuts_.size(); ++k)
    result.sections.push_back({run_.sections[k].name, rest_area_[k], compute_section_area(cuts_[k], sim_.mesh(), u_)});
  if (options_.write_vtu) write_pvd((dir_ / "series.pvd").string(), pvd_);
  write_text(dir_ / "frames.csv", csv_);
  if (has_proxies_) {
    write_text(dir_ / "forces.csv", forces_);
    write_text(dir_ / "devices.csv", devices_);
  }
  write_text(dir_ / "summary.json", summary_json().dump(2) + "\n");
}

Json HeadlessRun::summary_json() const {
  const TetMesh& mesh = sim_.mesh();
  const Scene& scene = scene_;
  const RunSettings& run = run_;
  Json s;
  s["scene"] = scene.name;
  s["variant"] = scene.variant.empty() ? Json(nullptr) : Json(scene.variant);
  s["description"] = scene.description;
  s["scene_file"] = scene.path;
  s["status"] = result.fault ? "fault" : "ok";
  s["mesh"] = Json{{"nodes", mesh.n_nodes()},
                   {"tets", mesh.n_tets()},
                   {"total_mass_kg", sim_.total_mass()},
                   {"mass_scaling", Json{{"dt_s", scene.spec.integrator.mass_scaling_dt},
                                         {"tets", sim_.mass_scaled_tets()},
                                         {"added_kg", sim_.added_mass()}}},
                   {"min_dihedral_deg", scene.quality.min_dihedral_deg},
                   {"max_dihedral_deg", scene.quality.max_dihedral_deg},
                   {"max_aspect_ratio", scene.quality.max_aspect_ratio},
                   {"poor_tets", scene.quality.poor.size()}};
  Json materials = Json::array();
  for (const MaterialSpec& m : scene.spec.materials)
    materials.push_back(
        Json{{"model", std::string(to_string(m.model))}, {"E_Pa", m.E}, {"nu", m.nu}, {"rho_kg_m3", m.rho}});
  s["materials"] = materials;
  const Effects& fx = scene.spec.effects;
  s["effects"] = Json{{"gravity", fx.gravity ? vec(fx.g) : Json(false)},
                      {"damping_alpha_per_s", fx.damping ? Json(fx.alpha) : Json(false)},
                      {"friction", fx.friction}};
  const IntegratorSpec& in = scene.spec.integrator;
  s["integrator"] = Json{{"precision", precision_name(in.precision)},
                         {"dt", in.dt > 0 ? Json(in.dt) : Json("auto")},
                         {"safety", in.safety},
                         {"unstable", in.unstable == UnstablePolicy::Refuse ? "refuse" : "subdivide"},
                         {"threads", in.threads},
                         {"threads_used", sim_.parts()},
                         {"kernel_isa", std::string(kernel_isa())},
                         {"dt_critical_rest_s", sim_.dt_rest()},
                         {"dt_s", dt_used_.to_json()},
                         {"dt_critical_s", dt_critical_.to_json()},
                         {"substeps_per_frame", substeps_.to_json()},
                         {"frames_subdivided", subdivided_frames_}};
  s["run"] =
      Json{{"duration_s", run.duration},   {"frame_rate_hz", run.frame_rate},
           {"frame_dt_s", frame_dt_},      {"frames_planned", n_frames_},
           {"frames_done", result.frames}, {"steps", result.steps},
           {"t_end_s", result.t},          {"control_interval_s", has_proxies_ ? Json(interval_) : Json(nullptr)},
           {"vtu", options_.write_vtu},    {"vtu_files", pvd_.size()}};
  s["frames"] = Json{{"wall_s", frame_wall_.to_json()},
                     {"max_displacement_m", max_u_.to_json()},
                     {"section_area_ratio", section_ratio_.to_json()}};
  Json tracked = Json::array();
  for (const TrackedResult& t : result.tracked)
    tracked.push_back(Json{{"name", t.name},
                           {"node", t.node},
                           {"rest_m", vec(t.X)},
                           {"position_m", vec(t.X + t.u)},
                           {"displacement_m", vec(t.u)},
                           {"distance_m", std::sqrt(glm::dot(t.u, t.u))}});
  s["tracked"] = tracked;
  Json sections = Json::array();
  for (const SectionResult& r : result.sections)
    sections.push_back(
        Json{{"name", r.name}, {"rest_area_m2", r.rest_area}, {"area_m2", r.area}, {"ratio", r.area / r.rest_area}});
  s["sections"] = sections;
  // Proxies and devices: means over the last control interval.
  const std::vector<ProxySpec>& proxies = sim_.proxies();
  Json proxies_json = Json::array();
  for (size_t j = 0; j < result.proxies.size(); ++j) {
    const ContactResult& c = result.proxies[j];
    const Pose pose = sim_.proxy_pose(int32_t(j));
    proxies_json.push_back(Json{{"name", c.name},
                                {"device", c.device},
                                {"hand", proxies[j].hand.empty() ? Json(nullptr) : Json(proxies[j].hand)},
                                {"shape", to_string(proxies[j].geometry.shape)},
                                {"scripted", j < scene.proxy_script.size() && scene.proxy_script[j].has_value()},
                                {"force_N", vec(c.force)},
                                {"torque_Nm", vec(c.torque)},
                                {"contacts", c.contacts},
                                {"peak_force_N", c.peak_force},
                                {"position_m", vec(c.position)},
                                {"orientation_wxyz", Json::array({pose.orientation.w, pose.orientation.x,
                                                                  pose.orientation.y, pose.orientation.z})}});
  }
  s["proxies"] = proxies_json;
  Json devices_json = Json::array();
  for (const ContactResult& c : result.devices)
    devices_json.push_back(Json{{"name", c.name},
                                {"force_N", vec(c.force)},
                                {"torque_Nm", vec(c.torque)},
                                {"contacts", c.contacts},
                                {"peak_force_N", c.peak_force}});
  s["devices"] = devices_json;
  s["energy"] = energy_json(result.energy);
  const double scale =
      std::max({std::fabs(result.energy.kinetic) + std::fabs(result.energy.elastic) + std::fabs(result.energy.gravity) +
                    std::fabs(result.energy.work_loads) + std::fabs(result.energy.work_essential) +
                    std::fabs(result.energy.work_contact) + result.energy.dissipated,
                1e-300});
  s["energy"]["balance_drift_relative"] = result.energy.balance() / scale;
  const double step_time = std::max(wall_, 1e-12);
  Json cost;
  for (int p = 0; p < kPassCount; ++p) {
    const Pass pass = Pass(p);
    cost[sim_.pass_name(pass)] =
        Json{{"total_s", timer_.total(pass)},
             {"per_step_us", result.steps ? 1e6 * timer_.total(pass) / double(result.steps) : 0.0},
             {"share", timer_.total(pass) / step_time}};
  }
  s["performance"] = Json{{"wall_s", wall_},
                          {"wall_with_output_s", std::chrono::duration<double>(Clock::now() - started_).count()},
                          {"steps_per_s", double(result.steps) / step_time},
                          {"tet_steps_per_s", double(result.steps) * double(mesh.n_tets()) / step_time},
                          {"real_time_factor", result.t / step_time},
                          {"cost_per_pass", cost}};
  s["fault"] = fault_json(result.fault);
  return s;
}

void HeadlessRun::log_summary() const {
  if (!options_.log) return;
  std::ostream& log = *options_.log;
  const double step_time = std::max(wall_, 1e-12);
  log << "  " << (result.fault ? "FAULT" : "done") << ": t = " << result.t << " s, " << result.steps << " steps in "
      << wall_ << " s (" << double(result.steps) * double(sim_.mesh().n_tets()) / step_time / 1e6
      << " M tet-steps/s)\n";
  for (const TrackedResult& t : result.tracked)
    log << "  " << t.name << ": displacement [" << t.u.x << ", " << t.u.y << ", " << t.u.z << "] m\n";
  for (const ContactResult& c : result.proxies)
    log << "  proxy " << c.name << " (" << c.device << "): force [" << c.force.x << ", " << c.force.y << ", "
        << c.force.z << "] N, " << c.contacts << " contacts, peak " << c.peak_force << " N\n";
  for (const SectionResult& r : result.sections)
    log << "  section " << r.name << ": area " << r.area << " m^2 (" << 100.0 * r.area / r.rest_area << " % of rest)\n";
  if (result.fault)
    log << "  fault (" << to_string(result.fault.kind) << ") at t = " << result.fault.t
        << " s: " << result.fault.message << "\n";
  log << "  wrote " << dir_.string() << "/ (summary.json, frames.csv"
      << (has_proxies_ ? ", forces.csv, devices.csv" : "")
      << (options_.write_vtu ? ", series.pvd and " + std::to_string(pvd_.size()) + " VTU files" : "") << ")\n";
}

}  // namespace

HeadlessResult run_headless(const Scene& scene, const HeadlessOptions& options) {
  HeadlessRun run(scene, options);
  run.run();
  run.write_outputs();
  run.log_summary();
  return std::move(run.result);
}

void write_comparison(const std::string& dir, const std::vector<HeadlessResult>& results) {
  fs::create_directories(dir);
  std::string csv = "variant,status,sim_time_s";
  if (!results.empty()) {
    for (const TrackedResult& t : results.front().tracked)
      csv += "," + t.name + "_ux_m," + t.name + "_uy_m," + t.name + "_uz_m," + t.name + "_distance_m";
    for (const SectionResult& r : results.front().sections)
      csv += "," + r.name + "_rest_area_m2," + r.name + "_area_m2," + r.name + "_ratio";
  }
  csv += '\n';
  Json variants = Json::array();
  for (const HeadlessResult& r : results) {
    csv += r.variant.empty() ? "run" : r.variant;
    csv += r.fault ? ",fault" : ",ok";
    append_number(csv, r.t);
    Json tracked = Json::array(), sections = Json::array();
    for (const TrackedResult& t : r.tracked) {
      const double d = std::sqrt(glm::dot(t.u, t.u));
      for (double x : {t.u.x, t.u.y, t.u.z, d}) append_number(csv, x);
      tracked.push_back(Json{{"name", t.name}, {"rest_m", vec(t.X)}, {"displacement_m", vec(t.u)}, {"distance_m", d}});
    }
    for (const SectionResult& s : r.sections) {
      for (double x : {s.rest_area, s.area, s.area / s.rest_area}) append_number(csv, x);
      sections.push_back(
          Json{{"name", s.name}, {"rest_area_m2", s.rest_area}, {"area_m2", s.area}, {"ratio", s.area / s.rest_area}});
    }
    csv += "\n";
    variants.push_back(Json{{"variant", r.variant},
                            {"status", r.fault ? "fault" : "ok"},
                            {"sim_time_s", r.t},
                            {"fault", fault_json(r.fault)},
                            {"tracked", tracked},
                            {"sections", sections}});
  }
  write_text(fs::path(dir) / "comparison.csv", csv);
  Json j{{"scene", results.empty() ? "" : results.front().scene}, {"variants", variants}};
  write_text(fs::path(dir) / "comparison.json", j.dump(2) + "\n");
}

std::vector<HeadlessResult> run_headless_all(const std::vector<Scene>& scenes, const HeadlessOptions& options) {
  std::vector<HeadlessResult> results;
  for (const Scene& s : scenes) results.push_back(run_headless(s, options));
  const bool variants = std::any_of(scenes.begin(), scenes.end(), [](const Scene& s) { return !s.variant.empty(); });
  if (variants && !results.empty()) {
    const fs::path dir = fs::path(options.out_dir) / results.front().scene;
    write_comparison(dir.string(), results);
    if (options.log) *options.log << "wrote " << (dir / "comparison.csv").string() << " and comparison.json\n";
  }
  return results;
}

}  // namespace tactile
