// The live loop: paced to the clock and never ahead of it, a haptic frame
// every step and state frames at their rate, device inputs that move the
// proxies and come back as force, and overload reported instead of hidden.
#include <gtest/gtest.h>

#include <atomic>
#include <cstddef>
#include <chrono>
#include <cmath>
#include <thread>
#include <vector>

#include "live/frames.hpp"
#include "live/realtime.hpp"
#include "mesh/primitives.hpp"
#include "tactile_generated.h"

// Heap allocations made on a thread while it has alloc_count::here set.
#include "app/alloc_count.hpp"

namespace tactile {
namespace {

using Clock = std::chrono::steady_clock;

// A soft block [0, 0.04] x [0, 0.02] x [0, 0.04] m on a fixed base, with a
// sphere on the "stylus" channel hovering 1 mm over the middle of its top.
ModelSpec poke_spec(std::array<int, 3> cells = {6, 3, 6}) {
  ModelSpec spec;
  spec.mesh = make_box(Vec3(0.0), Vec3(0.04, 0.02, 0.04), cells);
  spec.materials = {MaterialSpec{MaterialModel::StVK, 3e4, 0.3, 1000}};
  EssentialBc base;
  base.name = "base";
  base.where.kind = NodeSelector::Kind::Box;
  base.where.hi = Vec3(0.04, 0.0, 0.04);
  spec.essential = {base};
  spec.effects.damping = true;
  spec.effects.alpha = 20;
  ProxySpec tip;
  tip.name = "tip";
  tip.device = "stylus";
  tip.geometry = ProxyGeometry{ProxyShape::Sphere, 0.008, 0, Vec3(0.0)};
  tip.pose.position = Vec3(0.02, 0.029, 0.02);
  spec.proxies = {tip};
  return spec;
}

const proto::Envelope* envelope(std::span<const uint8_t> bytes) {
  flatbuffers::Verifier v(bytes.data(), bytes.size());
  return proto::VerifyEnvelopeBuffer(v) ? proto::GetEnvelope(bytes.data()) : nullptr;
}

TEST(RealtimeLoop, NeverAheadOfTheClockAndPublishesEveryStep) {
  Simulation sim(poke_spec());
  FrameEncoder frames(sim, "poke", 1, 2e-4);
  RealtimeOptions options;
  options.dt = 2e-4;
  RealtimeLoop loop(sim, frames, options);
  Clock::time_point start;
  double worst_lead = -1, last_sim = 0;
  int64_t haptics = 0, states = 0, bad = 0;
  loop.on_haptic([&](std::span<const uint8_t> m) {
    const proto::Envelope* e = envelope(m);
    if (!e || !e->message_as_HapticFrame()) {
      ++bad;
      return;
    }
    const double wall = std::chrono::duration<double>(Clock::now() - start).count();
    last_sim = e->message_as_HapticFrame()->sim_time();
    worst_lead = std::max(worst_lead, last_sim - wall);  // > 0 would be ahead of real time
    ++haptics;
  });
  loop.on_state([&](std::span<const uint8_t> m) {
    const proto::Envelope* e = envelope(m);
    if (!e || !e->message_as_StateFrame()) ++bad;
    else if (e->message_as_StateFrame()->positions()->size() != 3 * frames.surface().nodes.size()) ++bad;
    ++states;
  });
  std::atomic<bool> stop{false};
  start = Clock::now();
  loop.run(stop, 0.3);
  const RealtimeStats s = loop.stats();
  EXPECT_EQ(bad, 0);
  EXPECT_NEAR(s.sim_time, 0.3, options.dt);
  EXPECT_EQ(haptics, s.steps);            // one haptic frame per step
  EXPECT_EQ(haptics, s.haptic_frames);
  EXPECT_NEAR(double(states), 1 + 0.3 * 30, 1.0);  // at 30 Hz of simulated time, plus the first
  EXPECT_LE(worst_lead, 1e-4);            // never ahead (clock reads are microseconds apart)
  EXPECT_GE(s.wall_time, 0.3 - 1e-3);     // paced: 0.3 s simulated took 0.3 s of wall time or more
  EXPECT_GT(s.real_time_factor, 0.0);
  EXPECT_TRUE(s.fault.empty()) << s.fault;
}

// A device thread sends the stylus down into the block at 1 kHz; the haptic
// frames come back with the block pushing the sphere up, and they name the
// newest input they had seen.
TEST(RealtimeLoop, DeviceInputsMoveTheProxyAndTheForceComesBack) {
  Simulation sim(poke_spec());
  FrameEncoder frames(sim, "poke", 1, 2e-4);
  RealtimeOptions options;
  options.dt = 2e-4;
  RealtimeLoop loop(sim, frames, options);
  std::vector<float> force_y;  // per haptic frame while holding
  force_y.reserve(8000);
  std::atomic<bool> stop{false}, holding{false};
  std::atomic<uint64_t> seen_sequence{0};
  loop.on_haptic([&](std::span<const uint8_t> m) {
    const proto::HapticFrame* h = proto::GetEnvelope(m.data())->message_as_HapticFrame();
    if (holding) force_y.push_back(h->proxies()->Get(0)->force().y());
    seen_sequence = h->last_input_sequence();
  });
  bool device_done = false;
  uint64_t sent = 0;
  std::thread device([&] {
    const Clock::time_point t0 = Clock::now();
    for (int k = 1; k <= 300; ++k) {  // 0.3 s at 1 kHz: down 4 mm over 0.2 s, then hold
      std::this_thread::sleep_until(t0 + std::chrono::milliseconds(k));
      DeviceSample s;
      s.device = 0;
      s.sequence = uint64_t(k);
      s.device_time_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t0).count();
      s.pose.position = Vec3(0.02, 0.029 - 0.004 * std::min(1.0, k / 200.0), 0.02);
      if (loop.post_input(s)) sent = s.sequence;
    }
    device_done = true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the last input glides in
    holding = true;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    stop = true;
  });
  loop.run(stop);
  device.join();
  const RealtimeStats s = loop.stats();
  EXPECT_TRUE(device_done);
  EXPECT_EQ(s.inputs_dropped, 0);
  EXPECT_GT(s.inputs_applied, 250);
  EXPECT_EQ(seen_sequence.load(), sent);
  // Held 3 mm deep for 0.1 s: pushed up in every frame, steadily.
  ASSERT_GT(force_y.size(), 100u);
  float lowest = force_y.front(), mean = 0, flicker = 0;
  for (size_t k = 0; k < force_y.size(); ++k) {
    lowest = std::min(lowest, force_y[k]);
    mean += force_y[k] / float(force_y.size());
    if (k > 0) flicker = std::max(flicker, std::fabs(force_y[k] - force_y[k - 1]));
  }
  EXPECT_GT(lowest, 0.0f) << "pressed 3 mm into the block, the sphere should be pushed up in every frame";
  EXPECT_LT(flicker, 0.5f * mean) << "the force flickers from frame to frame";
  // The proxy reached the last input's pose.
  EXPECT_NEAR(sim.proxy_pose(0).position.y, 0.025, 1e-6);
}

// Steps far costlier than their dt: the loop falls behind, says so, and does
// not try to race through the backlog.
TEST(RealtimeLoop, OverloadIsReportedAsMissedDeadlines) {
  Simulation sim(poke_spec({16, 8, 16}));  // 12 k tets
  FrameEncoder frames(sim, "heavy", 1, 0.0);
  RealtimeOptions options;
  options.dt = 2e-6;  // each step costs far more than 2 us
  RealtimeLoop loop(sim, frames, options);
  std::atomic<bool> stop{false};
  std::thread timer([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    stop = true;
  });
  loop.run(stop);
  timer.join();
  const RealtimeStats s = loop.stats();
  EXPECT_GT(s.steps, 10);
  EXPECT_GT(s.missed_deadlines, s.steps / 2);
  EXPECT_GT(s.reanchors, 0);
  EXPECT_LT(s.real_time_factor, 0.5);
  EXPECT_GT(s.step_mean_us, 1e6 * options.dt);
}

// Once the builders have grown, the simulation thread allocates nothing:
// not for steps, inputs, haptic frames or state frames.
TEST(RealtimeLoop, SteadyStateAllocatesNothing) {
  Simulation sim(poke_spec());
  FrameEncoder frames(sim, "poke", 1, 2e-4);
  RealtimeOptions options;
  options.dt = 2e-4;
  RealtimeLoop loop(sim, frames, options);
  int64_t haptics = 0;
  size_t bytes = 0;
  loop.on_haptic([&](std::span<const uint8_t> m) {
    bytes += m.size();
    if (++haptics == 200) alloc_count::here = true;  // (the sim thread: counting from here on)
  });
  loop.on_state([&](std::span<const uint8_t> m) { bytes += m.size(); });
  std::atomic<bool> stop{false};
  std::thread device([&] {
    for (int k = 1; k <= 250; ++k) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      DeviceSample s;
      s.device = 0;
      s.sequence = uint64_t(k);
      s.device_time_ns = int64_t(k) * 1000000;
      s.pose.position = Vec3(0.02, 0.029 - 1e-5 * k, 0.02);
      loop.post_input(s);
    }
  });
  alloc_count::count = 0;
  loop.run(stop, 0.3);
  alloc_count::here = false;
  device.join();
  EXPECT_GT(haptics, 1000);
  EXPECT_GT(bytes, 0u);
  EXPECT_GT(loop.stats().inputs_applied, 100);
  EXPECT_EQ(alloc_count::count.load(), 0) << "allocations on the simulation thread in the steady state";
}

