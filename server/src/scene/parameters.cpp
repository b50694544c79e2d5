#include "scene/parameters.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string_view>

#include "scene/scene.hpp"

namespace tactile {

namespace {

// Ranges: what the core can run (nu below 0.5, where lambda diverges; E and
// rho positive), kept finite so that a user interface can draw a slider.
struct Range {
  double min, max;
  const char* unit;
};
constexpr Range kE{1.0, 1e12, "Pa"};
constexpr Range kNu{-0.99, 0.499, "-"};
constexpr Range kRho{1.0, 1e5, "kg/m^3"};
constexpr Range kAlpha{0.0, 1e4, "1/s"};
constexpr Range kG{-100.0, 100.0, "m/s^2"};
constexpr Range kMu{0.0, 10.0, "-"};
constexpr Range kSwitch{0.0, 1.0, "on/off"};

std::string format(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

[[noreturn]] void fail(const std::string& name, const std::string& what) { throw SceneError(name + ": " + what); }

void check(const std::string& name, double value, const Range& r) {
  if (!std::isfinite(value) || value < r.min || value > r.max)
    fail(name, "must be in [" + format(r.min) + ", " + format(r.max) + "] " + r.unit + ", got " + format(value));
}

bool on(const std::string& name, double value) {
  if (value != 0 && value != 1) fail(name, "must be 1 (on) or 0 (off), got " + format(value));
  return value == 1;
}

// "prefix[i].rest" -> i and rest; false when `name` has another shape.
bool indexed(std::string_view name, std::string_view prefix, size_t* index, std::string_view* rest) {
  if (name.substr(0, prefix.size()) != prefix || name.size() <= prefix.size() || name[prefix.size()] != '[')
    return false;
  const size_t close = name.find("].", prefix.size());
  if (close == std::string_view::npos) return false;
  const std::string_view digits = name.substr(prefix.size() + 1, close - prefix.size() - 1);
  if (digits.empty() || digits.size() > 6) return false;
  size_t i = 0;
  for (char c : digits) {
    if (c < '0' || c > '9') return false;
    i = 10 * i + size_t(c - '0');
  }
  *index = i;
  *rest = name.substr(close + 2);
  return true;
}

void set_material(MaterialSpec& m, const std::string& name, std::string_view field, double value) {
  if (field == "E") {
    check(name, value, kE);
    m.E = value;
  } else if (field == "nu") {
    check(name, value, kNu);
    m.nu = value;
  } else if (field == "rho") {
    check(name, value, kRho);
    m.rho = value;
  } else {
    fail(name, "a material has E, nu and rho");
  }
}

std::string known(const ModelSpec& spec) {
  std::string s;
  for (const Parameter& p : list_parameters(spec)) s += (s.empty() ? "" : ", ") + p.name;
  return s;
}

}  // namespace

std::vector<Parameter> list_parameters(const ModelSpec& spec) {
  std::vector<Parameter> out;
  auto add = [&](std::string name, double value, const Range& r) {
    out.push_back({std::move(name), value, r.min, r.max, r.unit});
  };
  const auto add_material = [&](const std::string& p, const MaterialSpec& m) {
    add(p + "E", m.E, kE);
    add(p + "nu", m.nu, kNu);
    add(p + "rho", m.rho, kRho);
  };
  if (spec.bodies.size() > 1) {
    for (size_t b = 0; b < spec.bodies.size(); ++b) {
      const BodySpec& body = spec.bodies[b];
      const std::string p = "bodies[" + std::to_string(b) + "].";
      if (body.material_end - body.material_begin == 1) {
        add_material(p + "material.", spec.materials[size_t(body.material_begin)]);
      } else {
        for (int32_t i = body.material_begin; i < body.material_end; ++i)
          add_material(p + "materials[" + std::to_string(i - body.material_begin) + "].", spec.materials[size_t(i)]);
      }
    }
  } else if (spec.materials.size() == 1) {
    add("material.E", spec.materials[0].E, kE);
    add("material.nu", spec.materials[0].nu, kNu);
    add("material.rho", spec.materials[0].rho, kRho);
  } else {
    for (size_t i = 0; i < spec.materials.size(); ++i) {
      const std::string p = "materials[" + std::to_string(i) + "].";
      add(p + "E", spec.materials[i].E, kE);
      add(p + "nu", spec.materials[i].nu, kNu);
      add(p + "rho", spec.materials[i].rho, kRho);
    }
  }
  const Effects& e = spec.effects;
  add("effects.damping", e.damping ? 1 : 0, kSwitch);
  add("damping.alpha", e.alpha, kAlpha);
  add("effects.gravity", e.gravity ? 1 : 0, kSwitch);
  add("gravity.x", e.g.x, kG);
  add("gravity.y", e.g.y, kG);
  add("gravity.z", e.g.z, kG);
  if (!spec.proxies.empty()) {
    add("effects.friction", e.friction ? 1 : 0, kSwitch);
    for (size_t i = 0; i < spec.proxies.size(); ++i)
      add("proxies[" + std::to_string(i) + "].friction", spec.proxies[i].friction, kMu);
  }
  return out;
}

void apply_parameter(ModelSpec& spec, const std::string& name, double value) {
  Effects& e = spec.effects;
  size_t i = 0;
  std::string_view rest;
  if (name.rfind("material.", 0) == 0) {
    if (spec.materials.empty()) fail(name, "this scene has no material");
    for (MaterialSpec& m : spec.materials) set_material(m, name, std::string_view(name).substr(9), value);
  } else if (indexed(name, "bodies", &i, &rest)) {
    if (i >= spec.bodies.size())
      fail(name, "no body " + std::to_string(i) + " (this scene has " +
                     std::to_string(std::max<size_t>(spec.bodies.size(), 1)) + ")");
    const BodySpec& body = spec.bodies[i];
    size_t k = 0;
    std::string_view field;
    if (rest.substr(0, 9) == "material.") {
      for (int32_t m = body.material_begin; m < body.material_end; ++m)
        set_material(spec.materials[size_t(m)], name, rest.substr(9), value);
    } else if (indexed(rest, "materials", &k, &field)) {
      if (k >= size_t(body.material_end - body.material_begin))
        fail(name, "no material " + std::to_string(k) + " in body " + std::to_string(i) + " (it has " +
                       std::to_string(body.material_end - body.material_begin) + ")");
      set_material(spec.materials[size_t(body.material_begin) + k], name, field, value);
    } else {
      fail(name, "a body's parameters are material.E, .nu, .rho and materials[i].E, .nu, .rho");
    }
  } else if (indexed(name, "materials", &i, &rest)) {
    if (i >= spec.materials.size())
      fail(name,
           "no material " + std::to_string(i) + " (this scene has " + std::to_string(spec.materials.size()) + ")");
    set_material(spec.materials[i], name, rest, value);
  } else if (name == "damping.alpha") {
    check(name, value, kAlpha);
    e.alpha = value;
    e.damping = value > 0;
  } else if (name == "gravity.x" || name == "gravity.y" || name == "gravity.z") {
    check(name, value, kG);
    e.g[name.back() - 'x'] = value;
    e.gravity = e.g != Vec3(0.0);
  } else if (name == "friction.mu") {
    if (spec.proxies.empty()) fail(name, "this scene has no proxies");
    check(name, value, kMu);
    for (ProxySpec& p : spec.proxies) p.friction = value;
    e.friction = value > 0;
  } else if (indexed(name, "proxies", &i, &rest)) {
    if (i >= spec.proxies.size())
      fail(name, "no proxy " + std::to_string(i) + " (this scene has " + std::to_string(spec.proxies.size()) + ")");
    if (rest != "friction") fail(name, "a proxy's parameter is friction");
    check(name, value, kMu);
    spec.proxies[i].friction = value;
    e.friction = false;
    for (const ProxySpec& p : spec.proxies) e.friction = e.friction || p.friction > 0;
  } else if (name == "effects.damping") {
    e.damping = on(name, value);
    if (e.damping && !(e.alpha > 0)) fail(name, "set damping.alpha > 0 to turn damping on");
  } else if (name == "effects.gravity") {
    e.gravity = on(name, value);
    if (e.gravity && e.g == Vec3(0.0)) fail(name, "set gravity.x, .y or .z to turn gravity on");
  } else if (name == "effects.friction") {
    if (spec.proxies.empty()) fail(name, "this scene has no proxies");
    e.friction = on(name, value);
  } else {
    fail(name, "no such parameter; this scene has " + known(spec));
  }
}

}  // namespace tactile
