#include "scene/scene.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <sstream>

#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include "core/bodies.hpp"
#include "core/model_build.hpp"
#include "core/quadratic.hpp"
#include "scene/json_fields.hpp"
#include "scene/scene_mesh.hpp"

namespace tactile {

using scene_json::Fields;
using scene_json::join;
using scene_json::Json;
using scene_json::Origin;

namespace {

namespace fs = std::filesystem;

constexpr double kDegree = std::numbers::pi / 180.0;

std::string format_vec(const Vec3& v) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "[%g, %g, %g]", v.x, v.y, v.z);
  return buf;
}

// Everything parse_one needs besides the JSON: where it came from and the meshes built so far.
struct Context {
  Origin origin;
  std::string scene_dir;
  std::map<std::string, SceneMesh>* mesh_cache;  // by the mesh object's JSON text: variants share meshes
  std::map<std::string, std::shared_ptr<const EmbeddedSurface>>* surface_cache;  // by mesh and surface JSON
};

MaterialSpec read_material(const Json& j, const std::string& path, const Origin& o) {
  const Fields f(j, path, o, {"model", "invertible", "E", "nu", "rho"});
  MaterialSpec m;
  const std::string model =
      scene_json::read_choice(f.at("model"), f.path("model"), o, {"linear", "stvk", "corotational", "neohookean"});
  parse_material_model(model, &m.model);
  if (const Json* inv = f.find("invertible")) {
    if (!inv->is_boolean()) o.fail(f.path("invertible"), "must be true or false, got " + scene_json::describe(*inv));
    // (Linear, corotational and Neo-Hookean take inversion as they are.)
    if (inv->get<bool>()) m.model = make_invertible(m.model);
  }
  m.E = f.positive("E");
  m.nu = f.number("nu");
  if (!(m.nu > -1.0 && m.nu < 0.5))
    o.fail(f.path("nu"), "must lie in (-1, 0.5), got " + scene_json::describe(f.at("nu")) +
                             " (0.5 is incompressible: lambda is infinite and no explicit step is stable)");
  m.rho = f.positive("rho");
  return m;
}

std::vector<MaterialSpec> read_materials(const Fields& root, const Origin& o) {
  const Json* one = root.find("material");
  const Json* many = root.find("materials");
  if (one && many) o.fail(root.path("materials"), "give \"material\" or \"materials\", not both");
  if (!one && !many) o.fail(root.path("material"), "required field missing (give \"material\" or \"materials\")");
  if (one) return {read_material(*one, root.path("material"), o)};
  const Json& arr = scene_json::read_array(*many, root.path("materials"), o, 1);
  std::vector<MaterialSpec> out;
  for (size_t i = 0; i < arr.size(); ++i) out.push_back(read_material(arr[i], join(root.path("materials"), i), o));
  return out;
}

// A box of JSON fields {lo, hi[, tolerance]}, hi >= lo.
void read_box(const Json& j, const std::string& path, const Origin& o, bool with_tolerance, NodeSelector& s) {
  const Fields f = with_tolerance ? Fields(j, path, o, {"lo", "hi", "tolerance"}) : Fields(j, path, o, {"lo", "hi"});
  s.lo = f.vec3("lo");
  s.hi = f.vec3("hi");
  for (int d = 0; d < 3; ++d)
    if (!(s.hi[d] >= s.lo[d])) o.fail(f.path("hi"), "must be >= lo in every axis");
  if (with_tolerance) s.tolerance = f.non_negative_or("tolerance", s.tolerance);
}

// Reads a selector and checks that it picks at least one node.
NodeSelector read_selector(const Json& j, const std::string& path, const Origin& o, const TetMesh& mesh) {
  const Fields f(j, path, o, {"box", "plane", "nodes"});
  const int kinds = int(f.has("box")) + int(f.has("plane")) + int(f.has("nodes"));
  if (kinds != 1) o.fail(path, "needs exactly one of \"box\", \"plane\", \"nodes\"");
  const Aabb aabb = compute_aabb(mesh.X);
  NodeSelector s;
  // Default slack: a millionth of the body's size, for coordinates that went through float (OBJ, STL) or scaling.
  s.tolerance = 1e-6 * glm::length(aabb.size());
  std::string what;
  if (f.has("box")) {
    s.kind = NodeSelector::Kind::Box;
    read_box(f.at("box"), f.path("box"), o, true, s);
    what = "box " + format_vec(s.lo) + " to " + format_vec(s.hi);
  } else if (f.has("plane")) {
    s.kind = NodeSelector::Kind::Plane;
    const Fields p(f.at("plane"), f.path("plane"), o, {"point", "normal", "tolerance"});
    s.point = p.vec3("point");
    s.normal = scene_json::read_direction(p.at("normal"), p.path("normal"), o);
    s.tolerance = p.non_negative_or("tolerance", s.tolerance);
    what = "plane through " + format_vec(s.point) + " normal " + format_vec(s.normal);
  } else {
    s.kind = NodeSelector::Kind::Nodes;
    const Json& ids = scene_json::read_array(f.at("nodes"), f.path("nodes"), o, 1);
    for (size_t i = 0; i < ids.size(); ++i)
      s.nodes.push_back(int32_t(scene_json::read_integer(ids[i], join(f.path("nodes"), i), o, 0, mesh.n_nodes() - 1)));
    what = "node list";
  }
  if (select_nodes(mesh, s).empty()) {
    char tol[32];
    std::snprintf(tol, sizeof tol, "%g", s.tolerance);
    o.fail(path, "selects no node (" + what + ", tolerance " + tol + " m; the mesh spans " + format_vec(aabb.lo) +
                     " to " + format_vec(aabb.hi) + ")");
  }
  return s;
}

MotionProfile read_ramp(const Fields& f, const std::string& amount_key, double unit) {
  MotionProfile p;
  p.kind = MotionProfile::Kind::Ramp;
  p.target = f.number(amount_key) * unit;
  p.duration = f.non_negative("duration");
  p.start = f.non_negative_or("start", 0.0);
  return p;
}

