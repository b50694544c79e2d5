#include "study/accuracy.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <numbers>
#include <stdexcept>
#include <utility>

#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include "app/section.hpp"
#include "core/quadratic.hpp"
#include "core/spec.hpp"
#include "mesh/primitives.hpp"
#include "scene/scene.hpp"
#include "sim/simulation.hpp"
#include "study/beam_theory.hpp"

namespace tactile::study {

namespace {

using Clock = std::chrono::steady_clock;
constexpr double kPi = std::numbers::pi;
constexpr MaterialModel kModels[] = {MaterialModel::Linear, MaterialModel::StVK, MaterialModel::Corotational,
                                     MaterialModel::NeoHookean, MaterialModel::InvertibleStVK};
constexpr Precision kPrecisions[] = {Precision::Float, Precision::Double};

const char* name_of(Precision p) { return p == Precision::Float ? "float" : "double"; }

// The element order of a run: a primitive's linear mesh as it is, or made quadratic.
struct Element {
  bool quadratic = false;
  const char* name() const { return quadratic ? "p2" : "p1"; }
  TetMesh mesh(TetMesh linear) const { return quadratic ? make_quadratic_mesh(linear) : linear; }
};

// Steps a simulation in intervals to `duration`, timing only the stepping; `each` sees it after every interval.
struct Stepped {
  int64_t steps = 0;
  double wall = 0;
  std::string fault;
};
Stepped step_for(Simulation& sim, double duration, double interval,
                 const std::function<void(const Simulation&)>& each = {}) {
  Stepped out;
  const int64_t steps0 = sim.steps();
  while (sim.time() < duration - 1e-12) {
    const Clock::time_point t0 = Clock::now();
    const AdvanceReport r = sim.advance(std::min(interval, duration - sim.time()));
    out.wall += std::chrono::duration<double>(Clock::now() - t0).count();
    if (r.fault) {
      out.fault = r.fault.message;
      break;
    }
    if (each) each(sim);
  }
  out.steps = sim.steps() - steps0;
  return out;
}

AccuracyRecord make_record(std::string problem, MaterialModel m, int32_t level, const Simulation& sim, double safety,
                           Precision p, const Stepped& s) {
  AccuracyRecord r;
  r.problem = std::move(problem);
  r.material = std::string(to_string(m));
  r.element = sim.mesh().quadratic() ? "p2" : "p1";
  r.level = level;
  r.tets = sim.n_tets();
  r.nodes = sim.n_nodes();
  r.safety = safety;
  r.precision = name_of(p);
  r.steps = s.steps;
  r.sim_time = sim.time();
  r.wall_s = s.wall;
  r.us_per_step = s.steps > 0 ? 1e6 * s.wall / double(s.steps) : 0;
  r.tet_steps_per_s = s.wall > 0 ? double(sim.n_tets()) * double(s.steps) / s.wall : 0;
  r.fault = s.fault;
  return r;
}

std::vector<int32_t> nodes_where(const TetMesh& mesh, const std::function<bool(const Vec3&)>& on) {
  std::vector<int32_t> out;
  for (int32_t i = 0; i < mesh.n_nodes(); ++i)
    if (on(mesh.X[size_t(i)])) out.push_back(i);
  return out;
}

double mean_displacement(const Simulation& sim, const std::vector<int32_t>& nodes, int axis) {
  double sum = 0;
  for (int32_t i : nodes) sum += sim.displacement(i)[axis];
  return nodes.empty() ? 0 : sum / double(nodes.size());
}

// ---- the cantilever against beam theory ------------------------------------------------------------------

// Length L along x, square section h = L / 10, clamped at x = 0; 10 n x n x n cells (the centred split, which
// bends without the Kuhn split's bias).
struct Beam : CantileverTheory {
  ModelSpec spec(Element el, MaterialModel m, int n, Precision p, double safety) const {
    ModelSpec s;
    s.mesh = el.mesh(make_box(Vec3(0.0), Vec3(L, h, h), {10 * n, n, n}, BoxSplit::centred24));
    s.materials = {MaterialSpec{m, E, nu, rho}};
    s.integrator.precision = p;
    s.integrator.safety = safety;
    EssentialBc clamp;
    clamp.name = "clamp";
    clamp.where.kind = NodeSelector::Kind::Plane;
    clamp.where.normal = Vec3(1, 0, 0);
    clamp.where.point = Vec3(0.0);
    s.essential = {clamp};
    return s;
  }
  std::vector<int32_t> end_nodes(const TetMesh& mesh) const {
    return nodes_where(mesh, [&](const Vec3& X) { return std::fabs(X.x - L) < 1e-9; });
  }
};

AccuracyRecord cantilever_deflection(Element el, MaterialModel m, int n, Precision p) {
  // A tip load that bends the beam by L / 1000 (the linear range), settled by damping critical for the first
  // mode: its error falls as (1 + w t) exp(-w t), 5e-4 at w t = 10.
  const Beam beam;
  const double P = 3 * beam.E * beam.I() * 1e-3 / (beam.L * beam.L);
  ModelSpec spec = beam.spec(el, m, n, p, 0.9);
  NaturalLoad load;
  load.name = "tip";
  load.where.kind = NodeSelector::Kind::Plane;
  load.where.normal = Vec3(1, 0, 0);
  load.where.point = Vec3(beam.L, 0, 0);
  load.force = Vec3(0, -P, 0);
  spec.loads = {load};
  spec.effects.damping = true;
  spec.effects.alpha = 2 * beam.omega1();
  Simulation sim(spec);
  const Stepped s = step_for(sim, 10 / beam.omega1(), 0.05 / beam.omega1());
  AccuracyRecord r = make_record("cantilever_deflection", m, n, sim, 0.9, p, s);
  r.value = -mean_displacement(sim, beam.end_nodes(sim.mesh()), 1);
  r.reference = beam.deflection(P);
  r.error = r.value / r.reference - 1;
  r.unit = "m";
  return r;
}

AccuracyRecord cantilever_frequency(Element el, MaterialModel m, int n, Precision p, double safety) {
  // Free vibration from the first Euler-Bernoulli mode shape (the sections turned by w'), undamped; the
  // frequency from the zero crossings of the tip's deflection over two periods.
  const Beam beam;
  Simulation sim(beam.spec(el, m, n, p, safety));
  const double bL = 1.8751040687, sigma = (std::cosh(bL) + std::cos(bL)) / (std::sinh(bL) + std::sin(bL));
  const double k = bL / beam.L;
  auto w = [&](double x) { return std::cosh(k * x) - std::cos(k * x) - sigma * (std::sinh(k * x) - std::sin(k * x)); };
  auto dw = [&](double x) {
    return k * (std::sinh(k * x) + std::sin(k * x) - sigma * (std::cosh(k * x) - std::cos(k * x)));
  };
  const double amplitude = 1e-3 * beam.L / w(beam.L);
  std::vector<double> u(3 * size_t(sim.n_nodes()), 0.0), v(u.size(), 0.0);
  for (int32_t i = 0; i < sim.n_nodes(); ++i) {
    const Vec3& X = sim.mesh().X[size_t(i)];
    u[3 * size_t(i)] = -amplitude * (X.y - beam.h / 2) * dw(X.x);
    u[3 * size_t(i) + 1] = amplitude * w(X.x);
  }
  sim.set_initial_state(u, v);
  const std::vector<int32_t> end = beam.end_nodes(sim.mesh());
  std::vector<double> crossings;
  double t_prev = 0, d_prev = mean_displacement(sim, end, 1);
  const Stepped s = step_for(sim, 2.3 / beam.f1(), 1.0 / (400 * beam.f1()), [&](const Simulation& at) {
    const double d = mean_displacement(at, end, 1);
    if ((d_prev > 0) != (d > 0)) crossings.push_back(t_prev + (at.time() - t_prev) * d_prev / (d_prev - d));
    t_prev = at.time();
    d_prev = d;
  });
  AccuracyRecord r = make_record("cantilever_frequency", m, n, sim, safety, p, s);
  r.value = crossings.size() >= 2 ? 0.5 * double(crossings.size() - 1) / (crossings.back() - crossings.front()) : 0;
  r.reference = beam.f1();
  r.error = r.value / r.reference - 1;
  r.unit = "Hz";
  return r;
}

AccuracyRecord wave_speed(Element el, MaterialModel m, int n, Precision p, double safety) {
  // A free bar 1 m long, 5 cm square, given a smooth axial velocity pulse (10 cm wide, much longer than the
  // section: the bar velocity sqrt(E / rho) holds); its speed from when the pulse's peak passes two sections
  // 0.4 m apart.
  const double E = 1e6, rho = 1000, h = 0.05;
  ModelSpec spec;
  spec.mesh = el.mesh(make_box(Vec3(0.0), Vec3(1.0, h, h), {20 * n, n, n}, BoxSplit::centred24));
  spec.materials = {MaterialSpec{m, E, 0.3, rho}};
  spec.integrator.precision = p;
  spec.integrator.safety = safety;
  Simulation sim(spec);
  std::vector<double> u(3 * size_t(sim.n_nodes()), 0.0), v(u.size(), 0.0);
  for (int32_t i = 0; i < sim.n_nodes(); ++i) {
    const double x = sim.mesh().X[size_t(i)].x;
    v[3 * size_t(i)] = 0.01 * std::exp(-std::pow((x - 0.15) / 0.05, 2));
  }
  sim.set_initial_state(u, v);
  const double xa = 0.35, xb = 0.75, c = std::sqrt(E / rho);
  const std::vector<int32_t> a = nodes_where(sim.mesh(), [&](const Vec3& X) { return std::fabs(X.x - xa) < 1e-9; });
  const std::vector<int32_t> b = nodes_where(sim.mesh(), [&](const Vec3& X) { return std::fabs(X.x - xb) < 1e-9; });
  // The mean axial velocity at each section over time (the direct pulse only: the one reflected from the
  // free end x = 0 reaches the first section after the direct one has passed both).
  std::vector<double> t, va, vb, vel;
  auto mean_v = [&](const std::vector<int32_t>& nodes) {
    double sum = 0;
    for (int32_t i : nodes) sum += vel[3 * size_t(i)];
    return sum / double(nodes.size());
  };
  const Stepped s = step_for(sim, (xb - 0.15) / c + 0.004, 2e-5, [&](const Simulation& at) {
    at.copy_velocity(vel);
    t.push_back(at.time());
    va.push_back(mean_v(a));
    vb.push_back(mean_v(b));
  });
  // Peak time, refined by a parabola through the largest sample and its neighbours.
  auto peak = [&](const std::vector<double>& y, double t_max) {
    size_t best = 0;
    for (size_t k = 0; k < y.size() && t[k] <= t_max; ++k)
      if (y[k] > y[best]) best = k;
    if (best == 0 || best + 1 >= y.size()) return t.empty() ? 0.0 : t[best];
    const double y0 = y[best - 1], y1 = y[best], y2 = y[best + 1], denom = y0 - 2 * y1 + y2;
    const double shift = denom != 0 ? 0.5 * (y0 - y2) / denom : 0;
    return t[best] + shift * (t[best + 1] - t[best]);
  };
  AccuracyRecord r = make_record("wave_speed", m, n, sim, safety, p, s);
  const double ta = peak(va, (xa - 0.15) / c + 0.004), tb = peak(vb, 1e9);
  r.value = tb > ta ? (xb - xa) / (tb - ta) : 0;
  r.reference = c;
  r.error = r.value / r.reference - 1;
  r.unit = "m/s";
  return r;
}

// ---- the paper's figures against converged runs -------------------------------------------------------------

// A shipped scene with its mesh cells and material model replaced (no variants).
Scene scene_at(const std::string& path, const nlohmann::json& cells, Element el, MaterialModel m, Precision p,
               const std::function<void(nlohmann::json&)>& edit = {}) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("accuracy study: cannot read " + path + " (--scenes names the folder)");
  nlohmann::json j = nlohmann::json::parse(in);
  j.erase("variants");
  j["mesh"]["cells"] = cells;
  // (A scene names invertible StVK as StVK with "invertible": true.)
  j["material"]["model"] = std::string(to_string(m == MaterialModel::InvertibleStVK ? MaterialModel::StVK : m));
  j["material"]["invertible"] = m == MaterialModel::InvertibleStVK;
  j["integrator"]["precision"] = name_of(p);
  j["element"] = el.name();
  if (edit) edit(j);
  return parse_scene(j, path).at(0);
}

struct Fig3Run {
  AccuracyRecord record;
  Vec3 tip;  // displacement of the tip's centre [m]
};
Fig3Run fig3(const std::string& scenes, Element el, MaterialModel m, int n, Precision p) {
  // The paper's Fig. 3 beam (1 x 0.1 x 0.1 m, E = 3 MPa) sagging under gravity by half its length: settled
  // by damping critical for its first mode (alpha = 2 w1 = 11 1/s) over 2 s.
  const Scene sc = scene_at(scenes + "/fig3_cantilever.json", {10 * n, n, n}, el, m, p,
                            [](nlohmann::json& j) { j["effects"]["damping"]["alpha"] = 11.1; });
  Simulation sim(sc.spec);
  const Stepped s = step_for(sim, 2.0, 0.01);
  int32_t tip = 0;
  for (int32_t i = 0; i < sim.n_nodes(); ++i)
    if (glm::length(sim.mesh().X[size_t(i)] - Vec3(1.0, 0.5, 0)) <
        glm::length(sim.mesh().X[size_t(tip)] - Vec3(1.0, 0.5, 0)))
      tip = i;
  Fig3Run out{make_record("fig3_tip", m, n, sim, sc.spec.integrator.safety, p, s), sim.displacement(tip)};
  out.record.value = out.tip.y;
  out.record.unit = "m";
  return out;
}

AccuracyRecord fig2(const std::string& scenes, Element el, MaterialModel m, int n, Precision p) {
  // The paper's Fig. 2 column, its lid turned 90 degrees over 1 s and held, as shipped: the mid-height
  // section's area over its rest area at 2.5 s.
  const Scene sc = scene_at(scenes + "/fig2_twist.json", {2 * n, 6 * n, 2 * n}, el, m, p);
  Simulation sim(sc.spec);
  const Stepped s = step_for(sim, sc.run.duration, 0.01);
  const SectionCut cut = make_section_cut(sim.mesh(), sc.run.sections.at(0));
  std::vector<double> u;
  sim.copy_displacement(u);
  AccuracyRecord r = make_record("fig2_area", m, n, sim, sc.spec.integrator.safety, p, s);
  r.value = compute_section_area(cut, sim.mesh(), u) / compute_section_area(cut, sim.mesh(), {});
  r.unit = "area / rest area";
  return r;
}

// ---- Hertz's two spheres ----------------------------------------------------------------------------------

// spheres_press.json at resolution n: two equal neo-Hookean spheres (R = 3 cm, E = 20 kPa, nu = 0.45), the
// lower held at its base, the upper's top cap driven 8 mm down over 4 s and held. Their density is raised a
// hundredfold (mass scaling, as quasi-static explicit analyses do): the step grows tenfold, and the spheres'
// lowest mode (about 0.1 s) stays some forty times quicker than the press. At 2, 3 and 4.4 s, each a mean
// over the 0.1 s before it: the load (the lower base's reaction), the approach of the centres (the mean
// displacement of the nodes within 5 mm of each, less the 0.5 mm they start apart), and the contact radius
// from the spread of the normal impulses between the spheres about their centre (Simulation::
// take_body_contact_moments; Hertz's pressure has mean r^2 = 2 a^2 / 5), and, as a check, the farthest from
// the axis of the lower sphere's boundary nodes within kHertzGap of the contact plane, midway between the two
// poles (hertz_radius_nodes). Against Hertz at the load measured: E* = E / (2 (1 - nu^2)), R* = R / 2,
// a = (3 F R* / (4 E*))^(1/3), approach a^2 / R*.
constexpr double kHertzMassScale = 100;
constexpr double kHertzGap = 5e-5;  // [m]

std::vector<AccuracyRecord> hertz(const std::string& scenes, Element el, int n, Precision p) {
  const std::string path = scenes + "/spheres_press.json";
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read " + path);
  nlohmann::json j = nlohmann::json::parse(in);
  for (nlohmann::json& b : j.at("bodies")) {
    b["mesh"]["resolution"] = n;
    b["element"] = el.name();
    b["material"]["rho"] = kHertzMassScale * b["material"]["rho"].get<double>();
  }
  j["integrator"]["precision"] = name_of(p);
  const Scene sc = parse_scene(j, path).at(0);
  const MaterialSpec mat = sc.spec.materials.at(0);
  const double R = 0.03, gap0 = 5e-4;
  const double e_star = mat.E / (2 * (1 - mat.nu * mat.nu)), r_star = R / 2;
  Simulation sim(sc.spec);
  const Vec3 c_lower(0, 0.03, 0), c_upper(0, 0.0905, 0);
  const auto near = [&](const Vec3& c) {
    return nodes_where(sim.mesh(), [&](const Vec3& X) { return glm::length(X - c) < 5e-3; });
  };
  const std::vector<int32_t> lower_c = near(c_lower), upper_c = near(c_upper);
  const auto body_of = [&](const Vec3& X) { return X.y < 0.06025 ? 0 : 1; };  // (the spheres start 0.5 mm apart)
  std::vector<int32_t> lower_surface;
  for (const std::array<int32_t, 3>& f : compute_boundary_faces(sim.mesh()))
    for (int32_t i : f)
      if (body_of(sim.mesh().X[size_t(i)]) == 0) lower_surface.push_back(i);
  std::sort(lower_surface.begin(), lower_surface.end());
  lower_surface.erase(std::unique(lower_surface.begin(), lower_surface.end()), lower_surface.end());
  int32_t lower_pole = lower_surface.front(), upper_pole = 0;
  for (int32_t i = 0; i < sim.n_nodes(); ++i) {
    const Vec3& X = sim.mesh().X[size_t(i)];
    if (glm::length(X - Vec3(0, 0.06, 0)) < glm::length(sim.mesh().X[size_t(lower_pole)] - Vec3(0, 0.06, 0)))
      lower_pole = i;
    if (glm::length(X - Vec3(0, 0.0605, 0)) < glm::length(sim.mesh().X[size_t(upper_pole)] - Vec3(0, 0.0605, 0)))
      upper_pole = i;
  }
  struct Sums {
    double load = 0, approach = 0, radius = 0;
    int samples = 0;
    ContactMoments moments;  // over the window
  };
  const std::array<double, 3> at = {2.0, 3.0, 4.4};
  std::array<Sums, 3> sums{};
  Stepped total;
  for (size_t k = 0; k < at.size(); ++k) {
    const auto sample = [&](const Simulation& now) {
      const ContactMoments m = sim.take_body_contact_moments();  // (`now` is sim)
      if (now.time() < at[k] - 0.1 - 1e-9) return;
      Sums& s = sums[k];
      if (s.samples > 0) s.moments.add(m);  // (the first take holds the impulses from before the window)
      s.load += now.held_force(0).y;
      s.approach += mean_displacement(now, lower_c, 1) - mean_displacement(now, upper_c, 1) - gap0;
      const double plane = 0.5 * (0.06 + now.displacement(lower_pole).y + 0.0605 + now.displacement(upper_pole).y);
      double radius = 0;
      for (int32_t i : lower_surface) {
        const Vec3 x = now.mesh().X[size_t(i)] + now.displacement(i);
        if (x.y >= plane - kHertzGap) radius = std::max(radius, std::hypot(x.x, x.z));
      }
      s.radius += radius;
      ++s.samples;
    };
    const Stepped s = step_for(sim, at[k], 0.005, sample);
    total.steps += s.steps;
    total.wall += s.wall;
    if (!s.fault.empty()) {
      total.fault = s.fault;
      break;
    }
  }
  std::vector<AccuracyRecord> out;
  for (const Sums& s : sums) {
    if (s.samples == 0) continue;
    const double F = s.load / s.samples, d = s.approach / s.samples;
    // The radius from the normal impulses' spread about their centre in the
    // contact plane (x, z): Hertz's pressure p0 sqrt(1 - r^2/a^2) has mean
    // r^2 = 2 a^2 / 5 over its load. (The farthest node in the plane comes in
    // steps of the surface's spacing; it is kept below as a check.)
    const ContactMoments& m = s.moments;
    double a = 0;
    if (m.weight > 0) {
      const double cx = m.first.x / m.weight, cz = m.first.z / m.weight;
      const double spread = m.second[0] / m.weight - cx * cx + m.second[2] / m.weight - cz * cz;
      a = std::sqrt(2.5 * std::max(spread, 0.0));
    }
    const double a_hertz = std::cbrt(3 * std::max(F, 0.0) * r_star / (4 * e_star));
    AccuracyRecord radius = make_record("hertz_radius", mat.model, n, sim, sc.spec.integrator.safety, p, total);
    radius.load = F;
    radius.value = a;
    radius.reference = a_hertz;
    radius.error = a_hertz > 0 ? a / a_hertz - 1 : 0;
    radius.unit = "m";
    AccuracyRecord approach = radius;
    approach.problem = "hertz_approach";
    approach.value = d;
    approach.reference = a_hertz * a_hertz / r_star;
    approach.error = approach.reference > 0 ? d / approach.reference - 1 : 0;
    AccuracyRecord nodes = radius;
    nodes.problem = "hertz_radius_nodes";
    nodes.value = s.radius / s.samples;
    nodes.error = a_hertz > 0 ? nodes.value / a_hertz - 1 : 0;
    out.push_back(radius);
    out.push_back(nodes);
    out.push_back(approach);
  }
  if (out.empty()) out.push_back(make_record("hertz_radius", mat.model, n, sim, sc.spec.integrator.safety, p, total));
  return out;
}

// ---- invariance under rigid rotation --------------------------------------------------------------------------

std::pair<AccuracyRecord, AccuracyRecord> rotation(Element el, MaterialModel m, int n, Precision p) {
  // A free 10 cm cube turned rigidly by 90 degrees about z, at rest: no strain, so no elastic energy, no
  // force, and its volume kept as it is left to move for 50 ms. The energy is shown per unit of E V (the
  // energy density of a unit strain, order 1), the volume change relative.
  const double a = 0.1, E = 1e5;
  ModelSpec spec;
  spec.mesh = el.mesh(make_box(Vec3(-a / 2), Vec3(a / 2), {3 * n, 3 * n, 3 * n}));
  spec.materials = {MaterialSpec{m, E, 0.3, 1000}};
  spec.integrator.precision = p;
  Simulation sim(spec);
  std::vector<double> u(3 * size_t(sim.n_nodes()), 0.0), v(u.size(), 0.0);
  for (int32_t i = 0; i < sim.n_nodes(); ++i) {
    const Vec3& X = sim.mesh().X[size_t(i)];
    u[3 * size_t(i)] = -X.y - X.x;  // (x, y) -> (-y, x)
    u[3 * size_t(i) + 1] = X.x - X.y;
  }
  sim.set_initial_state(u, v);
  const double energy = sim.compute_energy().elastic / (E * a * a * a);
  const Stepped s = step_for(sim, 0.05, 0.001);
  std::vector<double> x;
  sim.copy_positions(x);
  double volume = 0;
  auto at = [&](int32_t i) { return Vec3(x[3 * size_t(i)], x[3 * size_t(i) + 1], x[3 * size_t(i) + 2]); };
  for (const Tet& t : sim.mesh().tets) volume += compute_tet_volume(at(t[0]), at(t[1]), at(t[2]), at(t[3]));
  AccuracyRecord e = make_record("rotation_energy", m, n, sim, spec.integrator.safety, p, s);
  e.value = e.error = energy;
  e.unit = "elastic energy / (E V)";
  AccuracyRecord vol = e;
  vol.problem = "rotation_volume";
  vol.value = vol.error = volume / (a * a * a) - 1;
  vol.unit = "volume change / volume";
  return {e, vol};
}

// ---- real time ------------------------------------------------------------------------------------------------

RealtimeRecord realtime(Element el, MaterialModel m, Precision p, bool quick) {
  // The poke scene's block (8 x 4 x 8 cm, 30 kPa, damped, a sphere over it: the contact pass runs) at growing
  // resolutions, each stepped in 1 ms intervals as the live loop's haptic rate needs; the median wall time
  // of an interval against 1 ms.
  RealtimeRecord out;
  out.material = std::string(to_string(m));
  out.precision = name_of(p);
  out.element = el.name();
  const int k_max = quick ? 3 : 10;
  for (int k = 1; k <= k_max; ++k) {
    ModelSpec spec;
    spec.mesh = el.mesh(make_box(Vec3(-0.04, 0, -0.04), Vec3(0.04, 0.04, 0.04), {4 * k, 2 * k, 4 * k}));
    spec.materials = {MaterialSpec{m, 30e3, 0.3, 1000}};
    spec.integrator.precision = p;
    spec.effects.damping = true;
    spec.effects.alpha = 5.0;
    EssentialBc base;
    base.name = "base";
    base.where.kind = NodeSelector::Kind::Plane;
    base.where.point = Vec3(0.0);
    spec.essential = {base};
    ProxySpec ball;
    ball.name = ball.device = "stylus";
    ball.geometry.radius = 0.01;
    ball.pose.position = Vec3(0, 0.055, 0);
    spec.proxies = {ball};
    Simulation sim(spec);
    std::vector<double> ms;
    int32_t substeps = 0;
    const Clock::time_point start = Clock::now();
    while ((ms.size() < 20 || std::chrono::duration<double>(Clock::now() - start).count() < (quick ? 0.1 : 0.4)) &&
           ms.size() < 2000) {
      const Clock::time_point t0 = Clock::now();
      const AdvanceReport r = sim.advance(1e-3);
      ms.push_back(1e3 * std::chrono::duration<double>(Clock::now() - t0).count());
      substeps = std::max(substeps, r.substeps);
      if (r.fault) break;
    }
    std::nth_element(ms.begin(), ms.begin() + long(ms.size() / 2), ms.end());
    const double median = ms[ms.size() / 2];
    out.tets.push_back(sim.n_tets());
    out.interval_ms.push_back(median);
    out.substeps.push_back(substeps);
    if (median < 1.0) out.largest_realtime_tets = sim.n_tets();
    if (median >= 1.0) break;  // the next sizes only cost more
  }
  // Interpolated between the last size under 1 ms and the first over (log-log: cost ~ tets^(4/3)).
  const size_t n = out.tets.size();
  if (n >= 2 && out.interval_ms[n - 1] >= 1.0 && out.interval_ms[n - 2] < 1.0) {
    const double l1 = std::log(double(out.tets[n - 2])), l2 = std::log(double(out.tets[n - 1]));
    const double c1 = std::log(out.interval_ms[n - 2]), c2 = std::log(out.interval_ms[n - 1]);
    out.estimated_max_tets = std::exp(l1 + (0 - c1) / (c2 - c1) * (l2 - l1));
  } else {
    out.estimated_max_tets = out.largest_realtime_tets;
  }
  return out;
}

}  // namespace

