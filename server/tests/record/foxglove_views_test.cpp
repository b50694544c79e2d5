// Foxglove's view of the body: the boundary as the frame has it, or, for a
// scene with an embedded surface, the fine surface placed by its binding as
// the browser places it (x = sum_k w_k x_{c_k}).
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

nlohmann::json view_of(const proto::SceneDescriptionT& s, const proto::StateFrameT& f) {
  FoxgloveViews views;
  const std::vector<uint8_t> scene = bytes_of(s), state = bytes_of(f);
  views.scene(*flatbuffers::GetRoot<proto::SceneDescription>(scene.data()));
  const std::optional<std::string> text = views.body(*flatbuffers::GetRoot<proto::StateFrame>(state.data()), 1);
  EXPECT_TRUE(text.has_value());
  return text ? nlohmann::json::parse(*text)["entities"][0]["triangles"][0] : nlohmann::json();
}

TEST(FoxgloveViews, WithoutAnEmbeddedSurfaceTheBoundaryIsDrawnAsTheFrameHasIt) {
  const nlohmann::json t = view_of(tetrahedron_scene(), moved_frame());
  ASSERT_EQ(t["points"].size(), 4u);
  EXPECT_DOUBLE_EQ(t["points"][1]["x"].get<double>(), 2.0);
  EXPECT_DOUBLE_EQ(t["points"][3]["z"].get<double>(), 3.0);
  EXPECT_EQ(t["indices"].get<std::vector<uint32_t>>(), tetrahedron_scene().triangles);
}

TEST(FoxgloveViews, AnEmbeddedSurfaceIsPlacedByItsWeights) {
  proto::SceneDescriptionT s = tetrahedron_scene();
  s.embedded = std::make_unique<proto::EmbeddedSurfaceT>();
  // Three fine vertices: the centroid, a vertex at node 1, one outside (a negative weight).
  s.embedded->rest_positions = {0.25f, 0.25f, 0.25f, 1, 0, 0, -0.5f, 0, 0};
  s.embedded->triangles = {0, 1, 2};
  s.embedded->carriers = {0, 1, 2, 3, 1, 0, 2, 3, 0, 1, 2, 3};
  s.embedded->weights = {0.25f, 0.25f, 0.25f, 0.25f, 1, 0, 0, 0, 1.5f, -0.5f, 0, 0};
  const proto::StateFrameT f = moved_frame();
  const nlohmann::json t = view_of(s, f);
  ASSERT_EQ(t["points"].size(), 3u);
  EXPECT_EQ(t["indices"].get<std::vector<uint32_t>>(), (std::vector<uint32_t>{0, 1, 2}));
  const double expected[3][3] = {{(0.5 + 2 + 0.5 + 0.5) / 4, 0.25, 0.75}, {2, 0, 0}, {1.5 * 0.5 - 0.5 * 2, 0, 0}};
  for (int v = 0; v < 3; ++v)
    for (int d = 0; d < 3; ++d)
      EXPECT_NEAR(t["points"][v][std::string(1, char('x' + d))].get<double>(), expected[v][d], 1e-6) << v << d;
}

TEST(FoxgloveViews, ABindingThatReadsPastTheFrameFallsBackToTheBoundary) {
  proto::SceneDescriptionT s = tetrahedron_scene();
  s.embedded = std::make_unique<proto::EmbeddedSurfaceT>();
  s.embedded->rest_positions = {0, 0, 0};
  s.embedded->triangles = {0, 0, 0};
  s.embedded->carriers = {0, 1, 2, 9};  // no frame vertex 9
  s.embedded->weights = {0.25f, 0.25f, 0.25f, 0.25f};
  const nlohmann::json t = view_of(s, moved_frame());
  EXPECT_EQ(t["points"].size(), 4u);
  EXPECT_EQ(t["indices"].get<std::vector<uint32_t>>(), tetrahedron_scene().triangles);
}

}  // namespace
}  // namespace tactile
