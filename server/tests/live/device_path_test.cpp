// The device path (live/device_path.hpp): inputs on the device's clock, played out a little late.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "live/device_path.hpp"

namespace tactile {
namespace {

Pose at_x(double x) {
  Pose p;
  p.position = Vec3(x, 0.0, 0.0);
  return p;
}

// A device moving at 0.5 m/s whose 1 kHz inputs arrive 0-2 ms late: the path moves on at the device's speed
// within the lead's slew (it never stalls, steps back or jumps ahead, also when an input comes later than any
// before), its speed changing by the lead's acceleration at most (never at once: a coupled proxy's damper would pass
// the step to the hand), and lags the device by the delay at most.
TEST(DevicePath, LateInputsNeitherStallNorJumpThePath) {
  DevicePath path;
  const double v = 0.5;
  double newest_applied = -1, prev_x = -1, prev_step = -1, fastest_change = 0;
  bool started = false;
  uint64_t seed = 7;
  const auto late = [&] {  // 0-2 ms, pseudo-random
    seed = seed * 6364136223846793005ull + 1442695040888963407ull;
    return 2e-3 * double(seed >> 11) / double(1ull << 53);
  };
  double pending_t = 0, pending_s = 0;
  int k = 0;
  for (double t = 0.0; t < 0.3; t += 1e-4) {  // the loop's steps
    while (pending_t <= t) {                  // every input whose arrival has come
      if (k > 0) {
        const bool first = path.add(pending_s, at_x(v * pending_s), pending_t);
        EXPECT_EQ(first, !started) << "input " << k;
        started = true;
        newest_applied = pending_s;
      }
      ++k;
      pending_s = 1e-3 * k;
      pending_t = pending_s + late();
    }
    if (!started || t < 0.05) continue;
    const double x = path.at(t).position.x;
    if (prev_x >= 0) {
      const double slew = DevicePath::kLeadSlew * 1.0001;
      EXPECT_GE(x - prev_x, v * 1e-4 * (1 - slew)) << "the path slowed or went back at t = " << t;
      EXPECT_LE(x - prev_x, v * 1e-4 * (1 + slew)) << "the path jumped at t = " << t;
      if (prev_step >= 0) {
        fastest_change = std::max(fastest_change, std::fabs((x - prev_x) - prev_step));
        EXPECT_LE(std::fabs((x - prev_x) - prev_step), v * DevicePath::kLeadAccel * 1e-8 * 1.01 + 1e-15)
            << "the path's speed changed at once at t = " << t;
      }
      prev_step = x - prev_x;
    }
    EXPECT_GT(x, v * (t - DevicePath::kMaxDelay - 2e-3)) << "the path lags at t = " << t;
    EXPECT_LE(path.delay(), DevicePath::kMaxDelay);
    prev_x = x;
  }
  EXPECT_GT(newest_applied, 0.29);
  EXPECT_GT(fastest_change, 0.0) << "the lead never moved: the test shows nothing";
}

// A loop that stalls for 4 ms and catches up over the next 20 ms applies the inputs that came meanwhile at a time
// behind the wall clock's: their lags dip 4 ms below the link's 1 ms, more than the playout delay holds. Once it
// has caught up, the path plays no further past its newest input than a loop that never stalled (up to an input's
// interval, between one input and the next); held at the clocks' drift, the offset would leave it further ahead
// for a second, extrapolating. Its speed changes smoothly all along.
TEST(DevicePath, AMinimumLeftByALoopCatchingUpOnAStallDoesNotPlayThePathAheadOfItsInputs) {
  const double v = 0.5;
  const auto run = [&](bool stall) {            // the most the path plays past its newest input from 0.45 s [s]
    const auto loop_time = [stall](double w) {  // the loop's time at wall time w
      if (!stall || w < 0.2) return w;
      if (w < 0.204) return 0.2;
      return std::min(w, 0.2 + 1.2 * (w - 0.204));
    };
    DevicePath path;
    int k = 1;
    double newest = -1, prev_x = -1, prev_step = -1, ahead = 0;
    for (double w = 0.0; w < 0.6; w += 1e-4) {  // the loop's steps, in wall time
      const double t = loop_time(w);
      while (1e-3 * k + 1e-3 <= w) {  // inputs every 1 ms, arriving 1 ms after their stamp
        path.add(1e-3 * k, at_x(v * 1e-3 * k), t);
        newest = 1e-3 * k;
        ++k;
      }
      if (w < 0.05) continue;
      const double x = path.at(t).position.x;
      if (w > 0.225) {  // (steps 0.1 ms apart in the loop's time again)
        if (prev_step >= 0) {
          EXPECT_LE(std::fabs((x - prev_x) - prev_step), v * DevicePath::kLeadAccel * 1e-8 * 1.01 + 1e-15)
              << "the path's speed changed at once at w = " << w;
        }
        if (prev_x >= 0) prev_step = x - prev_x;
      }
      prev_x = x;
      if (w > 0.45) ahead = std::max(ahead, x / v - newest);
    }
    return ahead;
  };
  const double steady = run(false), after_stall = run(true);
  EXPECT_GT(steady, 0.5e-3) << "between inputs the path plays on past the newest: the test shows nothing";
  // (Within a quarter of an input's interval: the loop's 0.1 ms steps round the lags the offset recovers to.)
  EXPECT_LE(after_stall, steady + 0.25e-3)
      << "after the stall the path played " << (after_stall - steady) * 1e3 << " ms further past its newest input";
}

// A loaded host: the loop runs at 0.75 of the device's pace (its 1 kHz inputs applied every 0.75 ms of the
// loop's time) for 2 s. The path follows the device's own motion, played at 1/0.75 of the loop's pace, and once the
// lead has found the drift it stays within the playout delay (and 2.5 ms) of the newest input, its speed
// changing smoothly: a lead that trailed its drifting target would leave the proxy tens of milliseconds behind the
// hand, stepping along the oldest inputs it kept.
TEST(DevicePath, ALoopRunningBehindTheDevicesClockPlaysItsPathAtTheDevicesPace) {
  DevicePath path;
  const double v = 0.1, pace = 0.75;
  double worst_behind = 0, prev_x = -1, prev_step = -1;
  int k = 1;
  for (double t = 0.0; t < 2.0; t += 1e-4) {
    while (pace * 1e-3 * k <= t) {
      path.add(1e-3 * k, at_x(v * 1e-3 * k), t);
      ++k;
    }
    const double x = path.at(t).position.x, newest = v * 1e-3 * (k - 1);
    if (t > 0.5) {
      worst_behind = std::max(worst_behind, (newest - x) / v);
      EXPECT_LE(std::fabs((x - prev_x) - prev_step), v / pace * DevicePath::kLeadAccel * 1e-8 * 1.01 + 1e-15)
          << "the path's speed changed at once at t = " << t;
    }
    if (prev_x >= 0) prev_step = x - prev_x;
    prev_x = x;
  }
  std::printf("  the path trails the newest input by %.2f ms at most\n", 1e3 * worst_behind);
  EXPECT_LT(worst_behind, DevicePath::kMaxDelay + 2.5e-3);
  EXPECT_GT(k, 2600) << "the device's inputs should have run on";
}

// The loop's time stands still for 50 ms while the device runs on: its next input starts a new path (which the
// loop glides onto), and a device that stops sending comes to rest a little past where it said it was (at most
// its speed times twice kMaxExtrapolation), slowing down without a jump in its velocity.
TEST(DevicePath, AStallStartsANewPathAndASilentDeviceComesToRestNearWhereItSaidItWas) {
  DevicePath path;
  for (int k = 1; k <= 50; ++k) EXPECT_EQ(path.add(1e-3 * k, at_x(0.5e-3 * k), 1e-3 * k), k == 1);
  EXPECT_TRUE(path.add(0.051 + 0.05, at_x(0.5 * 0.101), 0.051)) << "a 50 ms stall is a new path";
  EXPECT_FALSE(path.add(0.102, at_x(0.5 * 0.102), 0.052));
  const double said = 0.5 * 0.102, rest = path.at(0.3).position.x;
  EXPECT_GE(rest, said);
  EXPECT_LE(rest, said + 0.5 * 2 * DevicePath::kMaxExtrapolation + 1e-12) << "long after its last input";
  EXPECT_NEAR(path.at(0.31).position.x, rest, 1e-9) << "at rest";
  double v_before = 0.5;
  for (double t = 0.052; t < 0.15; t += 1e-4) {  // its speed never changes by more than a 0.1 ms step's worth
    const double v = (path.at(t + 1e-4).position.x - path.at(t).position.x) / 1e-4;
    EXPECT_LT(std::fabs(v - v_before), 0.5 * 1e-4 / DevicePath::kMaxExtrapolation * 1.01 + 1e-6) << "at t = " << t;
    v_before = v;
  }
}

// A device whose clock runs backwards (each 1 kHz input stamped 1 ms before the one before) while it moves at
// 0.1 m/s: each input stamped before the newest starts a new path where the device says it is, and after
// kBackwards of them its inputs are timed by the loop: the path follows it. Before: every input stamped before the
// newest was ignored until one was 0.1 s away, the path standing still up to 94 ms while its inputs were taken.
TEST(DevicePath, ADeviceClockRunningBackwardsStillMovesThePath) {
  DevicePath path;
  const double v = 0.1;
  double worst_behind = 0;
  for (int k = 0; k < 200; ++k) {
    const double t = 1e-3 * k;
    path.add(1.0 - 1e-3 * k, at_x(v * t), t);
    worst_behind = std::max(worst_behind, v * t - path.at(t + 0.5e-3).position.x);
  }
  EXPECT_LT(worst_behind, 1e-12) << "the path stood still behind the device";
  EXPECT_TRUE(path.on_loop_time());
}

// A device whose stamps are microseconds apart for inputs a millisecond of motion apart (1 kHz, 0.5 m/s): once
// its clock has been judged (kClockWindow), the path follows its inputs on the loop's time, never past the newest
// pose sent by more than a millisecond of its motion. Before: the path raced through a millisecond of motion per
// microsecond played and overshot every pose sent by what the loop's speed limit let through (25-33 mm).
TEST(DevicePath, StampsMicrosecondsApartForMillisecondsOfMotionDoNotOvershoot) {
  DevicePath path;
  const double v = 0.5;
  double worst_ahead = 0, worst_behind = 0;
  for (double t = 0.0; t < 0.3; t += 1e-4) {
    const int k = int(std::floor(t * 1e3 + 1e-9));
    if (std::fabs(t - 1e-3 * k) < 5e-5) path.add(1e-6 * k, at_x(v * 1e-3 * k), t);  // input k at k ms
    if (t < DevicePath::kClockWindow + 0.01) continue;
    const double x = path.at(t).position.x, newest = v * 1e-3 * k;
    worst_ahead = std::max(worst_ahead, x - newest);
    worst_behind = std::max(worst_behind, newest - x);
  }
  std::printf("  past the judging: at most %.3f mm ahead of and %.3f mm behind the newest pose sent\n",
              1e3 * worst_ahead, 1e3 * worst_behind);
  EXPECT_TRUE(path.on_loop_time());
  EXPECT_LE(worst_ahead, v * 1e-3 * 1.01);
  EXPECT_LE(worst_behind, v * 1e-3 * 1.01);
}

// A device whose inputs stop for 40 ms and then come all at once (a stalled network) keeps its clock: the burst
// is judged once it is whole.
TEST(DevicePath, ABurstOfLateInputsLeavesTheClockTrusted) {
  DevicePath path;
  int k = 1;
  for (double t = 0.0; t < 0.3; t += 1e-4) {
    while (1e-3 * k <= t && !(k >= 100 && k <= 140 && t < 0.1405)) {
      path.add(1e-3 * k, at_x(0.5e-3 * k), t);
      ++k;
    }
  }
  EXPECT_FALSE(path.on_loop_time());
}

// A device moving at 0.5 m/s whose inputs stop for 8 ms (a loaded host) and then come all at once: its path
// goes on at its speed through the gap and after, within the lead's slew, its speed changing smoothly as the lead makes
// room for the lateness seen (a coupled proxy's damper answers a change of the path's velocity, 0.5 m/s in one step,
// with some 3 N).
TEST(DevicePath, AGapInTheInputsLeavesTheSpeedAsItWas) {
  DevicePath path;
  const double v = 0.5;
  double prev = -1, prev_step = -1;
  int k = 1;
  for (double t = 0.0; t < 0.2; t += 1e-4) {
    // Input k (device time k ms) arrives at k ms, except those of 100..108 ms, which arrive at 108.5 ms.
    while (1e-3 * k <= t && !(k >= 100 && k <= 108 && t < 0.1085)) {
      path.add(1e-3 * k, at_x(v * 1e-3 * k), t);
      ++k;
    }
    if (t < 0.05) continue;
    const double x = path.at(t).position.x;
    if (prev >= 0) {
      const double slew = DevicePath::kLeadSlew * 1.0001;  // (the lead makes room for the lateness seen)
      EXPECT_GE(x - prev, v * 1e-4 * (1 - slew)) << "slowed at t = " << t;
      EXPECT_LE(x - prev, v * 1e-4 * (1 + slew)) << "sped up at t = " << t;
      if (prev_step >= 0) {
        EXPECT_LE(std::fabs((x - prev) - prev_step), v * (1 + slew) * DevicePath::kLeadAccel * 1e-8 * 1.01 + 1e-15)
            << "the path's speed changed at once at t = " << t;
      }
      prev_step = x - prev;
    }
    prev = x;
  }
}

}  // namespace
}  // namespace tactile
