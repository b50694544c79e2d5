#include "live/realtime.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <thread>

#include <glm/common.hpp>

#include <sys/prctl.h>

namespace tactile {

namespace {

// A stall longer than this is not caught up on: the loop re-anchors its
// clock and says so, rather than running a burst of steps faster than real time.
constexpr double kMaxBacklog = 0.05;  // [s]
// How fast a proxy's pose glides onto its device's path when the path
// starts away from it (DevicePath::add).
constexpr double kApproachSpeed = 0.25;  // [m/s]
// A device's motion as the simulation takes it is no faster than this
// (a hand's fastest strike): an input that jumps (a glitch, a device
// re-homed, a stranger's input) is taken up by the approach, as a new path
// is, instead of sweeping a kinematic proxy through the body in one step or
// flinging a coupled one across the workspace at its coupling's limit.
constexpr double kMaxDeviceSpeed = 3.0;  // [m/s]
constexpr double kMaxJump = 0.5e-3;      // [m]
// The workspace: the body's rest bounds, widened on every side by its
// largest extent and at least this much.
constexpr double kWorkspaceMargin = 0.5;  // [m]

double seconds(RealtimeLoop::Clock::duration d) { return std::chrono::duration<double>(d).count(); }

int64_t nanoseconds(RealtimeLoop::Clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
}

}  // namespace

DeviceSample device_sample(const proto::DeviceInput& in, int32_t device, const DeviceDrive& drive) {
  const proto::Vec3d& p = *in.position();
  const proto::Quatd& q = *in.orientation();
  DeviceSample s;
  s.device = device;
  s.sequence = in.sequence();
  s.device_time_ns = in.device_time_ns();
  s.pose.position = Vec3(p.x(), p.y(), p.z());
  const double qn = std::sqrt(q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z());
  s.pose.orientation = Quat(q.w() / qn, q.x() / qn, q.y() / qn, q.z() / qn);
  s.buttons = in.buttons();
  s.drive = drive;
  return s;
}

int format_applied(const AppliedInput& a, char* buf, size_t size) {
  int n =
      std::snprintf(buf, size, R"({"loop_step":%lld,"device":%d,"sequence":%llu)", static_cast<long long>(a.loop_step),
                    int(a.device), static_cast<unsigned long long>(a.sequence));
  if (a.drive.direct)
    n += std::snprintf(buf + n, size - size_t(n), R"(,"direct":true)");
  else if (a.drive.has_limits)  // %.17g: the limits read back to the same bits
    n += std::snprintf(buf + n, size - size_t(n), R"(,"limits":[%.17g,%.17g,%.17g])", a.drive.limits.max_force,
                       a.drive.limits.max_torque, a.drive.limits.stiffness);
  n += std::snprintf(buf + n, size - size_t(n), "}");
  return n;
}

RealtimeLoop::RealtimeLoop(Simulation& sim, FrameEncoder& frames, const RealtimeOptions& options)
    : sim_(sim),
      frames_(frames),
      dt_(options.dt > 0 ? options.dt : 0.7 * sim.dt_rest()),
      state_period_(1.0 / std::max(options.state_rate_hz, 1e-3)),
      inputs_(options.input_capacity) {
  if (options.haptic_rate_hz > 0)
    haptic_every_ = std::max<int64_t>(1, int64_t(std::ceil(1.0 / (options.haptic_rate_hz * dt_) - 1e-9)));
  sim.set_probe(&pass_timer_);
  Vec3 lo(std::numeric_limits<double>::infinity()), hi(-std::numeric_limits<double>::infinity());
  for (const Vec3& X : sim.mesh().X) {
    lo = glm::min(lo, X);
    hi = glm::max(hi, X);
  }
  const Vec3 size = hi - lo;
  const double margin = std::max({kWorkspaceMargin, size.x, size.y, size.z});
  workspace_lo_ = lo - Vec3(margin);
  workspace_hi_ = hi + Vec3(margin);
  const std::vector<std::string>& devices = sim.devices();
  drivers_.resize(devices.size());
  device_sequences_.resize(devices.size());
  device_offsets_.assign(devices.size(), Vec3(0.0));
  for (size_t d = 0; d < devices.size(); ++d) {
    Driver& drv = drivers_[d];
    drv.hand = compute_device_hand(sim, int32_t(d));
    for (size_t j = 0; j < sim.proxies().size(); ++j)
      if (sim.proxy_device()[j] == int32_t(d) && sim.proxies()[j].hand.empty()) drv.proxies.push_back(int32_t(j));
    // Coupled from the start, with the scene's coupling (a body carried over
    // from a rebuilt model keeps the coupling it had).
    if (!sim.device_coupled(int32_t(d))) sim.couple_device(int32_t(d), nullptr);
  }
  sync_drivers();
}

void RealtimeLoop::sync_drivers() {
  for (Driver& drv : drivers_) {
    if (drv.hand >= 0) {
      drv.motion = hold(sim_.hand_pose(drv.hand));
      sim_.set_hand_motion(drv.hand, drv.motion);
    } else if (!drv.proxies.empty()) {
      drv.motion = hold(sim_.proxy_pose(drv.proxies.front()));
      for (int32_t j : drv.proxies) sim_.set_proxy_motion(j, hold(sim_.proxy_pose(j)));
    }
  }
}

bool RealtimeLoop::post_input(const DeviceSample& sample) {
  if (sample.device < 0 || size_t(sample.device) >= drivers_.size() || !inputs_.push(sample)) {
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  return true;
}

void RealtimeLoop::apply_inputs() {
  DeviceSample s;
  int64_t applied = 0;
  const double t = sim_.time();
  while (inputs_.pop(s)) {
    Driver& drv = drivers_[size_t(s.device)];
    if (!(s.drive == drv.drive)) {  // a device with its own limits, or one that drives directly
      if (s.drive.direct)
        sim_.release_device(s.device);
      else
        sim_.couple_device(s.device, s.drive.has_limits ? &s.drive.limits : nullptr);
      drv.drive = s.drive;
    }
    // An input outside the workspace is held at its edge (the server says so
    // to the device: Connection::on_input, net/connection.cpp); the path is never farther than that.
    s.pose.position = glm::clamp(s.pose.position, workspace_lo_, workspace_hi_);
    // A new path (the device's first input, or one after a pause) may start
    // far from where its proxy waits: the proxy's pose glides onto it.
    if (drv.path.add(1e-9 * double(s.device_time_ns), s.pose, t))
      drv.approach = drv.motion.at(t).position - drv.path.at(t).position;
    last_sequence_ = std::max(last_sequence_, s.sequence);
    device_sequences_[size_t(s.device)] = s.sequence;  // the latest, even when a restarted bridge counts from 1 again
    if (applied_sink_) applied_sink_({loop_steps_, s.device, s.sequence, s.drive});
    ++applied;
  }
  if (applied) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_.inputs_applied += applied;
  }
  // Every step, each driven channel's motion over the step: its device's
  // path (device_path.hpp) plus what remains of the approach, which shrinks
  // at kApproachSpeed (a coupled proxy pulled onto a far path in one step
  // would be pulled at the coupling's limit). What a hand could not do joins
  // the approach: a jump of the path between steps past kMaxJump (a far new
  // path, a stranger's input; a late input's small correction of the past
  // is taken as it is), and motion within a step faster than kMaxDeviceSpeed.
  const double t1 = t + dt_;
  for (Driver& drv : drivers_) {
    if (drv.path.empty()) continue;
    Pose path_t = drv.path.at(t), path_t1 = drv.path.at(t1);  // (extrapolated past an input: kept in the workspace)
    path_t.position = glm::clamp(path_t.position, workspace_lo_, workspace_hi_);
    path_t1.position = glm::clamp(path_t1.position, workspace_lo_, workspace_hi_);
    ProxyMotion m;
    m.t0 = t;
    m.t1 = t1;
    m.from = path_t;
    m.from.position += drv.approach;
    const Vec3 left_at = drv.motion.at(t).position;  // where the last step left it
    if (glm::distance(m.from.position, left_at) > kMaxJump) {
      drv.approach += left_at - m.from.position;
      m.from.position = left_at;
    }
    const double left = glm::length(drv.approach);
    if (left > 0) drv.approach *= std::max(0.0, left - kApproachSpeed * dt_) / left;
    m.to = path_t1;
    m.to.position += drv.approach;
    const Vec3 step = m.to.position - m.from.position;
    const double most = kMaxDeviceSpeed * dt_, length = glm::length(step);
    if (length > most) {  // faster than a hand
      m.to.position = m.from.position + step * (most / length);
      drv.approach = m.to.position - path_t1.position;
    }
    device_offsets_[size_t(&drv - drivers_.data())] = drv.approach;
    drv.motion = m;
    if (drv.hand >= 0) sim_.set_hand_motion(drv.hand, m);
    for (int32_t j : drv.proxies) sim_.set_proxy_motion(j, m);
  }
}

void RealtimeLoop::step_once(int64_t now_ns) {
  ++loop_steps_;
  const AdvanceReport report = sim_.advance(dt_);
  if (report.fault) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_.fault = report.fault.message;
    return;
  }
  frames_.add_step_forces();
  sim_.clear_impulses();
  const bool haptic = ++since_haptic_ >= haptic_every_;
  if (haptic) {
    since_haptic_ = 0;
    if (haptic_sink_) haptic_sink_(frames_.haptic_frame(now_ns, last_sequence_, device_sequences_, device_offsets_));
  }
  bool state = false;
  if (sim_.time() + 1e-12 >= next_state_) {
    next_state_ += state_period_;
    if (state_sink_) state_sink_(frames_.state_frame(now_ns, view_fields()));
    state = true;
  }
  std::lock_guard<std::mutex> lock(stats_mutex_);
  if (haptic) ++stats_.haptic_frames;
  if (state) ++stats_.state_frames;
}