EssentialBc read_boundary(const Json& j, const std::string& path, const Origin& o, const TetMesh& mesh) {
  const Fields f(j, path, o, {"name", "select", "fixed", "rotate", "spin", "translate"});
  EssentialBc bc;
  bc.name = f.string_or("name", "");
  bc.where = read_selector(f.at("select"), f.path("select"), o, mesh);
  const bool moving = f.has("rotate") || f.has("spin") || f.has("translate");
  if (const Json* fixed = f.find("fixed")) {
    if (!fixed->is_boolean() || !fixed->get<bool>())
      o.fail(f.path("fixed"),
             "must be true (leave it out for a moving condition), got " + scene_json::describe(*fixed));
    if (moving) o.fail(f.path("fixed"), "cannot be combined with rotate, spin or translate");
    return bc;
  }
  if (!moving) o.fail(path, "needs \"fixed\": true, or \"rotate\" or \"spin\" and/or \"translate\"");
  if (f.has("rotate") && f.has("spin")) o.fail(f.path("spin"), "give \"rotate\" or \"spin\", not both");
  if (const Json* r = f.find("rotate")) {
    const Fields g(*r, f.path("rotate"), o, {"centre", "axis", "angle_deg", "duration", "start"});
    bc.centre = g.vec3("centre");
    bc.axis = scene_json::read_direction(g.at("axis"), g.path("axis"), o);
    bc.angle = read_ramp(g, "angle_deg", kDegree);
  }
  if (const Json* r = f.find("spin")) {
    const Fields g(*r, f.path("spin"), o, {"centre", "axis", "rate_deg_s", "start", "spin_up"});
    bc.centre = g.vec3("centre");
    bc.axis = scene_json::read_direction(g.at("axis"), g.path("axis"), o);
    MotionProfile p;
    p.kind = MotionProfile::Kind::ConstantRate;
    p.rate = g.number("rate_deg_s") * kDegree;
    p.start = g.non_negative_or("start", 0.0);
    p.duration = g.positive_or("spin_up", 0.1);  // a spin at full rate at once would be an impulse
    bc.angle = p;
  }
  if (const Json* t = f.find("translate")) {
    const Fields g(*t, f.path("translate"), o, {"direction", "distance", "duration", "start"});
    bc.direction = scene_json::read_direction(g.at("direction"), g.path("direction"), o);
    bc.shift = read_ramp(g, "distance", 1.0);
  }
  return bc;
}

NaturalLoad read_load(const Json& j, const std::string& path, const Origin& o, const TetMesh& mesh) {
  const Fields f(j, path, o, {"name", "select", "force", "ramp"});
  NaturalLoad load;
  load.name = f.string_or("name", "");
  load.where = read_selector(f.at("select"), f.path("select"), o, mesh);
  load.force = f.vec3("force");
  if (const Json* r = f.find("ramp")) {
    const Fields g(*r, f.path("ramp"), o, {"duration", "start"});
    MotionProfile p;
    p.kind = MotionProfile::Kind::Ramp;
    p.target = 1.0;
    p.duration = g.non_negative("duration");
    p.start = g.non_negative_or("start", 0.0);
    load.scale = p;
  }
  return load;
}

// An identifier that goes into CSV files and summaries as it is: a proxy,
// hand or device channel name.
std::string read_label(const Json& v, const std::string& path, const Origin& o) {
  const std::string s = scene_json::read_string(v, path, o);
  bool ok = !s.empty() && s.size() <= 64 && s[0] != '.' && s[0] != '-';
  for (char c : s) ok = ok && (std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.');
  if (!ok)
    o.fail(path, "must be 1 to 64 letters, digits, '_', '-' or '.', not starting with '.' or '-', got " +
                     scene_json::describe(v));
  return s;
}

// [w, x, y, z], nonzero; normalised.
Quat read_quaternion(const Json& v, const std::string& path, const Origin& o) {
  if (!v.is_array() || v.size() != 4)
    o.fail(path, "must be a quaternion [w, x, y, z] (4 numbers), got " + scene_json::describe(v));
  double q[4];
  for (size_t i = 0; i < 4; ++i) q[i] = scene_json::read_number(v[i], join(path, i), o);
  const double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(len > 0)) o.fail(path, "must be a nonzero quaternion [w, x, y, z], got [0, 0, 0, 0]");
  return Quat(q[0] / len, q[1] / len, q[2] / len, q[3] / len);
}

// Whether two unit quaternions are one rotation (q and -q are).
bool same_rotation(const Quat& a, const Quat& b) { return std::fabs(glm::dot(a, b)) > 1.0 - 1e-12; }

// {"easing", "keyframes": [{"t", "position", "orientation"}]}. A keyframe
// without an orientation keeps the one before it (the first: `orientation`).
PoseScript read_script(const Json& j, const std::string& path, const Origin& o, const Quat& orientation) {
  const Fields f(j, path, o, {"easing", "keyframes"});
  PoseScript script;
  if (const Json* e = f.find("easing"))
    script.easing = scene_json::read_choice(*e, f.path("easing"), o, {"smooth", "linear"}) == "linear"
                        ? PoseScript::Easing::Linear
                        : PoseScript::Easing::Smooth;
  const Json& keys = scene_json::read_array(f.at("keyframes"), f.path("keyframes"), o, 1);
  Quat previous = orientation;
  for (size_t i = 0; i < keys.size(); ++i) {
    const std::string kpath = join(f.path("keyframes"), i);
    const Fields k(keys[i], kpath, o, {"t", "position", "orientation"});
    PoseScript::Keyframe key;
    key.t = k.non_negative("t");
    if (i > 0 && !(key.t > script.keys.back().t)) {
      char buf[96];
      std::snprintf(buf, sizeof buf, "must be greater than the previous keyframe's (%g s), got %g",
                    script.keys.back().t, key.t);
      o.fail(k.path("t"), buf);
    }
    key.pose.position = k.vec3("position");
    key.pose.orientation =
        k.has("orientation") ? read_quaternion(k.at("orientation"), k.path("orientation"), o) : previous;
    previous = key.pose.orientation;
    script.keys.push_back(key);
  }
  return script;
}