TEST(RealtimeLoop, AFullQueueOrAnUnknownDeviceDropsAndCounts) {
  Simulation sim(poke_spec({2, 1, 2}));
  FrameEncoder frames(sim, "tiny", 1, 0.0);
  RealtimeOptions options;
  options.input_capacity = 4;
  RealtimeLoop loop(sim, frames, options);
  DeviceSample s;
  s.device = 0;
  int accepted = 0;
  for (int k = 0; k < 10; ++k) accepted += loop.post_input(s) ? 1 : 0;
  EXPECT_EQ(accepted, 4);
  s.device = 7;  // no such channel
  EXPECT_FALSE(loop.post_input(s));
  EXPECT_EQ(loop.stats().inputs_dropped, 7);
}

TEST(FrameEncoder, SceneDescriptionMapsTheSurfaceToNodes) {
  Simulation sim(poke_spec({2, 1, 2}));
  FrameEncoder frames(sim, "tiny", 5, 1e-4);
  const proto::Envelope* e = envelope(frames.scene_description());
  ASSERT_NE(e, nullptr);
  const proto::SceneDescription* d = e->message_as_SceneDescription();
  ASSERT_NE(d, nullptr);
  EXPECT_EQ(d->scene_id(), 5u);
  // A 2 x 1 x 2 box has 3 x 2 x 3 = 18 nodes, all on its surface; 2 triangles per cell face.
  EXPECT_EQ(d->surface_nodes()->size(), 18u);
  EXPECT_EQ(d->triangles()->size(), 3u * 2u * (2 * (2 * 1) + 2 * (2 * 1) + 2 * (2 * 2)));
  for (uint32_t v : *d->triangles()) EXPECT_LT(v, d->surface_nodes()->size());
  for (size_t k = 0; k < d->surface_nodes()->size(); ++k) {
    const Vec3& X = sim.mesh().X[d->surface_nodes()->Get(uint32_t(k))];
    EXPECT_FLOAT_EQ(d->rest_positions()->Get(uint32_t(3 * k + 1)), float(X.y));
  }
  ASSERT_EQ(d->proxies()->size(), 1u);
  EXPECT_STREQ(d->proxies()->Get(0)->device()->c_str(), "stylus");
  EXPECT_STREQ(d->devices()->Get(0)->c_str(), "stylus");
}

}  // namespace
}  // namespace tactile
