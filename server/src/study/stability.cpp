#include "study/stability.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <optional>
#include <random>
#include <sstream>
#include <stdexcept>
#include <utility>

#include <glm/gtc/quaternion.hpp>
#include <nlohmann/json.hpp>

#include "core/bodies.hpp"
#include "core/contact/cluster_set.hpp"
#include "core/quadratic.hpp"
#include "core/spec.hpp"
#include "mesh/primitives.hpp"
#include "mesh/quality.hpp"
#include "mesh/tetgen.hpp"
#include "sim/simulation.hpp"

namespace tactile::study {

const char* to_string(Expect e) {
  switch (e) {
    case Expect::Runs: return "runs";
    case Expect::Caught: return "caught";
  }
  return "?";
}

namespace {

using Clock = std::chrono::steady_clock;
constexpr double kPi = std::numbers::pi;
// StVK as the live scenes run it, invertible: the paper's plain StVK cannot
// come back from an inverted element, by design, and its guard's fault is
// tested on its own (tests/test_fault_to_zero_force.py, --on-fault reset).
constexpr MaterialModel kModels[] = {MaterialModel::Linear, MaterialModel::InvertibleStVK, MaterialModel::Corotational,
                                     MaterialModel::NeoHookean};

// One run of a case: a model, what drives it, and what it must show.
struct Scenario {
  ModelSpec spec;
  double duration = 0.1;   // simulated [s]
  int64_t min_steps = 0;   // or run until this many steps (the long run)
  double interval = 1e-3;  // control interval: one advance() per interval, as a device loop
  // Sets the proxies' motion over [t0, t1] before each interval.
  std::function<void(Simulation&, double t0, double t1)> drive;
  // Sets the state before the first step.
  std::function<void(Simulation&)> init;
  bool conservative = false;  // energy drift checked
  double size_limit = 2.0;    // largest bounding-box diagonal over the rest one
  Expect expect = Expect::Runs;
  // After the run (when it did not fault): "" or what is wrong.
  std::function<std::string(const Simulation&)> final_check;
  // From time `change_at` on, the body runs on under this spec instead (a
  // load taken off): the same mesh and proxies, carried over as it is.
  std::optional<ModelSpec> change_to;
  double change_at = 0;
};

std::string fmt(const char* f, double a) {
  char s[96];
  std::snprintf(s, sizeof s, f, a);
  return s;
}

double diagonal(const std::vector<double>& x) {
  Vec3 lo(std::numeric_limits<double>::infinity()), hi(-std::numeric_limits<double>::infinity());
  for (size_t i = 0; i + 2 < x.size(); i += 3)
    for (int d = 0; d < 3; ++d) {
      lo[d] = std::min(lo[d], x[i + size_t(d)]);
      hi[d] = std::max(hi[d], x[i + size_t(d)]);
    }
  return glm::length(hi - lo);
}

// The nodes on the body's boundary (on a face of one tet only): the contact keeps these out of the
// proxies; the nodes inside the body are behind them.
std::vector<int32_t> surface_nodes(const TetMesh& mesh) {
  std::map<std::array<int32_t, 3>, int> faces;
  for (const Tet& t : mesh.tets)
    for (int skip = 0; skip < 4; ++skip) {
      std::array<int32_t, 3> f{};
      int k = 0;
      for (int c = 0; c < 4; ++c)
        if (c != skip) f[size_t(k++)] = int32_t(t[c]);
      std::sort(f.begin(), f.end());
      ++faces[f];
    }
  std::vector<char> on(size_t(mesh.n_nodes()), 0);
  for (const auto& [f, n] : faces)
    if (n == 1)
      for (int32_t i : f) on[size_t(i)] = 1;
  std::vector<int32_t> out;
  for (int32_t i = 0; i < mesh.n_nodes(); ++i)
    if (on[size_t(i)]) out.push_back(i);
  return out;
}

// The surface nodes against the proxies, at each control instant: how deep the deepest is, and which went
// through. A node that enters a proxy is remembered with the normal it entered by (in the proxy's frame) and
// the deepest it got; one that comes out on the opposite side having been deeper than the proxy's trust
// depth (see core/proxy.hpp) went through its interior: it tunnelled. (One that comes out opposite but was
// never that deep slid round the proxy's surface, which contact allows.) How deep a node sits meanwhile is
// the contact's accuracy, reported: the velocity-level contact stops a node within a step or two, by about
// dt^2 F / 2m, which on a coarse mesh with a step near the critical one is millimetres.
class ProxyWatch {
 public:
  ProxyWatch(const Simulation& sim, std::vector<int32_t> nodes)
      : nodes_(std::move(nodes)), stay_(nodes_.size() * sim.proxies().size()) {}

  // Returns the deepest node's depth [m]; counts the nodes that went through.
  double update(const Simulation& sim, const std::vector<double>& x) {
    double deepest = 0;
    for (size_t j = 0; j < sim.proxies().size(); ++j) {
      const Pose pose = sim.proxy_pose(int32_t(j));
      const ProxyGeometry& g = sim.proxies()[j].geometry;
      const double trust = trust_depth(g);
      for (size_t k = 0; k < nodes_.size(); ++k) {
        const size_t i = 3 * size_t(nodes_[k]);
        const SurfacePoint at = locate(g, pose.to_local(Vec3(x[i], x[i + 1], x[i + 2])));
        Stay& s = stay_[j * nodes_.size() + k];
        if (at.phi < 0) {
          deepest = std::max(deepest, -at.phi);
          if (!s.inside) s = Stay{true, !started_, at.n, 0};  // inside from the start: the way in unknown
          s.deepest = std::max(s.deepest, -at.phi);
        } else if (s.inside) {
          if (!s.from_start && s.deepest > trust && glm::dot(s.entry, at.n) < -0.5) ++tunnelled_;
          s.inside = false;
        }
      }
    }
    started_ = true;
    return deepest;
  }
  int64_t tunnelled() const { return tunnelled_; }