// The pose at t = 0 of a proxy or hand: "position" and "orientation", or,
// with a "script", the script's (which they may repeat but not contradict).
Pose read_start_pose(const Fields& f, const Origin& o, std::optional<PoseScript>& script) {
  Pose pose;
  if (f.has("orientation")) pose.orientation = read_quaternion(f.at("orientation"), f.path("orientation"), o);
  if (!f.has("script")) {
    pose.position = f.vec3("position");
    return pose;
  }
  script = read_script(f.at("script"), f.path("script"), o, pose.orientation);
  const Pose start = script->at(0.0);
  if (f.has("position") && glm::length(f.vec3("position") - start.position) > 1e-9)
    o.fail(f.path("position"),
           "differs from where the script starts, " + format_vec(start.position) + "; leave it out or make them agree");
  if (f.has("orientation") && !same_rotation(pose.orientation, start.orientation))
    o.fail(f.path("orientation"), "differs from the script's orientation at t = 0; leave it out or make them agree");
  return start;
}

// {"stiffness", "damping", "max_force", "angular_stiffness", "angular_damping",
// "max_torque", "mass", "inertia"}: each optional, each > 0 (core/coupling.hpp).
Coupling read_coupling(const Json& j, const std::string& path, const Origin& o) {
  const Fields f(
      j, path, o,
      {"stiffness", "damping", "max_force", "angular_stiffness", "angular_damping", "max_torque", "mass", "inertia"});
  Coupling c;
  const auto get = [&](const char* key, double& out) {
    if (f.has(key)) out = f.positive(key);
  };
  get("stiffness", c.stiffness);
  get("damping", c.damping);
  get("max_force", c.max_force);
  get("angular_stiffness", c.angular_stiffness);
  get("angular_damping", c.angular_damping);
  get("max_torque", c.max_torque);
  get("mass", c.mass);
  get("inertia", c.inertia);
  return c;
}

void read_hands(const Json& j, const Origin& o, Scene& scene) {
  const Json& arr = scene_json::read_array(j, "hands", o, 0);
  for (size_t i = 0; i < arr.size(); ++i) {
    const std::string path = join("hands", i);
    const Fields f(arr[i], path, o, {"name", "device", "position", "orientation", "script", "coupling"});
    HandSpec hand;
    hand.name = read_label(f.at("name"), f.path("name"), o);
    for (const HandSpec& h : scene.spec.hands)
      if (h.name == hand.name) o.fail(f.path("name"), "'" + hand.name + "' names two hands");
    hand.device = read_label(f.at("device"), f.path("device"), o);
    std::optional<PoseScript> script;
    hand.pose = read_start_pose(f, o, script);
    if (f.has("coupling")) hand.coupling = read_coupling(f.at("coupling"), f.path("coupling"), o);
    scene.spec.hands.push_back(hand);
    scene.hand_script.push_back(std::move(script));
  }
}

// Shape fields: what each shape needs, and nothing it does not use.
void read_geometry(const Fields& f, const Origin& o, ProxyGeometry& g) {
  const std::string shape =
      scene_json::read_choice(f.at("shape"), f.path("shape"), o, {"sphere", "capsule", "box", "plane"});
  auto refuse = [&](const char* key, const char* used_by) {
    if (f.has(key)) o.fail(f.path(key), std::string("is for ") + used_by + " only (shape is \"" + shape + "\")");
  };
  if (shape == "sphere") {
    g.shape = ProxyShape::Sphere;
    g.radius = f.positive("radius");
    refuse("half_length", "a capsule");
    refuse("half_extents", "a box");
  } else if (shape == "capsule") {
    g.shape = ProxyShape::Capsule;
    g.radius = f.positive("radius");
    g.half_length = f.positive("half_length");
    refuse("half_extents", "a box");
  } else if (shape == "box") {
    g.shape = ProxyShape::Box;
    g.half_extents = f.vec3("half_extents");
    for (size_t d = 0; d < 3; ++d)
      if (!(g.half_extents[int(d)] > 0))
        o.fail(join(f.path("half_extents"), d),
               "must be a number > 0, got " + scene_json::describe(f.at("half_extents")[d]));
    g.radius = f.non_negative_or("radius", 0.0);
    refuse("half_length", "a capsule");
  } else {
    g.shape = ProxyShape::Plane;
    refuse("radius", "a sphere, capsule or box");
    refuse("half_length", "a capsule");
    refuse("half_extents", "a box");
  }
}

