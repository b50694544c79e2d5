// The protocol messages the simulation publishes (proto/tactile.fbs), encoded
// from a Simulation into builders that are reused: after the first frames
// have grown their buffers, encoding a frame allocates nothing.
//
// Encoded messages are handed out as std::span, never flatbuffers::span:
// flatbuffers 2.0.8 makes that an alias of std::span or a class of its own
// depending on what a file included before it, so two files could disagree
// on the type (and on how it is returned).
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <flatbuffers/flatbuffers.h>

#include "app/simulation.hpp"
#include "tactile_generated.h"

namespace tactile {

// The body's surface as the viewers see it: the boundary nodes, renumbered
// densely, and the boundary triangles in that numbering.
struct Surface {
  std::vector<uint32_t> nodes;      // simulation node per surface vertex (n_vertices)
  std::vector<uint32_t> triangles;  // outward (n_triangles x 3), surface vertex ids
};
Surface extract_surface(const TetMesh& mesh);

class FrameEncoder {
 public:
  FrameEncoder(const Simulation& sim, std::string scene_name, uint32_t scene_id, double dt);

  const Surface& surface() const { return surface_; }

  // Each returns the encoded Envelope, valid until the same call is made again.
  // haptic_frame() is meant for every step: its forces are the means over
  // the step (see frames.cpp).
  std::span<const uint8_t> scene_description();
  std::span<const uint8_t> state_frame(int64_t server_time_ns);
  std::span<const uint8_t> haptic_frame(int64_t server_time_ns, uint64_t last_input_sequence);

 private:
  const Simulation& sim_;
  std::string scene_name_;
  uint32_t scene_id_;
  double dt_;
  Surface surface_;
  std::vector<double> x_;       // all node positions (n_nodes x 3)
  std::vector<double> u_;       // all node displacements (n_nodes x 3)
  std::vector<float> positions_, scalar_;
  std::vector<proto::ProxyPose> poses_;  // per proxy, staged for the builder
  std::vector<proto::Vec3f> forces_;
  std::vector<proto::ProxyHaptics> proxy_haptics_;
  std::vector<proto::DeviceHaptics> device_haptics_;
  struct Wrench {
    Vec3 force{0.0}, torque{0.0};
  };
  std::vector<Wrench> last_proxy_, last_device_;  // at the previous haptic frame
  flatbuffers::FlatBufferBuilder scene_builder_, state_builder_, haptic_builder_;
};

}  // namespace tactile