 private:
  struct Stay {
    bool inside = false, from_start = false;
    Vec3 entry{0.0};     // the normal it went in by (proxy frame)
    double deepest = 0;  // [m]
  };
  std::vector<int32_t> nodes_;
  std::vector<Stay> stay_;  // per (proxy, node)
  bool started_ = false;
  int64_t tunnelled_ = 0;
};

// The solid angle triangle (a, b, c) subtends at the origin, signed: positive when the origin is behind it
// (its corners counter-clockwise seen from outside) [sr] (Van Oosterom & Strackee 1983).
double solid_angle(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double la = glm::length(a), lb = glm::length(b), lc = glm::length(c);
  if (la == 0 || lb == 0 || lc == 0) return 0.0;  // a corner: the point is in the triangle's plane
  const double num = glm::dot(a, glm::cross(b, c));
  const double den = la * lb * lc + glm::dot(a, b) * lc + glm::dot(b, c) * la + glm::dot(c, a) * lb;
  return 2.0 * std::atan2(num, den);
}

// The bodies' boundaries against each other, and a body's against itself where the scene asks for self
// contact, at each control instant, by exact geometry on the boundaries as they are (not the contact's own
// tests): a surface node of one body is inside another when its winding number over that body's boundary
// is above one half, and inside its own body when its winding number over its own boundary is above one (a
// node on its own surface has at most 7/8, at a re-entrant corner; one that went through another part of its
// body has one more). Its depth is its distance to the nearest face of that boundary -- of its own, the
// faces outside its neighbourhood, as the contact leaves them out (a face whose rest distance from the node
// is under twice its longest edge).
class BodyWatch {
 public:
  BodyWatch(const Simulation& sim, bool self) : self_(self) {
    const std::vector<ModelBody>& bodies = sim.bodies();
    if (bodies.size() < 2 && !self) return;
    const TetMesh& mesh = sim.mesh();
    rest_ = mesh.X;
    bodies_.resize(bodies.size());
    const auto body_of = [&](int32_t n) {
      for (size_t b = 0; b < bodies.size(); ++b)
        if (n >= bodies[b].spec.node_begin && n < bodies[b].spec.node_end) return b;
      return size_t(0);
    };
    double shortest = std::numeric_limits<double>::infinity();
    for (const Tri& f : compute_boundary_faces(mesh)) {
      Body& b = bodies_[body_of(f[0])];
      b.faces.push_back(f);
      double longest = 0;
      for (int k = 0; k < 3; ++k) {
        const double e = glm::length(rest_[size_t(f[size_t(k)])] - rest_[size_t(f[size_t((k + 1) % 3)])]);
        longest = std::max(longest, e);
        shortest = std::min(shortest, e);
      }
      b.reach.push_back(2.0 * longest);
    }
    for (Body& b : bodies_) b.nodes = compute_boundary_nodes(b.faces);
    limit_ = std::min(0.5e-3, 0.02 * shortest);
    active_ = true;
  }
  bool active() const { return active_; }
  double limit() const { return limit_; }  // [m]

  // The deepest node inside another body, or its own, now [m]; 0 when none is.
  double update(const std::vector<double>& x) {
    const auto at = [&](int32_t n) { return Vec3(x[3 * size_t(n)], x[3 * size_t(n) + 1], x[3 * size_t(n) + 2]); };
    const auto winding = [&](const Body& b, const Vec3& p) {
      double w = 0;
      for (const Tri& f : b.faces) w += solid_angle(at(f[0]) - p, at(f[1]) - p, at(f[2]) - p);
      return w / (4 * kPi);
    };
    double deepest = 0;
    for (size_t a = 0; a < bodies_.size(); ++a)
      for (size_t b = 0; b < bodies_.size(); ++b) {
        if (a == b && !self_) continue;
        const Body& into = bodies_[b];
        Vec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
        for (int32_t n : into.nodes) {
          lo = glm::min(lo, at(n));
          hi = glm::max(hi, at(n));
        }
        for (int32_t n : bodies_[a].nodes) {
          const Vec3 p = at(n);
          if (a != b && !boxes_meet(p, p, lo, hi)) continue;
          if (winding(into, p) <= (a == b ? 1.0 : 0.5)) continue;
          double depth = std::numeric_limits<double>::infinity();
          for (size_t k = 0; k < into.faces.size(); ++k) {
            const Tri& f = into.faces[k];
            if (a == b && (glm::length(rest_[size_t(f[0])] - rest_[size_t(n)]) < into.reach[k] ||
                           glm::length(rest_[size_t(f[1])] - rest_[size_t(n)]) < into.reach[k] ||
                           glm::length(rest_[size_t(f[2])] - rest_[size_t(n)]) < into.reach[k]))
              continue;
            depth = std::min(depth, glm::length(p - compute_closest_on_triangle(p, at(f[0]), at(f[1]), at(f[2]))));
          }
          if (std::isfinite(depth)) deepest = std::max(deepest, depth);
        }
      }
    return deepest;
  }

 private:
  struct Body {
    std::vector<Tri> faces;      // spec's node ids, outward
    std::vector<double> reach;   // per face: its neighbourhood at rest [m]
    std::vector<int32_t> nodes;  // on its boundary
  };
  bool self_ = false, active_ = false;
  std::vector<Vec3> rest_;
  std::vector<Body> bodies_;
  double limit_ = 0;
};

// After each step's body contact pass: the largest |sum of the momentum it gave the bodies and the held nodes'
// constraints| over the sum of its points' |J|.
class MomentumWatch : public StepProbe {
 public:
  explicit MomentumWatch(const Simulation& sim) : sim_(&sim) {}
  void enter(Pass) override {}
  void leave(Pass p) override {
    if (p != Pass::BodyContact) return;
    const Simulation::BodyContactReport r = sim_->body_contact_report();
    Vec3 sum = r.held;
    for (const Vec3& g : r.given) sum += g;
    if (r.impulses > 0) residual_ = std::max(residual_, glm::length(sum) / r.impulses);
  }
  double residual() const { return residual_; }

 private:
  const Simulation* sim_;
  double residual_ = 0;
};

bool all_finite(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double a) { return std::isfinite(a); });
}