void read_proxies(const Json& j, const Origin& o, Scene& scene) {
  const Json& arr = scene_json::read_array(j, "proxies", o, 0);
  for (size_t i = 0; i < arr.size(); ++i) {
    const std::string path = join("proxies", i);
    const Fields f(arr[i], path, o,
                   {"name", "device", "hand", "shape", "radius", "half_length", "half_extents", "position",
                    "orientation", "friction", "script", "coupling"});
    ProxySpec proxy;
    proxy.name = read_label(f.at("name"), f.path("name"), o);
    for (const ProxySpec& p : scene.spec.proxies)
      if (p.name == proxy.name) o.fail(f.path("name"), "'" + proxy.name + "' names two proxies");
    read_geometry(f, o, proxy.geometry);
    proxy.friction = f.non_negative_or("friction", 0.0);
    if (f.has("hand")) {
      proxy.hand = read_label(f.at("hand"), f.path("hand"), o);
      const auto hand = std::find_if(scene.spec.hands.begin(), scene.spec.hands.end(),
                                     [&](const HandSpec& h) { return h.name == proxy.hand; });
      if (hand == scene.spec.hands.end()) {
        std::string names;
        for (const HandSpec& h : scene.spec.hands) names += (names.empty() ? "'" : ", '") + h.name + "'";
        o.fail(f.path("hand"), "'" + proxy.hand + "' is not among the hands (" +
                                   (names.empty() ? std::string("the scene has none") : "they are " + names) + ")");
      }
      if (f.has("device")) {
        const std::string device = read_label(f.at("device"), f.path("device"), o);
        if (device != hand->device)
          o.fail(f.path("device"), "'" + device + "' differs from the device of hand '" + hand->name + "' ('" +
                                       hand->device + "'); a hand's proxies go to its device (leave this out)");
      }
      if (f.has("script"))
        o.fail(f.path("script"), "a proxy in a hand moves with it; give the script to hand '" + hand->name + "'");
      if (f.has("coupling"))
        o.fail(f.path("coupling"), "a proxy in a hand moves with it; give the coupling to hand '" + hand->name + "'");
      // The core fills the device in from the hand; the spec keeps it empty.
    } else {
      if (!f.has("device"))
        o.fail(f.path("device"),
               "required field missing (the device channel that drives the proxy; or give a \"hand\")");
      proxy.device = read_label(f.at("device"), f.path("device"), o);
    }
    std::optional<PoseScript> script;
    proxy.pose = read_start_pose(f, o, script);
    if (f.has("coupling")) proxy.coupling = read_coupling(f.at("coupling"), f.path("coupling"), o);
    scene.spec.proxies.push_back(proxy);
    scene.proxy_script.push_back(std::move(script));
  }
  for (size_t h = 0; h < scene.spec.hands.size(); ++h) {
    const std::string& name = scene.spec.hands[h].name;
    if (std::none_of(scene.spec.proxies.begin(), scene.spec.proxies.end(),
                     [&](const ProxySpec& p) { return p.hand == name; }))
      o.fail(join("hands", h), "no proxy belongs to hand '" + name + "' (give proxies \"hand\": \"" + name + "\")");
  }
}

Effects read_effects(const Json& j, const Origin& o) {
  const Fields f(j, "effects", o, {"gravity", "damping", "friction", "body_contact", "self_contact"});
  Effects e;
  if (const Json* b = f.find("body_contact")) {
    if (b->is_boolean()) {
      e.body_contact = b->get<bool>();
    } else if (b->is_object()) {
      const Fields g(*b, f.path("body_contact"), o, {"friction", "depth_tolerance"});
      e.body_contact = true;
      e.body_friction = g.non_negative_or("friction", 0.0);
      e.body_depth_tolerance = g.non_negative_or("depth_tolerance", 0.0);
    } else {
      o.fail(f.path("body_contact"),
             "must be true, false or {\"friction\": mu, \"depth_tolerance\": m}, got " + scene_json::describe(*b));
    }
  }
  if (const Json* c = f.find("self_contact")) {
    if (!c->is_boolean()) o.fail(f.path("self_contact"), "must be true or false, got " + scene_json::describe(*c));
    e.self_contact = c->get<bool>();
  }
  if (const Json* fr = f.find("friction")) {
    if (!fr->is_boolean()) o.fail(f.path("friction"), "must be true or false, got " + scene_json::describe(*fr));
    e.friction = fr->get<bool>();
  }
  if (const Json* g = f.find("gravity")) {
    if (g->is_boolean() && !g->get<bool>()) {
      e.gravity = false;
    } else if (g->is_array()) {
      e.gravity = true;
      e.g = scene_json::read_vec3(*g, f.path("gravity"), o);
    } else {
      o.fail(f.path("gravity"), "must be [gx, gy, gz] in m/s^2 or false, got " + scene_json::describe(*g));
    }
  }
  if (const Json* d = f.find("damping")) {
    if (d->is_boolean() && !d->get<bool>()) {
      e.damping = false;
    } else if (d->is_object()) {
      const Fields g(*d, f.path("damping"), o, {"alpha"});
      e.damping = true;
      e.alpha = g.non_negative("alpha");
    } else {
      o.fail(f.path("damping"), "must be {\"alpha\": 1/s} or false, got " + scene_json::describe(*d));
    }
  }
  return e;
}

IntegratorSpec read_integrator(const Json& j, const Origin& o) {
  const Fields f(
      j, "integrator", o,
      {"precision", "dt", "safety", "unstable", "threads", "energy_tolerance", "energy_window", "mass_scaling_dt"});
  IntegratorSpec s;
  if (const Json* p = f.find("precision"))
    s.precision = scene_json::read_choice(*p, f.path("precision"), o, {"float", "double"}) == "float"
                      ? Precision::Float
                      : Precision::Double;
  if (const Json* dt = f.find("dt")) {
    const bool is_auto = dt->is_string() && dt->get<std::string>() == "auto";
    if (!is_auto) {
      if (!dt->is_number() || !(dt->get<double>() > 0) || !std::isfinite(dt->get<double>()))
        o.fail(f.path("dt"), "must be \"auto\" or a number > 0, got " + scene_json::describe(*dt));
      s.dt = dt->get<double>();
    }
  }
  if (f.has("safety")) {
    s.safety = f.positive("safety");
    if (s.safety > 1) o.fail(f.path("safety"), "must lie in (0, 1], got " + scene_json::describe(f.at("safety")));
  }
  if (const Json* u = f.find("unstable"))
    s.unstable = scene_json::read_choice(*u, f.path("unstable"), o, {"subdivide", "refuse"}) == "refuse"
                     ? UnstablePolicy::Refuse
                     : UnstablePolicy::Subdivide;
  s.threads = int32_t(f.integer_or("threads", 1, 256, 1));
  s.energy_tolerance = f.positive_or("energy_tolerance", s.energy_tolerance);
  s.energy_window = f.positive_or("energy_window", s.energy_window);
  s.mass_scaling_dt = f.positive_or("mass_scaling_dt", 0.0);
  return s;
}

// Whether some tet has nodes on both sides of the plane (d >= 0 and d < 0).
bool plane_cuts_mesh(const TetMesh& mesh, const Vec3& point, const Vec3& normal) {
  for (const Tet& t : mesh.tets) {
    int above = 0;
    for (int32_t i : t) above += glm::dot(mesh.X[size_t(i)] - point, normal) >= 0 ? 1 : 0;
    if (above > 0 && above < 4) return true;
  }
  return false;
}

