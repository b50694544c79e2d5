// The live simulation loop: steps the body paced to the monotonic clock,
// moves the proxies from the device inputs that reach it through a bounded
// lock-free queue, and publishes an encoded haptic frame after every step (or
// every few, when the step is shorter than the haptic rate needs) and a state
// frame at the state rate, without waiting for anyone who reads them.
//
// Pacing: the step to simulated time t starts only once the wall clock (from
// the loop's start) has reached t, so a published state is never ahead of
// real time; it is late by the cost of its step. A step that starts more
// than one step late is a missed deadline, counted and reported; after a
// stall of more than kMaxBacklog the loop re-anchors instead of racing to
// catch up. The real-time factor is simulated over wall time per second.
//
// Device inputs: a sample gives the pose of its device at its device's
// clock. The samples make a path, played out a little late and interpolated
// (a jitter buffer, live/device_path.hpp), so the pose moves smoothly at
// every step between 1 kHz inputs, however the network bunches them. Every channel's proxy (or hand) is
// coupled to it (core/coupling.hpp), with the scene's coupling until a
// sample brings its device's limits; a device that asks to drive directly
// moves its proxy kinematically along that path instead.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <limits>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "live/device_path.hpp"
#include "live/frames.hpp"
#include "live/spsc_ring.hpp"
#include "sim/simulation.hpp"

namespace tactile {

// How a device drives its channel, from its Hello: through the virtual
// coupling (core/coupling.hpp) within the limits it renders, or directly
// (the proxy kinematic, where the device is).
struct DeviceDrive {
  bool direct = false;
  bool has_limits = false;
  DeviceLimits limits;  // when has_limits
  bool operator==(const DeviceDrive& o) const {
    return direct == o.direct && has_limits == o.has_limits && limits.max_force == o.limits.max_force &&
           limits.max_torque == o.limits.max_torque && limits.stiffness == o.limits.stiffness;
  }
};

struct DeviceSample {
  int32_t device = -1;         // index into Simulation::devices()
  uint64_t sequence = 0;       // increasing per device
  int64_t device_time_ns = 0;  // the bridge's clock
  Pose pose;                   // scene frame
  uint32_t buttons = 0;
  DeviceDrive drive;  // its device's, from its Hello
};

// The sample a checked DeviceInput (net/inbound.cpp) becomes: the one
// conversion the live server and a re-simulation share, so that both move
// the proxy by the same bits.
DeviceSample device_sample(const proto::DeviceInput& in, int32_t device, const DeviceDrive& drive = {});

// An input the loop applied: which one, and before which of its steps (a
// recording keeps these, so that a re-simulation applies the same inputs at
// the same steps).
struct AppliedInput {
  int64_t loop_step;  // steps this loop had taken when it applied the input
  int32_t device;
  uint64_t sequence;
  DeviceDrive drive;  // how its device drove the channel
};

// The recording's /applied message for an input (proto/RECORDING.md), JSON,
// written into buf (256 bytes are enough); returns its length. The drive is
// written only when it is not the default (coupled, the scene's coupling).
int format_applied(const AppliedInput& a, char* buf, size_t size);

struct RealtimeOptions {
  // Step [s]; 0 picks 0.7 x the critical step at rest: under the stepper's
  // own limit (safety 0.9 x the current critical step, which stiffening
  // lowers) with room to spare, so that a step is one sub-step, not two.
  double dt = 0;
  double state_rate_hz = 30;  // state frames per simulated second
  // Haptic frames per simulated second at most: one every ceil(1 / (rate x
  // dt)) steps; 0: after every step. Every step's force still counts: the
  // encoder's force window spans at least the interval between frames.
  double haptic_rate_hz = 0;
  size_t input_capacity = 4096;  // queued device samples before new ones are dropped
};

struct RealtimeStats {
  int64_t steps = 0;
  double sim_time = 0;          // [s] since the loop started
  double clock = 0;             // the simulation's own time [s] (goes on across a parameter change)
  double wall_time = 0;         // [s] since the loop started
  double real_time_factor = 0;  // over the latest second of wall time
  double step_mean_us = 0;      // step cost over the latest second
  double step_max_us = 0;
  int64_t missed_deadlines = 0;  // steps started over one step late
  int64_t reanchors = 0;         // stalls the loop gave up catching up on
  int64_t inputs_applied = 0;
  int64_t inputs_dropped = 0;  // queue full
  int64_t state_frames = 0;
  int64_t haptic_frames = 0;
  // Mean time per step in each pass of the stepper over the latest second
  // [ns]: the cost of each effect (a pass the scene does not ask for is 0).
  std::array<double, kPassCount> pass_ns{};
  std::string fault;  // the fault that stopped the loop, if any
};

class RealtimeLoop {
 public:
  using Clock = std::chrono::steady_clock;
  using Sink = std::function<void(std::span<const uint8_t> message)>;

  RealtimeLoop(Simulation& sim, FrameEncoder& frames, const RealtimeOptions& options);

