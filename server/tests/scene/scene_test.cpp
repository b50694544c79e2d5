// Scene loading: shipped scenes load, fields map onto the core's spec, and
// bad scenes are refused with the file and JSON path of the field at fault.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <numbers>

#include <glm/geometric.hpp>

#include "scene/scene.hpp"
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
  j["loads"] = json::parse(R"([{ "name": "push", "select": { "nodes": [1, 2] }, "force": [0, 1, 0], "ramp": { "duration": 0.2 } }])");
  j["effects"] = json::parse(R"({ "gravity": false, "damping": { "alpha": 1.5 } })");
  j["integrator"] = json::parse(
      R"({ "precision": "float", "dt": 1e-4, "safety": 0.5, "unstable": "refuse", "threads": 2, "energy_tolerance": 0.1 })");
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
  // The tracked point is the nearest node, reported at its rest position.
  ASSERT_EQ(s.track.size(), 1u);
  EXPECT_EQ(s.track[0].X, Vec3(0.4, 0.05, 0.05));
  EXPECT_EQ(s.run.frame_rate, 100);
  EXPECT_EQ(s.run.vtu_every, 1);
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

// ---- refusals: each names the file and the JSON path -----------------------

TEST(SceneErrors, UnknownField) {
  SceneDir dir;
  json j = make_beam_scene();
  j["materal"] = j["material"];
  expect_scene_error(dir, "s.json", j, {"materal: unknown field"});
  j = make_beam_scene();
  j["material"]["young"] = 1;
  expect_scene_error(dir, "s.json", j, {"material.young: unknown field", "allowed here: model, E, nu, rho"});
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
  expect_scene_error(dir, "s.json", j,
                     {"material.model: must be one of \"linear\", \"stvk\", \"corotational\", \"neohookean\", got \"rubber\""});
}

TEST(SceneErrors, SelectorThatSelectsNoNode) {
  SceneDir dir;
  json j = make_beam_scene();
  j["boundary"][0]["select"]["box"] = json{{"lo", {1, 1, 1}}, {"hi", {2, 2, 2}}};
  expect_scene_error(dir, "s.json", j, {"boundary[0].select: selects no node", "the mesh spans [0, 0, 0] to [0.4, 0.1, 0.1]"});
  j = make_beam_scene();
  j["loads"] = json::parse(R"([{ "select": { "plane": { "point": [0, 5, 0], "normal": [0, 1, 0] } }, "force": [0, 1, 0] }])");
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

TEST(SceneErrors, MisplacedAndConflictingFields) {
  SceneDir dir;
  json j = make_beam_scene();
  j["materials"] = json::array({j["material"]});
  expect_scene_error(dir, "s.json", j, {"materials: give \"material\" or \"materials\", not both"});
  j = make_beam_scene();
  j["boundary"][0]["rotate"] = json::parse(R"({ "centre": [0, 0, 0], "axis": [1, 0, 0], "angle_deg": 10, "duration": 1 })");
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
  j["boundary"][0]["rotate"] = json::parse(R"({ "centre": [0, 0, 0], "axis": [0, 0, 0], "angle_deg": 10, "duration": 1 })");
  j["boundary"][0].erase("fixed");
  expect_scene_error(dir, "s.json", j, {"boundary[0].rotate.axis: must be a nonzero vector"});
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

TEST(SceneErrors, NotJson) {
  SceneDir dir;
  const std::string path = dir.write("broken.json", std::string("{ \"name\": \"x\", }"));
  try {
    load_scene(path);
    ADD_FAILURE() << "no error";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find(path + ": not valid JSON: parse error at line 1"), std::string::npos) << e.what();
  }
  EXPECT_THROW(load_scene(dir.file("absent.json")), SceneError);
}

}  // namespace
}  // namespace tactile