// What the live server's viewers are shown whatever they ask: "fields", per-vertex
// fields every state frame carries (core/fields.hpp's ViewField names).
void read_view(const Json& j, const Origin& o, Scene& scene) {
  const Fields f(j, "view", o, {"fields"});
  if (const Json* v = f.find("fields")) {
    const Json& arr = scene_json::read_array(*v, f.path("fields"), o, 0);
    for (size_t i = 0; i < arr.size(); ++i) {
      const std::string path = join(f.path("fields"), i);
      const std::string name = scene_json::read_string(arr[i], path, o);
      ViewField field;
      if (!parse_view_field(name, &field)) o.fail(path, "no field '" + name + "' (known: " + view_field_names() + ")");
      if (scene.view_fields & view_field_bit(field)) o.fail(path, "'" + name + "' is asked for twice");
      scene.view_fields |= view_field_bit(field);
    }
  }
}

// Tracked points of body `body`, whose nodes start at `first` (its own mesh: `mesh`).
void read_track(const Json& j, const std::string& at, const Origin& o, const TetMesh& mesh, int32_t body, int32_t first,
                Scene& scene) {
  const Json& arr = scene_json::read_array(j, at, o, 0);
  for (size_t i = 0; i < arr.size(); ++i) {
    const std::string path = join(at, i);
    const Fields g(arr[i], path, o, {"name", "point"});
    TrackedPoint p;
    p.name = scene_json::read_name(g.at("name"), g.path("name"), o);
    for (const TrackedPoint& q : scene.track)
      if (q.name == p.name) o.fail(g.path("name"), "'" + p.name + "' is tracked twice");
    p.point = g.vec3("point");
    double best = std::numeric_limits<double>::infinity();
    for (int32_t k = 0; k < mesh.n_nodes(); ++k) {
      const double d = glm::length(mesh.X[size_t(k)] - p.point);
      if (d < best) best = d, p.node = k;
    }
    p.X = mesh.X[size_t(p.node)];
    p.node += first;
    p.body = body;
    scene.track.push_back(p);
  }
}

void read_run(const Json& j, const Origin& o, const TetMesh& mesh, Scene& scene) {
  const Fields f(j, "run", o, {"duration", "frame_rate", "vtu_every", "vtu_fields", "track", "sections"});
  RunSettings& r = scene.run;
  r.duration = f.positive("duration");
  r.frame_rate = f.positive_or("frame_rate", r.frame_rate);
  if (r.duration * r.frame_rate > 1e6)
    o.fail(f.path("frame_rate"),
           "asks for " + std::to_string(std::llround(r.duration * r.frame_rate)) + " frames; the limit is 1000000");
  r.vtu_every = int32_t(f.integer_or("vtu_every", 1, std::numeric_limits<int32_t>::max(), 1));
  if (const Json* v = f.find("vtu_fields")) {
    const Json& arr = scene_json::read_array(*v, f.path("vtu_fields"), o, 0);
    std::vector<std::string> seen;
    for (size_t i = 0; i < arr.size(); ++i) {
      const std::string path = join(f.path("vtu_fields"), i);
      const std::string name = scene_json::read_choice(
          arr[i], path, o, {"cauchy_stress", "green_strain", "von_mises", "principal_stretches", "contact_force"});
      if (std::find(seen.begin(), seen.end(), name) != seen.end()) o.fail(path, "'" + name + "' is asked for twice");
      seen.push_back(name);
      if (name == "cauchy_stress") r.vtu_cells.cauchy_stress = true;
      if (name == "green_strain") r.vtu_cells.green_strain = true;
      if (name == "von_mises") r.vtu_cells.von_mises = true;
      if (name == "principal_stretches") r.vtu_cells.principal_stretches = true;
      if (name == "contact_force") r.vtu_contact_force = true;
    }
  }
  if (const Json* t = f.find("track")) {
    if (!scene.spec.bodies.empty())
      o.fail(f.path("track"), "in a scene of \"bodies\", each body tracks its own points (bodies[i].track)");
    read_track(*t, f.path("track"), o, mesh, 0, 0, scene);
  }
  if (const Json* s = f.find("sections")) {
    const Json& arr = scene_json::read_array(*s, f.path("sections"), o, 0);
    for (size_t i = 0; i < arr.size(); ++i) {
      const std::string path = join(f.path("sections"), i);
      const Fields g(arr[i], path, o, {"name", "point", "normal"});
      SectionPlane p;
      p.name = scene_json::read_name(g.at("name"), g.path("name"), o);
      for (const SectionPlane& q : r.sections)
        if (q.name == p.name) o.fail(g.path("name"), "'" + p.name + "' is named twice");
      p.point = g.vec3("point");
      p.normal = scene_json::read_direction(g.at("normal"), g.path("normal"), o);
      if (!plane_cuts_mesh(mesh, p.point, p.normal)) o.fail(path, "the plane cuts no tet of the mesh");
      r.sections.push_back(p);
    }
  }
}

// Region ids by tet centroid: later entries win over earlier ones and over the mesh's own ids.
void apply_regions(const Json& j, const std::string& at, const Origin& o, size_t n_materials, TetMesh& mesh) {
  const Json& arr = scene_json::read_array(j, at, o, 1);
  if (mesh.region.empty()) mesh.region.assign(mesh.tets.size(), 0);
  for (size_t i = 0; i < arr.size(); ++i) {
    const std::string path = join(at, i);
    const Fields f(arr[i], path, o, {"box", "material"});
    NodeSelector box;
    read_box(f.at("box"), f.path("box"), o, false, box);
    const auto material = int32_t(f.integer("material", 0, int64_t(n_materials) - 1));
    size_t hits = 0;
    for (size_t e = 0; e < mesh.tets.size(); ++e) {
      const Tet& t = mesh.tets[e];
      const Vec3 c = 0.25 * (mesh.X[size_t(t[0])] + mesh.X[size_t(t[1])] + mesh.X[size_t(t[2])] + mesh.X[size_t(t[3])]);
      if (glm::all(glm::greaterThanEqual(c, box.lo)) && glm::all(glm::lessThanEqual(c, box.hi))) {
        mesh.region[e] = material;
        ++hits;
      }
    }
    if (hits == 0) o.fail(f.path("box"), "contains no tet centroid");
  }
}

