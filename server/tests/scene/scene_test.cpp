// Scene loading: shipped scenes load, fields map onto the core's spec, and
// bad scenes are refused with the file and JSON path of the field at fault.
#include <gtest/gtest.h>

#include <chrono>

#include <cmath>
#include <filesystem>
#include <functional>
#include <numbers>
#include <set>

#include <glm/geometric.hpp>

#include "core/quadratic.hpp"
#include "mesh/mesh_io.hpp"
#include "mesh/primitives.hpp"
#include "scene/scene.hpp"
#include "scene/scene_mesh.hpp"
#include "scene_fixtures.hpp"

namespace tactile {
namespace {

using nlohmann::json;
using test::expect_scene_error;
using test::make_beam_scene;
using test::SceneDir;

std::vector<std::string> shipped_scenes() {
  std::vector<std::string> out;
  for (const auto& e : std::filesystem::directory_iterator(TACTILE_SCENE_DIR)) {
    const std::string p = e.path().string();
    if (e.path().extension() == ".json" && !p.ends_with(".schema.json")) out.push_back(p);
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(ShippedScenes, AllLoadWithSoundMeshes) {
  const std::vector<std::string> files = shipped_scenes();
  ASSERT_GE(files.size(), 4u);
  for (const std::string& f : files) {
    SCOPED_TRACE(f);
    const std::vector<Scene> scenes = load_scene(f);
    ASSERT_FALSE(scenes.empty());
    for (const Scene& s : scenes) {
      EXPECT_FALSE(s.name.empty());
      EXPECT_FALSE(s.description.empty());
      EXPECT_GT(s.spec.mesh.n_tets(), 0);
      EXPECT_TRUE(s.quality.inverted.empty() && s.quality.degenerate.empty());
      EXPECT_EQ(s.quality.n_tets, s.spec.mesh.n_tets());
      EXPECT_GT(s.run.duration, 0);
      for (const TrackedPoint& p : s.track) EXPECT_EQ(s.spec.mesh.X[size_t(p.node)], p.X);
    }
  }
}

TEST(ShippedScenes, PaperFiguresCompareLinearWithStvk) {
  for (const char* name : {"fig2_twist.json", "fig3_cantilever.json"}) {
    SCOPED_TRACE(name);
    const std::vector<Scene> scenes = load_scene(std::string(TACTILE_SCENE_DIR) + "/" + name);
    ASSERT_EQ(scenes.size(), 2u);
    EXPECT_EQ(scenes[0].variant, "linear");
    EXPECT_EQ(scenes[0].spec.materials.at(0).model, MaterialModel::Linear);
    EXPECT_EQ(scenes[1].variant, "stvk");
    EXPECT_EQ(scenes[1].spec.materials.at(0).model, MaterialModel::StVK);
    // The variants change the model only.
    EXPECT_EQ(scenes[0].spec.materials[0].E, scenes[1].spec.materials[0].E);
    EXPECT_EQ(scenes[0].spec.mesh.X, scenes[1].spec.mesh.X);
  }
  const Scene fig2 = load_scene(std::string(TACTILE_SCENE_DIR) + "/fig2_twist.json").at(0);
  ASSERT_EQ(fig2.run.sections.size(), 1u);
  const Aabb box = compute_aabb(fig2.spec.mesh.X);
  EXPECT_NEAR(box.size().y, 3.0 * box.size().x, 1e-12);  // three times as tall as wide
}

TEST(SceneMapping, FieldsBecomeTheCoreSpec) {
  SceneDir dir;
  json j = make_beam_scene();
  j["description"] = "mapping";
  j["boundary"].push_back(json::parse(R"({
    "name": "twist", "select": { "plane": { "point": [0.4, 0, 0], "normal": [2, 0, 0] } },
    "rotate": { "centre": [0.4, 0.05, 0.05], "axis": [3, 0, 0], "angle_deg": 90, "duration": 1.5, "start": 0.25 },
    "translate": { "direction": [0, 0, -2], "distance": 0.01, "duration": 0.5 } })"));
  j["loads"] = json::parse(
      R"([{ "name": "push", "select": { "nodes": [1, 2] }, "force": [0, 1, 0], "ramp": { "duration": 0.2 } }])");
  j["effects"] = json::parse(R"({ "gravity": false, "damping": { "alpha": 1.5 } })");
  j["integrator"] = json::parse(
      R"({ "precision": "float", "dt": 1e-4, "safety": 0.5, "unstable": "refuse", "threads": 2, "energy_tolerance": 0.1,
          "mass_scaling_dt": 2e-4 })");
  const std::vector<Scene> scenes = load_scene(dir.write_json("m.json", j));
  ASSERT_EQ(scenes.size(), 1u);
  const Scene& s = scenes[0];
  EXPECT_EQ(s.name, "beam");
  EXPECT_EQ(s.description, "mapping");
  EXPECT_EQ(s.variant, "");
  EXPECT_EQ(s.spec.mesh.n_tets(), 8 * 2 * 2 * 6);
  ASSERT_EQ(s.spec.essential.size(), 2u);
  const EssentialBc& clamp = s.spec.essential[0];
  EXPECT_FALSE(clamp.angle || clamp.shift);
  EXPECT_EQ(select_nodes(s.spec.mesh, clamp.where).size(), 3u * 3u);
  const EssentialBc& twist = s.spec.essential[1];
  ASSERT_TRUE(twist.angle && twist.shift);
  EXPECT_EQ(twist.angle->kind, MotionProfile::Kind::Ramp);
  EXPECT_NEAR(twist.angle->target, std::numbers::pi / 2, 1e-15);
  EXPECT_EQ(twist.angle->duration, 1.5);
  EXPECT_EQ(twist.angle->start, 0.25);
  EXPECT_NEAR(glm::length(twist.axis - Vec3(1, 0, 0)), 0.0, 1e-15);
  EXPECT_NEAR(glm::length(twist.direction - Vec3(0, 0, -1)), 0.0, 1e-15);
  EXPECT_EQ(twist.shift->target, 0.01);
  EXPECT_EQ(twist.shift->start, 0.0);
  ASSERT_EQ(s.spec.loads.size(), 1u);
  EXPECT_EQ(s.spec.loads[0].where.nodes, (std::vector<int32_t>{1, 2}));
  ASSERT_TRUE(s.spec.loads[0].scale);
  EXPECT_EQ(s.spec.loads[0].scale->target, 1.0);
  EXPECT_FALSE(s.spec.effects.gravity);
  EXPECT_TRUE(s.spec.effects.damping);
  EXPECT_EQ(s.spec.effects.alpha, 1.5);
  EXPECT_EQ(s.spec.integrator.precision, Precision::Float);
  EXPECT_EQ(s.spec.integrator.dt, 1e-4);
  EXPECT_EQ(s.spec.integrator.safety, 0.5);
  EXPECT_EQ(s.spec.integrator.unstable, UnstablePolicy::Refuse);
  EXPECT_EQ(s.spec.integrator.threads, 2);
  EXPECT_EQ(s.spec.integrator.energy_tolerance, 0.1);
  EXPECT_EQ(s.spec.integrator.mass_scaling_dt, 2e-4);
  // The tracked point is the nearest node, reported at its rest position.
  ASSERT_EQ(s.track.size(), 1u);
  EXPECT_EQ(s.track[0].X, Vec3(0.4, 0.05, 0.05));
  EXPECT_EQ(s.run.frame_rate, 100);
  EXPECT_EQ(s.run.vtu_every, 1);
}

// A scene of bodies: each read in its own numbering, then one after another.
TEST(SceneMapping, BodiesFollowEachOtherEachInItsOwnNumbering) {
  SceneDir dir;
  json j = make_beam_scene();
  json beam = json::object();
  for (const char* key : {"mesh", "material", "boundary"}) beam[key] = j[key], j.erase(key);
  beam["name"] = "beam";
  beam["track"] = j["run"]["track"];
  j["run"].erase("track");
  json block = json::parse(R"({
    "name": "block",
    "mesh": { "primitive": "box", "lo": [0.3, 0.1, 0], "hi": [0.4, 0.15, 0.1], "cells": [2, 1, 2] },
    "materials": [ { "model": "neohookean", "E": 2e4, "nu": 0.4, "rho": 900 },
                   { "model": "linear", "E": 3e4, "nu": 0.3, "rho": 900 } ],
    "regions": [ { "box": { "lo": [0.35, 0, 0], "hi": [1, 1, 1] }, "material": 1 } ],
    "loads": [ { "name": "push", "select": { "nodes": [0, 1] }, "force": [0, -1, 0] } ],
    "track": [ { "name": "corner", "point": [0.3, 0.1, 0] } ] })");
  j["bodies"] = json::array({beam, block});
  const Scene s = load_scene(dir.write_json("bodies.json", j)).at(0);
  ASSERT_EQ(s.spec.bodies.size(), 2u);
  const BodySpec& b = s.spec.bodies[1];
  EXPECT_EQ(s.spec.bodies[0].name, "beam");
  EXPECT_EQ(b.name, "block");
  EXPECT_EQ(b.node_begin, 9 * 3 * 3);
  EXPECT_EQ(b.tet_begin, 8 * 2 * 2 * 6);
  EXPECT_EQ(b.tet_end - b.tet_begin, 2 * 1 * 2 * 6);
  ASSERT_EQ(s.spec.materials.size(), 3u);  // the beam's, then the block's two
  std::set<int32_t> block_regions;
  for (int32_t e = b.tet_begin; e < b.tet_end; ++e) block_regions.insert(s.spec.mesh.region_of(e));
  EXPECT_EQ(block_regions, (std::set<int32_t>{1, 2}));
  // The block's nodes 0 and 1 are the spec's first two of the block.
  EXPECT_EQ(select_nodes(s.spec.mesh, s.spec.loads.at(0).where),
            (std::vector<int32_t>{b.node_begin, b.node_begin + 1}));
  EXPECT_EQ(select_nodes(s.spec.mesh, s.spec.essential.at(0).where).size(), 9u);
  ASSERT_EQ(s.track.size(), 2u);
  EXPECT_EQ(s.track[0].body, 0);
  EXPECT_EQ(s.track[1].body, 1);
  EXPECT_EQ(s.track[1].node, b.node_begin);  // the block's node 0 is at its lowest corner
  EXPECT_EQ(s.spec.mesh.X[size_t(s.track[1].node)], Vec3(0.3, 0.1, 0));

  // A body without a material is refused naming it.
  j["bodies"][1].erase("materials");
  expect_scene_error(dir, "nomat.json", j, {"nomat.json: bodies[1].material: required field missing"});
}

TEST(SceneMapping, AbsentEffectsAreOffAndAutoStepIsZero) {
  SceneDir dir;
  json j = make_beam_scene();
  j.erase("effects");
  j["integrator"] = json{{"dt", "auto"}};
  const Scene s = load_scene(dir.write_json("a.json", j)).at(0);
  EXPECT_FALSE(s.spec.effects.gravity);
  EXPECT_FALSE(s.spec.effects.damping);
  EXPECT_EQ(s.spec.integrator.dt, 0.0);
  EXPECT_EQ(s.spec.integrator.precision, Precision::Double);
}

// Optional VTU arrays are made only when the run lists them; a name not
// known, or one listed twice, is refused naming the entry.
TEST(SceneMapping, VtuFieldsAreAskedForByName) {
  SceneDir dir;
  json j = make_beam_scene();
  Scene s = load_scene(dir.write_json("a.json", j)).at(0);
  EXPECT_FALSE(s.run.vtu_cells.any());
  EXPECT_FALSE(s.run.vtu_contact_force);
  j["run"]["vtu_fields"] = json::array({"von_mises", "contact_force"});
  s = load_scene(dir.write_json("a.json", j)).at(0);
  EXPECT_TRUE(s.run.vtu_cells.von_mises);
  EXPECT_FALSE(s.run.vtu_cells.cauchy_stress);
  EXPECT_FALSE(s.run.vtu_cells.green_strain);
  EXPECT_TRUE(s.run.vtu_contact_force);
  j["run"]["vtu_fields"] = json::array({"von_mises", "stress"});
  expect_scene_error(dir, "s.json", j, {"run.vtu_fields[1]", "stress", "cauchy_stress"});
  j["run"]["vtu_fields"] = json::array({"green_strain", "green_strain"});
  expect_scene_error(dir, "s.json", j, {"run.vtu_fields[1]: 'green_strain' is asked for twice"});
}

// "view.fields": what every live state frame carries, by name; none by default.
TEST(SceneMapping, ViewFieldsAreAskedForByName) {
  SceneDir dir;
  json j = make_beam_scene();
  EXPECT_EQ(load_scene(dir.write_json("a.json", j)).at(0).view_fields, 0u);
  j["view"] = json{{"fields", json::array({"stretch_min", "von_mises"})}};
  EXPECT_EQ(load_scene(dir.write_json("a.json", j)).at(0).view_fields,
            view_field_bit(ViewField::StretchMin) | view_field_bit(ViewField::VonMises));
  j["view"]["fields"] = json::array({"von_mises", "strain"});
  expect_scene_error(dir, "s.json", j, {"view.fields[1]", "no field 'strain'", "energy_density"});
  j["view"]["fields"] = json::array({"von_mises", "von_mises"});
  expect_scene_error(dir, "s.json", j, {"view.fields[1]: 'von_mises' is asked for twice"});
  j["view"] = json{{"colours", 1}};
  expect_scene_error(dir, "s.json", j, {"view", "colours"});
  j.erase("view");
  j["run"]["vtu_fields"] = json::array({"principal_stretches"});
  EXPECT_TRUE(load_scene(dir.write_json("a.json", j)).at(0).run.vtu_cells.principal_stretches);
}

TEST(SceneMapping, NameDefaultsToTheFileStem) {
  SceneDir dir;
  json j = make_beam_scene();
  j.erase("name");
  EXPECT_EQ(load_scene(dir.write_json("my beam.json", j)).at(0).name, "my_beam");
}

TEST(SceneMapping, RegionsAssignMaterialsByCentroid) {
  SceneDir dir;
  json j = make_beam_scene();
  j.erase("material");
  j["materials"] = json::parse(R"([{ "model": "stvk", "E": 1e5, "nu": 0.3, "rho": 1000 },
                                    { "model": "neohookean", "E": 2e5, "nu": 0.4, "rho": 1100 }])");
  j["regions"] = json::parse(R"([{ "box": { "lo": [0.2, -1, -1], "hi": [1, 1, 1] }, "material": 1 }])");
  const Scene s = load_scene(dir.write_json("r.json", j)).at(0);
  ASSERT_EQ(s.spec.materials.size(), 2u);
  EXPECT_EQ(s.spec.materials[1].model, MaterialModel::NeoHookean);
  const TetMesh& m = s.spec.mesh;
  int ones = 0;
  for (int32_t e = 0; e < m.n_tets(); ++e) {
    const Tet& t = m.tets[size_t(e)];
    const double cx = 0.25 * (m.X[size_t(t[0])].x + m.X[size_t(t[1])].x + m.X[size_t(t[2])].x + m.X[size_t(t[3])].x);
    EXPECT_EQ(m.region_of(e), cx >= 0.2 ? 1 : 0) << "tet " << e;
    ones += m.region_of(e);
  }
  EXPECT_EQ(ones, m.n_tets() / 2);  // the box cuts the beam in half along cell boundaries
}

TEST(SceneMapping, VariantsAmendTheScene) {
  SceneDir dir;
  json j = make_beam_scene();
  j["integrator"] = json{{"precision", "double"}, {"safety", 0.8}};
  j["variants"] = json::parse(R"([
    { "name": "soft", "material": { "E": 5e4 } },
    { "name": "lin32", "description": "linear in float", "material": { "model": "linear" }, "integrator": { "precision": "float" } },
    { "name": "ball", "mesh": { "primitive": "sphere", "centre": [0.2, 0.05, 0.05], "radius": 0.2, "resolution": 1 } }
  ])");
  j["boundary"] = json::array();
  const std::vector<Scene> v = load_scene(dir.write_json("v.json", j));
  ASSERT_EQ(v.size(), 3u);
  EXPECT_EQ(v[0].variant, "soft");
  EXPECT_EQ(v[0].spec.materials[0].E, 5e4);
  EXPECT_EQ(v[0].spec.materials[0].model, MaterialModel::StVK);  // kept from the scene
  EXPECT_EQ(v[1].spec.materials[0].model, MaterialModel::Linear);
  EXPECT_EQ(v[1].spec.materials[0].E, 1e5);
  EXPECT_EQ(v[1].spec.integrator.precision, Precision::Float);
  EXPECT_EQ(v[1].spec.integrator.safety, 0.8);  // merged, not replaced
  EXPECT_EQ(v[1].description, "linear in float");
  EXPECT_NE(v[2].spec.mesh.n_tets(), v[0].spec.mesh.n_tets());  // a mesh of another kind replaces the box
  for (const Scene& s : v) EXPECT_EQ(s.name, "beam");
}