namespace {

MaterialModel material_named(const std::string& name) {
  for (MaterialModel m : kModels)
    if (name == to_string(m)) return m;
  throw std::invalid_argument("accuracy case: no material model '" + name + "'");
}

Precision precision_named(const std::string& name) {
  if (name == "float") return Precision::Float;
  if (name == "double") return Precision::Double;
  throw std::invalid_argument("accuracy case: precision must be float or double, got '" + name + "'");
}

}  // namespace

std::vector<AccuracyCase> list_accuracy_cases(const AccuracyOptions& o) {
  std::vector<AccuracyCase> cases;
  auto wants = [&](const char* problem) { return o.only.empty() || o.only == problem; };
  const bool q = o.quick;
  // Per element order: a quadratic tet has ten nodes and a step about a third of the linear one's, so its
  // levels stop earlier, where they already pass the linear tets' finest; and its time step is the
  // linear tets' finding (0.9 of the critical step), not a variation of its own.
  // Quick, the quadratic tets run StVK only: the element order is the axis there, not the model.
  struct Levels {
    const char* element;
    std::vector<int> statics, dynamics, waves, rotations, figures;
    std::vector<double> safeties;
    std::vector<MaterialModel> models;
  };
  const std::vector<MaterialModel> all(std::begin(kModels), std::end(kModels));
  const Levels p1 =
      q ? Levels{"p1", {1, 2}, {1}, {1, 2}, {1, 2}, {1, 2}, {0.9, 0.3}, all}
        : Levels{"p1", {1, 2, 3, 4}, {1, 2, 3}, {1, 2, 3, 4}, {1, 2, 3, 4}, {1, 2, 3}, {0.9, 0.6, 0.3}, all};
  const Levels p2 = q ? Levels{"p2", {1, 2}, {1}, {1, 2}, {1}, {1, 2}, {0.9}, {MaterialModel::StVK}}
                      : Levels{"p2", {1, 2, 3}, {1, 2}, {1, 2}, {1}, {1, 2}, {0.9}, all};
  auto add = [&](const char* problem, const char* element, MaterialModel m, int n, Precision p, double safety = 0) {
    AccuracyCase c;
    c.problem = problem;
    c.material = to_string(m);
    c.element = element;
    c.level = n;
    c.precision = name_of(p);
    c.safety = safety;
    c.quick = q;
    c.label = c.problem + " " + c.element + " " + c.material + " level " + std::to_string(n) + " " + c.precision;
    if (safety > 0) c.label += " dt " + std::to_string(safety).substr(0, 3);
    cases.push_back(std::move(c));
  };
  for (const Levels* L : {&p1, &p2})
    for (MaterialModel m : L->models)
      for (Precision p : kPrecisions) {
        if (wants("cantilever_deflection"))
          for (int n : L->statics) add("cantilever_deflection", L->element, m, n, p);
        for (double safety : L->safeties) {
          if (wants("cantilever_frequency"))
            for (int n : L->dynamics) add("cantilever_frequency", L->element, m, n, p, safety);
          if (wants("wave_speed"))
            for (int n : L->waves) add("wave_speed", L->element, m, n, p, safety);
        }
        if (wants("rotation"))
          for (int n : L->rotations) add("rotation", L->element, m, n, p);
      }
  // The figures: a converged StVK run in double, on quadratic tets (linear ones still lock in bending at
  // the finest level affordable: theirs is no reference), then every choice measured against it (quadratic
  // ones below the reference's level).
  auto figure = [&](const char* problem, const char* reference, int reference_level) {
    if (!wants(problem)) return;
    add(reference, "p2", MaterialModel::StVK, reference_level, Precision::Double);
    for (const Levels* L : {&p1, &p2})
      for (MaterialModel m : L->models)
        for (Precision p : kPrecisions)
          for (int n : L->figures)
            if (L == &p1 || n < reference_level) add(problem, L->element, m, n, p);
  };
  // Hertz's spheres, neo-Hookean as the scene is, in float: not quick (a minute and more a run).
  if (!q && wants("hertz"))
    for (const Levels* L : {&p1, &p2})
      for (int n : L == &p1 ? std::vector<int>{1, 2, 3} : std::vector<int>{1, 2})
        add("hertz", L->element, MaterialModel::NeoHookean, n, Precision::Float);
  figure("fig3_tip", "fig3_reference", q ? 3 : 4);
  figure("fig2_area", "fig2_reference", q ? 2 : 3);
  if (wants("realtime"))
    for (const Levels* L : {&p1, &p2})
      for (MaterialModel m : L->models)
        for (Precision p : kPrecisions) {
          add("realtime", L->element, m, 0, p);
          cases.back().label =
              "realtime " + cases.back().element + " " + cases.back().material + " " + cases.back().precision;
        }
  return cases;
}

