// Parameters a controller sets by name: each lands in the spec field it
// names, turns its effect on or off, and a bad name or value is refused with
// a message naming it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "core/bodies.hpp"
#include "mesh/primitives.hpp"
#include "scene/parameters.hpp"
#include "scene/scene.hpp"

namespace tactile {
namespace {

ModelSpec two_materials_one_proxy() {
  ModelSpec s;
  s.materials = {MaterialSpec{MaterialModel::StVK, 1e5, 0.3, 1000},
                 MaterialSpec{MaterialModel::NeoHookean, 2e5, 0.4, 900}};
  ProxySpec p;
  p.name = "tip";
  p.device = "stylus";
  s.proxies = {p};
  return s;
}

void expect_refused(ModelSpec spec, const std::string& name, double value, const std::string& part) {
  try {
    apply_parameter(spec, name, value);
    FAIL() << name << " = " << value << " was accepted";
  } catch (const SceneError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find(name), std::string::npos) << m;
    EXPECT_NE(m.find(part), std::string::npos) << m;
  }
}

TEST(Parameters, MaterialFieldsLandWhereTheyAreNamed) {
  ModelSpec s = two_materials_one_proxy();
  apply_parameter(s, "materials[1].E", 3e5);
  apply_parameter(s, "materials[0].nu", 0.45);
  apply_parameter(s, "materials[1].rho", 1100);
  EXPECT_EQ(s.materials[0].E, 1e5);
  EXPECT_EQ(s.materials[1].E, 3e5);
  EXPECT_EQ(s.materials[0].nu, 0.45);
  EXPECT_EQ(s.materials[1].nu, 0.4);
  EXPECT_EQ(s.materials[1].rho, 1100);
  apply_parameter(s, "material.E", 7e4);  // every material
  EXPECT_EQ(s.materials[0].E, 7e4);
  EXPECT_EQ(s.materials[1].E, 7e4);
}

TEST(Parameters, EffectsFollowTheValuesThatNeedThem) {
  ModelSpec s = two_materials_one_proxy();
  EXPECT_FALSE(s.effects.damping);
  apply_parameter(s, "damping.alpha", 5);
  EXPECT_TRUE(s.effects.damping);
  EXPECT_EQ(s.effects.alpha, 5);
  apply_parameter(s, "effects.damping", 0);
  EXPECT_FALSE(s.effects.damping);
  apply_parameter(s, "effects.damping", 1);  // alpha kept
  EXPECT_TRUE(s.effects.damping);
  apply_parameter(s, "damping.alpha", 0);
  EXPECT_FALSE(s.effects.damping);

  apply_parameter(s, "gravity.y", -3);
  EXPECT_TRUE(s.effects.gravity);
  EXPECT_EQ(s.effects.g, Vec3(0, -3, 0));
  apply_parameter(s, "gravity.y", 0);
  EXPECT_FALSE(s.effects.gravity) << "a zero vector is no gravity";

  apply_parameter(s, "proxies[0].friction", 0.6);
  EXPECT_TRUE(s.effects.friction);
  EXPECT_EQ(s.proxies[0].friction, 0.6);
  apply_parameter(s, "friction.mu", 0);
  EXPECT_FALSE(s.effects.friction);
}

TEST(Parameters, ListShowsCurrentValuesAndEveryNameApplies) {
  ModelSpec s = two_materials_one_proxy();
  s.effects.damping = true;
  s.effects.alpha = 2;
  const std::vector<Parameter> list = list_parameters(s);
  auto value = [&](const std::string& name) {
    for (const Parameter& p : list)
      if (p.name == name) return p.value;
    ADD_FAILURE() << name << " not listed";
    return std::numeric_limits<double>::quiet_NaN();
  };
  EXPECT_EQ(value("materials[1].E"), 2e5);
  EXPECT_EQ(value("damping.alpha"), 2);
  EXPECT_EQ(value("effects.damping"), 1);
  EXPECT_EQ(value("gravity.y"), -9.81);
  EXPECT_EQ(value("effects.gravity"), 0);
  for (const Parameter& p : list) {
    EXPECT_LE(p.min, p.value) << p.name;
    EXPECT_LE(p.value, p.max) << p.name;
    ModelSpec copy = s;
    if (p.name == "effects.gravity" || p.name == "effects.damping" || p.name == "effects.friction") continue;
    EXPECT_NO_THROW(apply_parameter(copy, p.name, p.max)) << p.name;
  }
  // One material: the names drop the index.
  ModelSpec one;
  one.materials = {MaterialSpec{}};
  const std::vector<Parameter> l1 = list_parameters(one);
  EXPECT_EQ(l1.front().name, "material.E");
  for (const Parameter& p : l1) EXPECT_EQ(p.name.find("friction"), std::string::npos) << "no proxies, no friction";
}

// Two bodies: "a" of one material, "b" of two (its second on its upper half).
ModelSpec two_bodies() {
  BodyParts a, b;
  a.name = "a";
  a.mesh = make_box(Vec3(0.0), Vec3(0.01), {1, 1, 1});
  a.materials = {MaterialSpec{MaterialModel::NeoHookean, 1e4, 0.3, 1000}};
  b.name = "b";
  b.mesh = make_box(Vec3(0.02, 0, 0), Vec3(0.03, 0.01, 0.01), {1, 2, 1});
  for (int32_t e = 0; e < b.mesh.n_tets(); ++e) b.mesh.region.push_back(e < b.mesh.n_tets() / 2 ? 0 : 1);
  b.materials = {MaterialSpec{MaterialModel::NeoHookean, 2e4, 0.3, 1000},
                 MaterialSpec{MaterialModel::NeoHookean, 3e4, 0.4, 1100}};
  ModelSpec s;
  add_bodies(s, {a, b});
  return s;
}

TEST(Parameters, ABodysMaterialsAreNamedByBodyAndLandInItsOwn) {
  ModelSpec s = two_bodies();
  const std::vector<Parameter> list = list_parameters(s);
  std::vector<std::string> names;
  for (const Parameter& p : list) names.push_back(p.name);
  for (const char* n : {"bodies[0].material.E", "bodies[1].materials[0].E", "bodies[1].materials[1].rho"})
    EXPECT_NE(std::find(names.begin(), names.end(), n), names.end()) << n;
  EXPECT_EQ(std::find(names.begin(), names.end(), "materials[2].E"), names.end()) << "named by body, not globally";
  for (const Parameter& p : list) {
    if (p.name.rfind("bodies[", 0) != 0) continue;
    ModelSpec copy = s;
    EXPECT_NO_THROW(apply_parameter(copy, p.name, p.max)) << p.name;
  }
  apply_parameter(s, "bodies[1].materials[1].E", 5e4);
  EXPECT_EQ(s.materials[2].E, 5e4);
  EXPECT_EQ(s.materials[1].E, 2e4);
  apply_parameter(s, "bodies[0].material.nu", 0.45);
  EXPECT_EQ(s.materials[0].nu, 0.45);
  EXPECT_EQ(s.materials[1].nu, 0.3);
  apply_parameter(s, "bodies[1].material.rho", 1200);  // every material of body b
  EXPECT_EQ(s.materials[1].rho, 1200);
  EXPECT_EQ(s.materials[2].rho, 1200);
  EXPECT_EQ(s.materials[0].rho, 1000);
  expect_refused(s, "bodies[2].material.E", 1e4, "no body 2");
  expect_refused(s, "bodies[1].materials[2].E", 1e4, "no material 2 in body 1");
  expect_refused(s, "bodies[0].colour.r", 1, "a body's parameters are");
  expect_refused(s, "bodies[0].material.E", -1, "must be in");
}

TEST(Parameters, BadNamesAndValuesAreRefusedByName) {
  const ModelSpec s = two_materials_one_proxy();
  expect_refused(s, "materials[0].nu", 0.5, "[-0.99, 0.499]");
  expect_refused(s, "material.E", -1, "got -1");
  expect_refused(s, "material.E", std::numeric_limits<double>::quiet_NaN(), "got nan");
  expect_refused(s, "materials[2].E", 1e5, "no material 2");
  expect_refused(s, "materials[0].G", 1e5, "E, nu and rho");
  expect_refused(s, "materials[x].E", 1e5, "no such parameter");
  expect_refused(s, "proxies[3].friction", 0.1, "no proxy 3");
  expect_refused(s, "effects.gravity", 0.5, "1 (on) or 0 (off)");
  expect_refused(s, "effects.damping", 1, "damping.alpha > 0");
  expect_refused(s, "youngs", 1, "materials[0].E");  // the message lists the names there are
  ModelSpec none;
  none.materials = {MaterialSpec{}};
  expect_refused(none, "friction.mu", 0.3, "no proxies");
}

}  // namespace
}  // namespace tactile