// The beam with a sphere scripted over it, a box and a plane holding still,
// and a hand of a capsule and a sphere turned by its script.
json make_proxy_scene() {
  json j = make_beam_scene();
  j["proxies"] = json::parse(R"([
    { "name": "tip", "device": "stylus", "shape": "sphere", "radius": 0.01, "friction": 0.5,
      "script": { "easing": "linear", "keyframes": [ { "t": 0.1, "position": [0.3, 0.12, 0.05] },
                                                     { "t": 0.3, "position": [0.3, 0.1, 0.05], "orientation": [0, 0, 2, 0] } ] } },
    { "name": "wall", "device": "fixed", "shape": "box", "half_extents": [0.01, 0.02, 0.03], "radius": 0.002,
      "position": [0.5, 0.05, 0.05], "orientation": [2, 0, 0, 0] },
    { "name": "floor", "device": "fixed", "shape": "plane", "position": [0, -0.1, 0] },
    { "name": "finger", "hand": "right", "shape": "capsule", "radius": 0.005, "half_length": 0.02,
      "position": [0.2, 0.11, 0.05] },
    { "name": "thumb", "hand": "right", "device": "glove", "shape": "sphere", "radius": 0.006,
      "position": [0.2, 0.11, 0.0] }
  ])");
  j["hands"] = json::parse(R"([
    { "name": "right", "device": "glove", "position": [0.2, 0.12, 0.05],
      "script": { "keyframes": [ { "t": 0, "position": [0.2, 0.12, 0.05] },
                                 { "t": 0.5, "position": [0.2, 0.12, 0.05], "orientation": [0.7071067811865476, 0, 0.7071067811865476, 0] } ] } }
  ])");
  j["effects"]["friction"] = true;
  return j;
}

