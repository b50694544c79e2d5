// A device's pose as a path in the loop's time, from its inputs: a jitter
// buffer. Each input carries the device's clock; the path plays them out a
// little late, interpolated between the two around the playout time, so an
// input that comes late or bunched with others neither stalls the path nor
// makes it jump. A coupled proxy follows this path through a stiff spring
// (core/coupling.hpp): a path that stalled for 2 ms behind a device moving
// at 0.5 m/s would pull on the hand with 2 N.
//
// Clocks: the loop's time minus the device's is the input's lag; the
// smallest lag seen lately is the clocks' offset (a minimum filter, as NTP
// keeps, let rise slowly so that drift cannot leave it stale), and how much
// later than that inputs come (their jitter, a peak that decays over a
// quarter of a second, at most kMaxDelay) is the playout delay. Their sum
// is the lead the path aims for: it drifts while a loaded loop runs behind
// the device's clock (at 0.75 of real time, by a quarter of a second each
// second), and the lead follows that drift, closing on the rest, its rate
// held to kLeadSlew and the rate's change to kLeadAccel. So the playout
// never steps back and its pace changes smoothly: a late input that raised
// the delay by 1 ms at once would step a device moving at 0.5 m/s back by
// 0.5 mm, a 1 N jolt through a 2000 N/m coupling; a pace that changed by
// 5 % at once would change the path's velocity by 25 mm/s in a step, which
// the coupling's damper passes to the hand as a 0.2 N tick; and a lead that
// trailed a drifting target would leave the proxy tens of milliseconds
// behind the hand. Past the newest input the path goes on at the device's
// latest velocity for kMaxExtrapolation, then slows to a stop with that
// time constant: a silent device's path stands at most its speed times
// twice kMaxExtrapolation past where it said it was.
//
// Pure: the loop gives it its time; a re-simulation that applies the same
// inputs at the same steps gets the same path, bit for bit.
#pragma once

#include <array>
#include <cstddef>

#include "core/proxy.hpp"

namespace tactile {

class DevicePath {
 public:
  static constexpr double kMaxDelay = 0.003;         // the playout delay at most [s]
  static constexpr double kMaxExtrapolation = 0.01;  // past the newest input, at its velocity [s]
  static constexpr double kPause = 0.1;              // inputs this far apart start a new path [s]
  // How fast the playout's lead may change [s/s]: a loop at half the
  // device's pace at the most (the playout then runs at 1.5 times the loop's).
  static constexpr double kLeadSlew = 0.5;
  // How fast that rate may change [1/s]: a path at 0.5 m/s then accelerates
  // by 1 m/s^2 at most, which a 10 g proxy follows with 0.01 N. Guarded by
  // bridge_bench.py loop --cases free,default --loaded (docs/perf.md).
  static constexpr double kLeadAccel = 2.0;
  // A device's stamps are judged as a clock over this much of the loop's
  // time [s]; one that ran less than kSlowestClock of it, or that stepped
  // back kBackwards times, is not a clock: its inputs are timed by when the
  // loop applies them (judge_clock()).
  static constexpr double kClockWindow = 0.02;
  static constexpr double kSlowestClock = 0.25;
  static constexpr int kBackwards = 3;

  // An input taken at device time `device_s` [s], applied at loop time `t` [s].
  // Returns true when it starts a new path (the first, after a pause, one
  // stamped before the newest, or after the loop's time stood still for a
  // while: its path jumped ahead).
  bool add(double device_s, const Pose& pose, double t);
  bool empty() const { return count_ == 0; }
  // The device's pose on the path at loop time t.
  Pose at(double t) const;
  double delay() const { return jitter_; }        // [s]
  bool on_loop_time() const { return arrival_; }  // the device's stamps were judged no clock

 private:
  struct Sample {
    double device_s;
    Pose pose;
  };
  const Sample& sample(size_t back) const { return ring_[(count_ - 1 - back) % ring_.size()]; }
  std::array<Sample, 32> ring_{};
  size_t count_ = 0;
  // The playout's lead (loop time minus the device time played out) [s] and
  // its rate [s/s] at loop time t: from the anchor toward offset_ + jitter_,
  // arriving at rest, at the fastest the limits kLeadSlew and kLeadAccel allow.
  struct Lead {
    double lead, rate;
  };
  Lead lead(double t) const;
  void judge_clock(double device_s, double t);
  bool arrival_ = false;                // inputs timed by the loop's time (the stamps are no clock)
  int backwards_ = 0;                   // inputs stamped before the newest, on this clock
  double last_t_ = 0;                   // the loop's time of the latest input [s]
  double window_t_ = 0, window_s_ = 0;  // where the clock's judging window began: loop, device time [s]
  double offset_ = 0;                   // loop time minus device time, the smallest lately [s]
  double jitter_ = 0;                   // how much later than that inputs come [s]
  double anchor_t_ = 0, anchor_lead_ = 0, anchor_rate_ = 0;  // the lead at the latest input [s], [s/s]
  double target_rate_ = 0;                                   // the target's drift, smoothed [s/s]
  double drift_t_ = 0, drift_target_ = 0;                    // the target when the drift was last taken [s]
};

}  // namespace tactile