AccuracyResults run_accuracy_case(const AccuracyCase& c, const std::string& scenes) {
  const MaterialModel m = material_named(c.material);
  const Precision p = precision_named(c.precision);
  if (c.element != "p1" && c.element != "p2")
    throw std::invalid_argument("accuracy case: element must be p1 or p2, got '" + c.element + "'");
  const Element el{c.element == "p2"};
  const int n = c.level;
  AccuracyResults out;
  auto fig3_record = [&](const char* problem) {
    Fig3Run run = fig3(scenes, el, m, n, p);
    run.record.problem = problem;
    run.record.tip = {run.tip.x, run.tip.y, run.tip.z};
    out.records.push_back(run.record);
  };
  if (c.problem == "cantilever_deflection") {
    out.records.push_back(cantilever_deflection(el, m, n, p));
  } else if (c.problem == "cantilever_frequency") {
    out.records.push_back(cantilever_frequency(el, m, n, p, c.safety));
  } else if (c.problem == "wave_speed") {
    out.records.push_back(wave_speed(el, m, n, p, c.safety));
  } else if (c.problem == "rotation") {
    auto [e, v] = rotation(el, m, n, p);
    out.records.push_back(e);
    out.records.push_back(v);
  } else if (c.problem == "fig3_tip" || c.problem == "fig3_reference") {
    fig3_record(c.problem == "fig3_tip" ? "fig3_tip" : "fig3_reference");
  } else if (c.problem == "fig2_area" || c.problem == "fig2_reference") {
    AccuracyRecord r = fig2(scenes, el, m, n, p);
    r.problem = c.problem;
    out.records.push_back(r);
  } else if (c.problem == "hertz") {
    if (m != MaterialModel::NeoHookean) throw std::invalid_argument("accuracy case: hertz is neo-Hookean only");
    for (AccuracyRecord& r : hertz(scenes, el, n, p)) out.records.push_back(std::move(r));
  } else if (c.problem == "realtime") {
    out.realtime.push_back(realtime(el, m, p, c.quick));
  } else {
    throw std::invalid_argument("accuracy case: no problem '" + c.problem + "'");
  }
  return out;
}