TEST(SceneMapping, ProxiesHandsAndScriptsBecomeTheCoreSpec) {
  SceneDir dir;
  const Scene s = load_scene(dir.write_json("p.json", make_proxy_scene())).at(0);
  const std::vector<ProxySpec>& p = s.spec.proxies;
  ASSERT_EQ(p.size(), 5u);
  ASSERT_EQ(s.proxy_script.size(), 5u);
  EXPECT_TRUE(s.spec.effects.friction);

  EXPECT_EQ(p[0].name, "tip");
  EXPECT_EQ(p[0].device, "stylus");
  EXPECT_EQ(p[0].hand, "");
  EXPECT_EQ(p[0].geometry.shape, ProxyShape::Sphere);
  EXPECT_EQ(p[0].geometry.radius, 0.01);
  EXPECT_EQ(p[0].friction, 0.5);
  ASSERT_TRUE(s.proxy_script[0]);
  const PoseScript& script = *s.proxy_script[0];
  EXPECT_EQ(script.easing, PoseScript::Easing::Linear);
  ASSERT_EQ(script.keys.size(), 2u);
  EXPECT_EQ(script.keys[1].t, 0.3);
  EXPECT_EQ(script.keys[0].pose.orientation, Quat(1, 0, 0, 0));  // the proxy's, identity when absent
  EXPECT_EQ(script.keys[1].pose.orientation, Quat(0, 0, 1, 0));  // normalised
  // A scripted proxy starts where its script does.
  EXPECT_EQ(p[0].pose.position, Vec3(0.3, 0.12, 0.05));

  EXPECT_EQ(p[1].geometry.shape, ProxyShape::Box);
  EXPECT_EQ(p[1].geometry.half_extents, Vec3(0.01, 0.02, 0.03));
  EXPECT_EQ(p[1].geometry.radius, 0.002);
  EXPECT_EQ(p[1].pose.position, Vec3(0.5, 0.05, 0.05));
  EXPECT_EQ(p[1].pose.orientation, Quat(1, 0, 0, 0));
  EXPECT_EQ(p[1].friction, 0.0);
  EXPECT_FALSE(s.proxy_script[1]);
  EXPECT_EQ(p[2].geometry.shape, ProxyShape::Plane);
  EXPECT_EQ(p[2].device, "fixed");

  EXPECT_EQ(p[3].geometry.shape, ProxyShape::Capsule);
  EXPECT_EQ(p[3].geometry.half_length, 0.02);
  EXPECT_EQ(p[3].hand, "right");
  EXPECT_EQ(p[3].device, "");  // the core gives a hand's proxies the hand's device
  EXPECT_EQ(p[4].hand, "right");

  ASSERT_EQ(s.spec.hands.size(), 1u);
  ASSERT_EQ(s.hand_script.size(), 1u);
  EXPECT_EQ(s.spec.hands[0].name, "right");
  EXPECT_EQ(s.spec.hands[0].device, "glove");
  EXPECT_EQ(s.spec.hands[0].pose.position, Vec3(0.2, 0.12, 0.05));
  ASSERT_TRUE(s.hand_script[0]);
  EXPECT_EQ(s.hand_script[0]->easing, PoseScript::Easing::Smooth);  // the default
}