void RealtimeLoop::run(const std::atomic<bool>& stop, double duration) {
  // This thread's sleeps end within a microsecond of their deadline, not 50.
  prctl(PR_SET_TIMERSLACK, 1000UL, 0UL, 0UL, 0UL);
  const double sim_start = sim_.time();
  Clock::time_point anchor = Clock::now();  // wall time of simulated time `anchor_sim`
  double anchor_sim = sim_start;
  begin(nanoseconds(anchor));

  const Clock::time_point start = anchor;
  Clock::time_point window_start = start;
  double window_sim = sim_start, cost_sum = 0, cost_max = 0;
  int64_t window_steps = 0, missed = 0, reanchors = 0;
  while (!stop.load(std::memory_order_relaxed) && !interrupt_.exchange(false, std::memory_order_relaxed) &&
         sim_.time() - sim_start < duration) {
    if (paused_.load(std::memory_order_relaxed)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      anchor = Clock::now();  // on resume, real time runs on from here
      anchor_sim = sim_.time();
      continue;
    }
    // The step to t + dt may start once the wall clock has reached t + dt.
    const double target = sim_.time() + dt_ - anchor_sim;
    const Clock::time_point due =
        anchor + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(target));
    Clock::time_point now = Clock::now();
    if (now < due) {
      // Slept, not spun: the wake-up comes tens of microseconds late on a
      // busy or virtual machine, which the absolute schedule makes up on
      // the next step, and a spin would take from the bridge and the browser
      // beside the server the time a step leaves, all of it where a step is
      // short. scripts/run.sh with client-web/bench/round_trip.mjs shows
      // what they get.
      std::this_thread::sleep_until(due);
    } else {
      const double late = seconds(now - due);
      if (late > dt_) ++missed;
      if (late > kMaxBacklog) {  // give up on the backlog: real time from here on
        anchor = now;
        anchor_sim = sim_.time() + dt_;
        ++reanchors;
      }
    }
    // The inputs first, then the stamp: a frame is never stamped before an
    // input it saw (a thread preempted between the two would make it so).
    const Clock::time_point t0 = Clock::now();
    apply_inputs();
    step_once(nanoseconds(Clock::now()));
    const Clock::time_point t1 = Clock::now();
    const double cost = seconds(t1 - t0);
    cost_sum += cost;
    cost_max = std::max(cost_max, cost);
    ++window_steps;

    std::lock_guard<std::mutex> lock(stats_mutex_);
    stats_.steps = sim_.steps();
    stats_.sim_time = sim_.time() - sim_start;
    stats_.clock = sim_.time();
    stats_.wall_time = seconds(t1 - start);
    stats_.missed_deadlines = missed;
    stats_.reanchors = reanchors;
    stats_.inputs_dropped = dropped_.load(std::memory_order_relaxed);
    const bool first_window = stats_.real_time_factor == 0 && seconds(t1 - window_start) >= 0.1;
    if (first_window) {  // provisional figures until the first full second
      stats_.real_time_factor = (sim_.time() - window_sim) / seconds(t1 - window_start);
      stats_.step_mean_us = 1e6 * cost_sum / double(window_steps);
      stats_.step_max_us = 1e6 * cost_max;
    }
    if (seconds(t1 - window_start) >= 1.0) {
      const std::array<double, kPassCount> passes = pass_timer_.take();
      for (int p = 0; p < kPassCount; ++p) stats_.pass_ns[size_t(p)] = 1e9 * passes[size_t(p)] / double(window_steps);
      stats_.real_time_factor = (sim_.time() - window_sim) / seconds(t1 - window_start);
      stats_.step_mean_us = 1e6 * cost_sum / double(window_steps);
      stats_.step_max_us = 1e6 * cost_max;
      window_start = t1;
      window_sim = sim_.time();
      cost_sum = cost_max = 0;
      window_steps = 0;
    }
    if (!stats_.fault.empty()) break;
  }
  // A run shorter than the window still reports its figures.
  std::lock_guard<std::mutex> lock(stats_mutex_);
  if (window_steps > 0 && stats_.real_time_factor == 0) {
    const double wall = seconds(Clock::now() - window_start);
    stats_.real_time_factor = wall > 0 ? (sim_.time() - window_sim) / wall : 0;
    stats_.step_mean_us = 1e6 * cost_sum / double(window_steps);
    stats_.step_max_us = 1e6 * cost_max;
  }
}

void RealtimeLoop::begin(int64_t stamp_ns) {
  sync_drivers();
  next_state_ = sim_.time();
  if (state_sink_) state_sink_(frames_.state_frame(stamp_ns, view_fields()));
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++stats_.state_frames;
  }
  next_state_ += state_period_;
}

RealtimeStats RealtimeLoop::stats() const {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  RealtimeStats s = stats_;
  s.inputs_dropped = dropped_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace tactile
