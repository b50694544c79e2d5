// The protocol messages the simulation publishes (proto/tactile.fbs), encoded
// from a Simulation into builders that are reused: after the first frames
// have grown their buffers, encoding a frame without fields allocates nothing.
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

#include "scene/parameters.hpp"
#include "sim/simulation.hpp"
#include "tactile_generated.h"

namespace tactile {

// The bodies as the viewers see them: the frame's vertices, body by body
// (each body's boundary nodes, then the interior nodes its embedded surface
// follows), renumbered densely, the boundary triangles in that numbering,
// and the embedded surface's binding to the frame's vertices.
struct Surface {
  // A body's slices (protocol BodyInfo): [begin, end) of the frame
  // vertices, of the triangles (counted in triangles), of the embedded
  // surface's vertices and triangles; its first node in the scene's mesh.
  struct Body {
    std::string name;
    uint32_t vertex_begin = 0, vertex_end = 0;
    uint32_t triangle_begin = 0, triangle_end = 0;
    uint32_t fine_vertex_begin = 0, fine_vertex_end = 0;
    uint32_t fine_triangle_begin = 0, fine_triangle_end = 0;
    uint32_t node_begin = 0;
  };
  std::vector<uint32_t> nodes;      // simulation node per frame vertex (n_vertices)
  std::vector<uint32_t> triangles;  // outward (n_triangles x 3), frame vertex ids, body by body
  std::vector<uint32_t> carriers;   // embedded: four frame vertices per fine vertex (n_fine x 4)
  std::vector<float> weights;       // embedded: their weights (n_fine x 4)
  std::vector<Body> bodies;         // the scene's order (one for a scene of one body)
};
Surface extract_surface(const Simulation& sim);

// The hand a device channel drives (an index into Simulation::hands()), or -1
// when it drives proxies alone; the live loop moves it, the haptic frames
// report its pose.
int32_t compute_device_hand(const Simulation& sim, int32_t device);

class FrameEncoder {
 public:
  // dt: the simulation step the frames come at [s] (0: 0.7 x the critical
  // step at rest, the live loop's default); force_window: what the haptic
  // frames' forces are averaged over [s] (an even number of steps, at least two).
  FrameEncoder(const Simulation& sim, std::string scene_name, uint32_t scene_id, double dt, double force_window = 1e-3);

  const Surface& surface() const { return surface_; }
  // What the haptic frames' forces are averaged over, in steps.
  size_t force_window_steps() const { return window_steps_; }

  // Each returns the encoded Envelope, valid until the same call is made again.
  // With the parameters a controller may set and the scenes it may load.
  std::span<const uint8_t> scene_description(std::span<const Parameter> parameters = {},
                                             std::span<const std::string> scenes = {});
  // With the per-vertex fields `fields` names (none: none computed).
  std::span<const uint8_t> state_frame(int64_t server_time_ns, ViewFieldMask fields = 0);
  // After every advance: adds its mean contact forces (impulse over time
  // since the simulation's last clear_impulses(), which the caller then
  // clears) to the force window.
  void add_step_forces();
  // After a step, every step or every few: its forces are the means over the
  // force window (see frames.cpp). last_input_sequence: the newest DeviceInput sequence
  // across all channels; input_sequences: the newest per channel (n_devices;
  // channels past its end read 0). device_offsets: per channel, how far
  // its coupled body's target stands off its device's path (the loop's
  // approach, [m]; channels past its end: none): a coupled channel that stands
  // off it by more than a millimetre is sent no stiffness (frames.cpp).
  std::span<const uint8_t> haptic_frame(int64_t server_time_ns, uint64_t last_input_sequence,
                                        std::span<const uint64_t> input_sequences = {},
                                        std::span<const Vec3> device_offsets = {});

 private:
  const Simulation& sim_;
  std::string scene_name_;
  uint32_t scene_id_;
  double dt_;
  Surface surface_;
  std::vector<float> positions_;
  // Per-vertex fields (state_frame), made on the first frame that asks: the
  // tets around the frame's vertices, and per vertex (field_start_, CSR) its
  // tets (an index into field_tets_) and their share of its volume.
  void build_field_map();
  std::vector<int32_t> field_tets_;
  std::vector<uint32_t> field_start_, field_entry_;
  std::vector<float> field_weight_;
  std::vector<float> field_values_[kViewFieldCount];
  std::vector<proto::ProxyPose> poses_;  // per proxy, staged for the builder
  std::vector<proto::Vec3f> forces_;
  std::vector<proto::ProxyHaptics> proxy_haptics_;
  std::vector<proto::DeviceHaptics> device_haptics_;
  std::vector<proto::ProxyPose> device_poses_;             // per device channel, staged for the builder
  std::vector<proto::ProxyPose> state_device_poses_;       // the same, for the state frames' builder
  std::vector<uint64_t> input_sequences_;                  // per device channel
  std::vector<proto::DeviceCoupling> device_couplings_;    // per device channel
  std::vector<proto::DeviceModel> device_models_;          // per device channel
  std::vector<double> model_radius_;                       // per device channel, DeviceModel.radius_m [m]
  std::vector<int32_t> contacts_proxy_, contacts_device_;  // the most contacts of a step since the last haptic frame
  std::vector<double> touched_;  // per device channel, the time its proxy last touched the body [s]
  // What each device channel's pose is: its hand (>= 0), else its first proxy.
  std::vector<int32_t> device_hand_, device_proxy_;  // (n_devices)
  struct Wrench {
    Vec3 force{0.0}, torque{0.0};
  };
  // The latest per-step forces (a ring of window_steps_ rows) and their sums.
  size_t window_steps_ = 1, window_next_ = 0, window_filled_ = 0;
  std::vector<Wrench> window_proxy_, window_device_, sum_proxy_, sum_device_;
  flatbuffers::FlatBufferBuilder scene_builder_, state_builder_, haptic_builder_;
};

}  // namespace tactile