// A proxy's or a hand's "coupling" bounds what a device asks of it live;
// what it leaves out stays 0 (the device's, or the defaults).
TEST(SceneMapping, CouplingsBecomeTheCoreSpec) {
  SceneDir dir;
  json j = make_proxy_scene();
  j["proxies"][1]["coupling"] = json{{"stiffness", 800.0}, {"max_force", 3.0}, {"mass", 0.05}};
  j["hands"][0]["coupling"] = json{{"max_torque", 0.2}, {"angular_stiffness", 4.0}};
  const Scene s = load_scene(dir.write_json("p.json", j)).at(0);
  const Coupling& c = s.spec.proxies[1].coupling;
  EXPECT_EQ(c.stiffness, 800.0);
  EXPECT_EQ(c.max_force, 3.0);
  EXPECT_EQ(c.mass, 0.05);
  EXPECT_EQ(c.damping, 0.0);
  EXPECT_EQ(s.spec.hands[0].coupling.max_torque, 0.2);
  EXPECT_EQ(s.spec.hands[0].coupling.angular_stiffness, 4.0);
  EXPECT_EQ(s.spec.proxies[0].coupling.stiffness, 0.0);  // none given
}

TEST(SceneErrors, BadCouplingsAreRefusedByField) {
  SceneDir dir;
  json j = make_proxy_scene();
  j["proxies"][1]["coupling"] = json{{"max_force", -1.0}};
  expect_scene_error(dir, "s.json", j, {"proxies[1].coupling.max_force: must be a number > 0, got -1"});
  j = make_proxy_scene();
  j["proxies"][1]["coupling"] = json{{"stifness", 800.0}};
  expect_scene_error(dir, "s.json", j, {"proxies[1].coupling", "stifness"});
  j = make_proxy_scene();
  j["proxies"][3]["coupling"] = json{{"max_force", 2.0}};
  expect_scene_error(dir, "s.json", j,
                     {"proxies[3].coupling: a proxy in a hand moves with it; give the coupling to hand 'right'"});
}

TEST(SceneMapping, VariantsCanTurnFrictionOnAndOff) {
  SceneDir dir;
  json j = make_proxy_scene();
  j["variants"] = json::parse(R"([{ "name": "dry" }, { "name": "slippery", "effects": { "friction": false } }])");
  const std::vector<Scene> v = load_scene(dir.write_json("v.json", j));
  ASSERT_EQ(v.size(), 2u);
  EXPECT_TRUE(v[0].spec.effects.friction);
  EXPECT_FALSE(v[1].spec.effects.friction);
  EXPECT_TRUE(v[1].spec.effects.gravity);  // the rest of the effects kept
  EXPECT_EQ(v[1].spec.proxies.size(), 5u);
}

// ---- scripts ----------------------------------------------------------------

PoseScript two_keys(PoseScript::Easing easing) {
  PoseScript s;
  s.easing = easing;
  s.keys.push_back({1.0, Pose{Vec3(0.0), Quat(1, 0, 0, 0)}});
  // A quarter turn about y and 2 m along x.
  s.keys.push_back(
      {3.0, Pose{Vec3(2.0, 0, 0), Quat(std::cos(std::numbers::pi / 4), 0, std::sin(std::numbers::pi / 4), 0)}});
  return s;
}

double angle_about_y(const Quat& q) { return 2.0 * std::atan2(q.y, q.w); }

