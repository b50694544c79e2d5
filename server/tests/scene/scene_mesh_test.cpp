// The `mesh` field: primitives, surface files through TetGen, .node/.ele
// files, scale and translate, and the gate against inverted (folded) tets.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include <glm/geometric.hpp>

#include "mesh/mesh_io.hpp"
#include "mesh/primitives.hpp"
#include "scene/scene_mesh.hpp"
#include "scene_fixtures.hpp"

namespace tactile {
namespace {

using nlohmann::json;
using test::expect_scene_error;
using test::SceneDir;

double total_volume(const TetMesh& m) {
  double v = 0;
  for (const Tet& t : m.tets)
    v += compute_tet_volume(m.X[size_t(t[0])], m.X[size_t(t[1])], m.X[size_t(t[2])], m.X[size_t(t[3])]);
  return v;
}

// A scene around a given mesh object, with nothing else that needs nodes.
json scene_with_mesh(const json& mesh) {
  return json{{"mesh", mesh},
              {"material", {{"model", "stvk"}, {"E", 1e5}, {"nu", 0.3}, {"rho", 1000}}},
              {"run", {{"duration", 0.1}}}};
}

// A unit box [0, 1]^3 mesh whose central node is pushed far across some of
// the tets around it, inverting a few (fewer than half); returns their ids.
TetMesh make_pushed_box(std::vector<int32_t>* inverted) {
  const int32_t centre = 1 + 3 * (1 + 3 * 1);
  for (const Vec3& to : {Vec3(0.95, 0.5, 0.5), Vec3(0.9, 0.2, 0.5), Vec3(0.8, 0.1, 0.3), Vec3(0.95, 0.05, 0.9)}) {
    TetMesh m = make_box(Vec3(0.0), Vec3(1.0), {2, 2, 2});
    EXPECT_EQ(m.X[size_t(centre)], Vec3(0.5));
    m.X[size_t(centre)] = to;
    inverted->clear();
    for (int32_t e = 0; e < m.n_tets(); ++e) {
      const Tet& t = m.tets[size_t(e)];
      if (compute_tet_volume(m.X[size_t(t[0])], m.X[size_t(t[1])], m.X[size_t(t[2])], m.X[size_t(t[3])]) < 0)
        inverted->push_back(e);
    }
    if (!inverted->empty() && inverted->size() * 2 < size_t(m.n_tets())) return m;
  }
  ADD_FAILURE() << "no push inverts a few tets";
  return {};
}

TEST(FoldedTets, NoneInSoundMeshes) {
  EXPECT_TRUE(compute_folded_tets(make_box(Vec3(0.0), Vec3(1.0, 2.0, 3.0), {3, 4, 5})).empty());
  EXPECT_TRUE(compute_folded_tets(make_box(Vec3(0.0), Vec3(1.0), {2, 2, 2}, BoxSplit::centred24)).empty());
  EXPECT_TRUE(compute_folded_tets(make_cylinder(0.1, 0.3, 12, 4, 2)).empty());
}

TEST(FoldedTets, FindsTetsInvertedAndThenReoriented) {
  std::vector<int32_t> inverted;
  TetMesh m = make_pushed_box(&inverted);
  ASSERT_FALSE(inverted.empty());
  ASSERT_LT(inverted.size() * 2, size_t(m.n_tets()));
  // What a reader that orients each tet on its own makes of them.
  for (int32_t e : inverted) std::swap(m.tets[size_t(e)][1], m.tets[size_t(e)][2]);
  EXPECT_EQ(compute_folded_tets(m), inverted);
}

TEST(SceneMesh, NodeEleWithAnInvertedTetIsRefusedByTetId) {
  SceneDir dir;
  std::vector<int32_t> inverted;
  const TetMesh m = make_pushed_box(&inverted);
  write_tetgen(m, dir.file("pushed"));
  std::string ids;
  for (size_t i = 0; i < inverted.size(); ++i) ids += (i ? ", " : "") + std::to_string(inverted[i]);
  const std::string what =
      inverted.size() == 1 ? "1 inverted tet (id " : std::to_string(inverted.size()) + " inverted tets (ids ";
  expect_scene_error(dir, "s.json", scene_with_mesh(json{{"file", "pushed.node"}}),
                     {"mesh: mesh refused: " + what + ids + ")"});
}

TEST(SceneMesh, NodeEleFileLoads) {
  SceneDir dir;
  const TetMesh m = make_box(Vec3(0.0), Vec3(0.2, 0.1, 0.1), {4, 2, 2});
  write_tetgen(m, dir.file("beam"));
  const Scene s = load_scene(dir.write_json("s.json", scene_with_mesh(json{{"file", "beam.ele"}}))).at(0);
  EXPECT_EQ(s.spec.mesh.X, m.X);
  EXPECT_EQ(s.spec.mesh.tets, m.tets);
  expect_scene_error(dir, "t.json", scene_with_mesh(json{{"file", "beam.node"}, {"tetgen", {{"max_volume", 1}}}}),
                     {"mesh.tetgen: applies to surface files"});
}

TEST(SceneMesh, SurfaceFileGoesThroughTetgen) {
  SceneDir dir;
  // The unit cube, outward-wound.
  dir.write(
      "cube.obj",
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
      "f 1 4 3\nf 1 3 2\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n");
  json mesh{{"file", "cube.obj"}, {"tetgen", {{"max_volume", 0.01}}}, {"scale", 0.5}, {"translate", {1, 2, 3}}};
  const Scene s = load_scene(dir.write_json("s.json", scene_with_mesh(mesh))).at(0);
  EXPECT_GE(s.spec.mesh.n_tets(), 13);  // no tet above 0.01 m^3 before scaling
  EXPECT_NEAR(total_volume(s.spec.mesh), 0.125, 1e-12);
  const Aabb box = compute_aabb(s.spec.mesh.X);
  EXPECT_NEAR(glm::length(box.lo - Vec3(1, 2, 3)), 0.0, 1e-12);
  EXPECT_NEAR(glm::length(box.hi - Vec3(1.5, 2.5, 3.5)), 0.0, 1e-12);
  mesh["tetgen"]["max_radius_edge_ratio"] = 0.5;
  expect_scene_error(dir, "t.json", scene_with_mesh(mesh), {"mesh.tetgen.max_radius_edge_ratio: must be 0"});
}

TEST(SceneMesh, PrimitivesHaveTheirVolumes) {
  SceneDir dir;
  const Scene box =
      load_scene(
          dir.write_json(
              "b.json",
              scene_with_mesh(json::parse(
                  R"({ "primitive": "box", "lo": [0, 0, 0], "hi": [1, 2, 3], "cells": [1, 2, 3], "split": "centred24", "scale": [2, 1, 0.5] })"))))
          .at(0);
  EXPECT_EQ(box.spec.mesh.n_tets(), 6 * 24);
  EXPECT_NEAR(total_volume(box.spec.mesh), 6.0, 1e-12);  // scaled by 2 * 1 * 0.5
  const Scene cyl =
      load_scene(
          dir.write_json(
              "c.json",
              scene_with_mesh(json::parse(
                  R"({ "primitive": "cylinder", "radius": 0.1, "height": 0.3, "around": 16, "layers": 3, "rings": 2 })"))))
          .at(0);
  EXPECT_NEAR(total_volume(cyl.spec.mesh), 8.0 * 0.01 * std::sin(2 * std::numbers::pi / 16) * 0.3, 1e-12);
  const Scene ball =
      load_scene(
          dir.write_json("s.json",
                         scene_with_mesh(json::parse(
                             R"({ "primitive": "sphere", "centre": [0, 1, 0], "radius": 0.2, "resolution": 2 })"))))
          .at(0);
  const double v = total_volume(ball.spec.mesh), exact = 4.0 / 3.0 * std::numbers::pi * 0.008;
  EXPECT_LT(v, exact);  // inscribed polyhedron
  EXPECT_GT(v, 0.9 * exact);
  expect_scene_error(dir, "e.json", scene_with_mesh(json::parse(R"({ "primitive": "cone", "radius": 1 })")),
                     {"mesh.primitive: must be one of \"box\", \"cylinder\", \"sphere\", got \"cone\""});
  expect_scene_error(
      dir, "e.json",
      scene_with_mesh(json::parse(R"({ "primitive": "sphere", "centre": [0, 0, 0], "radius": 1, "resolution": 9 })")),
      {"mesh.resolution: must be an integer in 0..6"});
  expect_scene_error(
      dir, "e.json",
      scene_with_mesh(json::parse(R"({ "primitive": "box", "lo": [0, 0, 0], "hi": [1, 0, 1], "cells": [1, 1, 1] })")),
      {"mesh.hi: must exceed lo in every axis"});
}

}  // namespace
}  // namespace tactile

