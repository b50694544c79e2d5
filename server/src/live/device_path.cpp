#include "live/device_path.hpp"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>

#include "core/coupling.hpp"

namespace tactile {

namespace {

// The offset may rise by this much per second of device time (clock drift
// is parts per million; a loop that fell behind re-anchors by more, and the
// minimum filter takes the new offset at its first faster input).
constexpr double kDrift = 1e-3;
// How fast the offset rises [s per second of device time] while inputs come
// later than it by more than the playout delay can hold (kMaxDelay): the
// minimum that set it was no transit of the link but a loop catching up on
// a stall, which applies inputs at a time behind the wall clock's. Held at
// kDrift, the path would play ahead of its newest input, extrapolating, for
// seconds after each such stall (bridge_bench.py loop --cases free: the
// coupling then jolts the hand in free space). A single late input moves
// it by a twentieth of its lateness at most.
constexpr double kRecover = 0.05;
// A lag this much below the offset is a stall of the loop's time [s].
constexpr double kStall = 0.01;
// The jitter's memory [s]: a burst of lateness sets the delay for about this
// long. Short: a host stall of tens of milliseconds saturates the delay, and
// a delay held long after it makes a direct (kinematic) loop ring
// (tests/test_bridge_closed_loop.py).
constexpr double kJitterMemory = 0.25;
// The memory of the target's drift [s]: long beside the jitter's bumps, short
// beside a loaded host's changes of pace.
constexpr double kDriftMemory = 0.1;

// The travel x and rate v at s [s] of a move of d from rate v0 that ends at
// rest, time-optimal under a rate limit r and a limit a on the rate's change
// (accelerate, cruise, brake), worked in the direction of travel.
void brake_to(double d, double v0, double s, double r, double a, double& x, double& v) {
  const double braking = v0 * std::fabs(v0) / (2 * a);  // travel to stop now
  const double sign = d > braking ? 1.0 : d < braking ? -1.0 : v0 > 0 ? 1.0 : v0 < 0 ? -1.0 : 0.0;
  x = v = 0;
  if (sign == 0) return;
  const double dist = sign * d, w0 = sign * v0;
  const double vp = std::min(r, std::sqrt(std::max(0.0, a * dist + 0.5 * w0 * w0)));  // the peak rate
  const double a1 = vp >= w0 ? a : -a;
  const double t1 = std::fabs(vp - w0) / a, d1 = (vp * vp - w0 * w0) / (2 * a1);
  const double t3 = vp / a, d3 = vp * vp / (2 * a);
  const double d2 = std::max(0.0, dist - d1 - d3), t2 = vp > 0 ? d2 / vp : 0.0;
  if (s < t1) {
    x = w0 * s + 0.5 * a1 * s * s;
    v = w0 + a1 * s;
  } else if (s < t1 + t2) {
    x = d1 + vp * (s - t1);
    v = vp;
  } else if (s < t1 + t2 + t3) {
    const double u = s - t1 - t2;
    x = d1 + d2 + vp * u - 0.5 * a * u * u;
    v = vp - a * u;
  } else {
    x = d1 + d2 + d3;
  }
  x *= sign;
  v *= sign;
}

}  // namespace

// The target moves on at its drift (a loop that runs behind the device's
// clock lowers it steadily); the lead closes on it from the anchor, in the
// target's frame, within the limits on its rate and the rate's change, so
// that it follows a steady drift without lagging and the path's speed is
// continuous.
DevicePath::Lead DevicePath::lead(double t) const {
  const double s = std::max(0.0, t - anchor_t_);
  const double drift = target_rate_, target = offset_ + jitter_;
  double x, v;
  brake_to(target - anchor_lead_, anchor_rate_ - drift, s, kLeadSlew - std::fabs(drift), kLeadAccel, x, v);
  return {anchor_lead_ + drift * s + x, drift + v};
}

// Whether the device's stamps are a clock: judged at the first input of
// each loop step, by the inputs of the steps before (a burst of late inputs
// is judged once it is whole). A clock that ran less than kSlowestClock of
// the loop's time over kClockWindow (stamps microseconds apart for inputs a
// millisecond apart), or that stepped back kBackwards times, is not one:
// its inputs are timed by the loop's time at which they are applied.
// (Interpolating stamps a microsecond apart, the path raced through a
// millisecond of motion per microsecond played and overshot the device by
// what the loop's speed limit let through.)
void DevicePath::judge_clock(double device_s, double t) {
  if (count_ == 0 || arrival_) return;
  if (device_s < sample(0).device_s) ++backwards_;
  if (t > last_t_) {
    const double span = last_t_ - window_t_;
    if (span >= kClockWindow) {
      if (sample(0).device_s - window_s_ < kSlowestClock * span) arrival_ = true;
      window_t_ = last_t_;
      window_s_ = sample(0).device_s;
    }
  }
  if (backwards_ >= kBackwards) arrival_ = true;
  if (arrival_) count_ = 0;  // a new path, on the loop's time
}

bool DevicePath::add(double device_s, const Pose& pose, double t) {
  judge_clock(device_s, t);
  last_t_ = t;
  if (arrival_) {
    // On the loop's time: a second input of one step is where the device is now.
    if (count_ > 0 && t <= sample(0).device_s) {
      ring_[(count_ - 1) % ring_.size()].pose = pose;
      return false;
    }
    device_s = t;
  }
  const double lag = t - device_s;
  // (The anchor never moves back: an input applied at an earlier time than
  // the one before would let the lead jump by the slew over the difference.)
  const double anchor_t = count_ > 0 ? std::max(t, anchor_t_) : t;
  const Lead now = count_ > 0 ? lead(anchor_t) : Lead{0.0, 0.0};
  bool first = false;
  // A new path: the first input, one after a pause, or one stamped before the
  // newest (a device whose clock restarted, or one that runs backwards: its
  // stamps order nothing, so each such input is where the device is now).
  if (count_ == 0 || device_s - sample(0).device_s > kPause || device_s < sample(0).device_s) {
    if (count_ > 0 && device_s - sample(0).device_s > kPause) {  // after a pause: judged again
      arrival_ = false;
      backwards_ = 0;
    }
    count_ = 0;
    offset_ = lag;
    jitter_ = 0;
    first = true;
    if (!arrival_) {
      window_t_ = t;
      window_s_ = device_s;
    }
  } else {
    const double gap = device_s - sample(0).device_s;
    if (!(gap > 0)) return false;  // stamped as the newest (a repeat): nothing new on the path
    offset_ += kDrift * gap;
    jitter_ *= std::exp(-gap / kJitterMemory);
    if (lag < offset_ - kStall) {
      // The loop's time stood still while the device's ran on (a stall it
      // re-anchored after, or a pause): the path jumps ahead by as much. A
      // new path from here, which the loop glides onto.
      offset_ = lag;
      jitter_ = 0;
      first = true;
    } else if (lag < offset_) {  // the fastest input yet: the others came later than thought
      jitter_ += offset_ - lag;
      offset_ = lag;
    } else if (lag - offset_ > kMaxDelay) {
      offset_ = std::min(lag - kMaxDelay, offset_ + kRecover * gap);
    }
    jitter_ = std::min(kMaxDelay, std::max(jitter_, lag - offset_));
  }
  // The target's drift: its change per second of the loop's time, smoothed
  // (inputs applied at one step add their changes up to the next).
  const double target = offset_ + jitter_;
  if (first) {
    target_rate_ = 0;
    drift_t_ = t;
    drift_target_ = target;
  } else if (t > drift_t_) {
    const double w = 1.0 - std::exp(-(t - drift_t_) / kDriftMemory);
    const double most = 0.5 * kLeadSlew;  // (leaving the lead room to close on it)
    target_rate_ =
        std::clamp(target_rate_ + w * ((target - drift_target_) / (t - drift_t_) - target_rate_), -most, most);
    drift_t_ = t;
    drift_target_ = target;
  }
  anchor_t_ = first ? t : anchor_t;
  anchor_lead_ = first ? target : now.lead;
  anchor_rate_ = first ? 0.0 : now.rate;
  ring_[count_ % ring_.size()] = {device_s, pose};
  ++count_;
  return first;
}

Pose DevicePath::at(double t) const {
  const double tau = t - lead(t).lead;  // device time played out at t
  const Sample& newest = sample(0);
  const size_t kept = std::min(count_, ring_.size());
  if (tau >= newest.device_s) {
    if (kept < 2) return newest.pose;
    // Past the newest: on at its latest velocity for kMaxExtrapolation (a
    // late input, a host that stalled the device's link), then slowing to
    // a stop with a time constant of as long (a device that stopped
    // sending), its velocity never changing at once: a coupled proxy
    // follows this path through a damper, which answers a step of 0.5 m/s
    // with some 3 N.
    const Sample& before = sample(1);
    const double gap = newest.device_s - before.device_s;
    const double past = tau - newest.device_s;
    const double after = past - kMaxExtrapolation;
    const double e =
        (after <= 0 ? past : kMaxExtrapolation + kMaxExtrapolation * (1.0 - std::exp(-after / kMaxExtrapolation))) /
        gap;
    Pose p = newest.pose;
    p.position += e * (newest.pose.position - before.pose.position);
    const Vec3 turn = compute_rotation_vector(before.pose.orientation, newest.pose.orientation);
    const double angle = glm::length(turn);
    if (angle > 0) p.orientation = glm::normalize(glm::angleAxis(e * angle, turn / angle) * newest.pose.orientation);
    return p;
  }
  for (size_t back = 1; back < kept; ++back) {
    const Sample& a = sample(back);
    if (a.device_s > tau) continue;
    const Sample& b = sample(back - 1);
    ProxyMotion m;  // linear between the two around tau, the shortest arc
    m.t0 = a.device_s;
    m.t1 = b.device_s;
    m.from = a.pose;
    m.to = b.pose;
    return m.at(tau);
  }
  return sample(kept - 1).pose;  // before the oldest kept
}

}  // namespace tactile