TEST(PoseScript, HoldsBeforeTheFirstKeyframeAndAfterTheLast) {
  for (auto easing : {PoseScript::Easing::Smooth, PoseScript::Easing::Linear}) {
    const PoseScript s = two_keys(easing);
    EXPECT_EQ(s.at(0.0).position, Vec3(0.0));
    EXPECT_EQ(s.at(1.0).position, Vec3(0.0));
    EXPECT_EQ(s.at(3.0).position, Vec3(2.0, 0, 0));
    EXPECT_EQ(s.at(10.0).position, Vec3(2.0, 0, 0));
    EXPECT_NEAR(angle_about_y(s.at(10.0).orientation), std::numbers::pi / 2, 1e-12);
    // Half way in time is half way in position and angle, both easings (the cycloid is symmetric).
    EXPECT_NEAR(s.at(2.0).position.x, 1.0, 1e-12);
    EXPECT_NEAR(angle_about_y(s.at(2.0).orientation), std::numbers::pi / 4, 1e-12);
  }
}

TEST(PoseScript, SmoothStartsAndStopsAtRestLinearKeepsOneSpeed) {
  const double h = 1e-6;
  auto speed = [&](const PoseScript& s, double t) {
    return (s.at(t + h).position.x - s.at(t - h).position.x) / (2 * h);
  };
  const PoseScript smooth = two_keys(PoseScript::Easing::Smooth);
  const PoseScript linear = two_keys(PoseScript::Easing::Linear);
  EXPECT_NEAR(speed(smooth, 1.0 + 2 * h), 0.0, 1e-4);
  EXPECT_NEAR(speed(smooth, 3.0 - 2 * h), 0.0, 1e-4);
  EXPECT_NEAR(speed(smooth, 2.0), 2.0, 1e-6);  // peak: twice the mean speed of 1 m/s
  for (double t : {1.1, 1.5, 2.0, 2.9}) EXPECT_NEAR(speed(linear, t), 1.0, 1e-6) << t;
  // The core's motion over an interval runs between the script's poses at its ends.
  const ProxyMotion m = smooth.motion(1.5, 1.6);
  EXPECT_EQ(m.t0, 1.5);
  EXPECT_EQ(m.t1, 1.6);
  EXPECT_EQ(m.from.position, smooth.at(1.5).position);
  EXPECT_EQ(m.to.position, smooth.at(1.6).position);
  EXPECT_NEAR(m.velocity().x, (smooth.at(1.6).position.x - smooth.at(1.5).position.x) / 0.1, 1e-9);
}

// ---- refusals: each names the file and the JSON path -----------------------

TEST(SceneErrors, UnknownField) {
  SceneDir dir;
  json j = make_beam_scene();
  j["materal"] = j["material"];
  expect_scene_error(dir, "s.json", j, {"materal: unknown field"});
  j = make_beam_scene();
  j["material"]["young"] = 1;
  expect_scene_error(dir, "s.json", j,
                     {"material.young: unknown field", "allowed here: model, invertible, E, nu, rho"});
  j = make_beam_scene();
  j["boundary"][0]["select"]["box"]["size"] = 1;
  expect_scene_error(dir, "s.json", j, {"boundary[0].select.box.size: unknown field"});
}

TEST(SceneErrors, WrongType) {
  SceneDir dir;
  json j = make_beam_scene();
  j["material"]["E"] = "soft";
  expect_scene_error(dir, "s.json", j, {"material.E: must be a number > 0, got \"soft\""});
  j = make_beam_scene();
  j["mesh"]["cells"] = json::array({8, 2});
  expect_scene_error(dir, "s.json", j, {"mesh.cells: must be an array of 3 integers"});
  j = make_beam_scene();
  j["run"]["track"][0]["point"][1] = true;
  expect_scene_error(dir, "s.json", j, {"run.track[0].point[1]: must be a number, got true"});
  j = make_beam_scene();
  j["boundary"] = json::object();
  expect_scene_error(dir, "s.json", j, {"boundary: must be an array"});
}

TEST(SceneErrors, OutOfRangeValues) {
  SceneDir dir;
  json j = make_beam_scene();
  j["material"]["E"] = -5;
  expect_scene_error(dir, "s.json", j, {"material.E: must be a number > 0, got -5"});
  j = make_beam_scene();
  j["material"]["nu"] = 0.5;
  expect_scene_error(dir, "s.json", j, {"material.nu: must lie in (-1, 0.5), got 0.5"});
  j = make_beam_scene();
  j["mesh"]["cells"][1] = 0;
  expect_scene_error(dir, "s.json", j, {"mesh.cells[1]: must be an integer in 1..10000, got 0"});
  j = make_beam_scene();
  j["integrator"] = json{{"safety", 1.5}};
  expect_scene_error(dir, "s.json", j, {"integrator.safety: must lie in (0, 1]"});
  j = make_beam_scene();
  j["integrator"] = json{{"mass_scaling_dt", -1e-4}};
  expect_scene_error(dir, "s.json", j, {"integrator.mass_scaling_dt: must be a number > 0"});
}

// "element": "p2" makes the mesh quadratic: a node on each edge, which the
// selectors pick as they pick corners; "p1" (the default) keeps it linear.
TEST(Scene, ElementP2GivesEveryEdgeANodeTheSelectorsReach) {
  SceneDir dir;
  json j = make_beam_scene();
  const Scene linear = load_scene(dir.write_json("p1.json", j)).at(0);
  j["element"] = "p2";
  const Scene quadratic = load_scene(dir.write_json("p2.json", j)).at(0);
  ASSERT_FALSE(linear.spec.mesh.quadratic());
  ASSERT_TRUE(quadratic.spec.mesh.quadratic());
  EXPECT_EQ(quadratic.spec.mesh.tets, linear.spec.mesh.tets);
  EXPECT_GT(quadratic.spec.mesh.n_nodes(), linear.spec.mesh.n_nodes());
  EXPECT_EQ(check_mesh_structure(quadratic.spec.mesh), "");
  // The clamp's face x = 0: 3 x 3 corners and, on its 2 x 2 split cells, 16 edges.
  EXPECT_EQ(select_nodes(linear.spec.mesh, linear.spec.essential.at(0).where).size(), 9u);
  EXPECT_EQ(select_nodes(quadratic.spec.mesh, quadratic.spec.essential.at(0).where).size(), 25u);
  j["element"] = "p3";
  expect_scene_error(dir, "s.json", j, {"element: must be one of \"p1\", \"p2\", got \"p3\""});
}

