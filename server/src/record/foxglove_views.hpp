// What a recording adds for Foxglove's own panels (proto/RECORDING.md): from
// the messages the recorder writes, JSON messages of Foxglove's well-known
// schemas, which its panels recognise by schema name:
//   /foxglove/body  foxglove.SceneUpdate, one per StateFrame: the body's
//                   surface as a triangle list (the fine surface it carries,
//                   placed by its binding, when the scene has one; else its
//                   boundary), each proxy as a sphere,
//                   capsule (a sphere at its centre) or box, for the 3D panel;
//   /foxglove/log   foxglove.Log, one per SafetyEvent and Error, for the Log
//                   panel.
// They are views: the replay and the readers use the protocol's channels.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tactile_generated.h"

namespace tactile {

// The JSON Schemas the views' channels carry (written for this project:
// the fields it fills, named as Foxglove's schemas name them).
std::string_view scene_update_json_schema();
std::string_view log_json_schema();

class FoxgloveViews {
 public:
  // Remembers the surface and proxies a StateFrame of this scene places.
  void scene(const proto::SceneDescription& s);
  // The body and proxies at this state; nothing for a state of another
  // scene than the last described, or of another size.
  std::optional<std::string> body(const proto::StateFrame& f, int64_t log_ns) const;
  // A log line for a safety event or an error the server answered.
  static std::string log(const proto::SafetyEvent& e, int64_t log_ns);
  static std::string log(const proto::Error& e, int64_t log_ns);

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
  // An embedded surface: per fine vertex, four frame vertices and weights.
  std::vector<uint32_t> carriers_;
  std::vector<float> weights_;
  std::vector<Proxy> proxies_;
};

}  // namespace tactile