Json merge(Json base, const Json& patch) {
  if (!base.is_object() || !patch.is_object()) return patch;
  for (const auto& item : patch.items())
    base[item.key()] = merge(base.contains(item.key()) ? base[item.key()] : Json(), item.value());
  return base;
}

// A variant's mesh of another kind (a file for a primitive, another primitive) replaces the scene's;
// one that names no kind, or the same, amends it.
bool same_mesh_kind(const Json& base, const Json& patch) {
  if (!base.is_object() || !patch.is_object()) return false;
  if (patch.contains("file")) return base.contains("file");
  if (patch.contains("primitive")) return base.contains("primitive") && base["primitive"] == patch["primitive"];
  return true;
}

// A body's own fields (at the top of a one-body scene, or one of "bodies"),
// read against its own mesh: selectors and node ids in its own numbering.
// `quality` (one body): the mesh's, as built.
BodyParts read_body(const Fields& root, const Context& ctx, MeshQuality* quality) {
  const Origin& o = ctx.origin;
  BodyParts body;
  // Mesh first: selectors and tracked points are checked against it. The
  // element order: linear tets as meshed, or quadratic ones, each edge of
  // the mesh given a node (core/quadratic.hpp), the selectors then picking
  // edge nodes as corners.
  const bool quadratic =
      root.has("element") && scene_json::read_choice(root.at("element"), root.path("element"), o, {"p1", "p2"}) == "p2";
  const std::string mesh_key = root.at("mesh").dump() + (quadratic ? "\np2" : "");
  auto cached = ctx.mesh_cache->find(mesh_key);
  if (cached == ctx.mesh_cache->end()) {
    SceneMesh built = build_scene_mesh(root.at("mesh"), root.path("mesh"), o, ctx.scene_dir);
    if (built.mesh.quadratic() && !quadratic)
      o.fail(root.path("element"), "the mesh file's tets are quadratic (10 nodes each): set \"element\": \"p2\"");
    if (quadratic && !built.mesh.quadratic()) built.mesh = make_quadratic_mesh(built.mesh);
    cached = ctx.mesh_cache->emplace(mesh_key, std::move(built)).first;
  }
  body.mesh = cached->second.mesh;
  if (quality) *quality = cached->second.quality;
  TetMesh& mesh = body.mesh;
  if (const Json* s = root.find("surface")) {
    // Bound once per mesh and surface: variants that share both share the binding.
    const std::string key = mesh_key + "\n" + s->dump();
    auto bound = ctx.surface_cache->find(key);
    if (bound == ctx.surface_cache->end())
      bound = ctx.surface_cache->emplace(key, build_embedded_surface(*s, root.path("surface"), o, ctx.scene_dir, mesh))
                  .first;
    body.surface = bound->second;
  }

  body.materials = read_materials(root, o);
  if (const Json* r = root.find("regions")) apply_regions(*r, root.path("regions"), o, body.materials.size(), mesh);
  for (int32_t e = 0; e < mesh.n_tets(); ++e) {
    const int32_t r = mesh.region_of(e);
    if (r < 0 || size_t(r) >= body.materials.size())
      o.fail(root.has("regions") ? root.path("regions") : root.path("mesh"),
             "tet " + std::to_string(e) + " is in region " + std::to_string(r) + " but there " +
                 (body.materials.size() == 1 ? "is 1 material"
                                             : "are " + std::to_string(body.materials.size()) + " materials") +
                 " (indices from 0); give more \"materials\" or assign \"regions\"");
  }

  std::vector<int32_t> held_by(size_t(mesh.n_nodes()), -1);
  if (const Json* b = root.find("boundary")) {
    const Json& arr = scene_json::read_array(*b, root.path("boundary"), o, 0);
    for (size_t i = 0; i < arr.size(); ++i) {
      const std::string at = join(root.path("boundary"), i);
      EssentialBc bc = read_boundary(arr[i], at, o, mesh);
      for (int32_t n : select_nodes(mesh, bc.where)) {
        if (held_by[size_t(n)] >= 0)
          o.fail(join(at, "select"), "node " + std::to_string(n) + " is also held by " +
                                         join(root.path("boundary"), size_t(held_by[size_t(n)])) +
                                         "; a node may follow one essential condition only");
        held_by[size_t(n)] = int32_t(i);
      }
      body.essential.push_back(std::move(bc));
    }
  }
  if (const Json* l = root.find("loads")) {
    const Json& arr = scene_json::read_array(*l, root.path("loads"), o, 0);
    for (size_t i = 0; i < arr.size(); ++i)
      body.loads.push_back(read_load(arr[i], join(root.path("loads"), i), o, mesh));
  }
  return body;
}