// A ten-node .ele file is a quadratic mesh as it is; a scene that reads one
// says "element": "p2", or is told to.
TEST(Scene, ATenNodeMeshFileAsksForElementP2) {
  SceneDir dir;
  const TetMesh q = make_quadratic_mesh(make_box(Vec3(0.0), Vec3(0.4, 0.1, 0.1), {8, 2, 2}));
  write_tetgen(q, dir.file("beam"));
  json j = make_beam_scene();
  j["mesh"] = json{{"file", "beam.node"}};
  expect_scene_error(dir, "s.json", j, {"element: the mesh file's tets are quadratic", "\"element\": \"p2\""});
  j["element"] = "p2";
  const Scene scene = load_scene(dir.write_json("p2.json", j)).at(0);
  EXPECT_EQ(scene.spec.mesh.edges, q.edges);
  EXPECT_EQ(scene.spec.mesh.X, q.X);
}

TEST(SceneErrors, MissingMesh) {
  SceneDir dir;
  json j = make_beam_scene();
  j.erase("mesh");
  expect_scene_error(dir, "s.json", j, {"mesh: required field missing"});
}

TEST(SceneErrors, UnknownMaterialModel) {
  SceneDir dir;
  json j = make_beam_scene();
  j["material"]["model"] = "rubber";
  expect_scene_error(
      dir, "s.json", j,
      {"material.model: must be one of \"linear\", \"stvk\", \"corotational\", \"neohookean\", got \"rubber\""});
}

TEST(SceneErrors, SelectorThatSelectsNoNode) {
  SceneDir dir;
  json j = make_beam_scene();
  j["boundary"][0]["select"]["box"] = json{{"lo", {1, 1, 1}}, {"hi", {2, 2, 2}}};
  expect_scene_error(dir, "s.json", j,
                     {"boundary[0].select: selects no node", "the mesh spans [0, 0, 0] to [0.4, 0.1, 0.1]"});
  j = make_beam_scene();
  j["loads"] =
      json::parse(R"([{ "select": { "plane": { "point": [0, 5, 0], "normal": [0, 1, 0] } }, "force": [0, 1, 0] }])");
  expect_scene_error(dir, "s.json", j, {"loads[0].select: selects no node"});
  j = make_beam_scene();
  j["boundary"][0]["select"] = json{{"nodes", {0, 100000}}};
  expect_scene_error(dir, "s.json", j, {"boundary[0].select.nodes[1]: must be an integer in 0.."});
}

TEST(SceneErrors, DtFastAndNegative) {
  SceneDir dir;
  json j = make_beam_scene();
  j["integrator"] = json{{"dt", "fast"}};
  expect_scene_error(dir, "cantilever.json", j, {"integrator.dt: must be \"auto\" or a number > 0, got \"fast\""});
  j["integrator"] = json{{"dt", -1}};
  const std::string path = dir.write_json("cantilever.json", j);
  try {
    load_scene(path);
    ADD_FAILURE() << "no error";
  } catch (const SceneError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": integrator.dt: must be \"auto\" or a number > 0, got -1");
  }
}

TEST(SceneErrors, BadMeshFilePath) {
  SceneDir dir;
  json j = make_beam_scene();
  j["mesh"] = json{{"file", "meshes/nowhere.obj"}};
  expect_scene_error(dir, "s.json", j, {"mesh.file: no such file", "nowhere.obj"});
  j["mesh"] = json{{"file", "shape.step"}};
  expect_scene_error(dir, "s.json", j, {"mesh.file: unknown mesh file extension '.step'"});
}

TEST(SceneErrors, SurfaceThatIsNotClosed) {
  SceneDir dir;
  // The unit cube's surface with its top face missing.
  dir.write("open.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
            "f 1 4 3\nf 1 3 2\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n");
  json j = make_beam_scene();
  j["mesh"] = json{{"file", "open.obj"}};
  j["boundary"] = json::array();
  j["run"].erase("track");
  expect_scene_error(dir, "s.json", j, {"mesh.file: ", "not closed"});
}

// A mesh too large to build is refused before any of it is built, naming
// the field that asks for it and how many tets it would make (before: a
// cylinder ran out of memory with a bare std::bad_alloc, TetGen under a tiny
// volume bound ran for minutes until the machine ran out of memory).
TEST(SceneErrors, MeshesTooLargeAreRefusedBeforeTheyAreBuilt) {
  SceneDir dir;
  json j = make_beam_scene();
  j["mesh"] = json::parse(R"({ "primitive": "cylinder", "radius": 0.05, "height": 0.2, "around": 4096,
                                "layers": 100000, "rings": 64 })");
  j["boundary"] = json::array();
  j["run"].erase("track");
  const auto t0 = std::chrono::steady_clock::now();
  expect_scene_error(dir, "s.json", j, {"mesh.layers: makes 78643.2 M tets; the limit is 20.0 M"});
  // The unit cube's surface, meshed by TetGen with a bound of a cubic micrometre per tet.
  dir.write("cube.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
            "f 1 4 3\nf 1 3 2\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n"
            "f 5 6 7\nf 5 7 8\n");
  j["mesh"] = json::parse(R"({ "file": "cube.obj", "tetgen": { "max_volume": 1e-18 } })");
  expect_scene_error(dir, "s.json", j, {"mesh.tetgen.max_volume: makes about ", "tets; the limit is 20.0 M"});
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(seconds, 5.0);  // (refused up front: building either would take minutes or all memory)
}

// Meshing expected to take a second or more is announced to the watch (the
// CLIs draw a progress bar on it) with the field, the tets expected and the
// time they take, and its end said; a quick one is not.
TEST(SceneMesh, LongMeshingIsAnnouncedToTheWatch) {
  struct Watch final : MeshingWatch {
    std::vector<std::string> seen;
    double tets = 0, seconds = 0;
    void begin(const std::string& field, double expected_tets, double expected_s) override {
      seen.push_back("begin " + field);
      tets = expected_tets;
      seconds = expected_s;
    }
    void end() override { seen.push_back("end"); }
  } watch;
  SceneDir dir;
  set_meshing_watch(&watch);
  json j = make_beam_scene();
  j["mesh"] = json::parse(R"({ "primitive": "sphere", "centre": [0, 0, 0], "radius": 0.1, "resolution": 4 })");
  j["boundary"] = json::array();
  j["run"].erase("track");
  const std::vector<Scene> long_one = load_scene(dir.write("sphere4.json", j.dump()));
  j["mesh"]["resolution"] = 2;
  const std::vector<Scene> quick_one = load_scene(dir.write("sphere2.json", j.dump()));
  set_meshing_watch(nullptr);
  EXPECT_EQ(watch.seen, (std::vector<std::string>{"begin mesh.resolution", "end"}));
  const double made = double(long_one.front().spec.mesh.tets.size());
  EXPECT_GT(watch.tets, made);        // the estimate errs high (it sizes what to refuse)
  EXPECT_LT(watch.tets, 1.5 * made);  // but not by much
  EXPECT_NEAR(watch.seconds, watch.tets / 1e5, 1e-9);
}

