// What a recording adds for Foxglove's own panels (proto/RECORDING.md): from
// the messages the recorder writes, JSON messages of Foxglove's well-known
// schemas, which its panels recognise by schema name:
//   /foxglove/body  foxglove.SceneUpdate, one per StateFrame: the body's
//                   boundary as a triangle list, each proxy as a sphere,
//                   capsule (a sphere at its centre) or box, for the 3D panel;
//                   the body coloured (viridis, as the page) by the state's
//                   first field, when it carries one
//                   (a scene of several bodies: an entity "body/<name>" per
//                   body, in its own vertices and colour, and "proxies");
//   /foxglove/surface  foxglove.SceneUpdate, for a scene with an embedded
//                   surface: the fine surface, placed by its binding as the
//                   browser places it (an entity "surface/<name>" per body
//                   in a scene of several), once a second of log time (20 k
//                   triangles are some 0.8 MB of JSON a message: at every
//                   state they were nine tenths of a recording's bytes);
//   /foxglove/log   foxglove.Log, one per SafetyEvent and Error, for the Log
//                   panel;
//   /foxglove/transform  foxglove.FrameTransform, at each scene and once a
//                   second of log time: the scene's frame, y-up, stood
//                   upright in Foxglove's z-up "world" (its 3D panel's
//                   display frame), so that a body does not lie on its side.
// They are views: the replay and the readers use the protocol's channels.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tactile_generated.h"

namespace tactile {

// The JSON Schemas the views' channels carry (written for this project,
// each field named as Foxglove's schemas name it).
const std::string& scene_update_json_schema();
const std::string& log_json_schema();
const std::string& frame_transform_json_schema();

class FoxgloveViews {
 public:
  // Remembers the surface and proxies a StateFrame of this scene places.
  void scene(const proto::SceneDescription& s);
  // The body and proxies at this state, the body coloured by the state's
  // first field when it has one; nothing for a state of another scene than
  // the last described, or of another size.
  std::optional<std::string> body(const proto::StateFrame& f, int64_t log_ns);
  // The fine surface at this state, when the scene has one and a second of
  // log time has passed since the last (the first state of a scene has it).
  std::optional<std::string> surface(const proto::StateFrame& f, int64_t log_ns);
  static constexpr int64_t kSurfaceEveryNs = 1'000'000'000;
  // A log line for a safety event or an error the server answered.
  static std::string log(const proto::SafetyEvent& e, int64_t log_ns);
  static std::string log(const proto::Error& e, int64_t log_ns);
  // The transform that stands the scene upright in Foxglove's z-up world
  // (foxglove.FrameTransform, "world" to "scene").
  static std::string upright(int64_t log_ns);
  static constexpr int64_t kUprightEveryNs = 1'000'000'000;  // (a panel opened mid-file finds one near)

 private:
  struct Proxy {
    proto::ProxyShape shape;
    float radius, half_length;
    float half_extents[3];
  };
  uint32_t scene_id_ = 0;
  bool described_ = false;
  size_t n_vertices_ = 0;
  std::vector<uint32_t> triangles_;
  // An embedded surface: its triangles, and per fine vertex four frame vertices and weights.
  std::vector<uint32_t> fine_triangles_, carriers_;
  std::vector<float> weights_;
  std::optional<int64_t> last_surface_ns_;
  std::vector<Proxy> proxies_;
  std::map<std::string, std::pair<double, double>> field_ranges_;  // per field, the range seen in this scene
  // A scene of several bodies: each one's slices (proto BodyInfo); empty
  // for a scene of one.
  struct Body {
    std::string name;
    uint32_t vertex_begin, vertex_end, triangle_begin, triangle_end;
    uint32_t fine_vertex_begin, fine_vertex_end, fine_triangle_begin, fine_triangle_end;
  };
  std::vector<Body> bodies_;
};

}  // namespace tactile