// Runs a scenario and judges it.
CaseOutcome run_scenario(Scenario sc, CaseOutcome out) {
  out.expect = sc.expect;
  out.size_limit = sc.size_limit;
  const Clock::time_point t0 = Clock::now();
  auto fail = [&](std::string why) {
    if (out.why.empty()) out.why = std::move(why);
  };
  std::unique_ptr<Simulation> sim_ptr;
  try {
    sim_ptr = std::make_unique<Simulation>(sc.spec);
  } catch (const std::exception& e) {
    out.outcome = std::string("refused at load: ") + e.what();
    fail("the model was refused at load");
    out.wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
    return out;
  }
  Simulation& sim = *sim_ptr;
  out.tets = sim.n_tets();
  if (sc.init) sc.init(sim);

  std::vector<double> x, u, v;
  sim.copy_positions(x);
  // The size check is body by body: bodies that part are not one body growing.
  const std::vector<ModelBody> parts = sim.bodies();
  const auto size_of = [&](const std::vector<double>& at, size_t b) {
    const BodySpec& body = parts[b].spec;
    return diagonal(std::vector<double>(at.begin() + 3 * body.node_begin, at.begin() + 3 * body.node_end));
  };
  std::vector<double> rest_size(parts.size());
  for (size_t b = 0; b < parts.size(); ++b) rest_size[b] = size_of(x, b);
  const bool has_proxies = !sim.proxies().empty();
  if (has_proxies) out.peak_force_N = 0;
  const std::vector<int32_t> surface = has_proxies ? surface_nodes(sim.mesh()) : std::vector<int32_t>{};
  ProxyWatch watch(sim, surface);
  if (has_proxies) watch.update(sim, x);
  const bool body_contact = sc.spec.effects.body_contact || sc.spec.effects.self_contact;
  BodyWatch bodies(sim, sc.spec.effects.self_contact);
  MomentumWatch momentum(sim);
  if (body_contact) {
    sim.set_probe(&momentum);
    out.momentum_residual = 0;
  }
  if (bodies.active()) {
    out.body_depth_limit_mm = 1e3 * bodies.limit();
    out.body_depth_mm = 1e3 * bodies.update(x);
  }

  double balance0 = 0, in_play = 0, drift = 0;
  bool energy_started = false, subdivided = false;
  Fault fault;
  bool changed = false;
  while (sim.time() < sc.duration - 1e-12 || sim.steps() < sc.min_steps) {
    if (sc.change_to && !changed && sim.time() >= sc.change_at - 1e-12) {
      Simulation next(*sc.change_to);
      next.continue_from(sim);
      sim = std::move(next);
      if (body_contact) sim.set_probe(&momentum);
      changed = true;
      energy_started = false;  // (another energy account from here)
    }
    const double t = sim.time();
    if (sc.drive) sc.drive(sim, t, t + sc.interval);
    const AdvanceReport r = sim.advance(sc.interval);
    out.substeps_max = std::max(out.substeps_max, r.substeps);
    subdivided = subdivided || r.subdivided;
    if (r.fault) {
      fault = r.fault;
      break;
    }
    sim.copy_positions(x);
    sim.copy_velocity(v);
    if (!all_finite(x) || !all_finite(v)) {
      fail("a non-finite position or velocity at t = " + fmt("%.4f s", sim.time()) + " with no fault reported");
      break;
    }
    for (size_t b = 0; b < parts.size(); ++b) out.size_ratio = std::max(out.size_ratio, size_of(x, b) / rest_size[b]);
    if (bodies.active()) out.body_depth_mm = std::max(out.body_depth_mm, 1e3 * bodies.update(x));
    if (has_proxies) {
      out.penetration_mm = std::max(out.penetration_mm, 1e3 * watch.update(sim, x));
      for (const DeviceReport& d : sim.device_reports())
        if (d.elapsed > 0) out.peak_force_N = std::max(out.peak_force_N, glm::length(d.impulse) / d.elapsed);
      sim.clear_impulses();
    }
    const Energy& e = sim.energy();
    if (!energy_started) {
      balance0 = e.balance();
      energy_started = true;
    }
    in_play = std::max(in_play, e.kinetic + e.elastic);
    drift = std::max(drift, std::abs(e.balance() - balance0));
  }
  out.steps = sim.steps();
  out.sim_time = sim.time();
  if (body_contact) {
    out.momentum_residual = momentum.residual();
    sim.set_probe(nullptr);
  }

  // What happened.
  if (fault) {
    std::ostringstream s;
    s << "fault: " << to_string(fault.kind) << fmt(" at t = %.4f s", fault.t);
    if (!fault.elements.empty()) s << " (" << fault.elements.size() << " tets named)";
    out.outcome = s.str();
  } else if (subdivided) {
    out.outcome = "ran, subdivided (up to " + std::to_string(out.substeps_max) + " sub-steps an interval)";
  } else {
    out.outcome = "ran";
  }

  // The checks.
  if (fault) {
    if (fault.message.empty()) fail("a fault with no message");
    const bool names_elements = fault.kind == Fault::Kind::Inverted || fault.kind == Fault::Kind::NonFinite;
    if (names_elements && fault.elements.empty())
      fail("an " + std::string(to_string(fault.kind)) + " fault naming no element");
    // Stopped for good: the next interval gives the fault again and takes no step.
    const int64_t steps = sim.steps();
    const AdvanceReport again = sim.advance(sc.interval);
    if (!again.fault || sim.steps() != steps) fail("the simulation went on after its fault");
    switch (sc.expect) {
      case Expect::Runs: fail("faulted: " + fault.message); break;
      case Expect::Caught:
        if (fault.kind != Fault::Kind::StepTooLarge) fail("faulted other than by refusing the step: " + fault.message);
        break;
    }
  } else if (sc.expect == Expect::Caught && !subdivided) {
    fail("a step above the critical one ran unsubdivided");
  }
  if (out.size_ratio > sc.size_limit) fail("the body grew to " + fmt("%.2f", out.size_ratio) + " times its rest size");
  if (sc.conservative && energy_started) {
    out.energy_drift = in_play > 0 ? drift / in_play : 0;
    if (out.energy_drift > 0.10) fail("energy drifted by " + fmt("%.1f %%", 100 * out.energy_drift));
  }
  if (watch.tunnelled() > 0)
    fail(std::to_string(watch.tunnelled()) +
         " times a surface node went deep into a proxy and came out on the side "
         "opposite the one it went in by (tunnelled)");
  if (out.body_depth_mm > out.body_depth_limit_mm && out.body_depth_limit_mm >= 0)
    fail("a surface node went " + fmt("%.3f mm", out.body_depth_mm) + " into a body (the case allows " +
         fmt("%.3f mm)", out.body_depth_limit_mm));
  if (out.momentum_residual > 1e-9)
    fail("body contact gave the bodies momenta that do not sum to zero (" + fmt("%.1e", out.momentum_residual) +
         " of what it gave)");
  if (!fault && sc.final_check) {
    const std::string bad = sc.final_check(sim);
    if (!bad.empty()) fail(bad);
  }
  out.pass = out.why.empty();
  out.wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
  return out;
}

// ---- building blocks -----------------------------------------------------------------------------------

struct Level {
  const char* name;
  int k;                   // resolution multiplier
  bool quadratic = false;  // the same meshes, made quadratic (core/quadratic.hpp)
};
constexpr Level kCoarse{"coarse", 1}, kFine{"fine", 2}, kCoarseP2{"coarse_p2", 1, true};

NodeSelector plane_y(double y) {
  NodeSelector s;
  s.kind = NodeSelector::Kind::Plane;
  s.point = Vec3(0, y, 0);
  s.normal = Vec3(0, 1, 0);
  s.tolerance = 1e-9;
  return s;
}

NodeSelector box_of(Vec3 lo, Vec3 hi) {
  NodeSelector s;
  s.kind = NodeSelector::Kind::Box;
  s.lo = lo;
  s.hi = hi;
  s.tolerance = 1e-9;
  return s;
}

EssentialBc fixed_bc(std::string name, NodeSelector where) {
  EssentialBc bc;
  bc.name = std::move(name);
  bc.where = std::move(where);
  return bc;
}

ModelSpec base_spec(TetMesh mesh, MaterialModel model, double E = 1e5, double nu = 0.3) {
  ModelSpec spec;
  spec.mesh = std::move(mesh);
  spec.materials = {MaterialSpec{model, E, nu, 1000}};
  return spec;
}

void damp(ModelSpec& spec, double alpha) {
  spec.effects.damping = true;
  spec.effects.alpha = alpha;
}

void gravity(ModelSpec& spec) {
  spec.effects.gravity = true;
  spec.effects.g = Vec3(0, -9.81, 0);
}

// A column 0.1 x 0.3 x 0.1 m, base at y = 0 (the paper's Fig. 2 proportions).
constexpr double kColW = 0.1, kColH = 0.3;
TetMesh column(Level l) {
  return make_box(Vec3(-kColW / 2, 0, -kColW / 2), Vec3(kColW / 2, kColH, kColW / 2), {3 * l.k, 9 * l.k, 3 * l.k});
}