TEST(SceneErrors, MisplacedAndConflictingFields) {
  SceneDir dir;
  json j = make_beam_scene();
  j["materials"] = json::array({j["material"]});
  expect_scene_error(dir, "s.json", j, {"materials: give \"material\" or \"materials\", not both"});
  j = make_beam_scene();
  j["boundary"][0]["rotate"] =
      json::parse(R"({ "centre": [0, 0, 0], "axis": [1, 0, 0], "angle_deg": 10, "duration": 1 })");
  expect_scene_error(dir, "s.json", j, {"boundary[0].fixed: cannot be combined"});
  j = make_beam_scene();
  j["boundary"].push_back(j["boundary"][0]);
  expect_scene_error(dir, "s.json", j, {"boundary[1].select: node", "also held by boundary[0]"});
  j = make_beam_scene();
  j["mesh"]["file"] = "x.obj";
  expect_scene_error(dir, "s.json", j, {"mesh: give \"primitive\" or \"file\", not both"});
  j = make_beam_scene();
  j["effects"]["gravity"] = true;
  expect_scene_error(dir, "s.json", j, {"effects.gravity: must be [gx, gy, gz] in m/s^2 or false"});
  j = make_beam_scene();
  j["run"]["sections"] = json::parse(R"([{ "name": "off", "point": [0, 3, 0], "normal": [0, 1, 0] }])");
  expect_scene_error(dir, "s.json", j, {"run.sections[0]: the plane cuts no tet"});
  j = make_beam_scene();
  j["boundary"][0]["rotate"] =
      json::parse(R"({ "centre": [0, 0, 0], "axis": [0, 0, 0], "angle_deg": 10, "duration": 1 })");
  j["boundary"][0].erase("fixed");
  expect_scene_error(dir, "s.json", j, {"boundary[0].rotate.axis: must be a nonzero vector"});
  // A spin eases in: its spin-up cannot be zero (a velocity jump, an impulse no step resolves).
  j = make_beam_scene();
  j["boundary"][0]["spin"] =
      json::parse(R"({ "centre": [0, 0, 0], "axis": [1, 0, 0], "rate_deg_s": 90, "spin_up": 0 })");
  j["boundary"][0].erase("fixed");
  expect_scene_error(dir, "s.json", j, {"boundary[0].spin.spin_up"});
}

TEST(Scene, ASpinEasesInOverItsSpinUpByDefault) {
  SceneDir dir;
  json j = make_beam_scene();
  j["boundary"][0]["spin"] = json::parse(R"({ "centre": [0, 0.05, 0.05], "axis": [1, 0, 0], "rate_deg_s": 90 })");
  j["boundary"][0].erase("fixed");
  const EssentialBc bc = load_scene(dir.write_json("spin.json", j)).at(0).spec.essential.at(0);
  ASSERT_TRUE(bc.angle.has_value());
  EXPECT_EQ(bc.angle->kind, MotionProfile::Kind::ConstantRate);
  EXPECT_DOUBLE_EQ(bc.angle->duration, 0.1);
  EXPECT_EQ(compute_profile(*bc.angle, 0.0).ds, 0.0);
  j["boundary"][0]["spin"]["spin_up"] = 0.25;
  EXPECT_DOUBLE_EQ(load_scene(dir.write_json("spin2.json", j)).at(0).spec.essential.at(0).angle->duration, 0.25);
}

TEST(SceneErrors, VariantErrorsNameTheVariant) {
  SceneDir dir;
  json j = make_beam_scene();
  j["variants"] = json::parse(R"([{ "name": "ok" }, { "name": "bad", "material": { "E": 0 } }])");
  expect_scene_error(dir, "s.json", j, {"variant 'bad': material.E: must be a number > 0, got 0"});
  j["variants"] = json::parse(R"([{ "name": "a", "run": { "duration": 1 } }])");
  expect_scene_error(dir, "s.json", j, {"variants[0].run: unknown field"});
  j["variants"] = json::parse(R"([{ "name": "a" }, { "name": "a" }])");
  expect_scene_error(dir, "s.json", j, {"variants[1].name: 'a' names two variants"});
  j["variants"] = json::parse(R"([{ "name": "a/b" }])");
  expect_scene_error(dir, "s.json", j, {"variants[0].name: must be 1 to 64 letters"});
}

TEST(SceneErrors, ProxyFields) {
  SceneDir dir;
  auto refused = [&](const std::function<void(json&)>& change, const std::vector<std::string>& parts) {
    json j = make_proxy_scene();
    change(j);
    expect_scene_error(dir, "s.json", j, parts);
  };
  refused([](json& j) { j["proxies"][0]["shape"] = "cone"; },
          {"proxies[0].shape: must be one of \"sphere\", \"capsule\", \"box\", \"plane\", got \"cone\""});
  refused([](json& j) { j["proxies"][0]["radius"] = -0.01; }, {"proxies[0].radius: must be a number > 0, got -0.01"});
  refused([](json& j) { j["proxies"][3]["half_length"] = 0; }, {"proxies[3].half_length: must be a number > 0, got 0"});
  refused([](json& j) { j["proxies"][1]["half_extents"][2] = -1; },
          {"proxies[1].half_extents[2]: must be a number > 0"});
  refused([](json& j) { j["proxies"][1]["radius"] = -1; }, {"proxies[1].radius: must be a number >= 0, got -1"});
  refused([](json& j) { j["proxies"][0]["half_length"] = 0.1; },
          {"proxies[0].half_length: is for a capsule only (shape is \"sphere\")"});
  refused([](json& j) { j["proxies"][2]["radius"] = 0.1; },
          {"proxies[2].radius: is for a sphere, capsule or box only"});
  refused([](json& j) { j["proxies"][0]["colour"] = "red"; }, {"proxies[0].colour: unknown field"});
  refused([](json& j) { j["proxies"][0]["friction"] = -0.1; }, {"proxies[0].friction: must be a number >= 0"});
  refused(
      [](json& j) {
        j["proxies"][1]["orientation"] = json::array({0, 0, 0, 0});
      },
      {"proxies[1].orientation: must be a nonzero quaternion"});
  refused(
      [](json& j) {
        j["proxies"][1]["orientation"] = json::array({1, 0, 0});
      },
      {"proxies[1].orientation: must be a quaternion [w, x, y, z] (4 numbers)"});
  refused([](json& j) { j["proxies"][1].erase("position"); }, {"proxies[1].position: required field missing"});
  refused([](json& j) { j["proxies"][1].erase("device"); }, {"proxies[1].device: required field missing"});
  refused([](json& j) { j["proxies"][1]["device"] = "a,b"; }, {"proxies[1].device: must be 1 to 64 letters"});
  refused([](json& j) { j["proxies"][2]["name"] = "tip"; }, {"proxies[2].name: 'tip' names two proxies"});
  refused([](json& j) { j["proxies"] = json::object(); }, {"proxies: must be an array"});
  refused([](json& j) { j["effects"]["friction"] = 1; }, {"effects.friction: must be true or false, got 1"});
}

