// What a controller changes in a live session: the scene that runs, its
// reset, and its parameters. Each change builds a whole new LiveScene (model,
// stepper, encoder, loop) off the simulation thread, so that neither meshing
// nor model building ever stalls a step; the simulation thread then switches
// to it between two steps. A parameter change carries the body over
// (Simulation::continue_from); a load or a reset starts from rest with a new
// scene id, which every frame carries, so a client can tell the timelines apart.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "live/frames.hpp"
#include "live/outbox.hpp"
#include "live/realtime.hpp"
#include "scene/scene.hpp"
#include "sim/simulation.hpp"

namespace tactile {

struct LiveOptions {
  std::optional<double> dt;  // the step [s]; unset: the scene's fixed step, else 0.7 x the critical step at rest
  double state_rate_hz = 30;
  double haptic_rate_hz = 0;   // haptic frames per second at most (0: after every step)
  double force_window = 1e-3;  // haptic forces are means over this [s], and at least over the frame interval
};

// One scene running live. Built on any thread; once handed to a Director,
// its loop runs on the simulation thread and the rest is read-only to others.
class LiveScene {
 public:
  // Builds the model from scene.spec: throws ModelError for a spec the core refuses.
  LiveScene(Scene scene, uint32_t id, const LiveOptions& options);

  const Scene& scene() const { return scene_; }
  uint32_t id() const { return id_; }
  Simulation& sim() { return sim_; }
  const Simulation& sim() const { return sim_; }
  FrameEncoder& frames() { return frames_; }
  RealtimeLoop& loop() { return loop_; }
  const RealtimeLoop& loop() const { return loop_; }

  // The SceneDescription: surface, proxies, devices, the parameters and
  // their values, and the scenes a controller may load. Reads only what does
  // not change while the loop runs; call from one thread at a time.
  std::vector<uint8_t> describe(std::span<const std::string> scenes);

  // Gives the scene its outbox (live/outbox.hpp), sized for its frames, as
  // the loop's sinks; `wakeup` is signalled after each frame. Before the
  // loop runs. A scene run otherwise (a re-simulation) sets its own sinks.
  void publish(std::shared_ptr<Wakeup> wakeup);
  Outbox* outbox() { return outbox_.get(); }  // null until published

 private:
  Scene scene_;
  uint32_t id_;
  Simulation sim_;
  FrameEncoder frames_;
  RealtimeLoop loop_;
  std::unique_ptr<Outbox> outbox_;
};

class Director {
 public:
  using Installed = std::function<void(const std::shared_ptr<LiveScene>&)>;

  // Publishes `first` (LiveScene::publish) and every scene it builds, all
  // waking wakeup().
  explicit Director(std::shared_ptr<LiveScene> first);
  ~Director();  // waits for a scene being built
  Director(const Director&) = delete;
  Director& operator=(const Director&) = delete;

  // Where a Load finds scenes (the JSON files of the folder, not the
  // schema; "" for none) and how the scenes it builds run. Set before the
  // first change.
  void set_library(const std::string& scenes_dir, const LiveOptions& options);
  const std::vector<std::string>& scenes() const { return scenes_; }  // the names a Load may give

  // A change a controller (or the server, after a fault) asks for.
  struct Change {
    enum class Kind { Reset, Load, Parameter } kind = Kind::Reset;
    std::string scene;      // Load: one of scenes()
    std::string parameter;  // Parameter: its name (scene/parameters.hpp)
    double value = 0;
  };
  // The answer to a change, called once (unless the director stops first):
  // with the scene installed (on the simulation thread, before its first
  // step), or with what went wrong (the scene null, on the builder thread:
  // the build failed, or a later replacement took its place before it ran).
  using Done = std::function<void(std::shared_ptr<LiveScene> installed, const std::string& error)>;
  // Checks the change, builds its scene on a thread of the director's own
  // (meshing and model building take from milliseconds to seconds: never on
  // the network's or the simulation's thread), publishes it and installs it
  // between two steps. Returns "" when the build started, else why not (a
  // scene it lacks, a parameter the scene refuses; `busy` is set when a
  // build is still under way), and then `done` is never called. A parameter
  // change carries the body on in the same timeline with the same scene id;
  // a reset or a load (and a parameter change after a fault, when there is
  // no body to carry) starts from rest with a new id.
  std::string request(const Change& change, Done done, bool* busy = nullptr);
  void finish_building();  // waits for the scene being built, if any

  // The eventfd every published scene signals after each frame.
  const std::shared_ptr<Wakeup>& wakeup() const { return wakeup_; }

  // From any thread: the per-vertex fields the state frames carry besides
  // each scene's own (the viewers'), for the running scene and every one
  // installed after it.
  void set_view_fields(ViewFieldMask extra);

  // From any thread: the scene the simulation thread runs (or is about to).
  std::shared_ptr<LiveScene> current() const;

  // From any thread: switch to `next` between two steps. With `carry`, next
  // takes over the current body and proxies (same mesh required). The
  // paused state carries over either way. A replacement not yet installed
  // is itself replaced (its `done` told so). `done`, if set, is called once
  // with `next` once it is installed.
  void replace(std::shared_ptr<LiveScene> next, bool carry, Done done = nullptr);

  // Called on the simulation thread after each switch, before the new
  // scene's first step. Set before run().
  void on_installed(Installed f) { installed_ = std::move(f); }

  // Runs on the simulation thread until `stop` is set or `duration` of
  // simulated time has run over all scenes. A fault stops the scene's
  // steps (the loop's stats name it) until a replacement comes; with a finite
  // duration, it ends the run.
  void run(const std::atomic<bool>& stop, double duration = std::numeric_limits<double>::infinity());

  // The fault that stopped the current scene, "" if it runs.
  std::string fault() const;

 private:
  std::string scenes_dir_;
  std::vector<std::string> scenes_;
  LiveOptions options_;
  uint32_t next_id_;
  std::thread builder_;
  std::atomic<bool> building_{false};
  std::shared_ptr<Wakeup> wakeup_ = std::make_shared<Wakeup>();

  mutable std::mutex mutex_;
  std::shared_ptr<LiveScene> current_, next_;
  bool carry_ = false;
  Done next_done_;
  ViewFieldMask extra_fields_ = 0;
  std::atomic<bool> faulted_{false};
  Installed installed_;
};

}  // namespace tactile