namespace tactile {
namespace {

// The `surface` field: a fine surface file bound to the body, scaled and moved as the mesh is, its errors by field.
TEST(SceneSurface, AFileIsBoundToTheBodyAndSharedByVariants) {
  SceneDir dir;
  // An octahedron in the unit box, wound inward (the loader winds it outward), poking 1 cm out of the top.
  dir.write("gem.obj",
            "v 0.5 1.01 0.5\nv 0.5 0.1 0.5\nv 0.1 0.5 0.5\nv 0.9 0.5 0.5\nv 0.5 0.5 0.1\nv 0.5 0.5 0.9\n"
            "f 1 3 5\nf 1 5 4\nf 1 4 6\nf 1 6 3\nf 2 5 3\nf 2 4 5\nf 2 6 4\nf 2 3 6\n");
  json j = scene_with_mesh(json{{"primitive", "box"}, {"lo", {0, 0, 0}}, {"hi", {2, 2, 2}}, {"cells", {4, 4, 4}}});
  j["mesh"]["scale"] = 0.5;
  j["surface"] = json{{"file", "gem.obj"}, {"max_outside", 0.02}};
  j["variants"] = json::array({json{{"name", "soft"}}, json{{"name", "stiff"}, {"material", {{"E", 1e6}}}}});
  const std::vector<Scene> scenes = load_scene(dir.write_json("s.json", j));
  ASSERT_EQ(scenes.size(), 2u);
  const auto& e = scenes[0].spec.surface;
  ASSERT_TRUE(e);
  EXPECT_EQ(e.get(), scenes[1].spec.surface.get());  // bound once
  EXPECT_EQ(e->n_vertices(), 6);
  EXPECT_NEAR(e->outside[0], 0.01, 1e-7);  // (Assimp reads coordinates as float)
  double volume = 0;
  for (const Tri& t : e->rest.triangles)
    volume += glm::dot(e->rest.vertices[size_t(t[0])],
                       glm::cross(e->rest.vertices[size_t(t[1])], e->rest.vertices[size_t(t[2])])) /
              6;
  EXPECT_GT(volume, 0);  // wound outward
  // Too far out for the bound, and for the default one (2 % of the 1.73 m diagonal is 3.5 cm: a 5 cm poke).
  j["surface"]["max_outside"] = 0.005;
  expect_scene_error(dir, "t.json", j, {"surface: vertex 0 at (0.5, 1.01, 0.5) is outside the body: 0.01"});
  j["surface"].erase("max_outside");
  j["surface"]["translate"] = {0, 0.04, 0};
  expect_scene_error(dir, "t.json", j, {"surface: vertex 0", "(the default: 2 % of the body's size)"});
  j["surface"] = json{{"file", "nothing.obj"}};
  expect_scene_error(dir, "t.json", j, {"surface.file: no such file"});
  j["surface"] = json{{"file", "gem.vtk"}};
  expect_scene_error(dir, "t.json", j, {"surface.file: unknown surface file extension '.vtk'"});
  j["surface"] = json{{"file", "gem.obj"}, {"shade", "smooth"}};
  expect_scene_error(dir, "t.json", j, {"surface.shade: unknown field"});
}

}  // namespace
}  // namespace tactile