Scene parse_one(const Json& j, const std::string& path, const Context& ctx) {
  const Origin& o = ctx.origin;
  const Fields root(
      j, "", o,
      {"$schema", "name", "description", "mesh", "element", "surface", "material", "materials", "regions", "boundary",
       "loads", "bodies", "proxies", "hands", "effects", "integrator", "run", "view", "variants"});
  Scene scene;
  scene.path = path;
  if (const Json* s = root.find("$schema")) scene_json::read_string(*s, "$schema", o);
  if (root.has("name")) {
    scene.name = scene_json::read_name(root.at("name"), "name", o);
  } else {  // the file's stem, made folder-safe
    scene.name = fs::path(path).stem().string();
    for (char& c : scene.name)
      if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.') c = '_';
    if (scene.name.empty()) scene.name = "scene";
  }
  scene.description = root.string_or("description", "");

  if (const Json* b = root.find("bodies")) {
    for (const char* key : {"mesh", "element", "surface", "material", "materials", "regions", "boundary", "loads"})
      if (root.has(key)) o.fail(key, "a scene of \"bodies\" gives each body its own; move it into bodies[i]");
    const Json& arr = scene_json::read_array(*b, "bodies", o, 1);
    std::vector<BodyParts> parts;
    std::vector<TetMesh> meshes;
    for (size_t i = 0; i < arr.size(); ++i) {
      const Fields f(
          arr[i], join("bodies", i), o,
          {"name", "mesh", "element", "surface", "material", "materials", "regions", "boundary", "loads", "track"});
      BodyParts body = read_body(f, ctx, nullptr);
      body.name = scene_json::read_name(f.at("name"), f.path("name"), o);
      for (size_t k = 0; k < parts.size(); ++k)
        if (parts[k].name == body.name) o.fail(f.path("name"), "'" + body.name + "' names two bodies");
      if (i > 0 && body.mesh.quadratic() != parts[0].mesh.quadratic())
        o.fail(f.path("element"), "must be bodies[0]'s (\"" + std::string(parts[0].mesh.quadratic() ? "p2" : "p1") +
                                      "\"): the bodies of a scene share one element order");
      parts.push_back(std::move(body));
    }
    for (const BodyParts& body : parts) meshes.push_back(body.mesh);
    try {
      add_bodies(scene.spec, std::move(parts));
      check_bodies(scene.spec);
    } catch (const ModelError& e) {
      o.fail("bodies", e.what());
    }
    for (size_t i = 0; i < arr.size(); ++i) {
      const Fields f(
          arr[i], join("bodies", i), o,
          {"name", "mesh", "element", "surface", "material", "materials", "regions", "boundary", "loads", "track"});
      if (const Json* t = f.find("track"))
        read_track(*t, f.path("track"), o, meshes[i], int32_t(i), scene.spec.bodies[i].node_begin, scene);
    }
    scene.quality = compute_quality(scene.spec.mesh);
  } else {
    // One body: its fields at the top, read as they always were.
    BodyParts body = read_body(root, ctx, &scene.quality);
    scene.spec.mesh = std::move(body.mesh);
    scene.spec.surface = std::move(body.surface);
    scene.spec.materials = std::move(body.materials);
    scene.spec.essential = std::move(body.essential);
    scene.spec.loads = std::move(body.loads);
  }
  const TetMesh& mesh = scene.spec.mesh;
  if (const Json* h = root.find("hands")) read_hands(*h, o, scene);
  read_proxies(root.has("proxies") ? root.at("proxies") : Json::array(), o, scene);  // checks that each hand has one
  if (const Json* e = root.find("effects")) scene.spec.effects = read_effects(*e, o);
  if (scene.spec.effects.body_contact && scene.spec.bodies.size() < 2)
    o.fail("effects.body_contact", "the scene has one body; contact between bodies needs \"bodies\" of two or more");
  if (const Json* g = root.find("integrator")) scene.spec.integrator = read_integrator(*g, o);
  read_run(root.at("run"), o, mesh, scene);
  if (const Json* v = root.find("view")) read_view(*v, o, scene);
  return scene;
}

}  // namespace

Pose PoseScript::at(double t) const {
  if (keys.empty()) return Pose{};
  if (t <= keys.front().t) return keys.front().pose;
  if (t >= keys.back().t) return keys.back().pose;
  // The segment [keys[k - 1].t, keys[k].t) holding t.
  const auto next = std::upper_bound(keys.begin(), keys.end(), t, [](double x, const Keyframe& k) { return x < k.t; });
  const Keyframe& a = *(next - 1);
  const Keyframe& b = *next;
  const double tau = (t - a.t) / (b.t - a.t);
  // Cycloidal: s' = 1 - cos(2 pi tau) vanishes at both ends, as the boundary ramps do (core/spec.hpp).
  const double s =
      easing == Easing::Linear ? tau : tau - std::sin(2.0 * std::numbers::pi * tau) / (2.0 * std::numbers::pi);
  Pose p;
  p.position = a.pose.position + s * (b.pose.position - a.pose.position);
  Quat q = b.pose.orientation;
  if (glm::dot(a.pose.orientation, q) < 0) q = -q;  // the shorter arc
  p.orientation = glm::normalize(glm::slerp(a.pose.orientation, q, s));
  return p;
}

ProxyMotion PoseScript::motion(double t0, double t1) const {
  ProxyMotion m;
  m.t0 = t0;
  m.t1 = t1;
  m.from = at(t0);
  m.to = at(t1);
  return m;
}

namespace {
std::vector<Scene> parse_variants(const Json& j, const std::string& path);
}  // namespace

std::vector<Scene> parse_scene(const Json& j, const std::string& path) {
  std::vector<Scene> out = parse_variants(j, path);
  const std::string source = j.dump();
  for (Scene& s : out) s.source = source;
  return out;
}