// A block 6 x 3 x 6 cm, base at y = 0 (the poke scenes' block).
constexpr double kBlockW = 0.06, kBlockH = 0.03;
TetMesh block(Level l) {
  return make_box(Vec3(-kBlockW / 2, 0, -kBlockW / 2), Vec3(kBlockW / 2, kBlockH, kBlockW / 2),
                  {6 * l.k, 3 * l.k, 6 * l.k});
}

// A 2 cm cube, base at y = 0.
constexpr double kCube = 0.02;
TetMesh cube(Level l) {
  return make_box(Vec3(-kCube / 2, 0, -kCube / 2), Vec3(kCube / 2, kCube, kCube / 2), {3 * l.k, 3 * l.k, 3 * l.k});
}

// A plate 5 x 5 cm, 2 mm thick, top at y = 0.
constexpr double kPlateW = 0.05, kPlateT = 0.002;
TetMesh plate(Level l) {
  return make_box(Vec3(-kPlateW / 2, -kPlateT, -kPlateW / 2), Vec3(kPlateW / 2, 0, kPlateW / 2),
                  {10 * l.k, 1 * l.k, 10 * l.k});
}
// Its four edges, fixed.
std::vector<EssentialBc> plate_edges() {
  const double h = kPlateW / 2, t = kPlateT, in = h - 1e-6;  // the z edges stop short of the x edges' corners
  return {fixed_bc("x-", box_of(Vec3(-h, -t, -h), Vec3(-h, 0, h))),
          fixed_bc("x+", box_of(Vec3(h, -t, -h), Vec3(h, 0, h))),
          fixed_bc("z-", box_of(Vec3(-in, -t, -h), Vec3(in, 0, -h))),
          fixed_bc("z+", box_of(Vec3(-in, -t, h), Vec3(in, 0, h)))};
}

ProxySpec sphere_proxy(std::string name, double radius, Vec3 at) {
  ProxySpec p;
  p.name = name;
  p.device = std::move(name);
  p.geometry.shape = ProxyShape::Sphere;
  p.geometry.radius = radius;
  p.pose.position = at;
  return p;
}

// Moves proxy j over [t0, t1] to where `path(t1)` says (as a device input each interval would).
void follow(Simulation& sim, int32_t j, double t0, double t1, const std::function<Vec3(double)>& path) {
  ProxyMotion m;
  m.t0 = t0;
  m.t1 = t1;
  m.from = sim.proxy_pose(j);
  m.to = m.from;
  m.to.position = path(t1);
  sim.set_proxy_motion(j, m);
}

// Smooth 0 -> 1 over [a, b] (cycloidal), 0 before and 1 after.
double ease(double t, double a, double b) {
  if (t <= a) return 0;
  if (t >= b) return 1;
  const double s = (t - a) / (b - a);
  return s - std::sin(2 * kPi * s) / (2 * kPi);
}

int32_t nearest_node(const TetMesh& mesh, Vec3 p) {
  int32_t best = 0;
  double d = std::numeric_limits<double>::infinity();
  for (int32_t i = 0; i < mesh.n_nodes(); ++i)
    if (const double e = glm::length(mesh.X[size_t(i)] - p); e < d) d = e, best = i;
  return best;
}

// The tets of the current configuration with det F <= 0.
int32_t count_inverted(const Simulation& sim) {
  std::vector<double> x;
  sim.copy_positions(x);
  auto at = [&](int32_t i) { return Vec3(x[3 * size_t(i)], x[3 * size_t(i) + 1], x[3 * size_t(i) + 2]); };
  int32_t n = 0;
  for (const Tet& t : sim.mesh().tets)
    if (compute_tet_volume(at(t[0]), at(t[1]), at(t[2]), at(t[3])) <= 0) ++n;
  return n;
}

// "" when no element is left inverted and every node is back within `share`
// of `size` [m] of its rest place; else what is not.
std::string check_back_at_rest(const Simulation& sim, double size, double share, const char* what) {
  if (const int32_t n = count_inverted(sim); n > 0) return std::to_string(n) + " tets still inverted";
  std::vector<double> u;
  sim.copy_displacement(u);
  double worst = 0;
  for (size_t i = 0; i < u.size(); i += 3) worst = std::max(worst, std::hypot(u[i], u[i + 1], u[i + 2]));
  if (worst > share * size)
    return std::string(what) + " did not come back to its rest shape (a node " +
           fmt("%.2f %% of its size away)", 100 * worst / size);
  return "";
}

// The block on its fixed base, damped by `alpha`; the plate (Young's modulus E) held by its edges, likewise.
Scenario damped_block(MaterialModel m, Level l, double alpha) {
  Scenario sc;
  sc.spec = base_spec(block(l), m);
  damp(sc.spec, alpha);
  sc.spec.essential.push_back(fixed_bc("base", plane_y(0)));
  return sc;
}
Scenario damped_plate(MaterialModel m, Level l, double E, double alpha) {
  Scenario sc;
  sc.spec = base_spec(plate(l), m, E);
  damp(sc.spec, alpha);
  sc.spec.essential = plate_edges();
  return sc;
}

// ---- the cases -------------------------------------------------------------------------------------------

// The column, base fixed, damped, its lid turned about the column's axis as `angle` says.
Scenario turned_column(MaterialModel m, Level l, MotionProfile angle, double duration) {
  Scenario sc;
  sc.spec = base_spec(column(l), m);
  damp(sc.spec, 5.0);
  sc.spec.essential.push_back(fixed_bc("base", plane_y(0)));
  EssentialBc lid = fixed_bc("lid", plane_y(kColH));
  lid.centre = Vec3(0, kColH, 0);
  lid.axis = Vec3(0, 1, 0);
  lid.angle = angle;
  sc.spec.essential.push_back(lid);
  sc.duration = duration;
  return sc;
}

// The lid turned 450 degrees (the paper's 90 and on, past a full turn), then held.
Scenario twist(MaterialModel m, Level l, bool quick) {
  return turned_column(m, l, MotionProfile{MotionProfile::Kind::Ramp, 0.0, quick ? 0.75 : 1.5, 2.5 * kPi, 0.0},
                       quick ? 1.0 : 2.0);
}

// The lid spun up to two turns a second within 0.1 s: the column winds up.
Scenario spin(MaterialModel m, Level l, bool quick) {
  return turned_column(m, l, MotionProfile{MotionProfile::Kind::ConstantRate, 0.0, 0.1, 0.0, 4 * kPi},
                       quick ? 0.3 : 0.6);
}

