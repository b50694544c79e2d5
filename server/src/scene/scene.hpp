// Scene files: JSON (schema: server/scenes/scene.schema.json), SI units, y up.
//
// A scene names one body (a mesh, materials, boundary conditions, loads) or
// several ("bodies", each with its own), rigid proxies
// and hands (with their scripted motions), the effects it wants, integrator
// settings and what a headless run records. Loading is
// strict: an unknown field, a wrong type or an out-of-range value throws
// SceneError naming the file and the JSON path of the field at fault, e.g.
//   cantilever.json: integrator.dt: must be "auto" or a number > 0, got -1
// and a mesh with inverted or degenerate tets is refused naming the tets.
// Keep this loader and the schema in agreement (tests/test_scenes_schema.py).
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "core/fields.hpp"
#include "core/spec.hpp"
#include "mesh/quality.hpp"

namespace tactile {

struct SceneError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A point whose motion a run reports: the node of its body nearest to `point`.
struct TrackedPoint {
  std::string name;
  Vec3 point{0.0};    // as asked [m]
  int32_t body = 0;   // index into spec.bodies (0 in a one-body scene)
  int32_t node = -1;  // nearest node id, in the spec's mesh (the body's first node + its own id)
  Vec3 X{0.0};        // rest position of that node [m]
};

// A plane through the body at rest; a run reports the area of the deformed
// material section it cuts (the paper's Fig. 2 is about this area).
struct SectionPlane {
  std::string name;
  Vec3 point{0.0};             // a point of the plane at rest [m]
  Vec3 normal{0.0, 1.0, 0.0};  // unit normal
};

// A scripted motion of a proxy or a hand: world poses at keyframes, eased
// between them; before the first keyframe and after the last, the pose
// holds. Scripts live here, not in the core: the core is told one
// ProxyMotion per control interval (core/proxy.hpp).
struct PoseScript {
  enum class Easing : uint8_t {
    Smooth,  // cycloidal ease in and out per segment: zero velocity at every keyframe
    Linear,  // constant velocity per segment
  };
  struct Keyframe {
    double t = 0;  // [s], strictly increasing
    Pose pose;     // world
  };
  Easing easing = Easing::Smooth;
  std::vector<Keyframe> keys;  // at least one

  Pose at(double t) const;
  // The core's motion over [t0, t1]: from at(t0) to at(t1), linear in between.
  ProxyMotion motion(double t0, double t1) const;
};

struct RunSettings {
  double duration = 1.0;     // simulated time [s]
  double frame_rate = 30.0;  // output frames per simulated second [Hz]
  int32_t vtu_every = 1;     // a VTU file every this many frames
  // Optional VTU arrays, computed only because the scene asks for them:
  // "cauchy_stress", "green_strain", "von_mises", "principal_stretches" (cell data) and
  // "contact_force" (point data).
  ElementFieldRequest vtu_cells;
  bool vtu_contact_force = false;
  std::vector<SectionPlane> sections;
};

struct Scene {
  std::string name, description;
  std::string path;  // the scene file, as given
  ModelSpec spec;    // what the core builds
  // Scripted motions, by index into spec.proxies and spec.hands; a proxy or
  // hand with none holds its pose. A scripted one's pose at t = 0 in spec is
  // its script's.
  std::vector<std::optional<PoseScript>> proxy_script;  // (n_proxies)
  std::vector<std::optional<PoseScript>> hand_script;   // (n_hands)
  RunSettings run;
  std::vector<TrackedPoint> track;
  std::string variant;  // "" when the scene has no variants
  MeshQuality quality;  // of spec.mesh; poor tets are allowed and listed here
  // "view.fields": per-vertex fields the live server's state frames carry
  // whether or not a viewer asks (none by default: none computed).
  ViewFieldMask view_fields = 0;
  // The scene's JSON (every variant's) as it was parsed, so that a copy of
  // it can be made elsewhere (a pickled Scene, on a Dask worker).
  std::string source;
};

// Reads and checks a scene file; one entry per variant (one when it has none).
// Throws SceneError.
std::vector<Scene> load_scene(const std::string& path);

// The same from parsed JSON; `path` names the file in messages and anchors
// relative mesh paths.
std::vector<Scene> parse_scene(const nlohmann::json& j, const std::string& path);

// The variant named `variant` of the scenes loaded from `path`. Throws
// SceneError naming the variants there are.
Scene pick_variant(std::vector<Scene> scenes, const std::string& variant, const std::string& path);

}  // namespace tactile