void finish_accuracy(AccuracyResults& results) {
  std::vector<AccuracyRecord>& rs = results.records;
  const auto find = [&](const char* problem) {
    return std::find_if(rs.begin(), rs.end(), [&](const AccuracyRecord& r) { return r.problem == problem; });
  };
  if (auto ref = find("fig3_reference"); ref != rs.end()) {
    const Vec3 tip(ref->tip[0], ref->tip[1], ref->tip[2]);
    for (AccuracyRecord& r : rs)
      if (r.problem == "fig3_tip") {
        r.reference = tip.y;
        r.error = glm::length(Vec3(r.tip[0], r.tip[1], r.tip[2]) - tip) / glm::length(tip);
      }
  }
  if (auto ref = find("fig2_reference"); ref != rs.end()) {
    const double area = ref->value;
    for (AccuracyRecord& r : rs)
      if (r.problem == "fig2_area") {
        r.reference = area;
        r.error = r.value - area;
      }
  }
  std::erase_if(rs,
                [](const AccuracyRecord& r) { return r.problem == "fig3_reference" || r.problem == "fig2_reference"; });
}

AccuracyResults run_accuracy_study(const AccuracyOptions& o) {
  const std::vector<AccuracyCase> cases = list_accuracy_cases(o);
  AccuracyResults results;
  for (size_t k = 0; k < cases.size(); ++k) {
    if (o.progress) o.progress(k, cases.size(), cases[k].label);
    AccuracyResults one = run_accuracy_case(cases[k], o.scenes);
    results.records.insert(results.records.end(), one.records.begin(), one.records.end());
    results.realtime.insert(results.realtime.end(), one.realtime.begin(), one.realtime.end());
  }
  if (o.progress) o.progress(cases.size(), cases.size(), "");
  finish_accuracy(results);
  return results;
}

