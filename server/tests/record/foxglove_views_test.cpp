// Foxglove's views of the body: the boundary as the frame has it, and, for a
// scene with an embedded surface, the fine surface placed by its binding as
// the browser places it (x = sum_k w_k x_{c_k}), once a second.
#include "record/foxglove_views.hpp"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "tactile_generated.h"

namespace tactile {
namespace {

// Builds a message of type T (an object API type) and returns its bytes.
template <class T>
std::vector<uint8_t> bytes_of(const T& m) {
  flatbuffers::FlatBufferBuilder b;
  b.Finish(T::TableType::Pack(b, &m));
  return {b.GetBufferPointer(), b.GetBufferPointer() + b.GetSize()};
}

proto::SceneDescriptionT tetrahedron_scene() {
  proto::SceneDescriptionT s;
  s.scene_id = 7;
  s.rest_positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  s.triangles = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
  return s;
}

proto::StateFrameT moved_frame() {
  proto::StateFrameT f;
  f.scene_id = 7;
  f.positions = {0.5f, 0, 0, 2, 0, 0, 0.5f, 1, 0, 0.5f, 0, 3};
  return f;
}

// The triangle list of a view, or null when there is none.
nlohmann::json triangles_of(const std::optional<std::string>& text) {
  return text ? nlohmann::json::parse(*text)["entities"][0]["triangles"][0] : nlohmann::json();
}

struct Views {
  FoxgloveViews views;
  std::vector<uint8_t> state;
  Views(const proto::SceneDescriptionT& s, const proto::StateFrameT& f) : state(bytes_of(f)) {
    const std::vector<uint8_t> scene = bytes_of(s);
    views.scene(*flatbuffers::GetRoot<proto::SceneDescription>(scene.data()));
  }
  const proto::StateFrame& frame() const { return *flatbuffers::GetRoot<proto::StateFrame>(state.data()); }
};

nlohmann::json view_of(const proto::SceneDescriptionT& s, const proto::StateFrameT& f) {
  Views v(s, f);
  return triangles_of(v.views.body(v.frame(), 1));
}

TEST(FoxgloveViews, WithoutAnEmbeddedSurfaceTheBoundaryIsDrawnAsTheFrameHasIt) {
  const nlohmann::json t = view_of(tetrahedron_scene(), moved_frame());
  ASSERT_EQ(t["points"].size(), 4u);
  EXPECT_DOUBLE_EQ(t["points"][1]["x"].get<double>(), 2.0);
  EXPECT_DOUBLE_EQ(t["points"][3]["z"].get<double>(), 3.0);
  EXPECT_EQ(t["indices"].get<std::vector<uint32_t>>(), tetrahedron_scene().triangles);
}

proto::SceneDescriptionT embedded_scene() {
  proto::SceneDescriptionT s = tetrahedron_scene();
  s.embedded = std::make_unique<proto::EmbeddedSurfaceT>();
  // Three fine vertices: the centroid, a vertex at node 1, one outside (a negative weight).
  s.embedded->rest_positions = {0.25f, 0.25f, 0.25f, 1, 0, 0, -0.5f, 0, 0};
  s.embedded->triangles = {0, 1, 2};
  s.embedded->carriers = {0, 1, 2, 3, 1, 0, 2, 3, 0, 1, 2, 3};
  s.embedded->weights = {0.25f, 0.25f, 0.25f, 0.25f, 1, 0, 0, 0, 1.5f, -0.5f, 0, 0};
  return s;
}

TEST(FoxgloveViews, AnEmbeddedSurfaceIsPlacedByItsWeightsOnceASecond) {
  Views v(embedded_scene(), moved_frame());
  // The body stays the boundary, every state.
  EXPECT_EQ(triangles_of(v.views.body(v.frame(), 1))["points"].size(), 4u);
  const nlohmann::json t = triangles_of(v.views.surface(v.frame(), 1000));
  ASSERT_EQ(t["points"].size(), 3u);
  EXPECT_EQ(t["indices"].get<std::vector<uint32_t>>(), (std::vector<uint32_t>{0, 1, 2}));
  const double expected[3][3] = {{(0.5 + 2 + 0.5 + 0.5) / 4, 0.25, 0.75}, {2, 0, 0}, {1.5 * 0.5 - 0.5 * 2, 0, 0}};
  for (int k = 0; k < 3; ++k)
    for (int d = 0; d < 3; ++d)
      EXPECT_NEAR(t["points"][k][std::string(1, char('x' + d))].get<double>(), expected[k][d], 1e-6) << k << d;
  // Not again before a second of log time has passed; then again.
  EXPECT_FALSE(v.views.surface(v.frame(), 1000 + FoxgloveViews::kSurfaceEveryNs - 1).has_value());
  EXPECT_TRUE(v.views.surface(v.frame(), 1000 + FoxgloveViews::kSurfaceEveryNs).has_value());
}

TEST(FoxgloveViews, NoSurfaceWithoutOneOrWithABindingThatReadsPastTheFrame) {
  Views plain(tetrahedron_scene(), moved_frame());
  EXPECT_FALSE(plain.views.surface(plain.frame(), 1).has_value());
  proto::SceneDescriptionT s = embedded_scene();
  s.embedded->carriers[3] = 9;  // no frame vertex 9
  Views bad(s, moved_frame());
  EXPECT_FALSE(bad.views.surface(bad.frame(), 1).has_value());
  EXPECT_EQ(triangles_of(bad.views.body(bad.frame(), 1))["points"].size(), 4u);
}

// Two tetrahedra, "a" then "b", each a body of its own; the second moved by 10 along x.
proto::SceneDescriptionT two_bodies() {
  proto::SceneDescriptionT s = tetrahedron_scene();
  const std::vector<float> rest = s.rest_positions;
  const std::vector<uint32_t> triangles = s.triangles;
  for (size_t k = 0; k < rest.size(); ++k) s.rest_positions.push_back(rest[k] + (k % 3 == 0 ? 10.0f : 0.0f));
  for (uint32_t v : triangles) s.triangles.push_back(v + 4);
  for (uint32_t b = 0; b < 2; ++b) {
    auto body = std::make_unique<proto::BodyInfoT>();
    body->name = std::string(1, char('a' + b));
    body->vertex_begin = 4 * b;
    body->vertex_end = 4 * b + 4;
    body->triangle_begin = 4 * b;
    body->triangle_end = 4 * b + 4;
    s.bodies.push_back(std::move(body));
  }
  return s;
}

proto::StateFrameT two_bodies_frame() {
  proto::StateFrameT f;
  f.scene_id = 7;
  f.positions = two_bodies().rest_positions;
  f.positions[3 * 5 + 1] = 2.0f;  // b's second vertex moved up
  return f;
}

TEST(FoxgloveViews, ASceneOfSeveralBodiesHasAnEntityPerBodyInItsOwnVertices) {
  Views v(two_bodies(), two_bodies_frame());
  const std::optional<std::string> text = v.views.body(v.frame(), 1);
  ASSERT_TRUE(text.has_value());
  const nlohmann::json entities = nlohmann::json::parse(*text)["entities"];
  ASSERT_EQ(entities.size(), 3u);
  EXPECT_EQ(entities[0]["id"], "body/a");
  EXPECT_EQ(entities[1]["id"], "body/b");
  EXPECT_EQ(entities[2]["id"], "proxies");
  const nlohmann::json b = entities[1]["triangles"][0];
  ASSERT_EQ(b["points"].size(), 4u);
  EXPECT_DOUBLE_EQ(b["points"][0]["x"].get<double>(), 10.0);
  EXPECT_DOUBLE_EQ(b["points"][1]["y"].get<double>(), 2.0);
  EXPECT_EQ(b["indices"].get<std::vector<uint32_t>>(), tetrahedron_scene().triangles);  // in b's own numbering
  EXPECT_NE(entities[0]["triangles"][0]["color"], b["color"]);
}

TEST(FoxgloveViews, BodiesWhoseSlicesDoNotFitAreDrawnAsOne) {
  proto::SceneDescriptionT s = two_bodies();
  s.triangles[0] = 5;  // a's first triangle reaches into b
  Views v(s, two_bodies_frame());
  const nlohmann::json entities = nlohmann::json::parse(*v.views.body(v.frame(), 1))["entities"];
  ASSERT_EQ(entities.size(), 1u);
  EXPECT_EQ(entities[0]["id"], "body");
  EXPECT_EQ(entities[0]["triangles"][0]["points"].size(), 8u);
}

}  // namespace
}  // namespace tactile