Scenario compress(MaterialModel m, Level l, bool quick, double fraction) {
  // A plate pressed down `fraction` of the block's height, held, lifted away: the block springs back, and
  // after a second to settle stands within 1 % of its height of its rest shape.
  Scenario sc = damped_block(m, l, 10.0);
  ProxySpec p;
  p.name = p.device = "plate";
  p.geometry.shape = ProxyShape::Box;
  p.geometry.half_extents = Vec3(0.05, 0.01, 0.05);
  p.geometry.radius = 0.002;
  const double y0 = kBlockH + 0.01 + 0.002 + 1e-4;  // just above the top (the rounding adds to the half extents)
  p.pose.position = Vec3(0, y0, 0);
  sc.spec.proxies.push_back(p);
  const double s = quick ? 0.5 : 1.0;
  sc.drive = [=](Simulation& sim, double, double t1) {
    follow(sim, 0, sim.time(), t1, [&](double t) {
      const double down = fraction * kBlockH * (ease(t, 0, 0.4 * s) - ease(t, 0.6 * s, 1.0 * s));
      return Vec3(0, y0 - down, 0);
    });
  };
  sc.duration = 1.0 * s + 1.0;
  // Released: no element left inverted, every node back within 1 % of the block's height of its rest place.
  sc.final_check = [](const Simulation& sim) { return check_back_at_rest(sim, kBlockH, 0.01, "the block"); };
  return sc;
}

Scenario bad_start(MaterialModel m, Level l, double through) {
  // The block's top corner node pushed down `through` cell heights at the start: 1 puts it on the plane of
  // the cell's lower face (tets flattened), 1.5 through it (tets inverted). Damped, it must recover.
  Scenario sc = damped_block(m, l, 20.0);
  const double h = kBlockH / (3 * l.k);
  const int32_t corner = nearest_node(sc.spec.mesh, Vec3(kBlockW / 2, kBlockH, kBlockW / 2));
  sc.init = [=](Simulation& sim) {
    std::vector<double> u(3 * size_t(sim.n_nodes()), 0.0), v(u.size(), 0.0);
    u[3 * size_t(corner) + 1] = -through * h;
    sim.set_initial_state(u, v);
  };
  sc.duration = 0.3;
  sc.final_check = [](const Simulation& sim) -> std::string {
    if (const int32_t n = count_inverted(sim); n > 0) return std::to_string(n) + " tets still inverted at the end";
    return "";
  };
  return sc;
}

Scenario under_gravity(MaterialModel m, TetMesh mesh, double E, double nu, double duration) {
  // Base fixed, no damping: the body sags and swings under its weight, and the energy balance holds.
  Scenario sc;
  sc.spec = base_spec(std::move(mesh), m, E, nu);
  gravity(sc.spec);
  sc.spec.essential.push_back(fixed_bc("base", plane_y(0)));
  sc.duration = duration;
  sc.conservative = true;
  return sc;
}

Scenario time_step(MaterialModel m, Level l, double factor, UnstablePolicy policy) {
  // A fixed step of `factor` times the critical estimate at rest (conservative: gravity, no damping).
  Scenario sc = under_gravity(m, block(l), 1e5, 0.3, 0.1);
  const double dt_rest = Simulation(sc.spec).dt_rest();
  sc.spec.integrator.dt = factor * dt_rest;
  sc.spec.integrator.unstable = policy;
  sc.interval = 4 * sc.spec.integrator.dt;  // four steps an interval, each at the fixed step
  sc.expect = factor < 1 ? Expect::Runs : Expect::Caught;
  return sc;
}

Scenario impact(MaterialModel m, Level l, bool) {
  // A 5 mm sphere at 10 m/s through where a 2 mm plate (edges fixed) is: it must carry the plate along.
  Scenario sc = damped_plate(m, l, 1e6, 20.0);
  const double r = 0.005, y0 = 0.010, travel = 0.022, speed = 10.0;
  sc.spec.proxies.push_back(sphere_proxy("ball", r, Vec3(0, y0 + r, 0)));
  const double t_end = travel / speed;
  sc.drive = [=](Simulation& sim, double, double t1) {
    follow(sim, 0, sim.time(), t1, [&](double t) { return Vec3(0, y0 + r - speed * std::min(t, t_end), 0); });
  };
  sc.interval = 1e-4;  // the ball's path in steps of 1 mm
  sc.duration = 0.05;
  const int32_t centre = nearest_node(sc.spec.mesh, Vec3(0, 0, 0));
  sc.final_check = [=](const Simulation& sim) -> std::string {
    // No tunnelling: the plate's centre is under the ball, not back at rest above it.
    const double y = sim.mesh().X[size_t(centre)].y + sim.displacement(centre).y;
    const double bottom = sim.proxy_pose(0).position.y - r;
    if (y > bottom + 0.5e-3)
      return "the ball went through the plate (its centre at " + fmt("%.4f m", y) + ", the ball's bottom at " +
             fmt("%.4f m)", bottom);
    return "";
  };
  return sc;
}

Scenario inside(MaterialModel m, Level l, bool) {
  // A sphere that starts half inside the block, held, then lifted out: nodes inside stay put, none goes
  // deeper, nothing is thrown out.
  Scenario sc = damped_block(m, l, 10.0);
  const double r = 0.008;
  const Vec3 start(0, kBlockH, 0);
  sc.spec.proxies.push_back(sphere_proxy("ball", r, start));
  sc.drive = [=](Simulation& sim, double, double t1) {
    follow(sim, 0, sim.time(), t1, [&](double t) { return start + Vec3(0, 0.02 * ease(t, 0.2, 0.4), 0); });
  };
  sc.duration = 0.5;
  sc.expect = Expect::Runs;
  return sc;
}

Scenario pinch(MaterialModel m, Level l, bool) {
  // Two spheres close on the plate's centre from above and below until they overlap by 1 mm: the nodes
  // between have nowhere to go. Held, then parted.
  Scenario sc = damped_plate(m, l, 1e5, 20.0);
  const double r = 0.005, gap = 0.003;
  const double top0 = r + gap, bottom0 = -kPlateT - r - gap;
  const double close = gap + kPlateT / 2 + 0.0005;  // each travels past the mid-plane by 0.5 mm
  sc.spec.proxies.push_back(sphere_proxy("upper", r, Vec3(0, top0, 0)));
  sc.spec.proxies.push_back(sphere_proxy("lower", r, Vec3(0, bottom0, 0)));
  sc.drive = [=](Simulation& sim, double, double t1) {
    const auto s = [&](double t) { return ease(t, 0, 0.2) - ease(t, 0.3, 0.5); };
    follow(sim, 0, sim.time(), t1, [&](double t) { return Vec3(0, top0 - close * s(t), 0); });
    follow(sim, 1, sim.time(), t1, [&](double t) { return Vec3(0, bottom0 + close * s(t), 0); });
  };
  sc.duration = 0.6;
  return sc;
}

Scenario drag(MaterialModel m, Level l, bool) {
  // A sphere pressed 5 mm in and dragged 4 cm across the block at 1 m/s with friction mu = 1, then lifted.
  Scenario sc = damped_block(m, l, 10.0);
  sc.spec.effects.friction = true;
  const double r = 0.01;
  const Vec3 above(-0.02, kBlockH + r + 0.001, 0);
  ProxySpec p = sphere_proxy("ball", r, above);
  p.friction = 1.0;
  sc.spec.proxies.push_back(p);
  sc.drive = [=](Simulation& sim, double, double t1) {
    follow(sim, 0, sim.time(), t1, [&](double t) {
      return above + Vec3(0.04 * ease(t, 0.1, 0.14), -0.006 * (ease(t, 0, 0.1) - ease(t, 0.15, 0.25)), 0);
    });
  };
  sc.duration = 0.35;
  return sc;
}