TEST(SceneErrors, ProxyScripts) {
  SceneDir dir;
  auto refused = [&](const std::function<void(json&)>& change, const std::vector<std::string>& parts) {
    json j = make_proxy_scene();
    change(j);
    expect_scene_error(dir, "s.json", j, parts);
  };
  refused([](json& j) { j["proxies"][0]["script"]["keyframes"][1]["t"] = 0.1; },
          {"proxies[0].script.keyframes[1].t: must be greater than the previous keyframe's (0.1 s), got 0.1"});
  refused([](json& j) { j["proxies"][0]["script"]["keyframes"][1]["t"] = 0.05; },
          {"proxies[0].script.keyframes[1].t: must be greater than the previous keyframe's"});
  refused([](json& j) { j["hands"][0]["script"]["keyframes"][0]["t"] = -1; },
          {"hands[0].script.keyframes[0].t: must be a number >= 0, got -1"});
  refused([](json& j) { j["proxies"][0]["script"]["keyframes"] = json::array(); },
          {"proxies[0].script.keyframes: must have at least 1 entry"});
  refused([](json& j) { j["proxies"][0]["script"]["easing"] = "bouncy"; },
          {"proxies[0].script.easing: must be one of \"smooth\", \"linear\", got \"bouncy\""});
  refused(
      [](json& j) {
        j["proxies"][0]["script"]["keyframes"][0]["velocity"] = json::array({0, 0, 0});
      },
      {"proxies[0].script.keyframes[0].velocity: unknown field"});
  refused([](json& j) { j["proxies"][0]["script"]["keyframes"][0].erase("position"); },
          {"proxies[0].script.keyframes[0].position: required field missing"});
  refused(
      [](json& j) {
        j["proxies"][0]["position"] = json::array({0, 0, 0});
      },
      {"proxies[0].position: differs from where the script starts, [0.3, 0.12, 0.05]"});
  refused(
      [](json& j) {
        j["hands"][0]["orientation"] = json::array({0, 1, 0, 0});
        j["hands"][0]["script"]["keyframes"][0]["orientation"] = json::array({1, 0, 0, 0});
      },
      {"hands[0].orientation: differs from the script's orientation at t = 0"});
}

TEST(SceneErrors, HandsAndTheirProxies) {
  SceneDir dir;
  auto refused = [&](const std::function<void(json&)>& change, const std::vector<std::string>& parts) {
    json j = make_proxy_scene();
    change(j);
    expect_scene_error(dir, "s.json", j, parts);
  };
  refused([](json& j) { j["proxies"][3]["hand"] = "left"; },
          {"proxies[3].hand: 'left' is not among the hands (they are 'right')"});
  refused(
      [](json& j) {
        j.erase("hands");
        j["proxies"][3]["hand"] = "right";
      },
      {"proxies[3].hand: 'right' is not among the hands (the scene has none)"});
  refused([](json& j) { j["proxies"][4]["device"] = "stylus"; },
          {"proxies[4].device: 'stylus' differs from the device of hand 'right' ('glove')"});
  refused([](json& j) { j["proxies"][3]["script"] = j["proxies"][0]["script"]; },
          {"proxies[3].script: a proxy in a hand moves with it; give the script to hand 'right'"});
  refused(
      [](json& j) {
        j["hands"].push_back(json::parse(R"({ "name": "left", "device": "g2", "position": [0, 0, 0] })"));
      },
      {"hands[1]: no proxy belongs to hand 'left'"});
  refused([](json& j) { j["hands"].push_back(j["hands"][0]); }, {"hands[1].name: 'right' names two hands"});
  refused([](json& j) { j["hands"][0].erase("device"); }, {"hands[0].device: required field missing"});
  refused([](json& j) { j["hands"][0]["fingers"] = 5; }, {"hands[0].fingers: unknown field"});
  refused(
      [](json& j) {
        j["hands"][0].erase("script");
        j["hands"][0].erase("position");
      },
      {"hands[0].position: required field missing"});
  refused([](json& j) { j["variants"] = json::parse(R"([{ "name": "v", "proxies": [] }])"); },
          {"variants[0].proxies: unknown field"});
}

// What the JSON parser refuses is named by the file, its line and column,
// and the field it was reading: a stray comma, a number past a double's
// range (nlohmann's own text named neither), a bad token in a list.
TEST(SceneErrors, NotJson) {
  SceneDir dir;
  const auto error = [&](const std::string& name, const std::string& text) {
    const std::string path = dir.write(name, text);
    try {
      load_scene(path);
    } catch (const SceneError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string comma = error("broken.json", "{ \"name\": \"x\", }");
  EXPECT_NE(comma.find(dir.file("broken.json") + ":1:"), std::string::npos) << comma;
  EXPECT_NE(comma.find("not valid JSON"), std::string::npos) << comma;
  const std::string huge =
      error("huge.json", "{\n  \"name\": \"x\",\n  \"material\": { \"model\": \"stvk\", \"E\": 1e999 }\n}");
  EXPECT_NE(huge.find(dir.file("huge.json") + ":3:"), std::string::npos) << huge;
  EXPECT_NE(huge.find("at material.E: 1e999 is out of range"), std::string::npos) << huge;
  const std::string listed =
      error("list.json", "{ \"proxies\": [ {}, { \"radius\": 0.01, \"position\": [0, 1, nope] } ] }");
  EXPECT_NE(listed.find("at proxies[1].position[2]"), std::string::npos) << listed;
  EXPECT_THROW(load_scene(dir.file("absent.json")), SceneError);
}

}  // namespace
}  // namespace tactile