std::string accuracy_json(const AccuracyResults& results, bool quick) {
  nlohmann::json records = nlohmann::json::array(), realtime = nlohmann::json::array();
  for (const AccuracyRecord& r : results.records) {
    nlohmann::json j = {{"problem", r.problem},
                        {"material", r.material},
                        {"element", r.element},
                        {"level", r.level},
                        {"tets", r.tets},
                        {"nodes", r.nodes},
                        {"safety", r.safety},
                        {"precision", r.precision},
                        {"value", r.value},
                        {"reference", r.reference},
                        {"error", r.error},
                        {"unit", r.unit},
                        {"steps", r.steps},
                        {"sim_time_s", r.sim_time},
                        {"wall_s", r.wall_s},
                        {"us_per_step", r.us_per_step},
                        {"tet_steps_per_s", r.tet_steps_per_s},
                        {"fault", r.fault}};
    if (r.problem == "fig3_tip" || r.problem == "fig3_reference") j["tip_m"] = r.tip;
    if (r.problem.starts_with("hertz_")) j["load_n"] = r.load;
    records.push_back(std::move(j));
  }
  for (const RealtimeRecord& r : results.realtime)
    realtime.push_back({{"material", r.material},
                        {"precision", r.precision},
                        {"element", r.element},
                        {"tets", r.tets},
                        {"interval_ms", r.interval_ms},
                        {"substeps", r.substeps},
                        {"largest_realtime_tets", r.largest_realtime_tets},
                        {"estimated_max_tets", r.estimated_max_tets}});
  return nlohmann::json{{"quick", quick}, {"records", records}, {"realtime", realtime}}.dump(1) + "\n";
}