// A ring's surface with few segments, meshed by TetGen with no quality bound: slivers.
TetMesh sliver_mesh(Level l) {
  SurfaceMesh s;
  const int n_major = 10 * l.k, n_minor = 5 * l.k;
  const double R = 0.03, r = 0.012;
  for (int i = 0; i < n_major; ++i)
    for (int j = 0; j < n_minor; ++j) {
      const double a = 2 * kPi * i / n_major, b = 2 * kPi * j / n_minor;
      s.vertices.push_back(
          Vec3((R + r * std::cos(b)) * std::cos(a), r * std::sin(b) + r, (R + r * std::cos(b)) * std::sin(a)));
    }
  auto id = [&](int i, int j) { return int32_t(((i + n_major) % n_major) * n_minor + (j + n_minor) % n_minor); };
  for (int i = 0; i < n_major; ++i)
    for (int j = 0; j < n_minor; ++j) {
      s.triangles.push_back(Tri{id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      s.triangles.push_back(Tri{id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  TetgenOptions o;
  o.max_radius_edge_ratio = 0;  // no quality refinement
  return tetrahedralize(s, o);
}

Scenario slivers(MaterialModel m, Level l, bool) {
  // The ring rests on its lowest nodes, sags under gravity and is poked by a sphere.
  Scenario sc;
  sc.spec = base_spec(sliver_mesh(l), m);
  damp(sc.spec, 10.0);
  gravity(sc.spec);
  sc.spec.essential.push_back(fixed_bc("base", box_of(Vec3(-1, -1, -1), Vec3(1, 0.002, 1))));
  const double r = 0.006;
  const Vec3 above(0.03, 2 * 0.012 + r + 0.001, 0);
  sc.spec.proxies.push_back(sphere_proxy("ball", r, above));
  sc.drive = [=](Simulation& sim, double, double t1) {
    follow(sim, 0, sim.time(), t1,
           [&](double t) { return above - Vec3(0, 0.008 * (ease(t, 0, 0.15) - ease(t, 0.2, 0.35)), 0); });
  };
  sc.duration = 0.4;
  return sc;
}

Scenario random_velocity(MaterialModel m, Level l, uint64_t seed) {
  // A free block with a random velocity at every node (about 0.3 m/s, no net momentum), no damping: it
  // rattles, and its energy holds.
  Scenario sc;
  sc.spec = base_spec(block(l), m);
  sc.duration = 0.2;
  sc.conservative = true;
  sc.init = [=](Simulation& sim) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> n(0.0, 0.3);
    std::vector<double> u(3 * size_t(sim.n_nodes()), 0.0), v(u.size());
    Vec3 mean(0.0);
    for (size_t i = 0; i < v.size(); ++i) v[i] = n(rng);
    for (size_t i = 0; i < v.size(); i += 3) mean += Vec3(v[i], v[i + 1], v[i + 2]);
    mean /= double(sim.n_nodes());
    for (size_t i = 0; i < v.size(); i += 3)
      for (int d = 0; d < 3; ++d) v[i + size_t(d)] -= mean[d];
    sim.set_initial_state(u, v);
  };
  sc.size_limit = 2.0;
  return sc;
}

Scenario random_input(MaterialModel m, Level l, uint64_t seed, int64_t steps) {
  // A sphere driven by random device input every millisecond (a random walk of the target, up to
  // 0.3 m/s, in and out of the block and across it), with friction: the long live session.
  Scenario sc = damped_block(m, l, 10.0);
  sc.spec.effects.friction = true;
  const double r = 0.008;
  const Vec3 start(0, kBlockH + r + 0.002, 0);
  ProxySpec p = sphere_proxy("stylus", r, start);
  p.friction = 0.3;
  sc.spec.proxies.push_back(p);
  auto rng = std::make_shared<std::mt19937_64>(seed);
  auto vel = std::make_shared<Vec3>(0.0);
  sc.drive = [=](Simulation& sim, double, double t1) {
    std::normal_distribution<double> n(0.0, 1.0);
    const double dt = t1 - sim.time();
    // An Ornstein-Uhlenbeck velocity (about 0.3 m/s, correlated over 50 ms), pulled back towards the start
    // so the walk stays over the block, never deeper than 8 mm.
    const Vec3 at = sim.proxy_pose(0).position;
    const Vec3 kick(n(*rng), n(*rng), n(*rng));
    *vel += -(*vel) * (dt / 0.05) + kick * (0.3 * std::sqrt(2 * dt / 0.05)) - (at - start) * (dt * 20.0);
    Vec3 to = at + *vel * dt;
    to.y = std::clamp(to.y, kBlockH + r - 0.008, start.y + 0.01);
    to.x = std::clamp(to.x, -0.025, 0.025);
    to.z = std::clamp(to.z, -0.025, 0.025);
    follow(sim, 0, sim.time(), t1, [&](double) { return to; });
  };
  sc.duration = 0;
  sc.min_steps = steps;
  return sc;
}

// ---- several bodies --------------------------------------------------------------------------------------

// A body of a scene of several (core/bodies.hpp), made quadratic on the P2 level (each body before they are
// put together: the suite's own conversion of the whole mesh would renumber them).
BodyParts body_part(std::string name, TetMesh mesh, MaterialModel m, Level l, std::vector<EssentialBc> held = {}) {
  BodyParts b;
  b.name = std::move(name);
  b.mesh = l.quadratic ? make_quadratic_mesh(mesh) : std::move(mesh);
  b.materials = {MaterialSpec{m, 1e5, 0.3, 1000}};
  b.essential = std::move(held);
  return b;
}

ModelSpec bodies_spec(std::vector<BodyParts> parts, double alpha, bool between, bool self) {
  ModelSpec spec;
  add_bodies(spec, std::move(parts));
  damp(spec, alpha);
  spec.effects.body_contact = between;
  spec.effects.self_contact = self;
  return spec;
}

// Body b's centre of mass [m], of its nodes' positions weighted alike.
Vec3 body_centre(const Simulation& sim, size_t b) {
  std::vector<double> x;
  sim.copy_positions(x);
  const BodySpec& body = sim.bodies()[b].spec;
  Vec3 c(0.0);
  for (int32_t n = body.node_begin; n < body.node_end; ++n)
    c += Vec3(x[3 * size_t(n)], x[3 * size_t(n) + 1], x[3 * size_t(n) + 2]);
  return c / double(body.node_end - body.node_begin);
}

// Sets every node of body b moving at v, before the first step.
void launch(Simulation& sim, size_t b, Vec3 v) {
  std::vector<double> u(3 * size_t(sim.n_nodes()), 0.0), vel(u.size(), 0.0);
  const BodySpec& body = sim.bodies()[b].spec;
  for (int32_t n = body.node_begin; n < body.node_end; ++n)
    for (int d = 0; d < 3; ++d) vel[3 * size_t(n) + size_t(d)] = v[d];
  sim.set_initial_state(u, vel);
}

Scenario stack_drop(MaterialModel m, Level l, bool quick) {
  // Two 2 cm cubes, one 1 mm above the other, fall onto a 4 x 2 x 4 cm block held at its base, the lower cube
  // 1 mm above it, at the speed of a 20 cm fall (1.98 m/s), under gravity, lightly damped, with friction: they
  // strike, bounce and come to rest in a stack, in order.
  const double w = 0.02, gap = 0.001, speed = std::sqrt(2 * 9.81 * 0.2);
  const Vec3 half(w / 2, 0, w / 2);
  const TetMesh base = make_box(Vec3(-w, 0, -w), Vec3(w, w, w), {4 * l.k, 2 * l.k, 4 * l.k});
  std::vector<BodyParts> parts;
  parts.push_back(body_part("base", base, m, l, {fixed_bc("base", plane_y(0))}));
  // (A millimetre off each other's rims, as blocks stacked by hand are: rims that meet exactly meet edge to
  // edge, which vertex-face contact holds less well; see docs/perf.md.)
  const Vec3 mid(0.001, w + gap, 0.0005), top(-0.0005, 2 * w + 2 * gap, 0.001);
  const Vec3 up(0, w, 0);
  parts.push_back(body_part("middle", make_box(mid - half, mid + half + up, {3 * l.k, 3 * l.k, 3 * l.k}), m, l));
  parts.push_back(body_part("top", make_box(top - half, top + half + up, {3 * l.k, 3 * l.k, 3 * l.k}), m, l));
  Scenario sc;
  sc.spec = bodies_spec(std::move(parts), 30.0, true, false);
  sc.spec.effects.body_friction = 0.5;  // (frictionless, the least asymmetry slides a block off)
  gravity(sc.spec);
  sc.init = [=](Simulation& sim) {
    std::vector<double> u(3 * size_t(sim.n_nodes()), 0.0), v(u.size(), 0.0);
    for (size_t b = 1; b < 3; ++b)
      for (int32_t n = sim.bodies()[b].spec.node_begin; n < sim.bodies()[b].spec.node_end; ++n)
        v[3 * size_t(n) + 1] = -speed;
    sim.set_initial_state(u, v);
  };
  sc.duration = quick ? 0.3 : 0.6;
  sc.final_check = [](const Simulation& sim) -> std::string {
    const double y[3] = {body_centre(sim, 0).y, body_centre(sim, 1).y, body_centre(sim, 2).y};
    if (!(y[0] < y[1] && y[1] < y[2]))
      return "the stack is out of order (centres at " + fmt("%.4f", y[0]) + ", " + fmt("%.4f", y[1]) + ", " +
             fmt("%.4f m)", y[2]);
    return "";
  };
  return sc;
}

Scenario ball_throw(MaterialModel m, Level l, bool) {
  // A 1 cm ball thrown at 3 m/s, without gravity, at the side of a 4 cm block held at its base, 1 mm away:
  // it strikes, comes back no faster than it came, and ends on the side it came from.
  const double w = 0.04, r = 0.01, speed = 3.0;
  std::vector<BodyParts> parts;
  parts.push_back(body_part("block",
                            make_box(Vec3(-w / 2, 0, -w / 2), Vec3(w / 2, w, w / 2), {4 * l.k, 4 * l.k, 4 * l.k}), m, l,
                            {fixed_bc("base", plane_y(0))}));
  parts.push_back(body_part("ball", make_sphere(Vec3(w / 2 + r + 0.001, w / 2, 0), r, l.k), m, l));
  Scenario sc;
  sc.spec = bodies_spec(std::move(parts), 2.0, true, false);
  sc.init = [=](Simulation& sim) { launch(sim, 1, Vec3(-speed, 0, 0)); };
  sc.duration = 0.05;
  sc.final_check = [=](const Simulation& sim) -> std::string {
    std::vector<double> v;
    sim.copy_velocity(v);
    const BodySpec& ball = sim.bodies()[1].spec;
    Vec3 mean(0.0);
    for (int32_t n = ball.node_begin; n < ball.node_end; ++n)
      mean += Vec3(v[3 * size_t(n)], v[3 * size_t(n) + 1], v[3 * size_t(n) + 2]);
    mean /= double(ball.node_end - ball.node_begin);
    if (body_centre(sim, 1).x < w / 2) return "the ball ended inside the block's side";
    if (glm::length(mean) > speed)
      return "the ball came back faster than it was thrown (" + fmt("%.2f m/s)", glm::length(mean));
    return "";
  };
  return sc;
}

Scenario u_fold(MaterialModel m, Level l, bool) {
  // A beam 10 x 0.5 x 2 cm clamped at one end while its other end is turned half a turn over it in 0.3 s, to
  // lie 1 cm above the clamp; then a palm (a 4 x 1 x 3 cm box) presses the fold's upper arm down onto the
  // lower one until they are squeezed by 1 mm, and holds it. Self contact holds the arms apart, and no face
  // touches its own neighbourhood on the bend.
  const double len = 0.1, h = 0.005, wz = 0.02, apart = 0.01;
  TetMesh beam = make_box(Vec3(0, 0, -wz / 2), Vec3(len, h, wz / 2), {10 * l.k, 1 * l.k, 2 * l.k});
  EssentialBc fold = fixed_bc("fold", box_of(Vec3(len, -1, -1), Vec3(1, 1, 1)));
  fold.centre = Vec3(len / 2, h + apart / 2, 0);
  fold.axis = Vec3(0, 0, 1);
  fold.angle = MotionProfile{MotionProfile::Kind::Ramp, 0.0, 0.3, kPi, 0.0};
  std::vector<BodyParts> parts;
  parts.push_back(
      body_part("beam", std::move(beam), m, l, {fixed_bc("clamp", box_of(Vec3(-1, -1, -1), Vec3(0, 1, 1))), fold}));
  Scenario sc;
  sc.spec = bodies_spec(std::move(parts), 10.0, false, true);
  ProxySpec palm;
  palm.name = palm.device = "palm";
  palm.geometry.shape = ProxyShape::Box;
  palm.geometry.half_extents = Vec3(0.02, 0.005, 0.015);
  palm.geometry.radius = 0.001;
  const Vec3 above(0.03, 0.1, 0);               // clear of the end's half turn (up to 6.5 cm high)
  const double lowest = 2 * h - 0.001 + 0.006;  // the palm's centre at the end (its half height and rounding)
  palm.pose.position = above;
  sc.spec.proxies.push_back(palm);
  sc.drive = [=](Simulation& sim, double, double t1) {
    follow(sim, 0, sim.time(), t1,
           [&](double t) { return above - Vec3(0, (above.y - lowest) * ease(t, 0.3, 0.5), 0); });
  };
  sc.duration = 0.6;
  return sc;
}

}  // namespace

std::vector<StabilityCase> stability_cases(const SuiteOptions& o) {
  std::vector<StabilityCase> cases;
  const bool quick = o.quick;
  std::vector<Level> levels{kCoarse};
  if (!quick) levels.push_back(kFine);
  // On quadratic tets, the hard cases the linear ones run: quick, those that squash, invert and strike the
  // body, shake it, throw it at another, on slivers and at too long a step (the pinch, the slowest of all,
  // in full only); in full, every case.
  const std::vector<std::string> quadratic_quick{
      "twist_450deg", "compress_90pct_release", "inverted_start",  "impact_10m_s",        "slivers",
      "dt_3x_refuse", "random_velocity",        "stack_drop_20cm", "u_fold_self_contact", "ball_3m_s"};
  auto add = [&](const std::string& group, MaterialModel m, Level l, std::function<Scenario()> make) {
    if (l.quadratic && quick &&
        std::find(quadratic_quick.begin(), quadratic_quick.end(), group) == quadratic_quick.end())
      return;
    CaseOutcome head;
    head.group = group;
    head.material = std::string(to_string(m));
    head.mesh = l.name;
    head.name = group + "/" + head.material + "/" + head.mesh;
    if (!o.filter.empty() && head.name.find(o.filter) == std::string::npos) return;
    const bool quadratic = l.quadratic;
    cases.push_back({head.name, [head, quadratic, make = std::move(make)] {
                       Scenario sc = make();
                       // (Corners keep their ids: a node a scenario picked is the same node. A scene of
                       // several bodies made its bodies quadratic itself.)
                       if (quadratic && sc.spec.bodies.empty()) {
                         sc.spec.mesh = make_quadratic_mesh(sc.spec.mesh);
                         if (sc.change_to) sc.change_to->mesh = sc.spec.mesh;
                       }
                       return run_scenario(std::move(sc), head);
                     }});
  };
  levels.push_back(kCoarseP2);
  for (const Level l : levels) {
    for (MaterialModel m : kModels) {
      add("twist_450deg", m, l, [=] { return twist(m, l, quick); });
      add("spin_720deg_s", m, l, [=] { return spin(m, l, quick); });
      add("compress_60pct_release", m, l, [=] { return compress(m, l, quick, 0.6); });
      add("compress_90pct_release", m, l, [=] { return compress(m, l, quick, 0.9); });
      add("flattened_start", m, l, [=] { return bad_start(m, l, 1.0); });
      add("inverted_start", m, l, [=] { return bad_start(m, l, 1.5); });
      add("nu_0.49", m, l, [=] { return under_gravity(m, block(l), 1e5, 0.49, quick ? 0.1 : 0.3); });
      add("soft_1kPa", m, l, [=] {
        // Let go from rest, undamped, a 1 kPa cube sinks to twice its static strain (0.2) and more where the
        // fixed base corners concentrate it: past StVK's 42 % limit, which the fine mesh resolves.
        return under_gravity(m, cube(l), 1e3, 0.3, quick ? 0.3 : 1.0);
      });
      add("soft_1kPa_let_go", m, l, [=] {
        // The 1 kPa cube collapses under its weight; then gravity is taken off and damping put on, and it
        // comes back to within 1 % of its size of its rest shape.
        Scenario sc = under_gravity(m, cube(l), 1e3, 0.3, 2.5);
        sc.conservative = false;
        sc.change_at = 0.5;
        sc.change_to = sc.spec;
        sc.change_to->effects.gravity = false;
        damp(*sc.change_to, 20.0);
        sc.final_check = [](const Simulation& sim) {
          std::vector<double> x;
          sim.copy_positions(x);
          return check_back_at_rest(sim, diagonal(x) / std::sqrt(3.0), 0.01, "the cube");
        };
        return sc;
      });
      add("stiff_1MPa", m, l, [=] { return under_gravity(m, cube(l), 1e6, 0.3, quick ? 0.05 : 0.2); });
      add("dt_0.9x", m, l, [=] { return time_step(m, l, 0.9, UnstablePolicy::Subdivide); });
      add("dt_1.5x_subdivide", m, l, [=] { return time_step(m, l, 1.5, UnstablePolicy::Subdivide); });
      add("dt_1.5x_refuse", m, l, [=] { return time_step(m, l, 1.5, UnstablePolicy::Refuse); });
      add("dt_3x_subdivide", m, l, [=] { return time_step(m, l, 3.0, UnstablePolicy::Subdivide); });
      add("dt_3x_refuse", m, l, [=] { return time_step(m, l, 3.0, UnstablePolicy::Refuse); });
      add("impact_10m_s", m, l, [=] { return impact(m, l, quick); });
      add("proxy_inside", m, l, [=] { return inside(m, l, quick); });
      add("pinch", m, l, [=] { return pinch(m, l, quick); });
      add("drag_friction", m, l, [=] { return drag(m, l, quick); });
      add("slivers", m, l, [=] { return slivers(m, l, quick); });
      add("random_velocity", m, l, [=, seed = o.seed] { return random_velocity(m, l, seed); });
      add(quick ? "random_input_50k" : "random_input_1M", m, l,
          [=, seed = o.seed] { return random_input(m, l, seed, quick ? 50'000 : 1'000'000); });
      add("ball_3m_s", m, l, [=] { return ball_throw(m, l, quick); });
      // (Not linear elasticity: blocks that bounce off each other turn, and a fold is a half turn, which it
      // does not model.)
      if (m != MaterialModel::Linear) {
        add("stack_drop_20cm", m, l, [=] { return stack_drop(m, l, quick); });
        add("u_fold_self_contact", m, l, [=] { return u_fold(m, l, quick); });
      }
    }
  }
  return cases;
}

CaseOutcome run_stability_case(SuiteOptions options, const std::string& name) {
  options.filter = name;
  for (const StabilityCase& c : stability_cases(options))
    if (c.name == name) return c.run();
  throw std::invalid_argument("stability: no case named '" + name + "'");
}

std::string outcome_json(const CaseOutcome& r) {
  const nlohmann::json j = {
      {"name", r.name},
      {"group", r.group},
      {"material", r.material},
      {"mesh", r.mesh},
      {"expects", to_string(r.expect)},
      {"pass", r.pass},
      {"outcome", r.outcome},
      {"why", r.why},
      {"tets", r.tets},
      {"steps", r.steps},
      {"sim_time_s", r.sim_time},
      {"wall_s", r.wall_s},
      {"size_ratio", r.size_ratio},
      {"size_limit", r.size_limit},
      {"energy_drift", r.energy_drift < 0 ? nlohmann::json() : nlohmann::json(r.energy_drift)},
      {"penetration_mm", r.penetration_mm},
      {"peak_force_N", r.peak_force_N < 0 ? nlohmann::json() : nlohmann::json(r.peak_force_N)},
      {"substeps_max", r.substeps_max},
      {"body_depth_mm", r.body_depth_mm < 0 ? nlohmann::json() : nlohmann::json(r.body_depth_mm)},
      {"body_depth_limit_mm", r.body_depth_limit_mm < 0 ? nlohmann::json() : nlohmann::json(r.body_depth_limit_mm)},
      {"momentum_residual", r.momentum_residual < 0 ? nlohmann::json() : nlohmann::json(r.momentum_residual)}};
  return j.dump();
}

}  // namespace tactile::study
