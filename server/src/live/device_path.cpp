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
// A lag this much below the offset is a stall of the loop's time [s].
constexpr double kStall = 0.01;
// The jitter's memory [s]: a burst of lateness sets the delay for about this
// long. Short: a host stall of tens of milliseconds saturates the delay, and
// a delay held long after it makes a direct (kinematic) loop ring
// (tests/test_bridge_closed_loop.py).
constexpr double kJitterMemory = 0.25;

}  // namespace

double DevicePath::lead(double t) const {
  const double most = kLeadSlew * std::max(0.0, t - anchor_t_);
  return anchor_lead_ + std::clamp(offset_ + jitter_ - anchor_lead_, -most, most);
}

bool DevicePath::add(double device_s, const Pose& pose, double t) {
  const double lag = t - device_s;
  // (The anchor never moves back: an input applied at an earlier time than
  // the one before would let the lead jump by the slew over the difference.)
  const double anchor_t = count_ > 0 ? std::max(t, anchor_t_) : t;
  const double lead_now = count_ > 0 ? lead(anchor_t) : 0.0;
  bool first = false;
  if (count_ == 0 || std::fabs(device_s - sample(0).device_s) > kPause) {
    count_ = 0;  // a new path: the first input, or one after a pause (or a device that restarted its clock)
    offset_ = lag;
    jitter_ = 0;
    first = true;
  } else {
    const double gap = device_s - sample(0).device_s;
    if (!(gap > 0)) return false;  // no later than the newest: nothing new on the path
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
    }
    jitter_ = std::min(kMaxDelay, std::max(jitter_, lag - offset_));
  }
  anchor_t_ = first ? t : anchor_t;
  anchor_lead_ = first ? offset_ + jitter_ : lead_now;
  ring_[count_ % ring_.size()] = {device_s, pose};
  ++count_;
  return first;
}

Pose DevicePath::at(double t) const {
  const double tau = t - lead(t);  // device time played out at t
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