  double dt() const { return dt_; }
  // Steps between haptic frames (1: every step).
  int64_t haptic_every() const { return haptic_every_; }
  // Called on the simulation thread with each encoded message; must not block.
  void on_haptic(Sink sink) { haptic_sink_ = std::move(sink); }
  void on_state(Sink sink) { state_sink_ = std::move(sink); }
  // Called on the simulation thread with each input as it is applied; must not block.
  void on_applied(std::function<void(const AppliedInput&)> sink) { applied_sink_ = std::move(sink); }

  // From one producer thread: queues a device's pose; false (and counted)
  // when the queue is full or the device unknown.
  bool post_input(const DeviceSample& sample);

  // Runs on the calling thread until `stop` is set, interrupt() is called,
  // `duration` of simulated time has passed, or a step faults. Each run
  // starts its proxies from where the simulation has them (held there until
  // the next input), its clock from now.
  void run(const std::atomic<bool>& stop, double duration = std::numeric_limits<double>::infinity());
  // From any thread: the current (or next) run returns after its step.
  void interrupt() { interrupt_.store(true, std::memory_order_relaxed); }

  // Unpaced, on one thread, for a re-simulation: begin() does what run()
  // does at its start (holds the proxies where they are, publishes the
  // first state); step() applies the queued inputs and takes one step,
  // publishing as run() does, stamped `stamp_ns`. Not with run().
  void begin(int64_t stamp_ns);
  void step(int64_t stamp_ns) {
    apply_inputs();
    step_once(stamp_ns);
  }
  int64_t loop_steps() const { return loop_steps_; }
  // Where a device may drive its proxy: the body's rest bounds widened by
  // its largest extent (0.5 m at least); inputs outside are held at the edge.
  Vec3 workspace_lo() const { return workspace_lo_; }
  Vec3 workspace_hi() const { return workspace_hi_; }

  // A snapshot, from any thread (updated every step; the per-second figures
  // once a second).
  RealtimeStats stats() const;

  // From any thread: holds the simulation (no steps, no frames) until
  // resumed; simulated time then goes on from where it stopped.
  void set_paused(bool paused) { paused_.store(paused, std::memory_order_relaxed); }
  bool paused() const { return paused_.load(std::memory_order_relaxed); }

  // From any thread: the per-vertex fields the state frames carry from the
  // next one on (the viewers' and the scene's; none: none computed).
  void set_view_fields(ViewFieldMask fields) { view_fields_.store(fields, std::memory_order_relaxed); }
  ViewFieldMask view_fields() const { return view_fields_.load(std::memory_order_relaxed); }

 private:
  struct Driver {                  // what one device channel moves
    int32_t hand = -1;             // the hand it drives, or -1
    std::vector<int32_t> proxies;  // else the proxies it drives alone
    ProxyMotion motion;            // its motion over the latest step
    DevicePath path;               // its device's pose, from its inputs
    Vec3 approach{0.0};            // how far the motion still stands off the path [m]
    DeviceDrive drive;             // as the simulation has it
  };
  Vec3 workspace_lo_{0.0}, workspace_hi_{0.0};
  // Per device: how far its motion stands off its device's path (the
  // approach still to glide), taken off the pose its haptic frames report.
  std::vector<Vec3> device_offsets_;
  void sync_drivers();
  void apply_inputs();
  // One step after the inputs are applied; its frames stamped `now_ns`.
  void step_once(int64_t now_ns);

  // Times the stepper's passes (the core reads no clock; this layer does).
  class PassTimer final : public StepProbe {
   public:
    void enter(Pass) override { t0_ = Clock::now(); }
    void leave(Pass p) override { total_[size_t(p)] += std::chrono::duration<double>(Clock::now() - t0_).count(); }
    std::array<double, kPassCount> take() {
      const std::array<double, kPassCount> out = total_;
      total_ = {};
      return out;
    }

   private:
    Clock::time_point t0_;
    std::array<double, kPassCount> total_{};
  };
  PassTimer pass_timer_;

  Simulation& sim_;
  FrameEncoder& frames_;
  double dt_;
  double state_period_;
  Sink haptic_sink_, state_sink_;
  std::function<void(const AppliedInput&)> applied_sink_;
  int64_t loop_steps_ = 0;  // step_once calls
  SpscRing<DeviceSample> inputs_;
  std::vector<Driver> drivers_;
  uint64_t last_sequence_ = 0;              // the newest input's sequence, across channels
  std::vector<uint64_t> device_sequences_;  // the newest input's sequence per channel (n_devices)
  double next_state_ = 0;
  int64_t haptic_every_ = 1, since_haptic_ = 0;

  mutable std::mutex stats_mutex_;
  RealtimeStats stats_;
  std::atomic<int64_t> dropped_{0};
  std::atomic<bool> paused_{false};
  std::atomic<ViewFieldMask> view_fields_{0};
  std::atomic<bool> interrupt_{false};
};

}  // namespace tactile