AccuracyResults accuracy_from_json(const std::string& text) {
  const nlohmann::json j = nlohmann::json::parse(text);
  AccuracyResults out;
  for (const nlohmann::json& r : j.at("records")) {
    AccuracyRecord a;
    a.problem = r.at("problem");
    a.material = r.at("material");
    a.element = r.value("element", "p1");
    a.level = r.at("level");
    a.tets = r.at("tets");
    a.nodes = r.value("nodes", 0);
    a.safety = r.at("safety");
    a.precision = r.at("precision");
    a.value = r.at("value");
    a.reference = r.at("reference");
    a.error = r.at("error");
    a.unit = r.at("unit");
    a.steps = r.at("steps");
    a.sim_time = r.at("sim_time_s");
    a.wall_s = r.at("wall_s");
    a.us_per_step = r.at("us_per_step");
    a.tet_steps_per_s = r.at("tet_steps_per_s");
    a.fault = r.at("fault");
    if (r.contains("tip_m")) a.tip = r.at("tip_m");
    a.load = r.value("load_n", 0.0);
    out.records.push_back(std::move(a));
  }
  for (const nlohmann::json& r : j.at("realtime")) {
    RealtimeRecord t;
    t.material = r.at("material");
    t.precision = r.at("precision");
    t.element = r.value("element", "p1");
    t.tets = r.at("tets").get<std::vector<int32_t>>();
    t.interval_ms = r.at("interval_ms").get<std::vector<double>>();
    t.substeps = r.at("substeps").get<std::vector<int32_t>>();
    t.largest_realtime_tets = r.at("largest_realtime_tets");
    t.estimated_max_tets = r.at("estimated_max_tets");
    out.realtime.push_back(std::move(t));
  }
  return out;
}

}  // namespace tactile::study