namespace {

std::vector<Scene> parse_variants(const Json& j, const std::string& path) {
  std::map<std::string, SceneMesh> meshes;
  std::map<std::string, std::shared_ptr<const EmbeddedSurface>> surfaces;
  Context ctx{Origin{path, ""}, fs::path(path).parent_path().string(), &meshes, &surfaces};
  if (ctx.scene_dir.empty()) ctx.scene_dir = ".";
  if (!j.is_object()) ctx.origin.fail("", "a scene must be a JSON object, got " + scene_json::describe(j));
  const auto variants = j.find("variants");
  if (variants == j.end()) return {parse_one(j, path, ctx)};
  // The scene itself names its material, so that variants amend rather than supply it (as the schema says).
  if (!j.contains("material") && !j.contains("materials") && !j.contains("bodies"))
    ctx.origin.fail("material", "required field missing (give \"material\" or \"materials\")");

  const Json& arr = scene_json::read_array(*variants, "variants", ctx.origin, 1);
  // Check every variant's own fields before merging, so errors name where they are.
  std::vector<std::string> names;
  for (size_t i = 0; i < arr.size(); ++i) {
    const std::string vpath = join("variants", i);
    const Fields f(arr[i], vpath, ctx.origin,
                   {"name", "description", "material", "materials", "effects", "integrator", "mesh"});
    const std::string name = scene_json::read_name(f.at("name"), f.path("name"), ctx.origin);
    if (std::find(names.begin(), names.end(), name) != names.end())
      ctx.origin.fail(f.path("name"), "'" + name + "' names two variants");
    if (f.has("material") && f.has("materials"))
      ctx.origin.fail(f.path("materials"), "give \"material\" or \"materials\", not both");
    if (f.has("description")) scene_json::read_string(f.at("description"), f.path("description"), ctx.origin);
    if (j.contains("bodies"))
      for (const char* key : {"material", "materials", "mesh"})
        if (f.has(key))
          ctx.origin.fail(f.path(key),
                          "a scene of \"bodies\" has no top-level " + std::string(key) + " for a variant to change");
    names.push_back(name);
  }
  std::vector<Scene> out;
  for (size_t i = 0; i < arr.size(); ++i) {
    const Json& v = arr[i];
    Json merged = j;
    merged.erase("variants");
    if (v.contains("material")) {
      merged.erase("materials");
      merged["material"] = merge(merged.contains("material") ? merged["material"] : Json(), v["material"]);
    }
    if (v.contains("materials")) {
      merged.erase("material");
      merged["materials"] = v["materials"];
    }
    for (const char* key : {"effects", "integrator"})
      if (v.contains(key)) merged[key] = merge(merged.contains(key) ? merged[key] : Json(), v[key]);
    if (v.contains("mesh"))
      merged["mesh"] = same_mesh_kind(merged["mesh"], v["mesh"]) ? merge(merged["mesh"], v["mesh"]) : v["mesh"];
    Context vctx = ctx;
    vctx.origin.variant = names[i];
    Scene s = parse_one(merged, path, vctx);
    s.variant = names[i];
    if (v.contains("description")) s.description = v["description"].get<std::string>();
    out.push_back(std::move(s));
  }
  return out;
}

namespace {

// Builds the document as nlohmann's own parser does, keeping the path to
// each value ("material.E", "proxies[0].radius"), so that what the parser
// refuses (a number past a double's range, a stray token) is named by its
// field as the schema's errors are.
class NamedDom {
 public:
  explicit NamedDom(Json& root) : dom_(root, false) {}
  bool null() { return enter() && dom_.null(); }
  bool boolean(bool v) { return enter() && dom_.boolean(v); }
  bool number_integer(Json::number_integer_t v) { return enter() && dom_.number_integer(v); }
  bool number_unsigned(Json::number_unsigned_t v) { return enter() && dom_.number_unsigned(v); }
  bool number_float(Json::number_float_t v, const Json::string_t& s) { return enter() && dom_.number_float(v, s); }
  bool string(Json::string_t& v) { return enter() && dom_.string(v); }
  bool binary(Json::binary_t& v) { return enter() && dom_.binary(v); }
  bool start_object(std::size_t n) {
    enter();
    levels_.push_back({false, -1, ""});
    return dom_.start_object(n);
  }
  bool key(Json::string_t& k) {
    levels_.back().key = k;
    return dom_.key(k);
  }
  bool end_object() {
    levels_.pop_back();
    return dom_.end_object();
  }
  bool start_array(std::size_t n) {
    enter();
    levels_.push_back({true, -1, ""});
    return dom_.start_array(n);
  }
  bool end_array() {
    levels_.pop_back();
    return dom_.end_array();
  }
  bool parse_error(std::size_t position, const std::string& token, const nlohmann::detail::exception& e) {
    enter();  // (in a list, the element that failed is the next one)
    position_ = position;
    token_ = token;
    error_ = e.what();
    error_id_ = e.id;
    return dom_.parse_error(position, token, e);
  }

  // The field being read ("" at the top).
  std::string field() const {
    std::string out;
    for (const Level& l : levels_) {
      if (l.array) {
        out += '[';
        out += std::to_string(std::max(0, l.index));
        out += ']';
      } else if (!l.key.empty()) {
        if (!out.empty()) out += '.';
        out += l.key;
      }
    }
    return out;
  }
  std::size_t position_ = 0;
  std::string token_, error_;
  int error_id_ = 0;

 private:
  struct Level {
    bool array;
    int index;        // arrays: the element being read
    std::string key;  // objects: the key being read
  };
  bool enter() {
    if (!levels_.empty() && levels_.back().array) ++levels_.back().index;
    return true;
  }
  nlohmann::detail::json_sax_dom_parser<Json> dom_;
  std::vector<Level> levels_;
};

}  // namespace

}  // namespace

std::vector<Scene> load_scene(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path + ": cannot open scene file");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();
  Json j;
  NamedDom dom(j);
  if (!Json::sax_parse(text, &dom)) {
    // Where: line and column of the byte the parser stopped at (1-based).
    const std::size_t at = std::min(dom.position_, text.size());
    const std::size_t line = 1 + size_t(std::count(text.begin(), text.begin() + long(at), '\n'));
    const std::size_t line_start = text.rfind('\n', at == 0 ? 0 : at - 1);
    const std::size_t column = at - (line_start == std::string::npos || at == 0 ? 0 : line_start + 1);
    const std::string field = dom.field();
    std::string what = dom.error_;
    if (const size_t cut = what.find("] "); cut != std::string::npos) what = what.substr(cut + 2);
    if (dom.error_id_ == 406)  // a number past a double's range (nlohmann's out_of_range.406)
      what = dom.token_ + " is out of range for a number (a double holds magnitudes up to 1.8e308)";
    throw SceneError(path + ":" + std::to_string(line) + ":" + std::to_string(column) + ": not valid JSON" +
                     (field.empty() ? "" : " at " + field) + ": " + what);
  }
  return parse_scene(j, path);
}

Scene pick_variant(std::vector<Scene> scenes, const std::string& variant, const std::string& path) {
  std::string names;
  for (Scene& s : scenes) {
    if (s.variant == variant) return std::move(s);
    names += (names.empty() ? "" : ", ") + (s.variant.empty() ? std::string("(none)") : s.variant);
  }
  throw SceneError(path + ": no variant '" + variant + "' (the scene has: " + names + ")");
}

}  // namespace tactile
