// The live loop: paced to the clock and never ahead of it, a haptic frame
// every step and state frames at their rate, device inputs that move the
// proxies and come back as force, and overload reported instead of hidden.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include <glm/geometric.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/matrix.hpp>

#include "core/bodies.hpp"
#include "core/embedding.hpp"
#include "core/fields.hpp"
#include "core/material.hpp"
#include "core/mesh.hpp"
#include "core/model.hpp"
#include "core/proxy.hpp"
#include "live/frames.hpp"
#include "live/realtime.hpp"
#include "mesh/primitives.hpp"
#include "tactile_generated.h"

// Heap allocations made on a thread while it has alloc_count::here set.
#include "alloc_count.hpp"
#include "surface_fixtures.hpp"

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
    if (!e || !e->message_as_StateFrame())
      ++bad;
    else if (e->message_as_StateFrame()->positions()->size() != 3 * frames.surface().nodes.size())
      ++bad;
    ++states;
  });
  std::atomic<bool> stop{false};
  start = Clock::now();
  loop.run(stop, 0.3);
  const RealtimeStats s = loop.stats();
  EXPECT_EQ(bad, 0);
  EXPECT_NEAR(s.sim_time, 0.3, options.dt);
  EXPECT_EQ(haptics, s.steps);  // one haptic frame per step
  EXPECT_EQ(haptics, s.haptic_frames);
  EXPECT_NEAR(double(states), 1 + 0.3 * 30, 1.0);  // at 30 Hz of simulated time, plus the first
  EXPECT_LE(worst_lead, 1e-4);                     // never ahead (clock reads are microseconds apart)
  EXPECT_GE(s.wall_time, 0.3 - 1e-3);              // paced: 0.3 s simulated took 0.3 s of wall time or more
  EXPECT_GT(s.real_time_factor, 0.0);
  EXPECT_TRUE(s.fault.empty()) << s.fault;
}

// A device that drives its proxy directly (the kinematic proxy, as before
// the coupling) sends the stylus down into the block at 1 kHz; the haptic
// frames come back with the block pushing the sphere up, and they name the
// newest input they had seen.
TEST(RealtimeLoop, DeviceInputsMoveTheProxyAndTheForceComesBack) {
  // Neo-Hookean: the press squashes the coarse block's top elements by some
  // 45 %, past what StVK recovers from once a loaded machine's bursts of
  // inputs ring it (issue 23); this test is about the loop.
  ModelSpec spec = poke_spec();
  spec.materials[0].model = MaterialModel::NeoHookean;
  Simulation sim(spec);
  FrameEncoder frames(sim, "poke", 1, 2e-4);
  RealtimeOptions options;
  options.dt = 2e-4;
  RealtimeLoop loop(sim, frames, options);
  std::vector<float> force_y;  // per haptic frame while holding
  force_y.reserve(8000);
  std::atomic<bool> stop{false}, holding{false};
  std::atomic<uint64_t> seen_sequence{0}, seen_channel_sequence{0};
  std::atomic<size_t> frames_held{0};
  std::atomic<float> device_y{0};
  loop.on_haptic([&](std::span<const uint8_t> m) {
    const proto::HapticFrame* h = proto::GetEnvelope(m.data())->message_as_HapticFrame();
    if (holding) {
      force_y.push_back(h->proxies()->Get(0)->force().y());
      frames_held = force_y.size();
    }
    seen_sequence = h->last_input_sequence();
    seen_channel_sequence = h->device_input_sequences()->Get(0);
    device_y = h->device_poses()->Get(0)->position().y();
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
      s.drive.direct = true;
      if (loop.post_input(s)) sent = s.sequence;
    }
    device_done = true;
    // The last input glides in, and the ringing of the press (whose inputs a
    // loaded machine delivers in bursts) dies down (damping alpha = 20/s);
    // then 0.1 s held. (On a loaded machine the loop may take longer to get
    // to the last input and to send a hundred frames: waited for, 5 s at most.)
    const Clock::time_point give_up = Clock::now() + std::chrono::seconds(5);
    while (seen_sequence.load() < sent && Clock::now() < give_up)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    holding = true;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    while (frames_held.load() < 101 && Clock::now() < give_up)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    stop = true;
  });
  loop.run(stop);
  device.join();
  const RealtimeStats s = loop.stats();
  EXPECT_TRUE(device_done);
  EXPECT_EQ(s.fault, "");
  EXPECT_EQ(s.inputs_dropped, 0);
  EXPECT_GT(s.inputs_applied, 250);
  EXPECT_EQ(seen_sequence.load(), sent);
  EXPECT_EQ(seen_channel_sequence.load(), sent);
  // Held 3 mm deep for 0.1 s: pushed up in every frame, steadily.
  ASSERT_GT(force_y.size(), 100u);
  // (Per step the contact comes in pulses, often every other step: the
  // frames' even window of steps takes them out.)
  float lowest = force_y.front(), mean = 0, flicker = 0, jump = 0;
  for (size_t k = 0; k < force_y.size(); ++k) {
    lowest = std::min(lowest, force_y[k]);
    mean += force_y[k] / float(force_y.size());
    if (k == 0) continue;
    const float d = force_y[k] - force_y[k - 1];
    flicker += d * d / float(force_y.size() - 1);
    jump = std::max(jump, std::fabs(d));
  }
  flicker = std::sqrt(flicker);
  std::printf("held: mean %.3f N, frame-to-frame rms %.3f N, largest %.3f N\n", mean, flicker, jump);
  EXPECT_GT(lowest, 0.0f) << "pressed 3 mm into the block, the sphere should be pushed up in every frame";
  EXPECT_LT(flicker, 0.1f * mean) << "the force flickers from frame to frame";
  EXPECT_LT(jump, 0.25f * mean) << "the force jumps from frame to frame";
  // The proxy reached the last input's pose, and the frames said so.
  EXPECT_NEAR(sim.proxy_pose(0).position.y, 0.025, 1e-6);
  EXPECT_NEAR(device_y.load(), 0.025f, 1e-6f);
}

// The frames' surface vertices are the scene mesh's boundary nodes, in its
// numbering and order, whatever order the model keeps its nodes in (float
// and double models, or models of other materials, number them otherwise):
// a re-simulation under another scene compares the same vertex with the
// same vertex, and each vertex is drawn where its node is.
TEST(FrameEncoder, SurfaceVerticesFollowTheMeshNotTheModel) {
  ModelSpec spec = poke_spec({12, 6, 12});  // 5184 tets: float and double blocks number the nodes apart
  ASSERT_NE(build_model<double>(spec).node_model, build_model<float>(spec).node_model)
      << "the two models should number the nodes differently, or this shows nothing";
  Simulation d(spec);
  spec.integrator.precision = Precision::Float;
  Simulation f(spec);
  Pose to = d.proxy_pose(0);
  to.position.y -= 0.004;
  for (Simulation* sim : {&d, &f}) {
    sim->set_proxy_motion(0, ProxyMotion{0.0, 0.01, sim->proxy_pose(0), to});
    ASSERT_FALSE(sim->advance(0.01).fault);
  }
  FrameEncoder ed(d, "poke", 1, 2e-4), ef(f, "poke", 1, 2e-4);
  const Surface& sd = ed.surface();
  const Surface& sf = ef.surface();
  const std::vector<int32_t> boundary = compute_boundary_nodes(compute_boundary_faces(spec.mesh));
  EXPECT_EQ(std::vector<uint32_t>(boundary.begin(), boundary.end()), sd.nodes);
  EXPECT_EQ(sd.nodes, sf.nodes);
  EXPECT_EQ(sd.triangles, sf.triangles);
  EXPECT_TRUE(std::is_sorted(sd.nodes.begin(), sd.nodes.end()));
  // Each vertex where its node is: the rest position plus the node's displacement.
  for (Simulation* sim : {&d, &f}) {
    FrameEncoder& e = sim == &d ? ed : ef;
    const std::span<const uint8_t> bytes = e.state_frame(0);
    const auto* frame = proto::GetEnvelope(bytes.data())->message_as_StateFrame();
    ASSERT_NE(frame, nullptr);
    double moved = 0;
    for (size_t k = 0; k < sd.nodes.size(); ++k) {
      const int32_t node = int32_t(sd.nodes[k]);
      const Vec3 x = spec.mesh.X[size_t(node)] + sim->displacement(node);
      for (int c = 0; c < 3; ++c)
        ASSERT_NEAR(frame->positions()->Get(uint32_t(3 * k) + uint32_t(c)), x[c], 1e-6) << "vertex " << k;
      moved = std::max(moved, glm::length(sim->displacement(node)));
    }
    EXPECT_GT(moved, 1e-4) << "the poke moved no vertex, so this shows nothing";
  }
}

// An embedded surface comes once, in the scene description: its rest shape and its binding to the frame's
// vertices, which grow by the interior nodes it follows. Each state then places it from those vertices alone.
TEST(FrameEncoder, AnEmbeddedSurfaceComesOnceAndFollowsTheFrameVertices) {
  ModelSpec spec = poke_spec();
  const size_t boundary = compute_boundary_nodes(compute_boundary_faces(spec.mesh)).size();
  // A sphere inside the block, its top 1 mm under the block's: it binds to interior nodes too.
  spec.surface = std::make_shared<const EmbeddedSurface>(
      embed_surface(spec.mesh, test::make_uv_sphere(Vec3(0.02, 0.0105, 0.02), 0.0085, 24, 12), 0.001));
  Simulation sim(spec);
  Pose to = sim.proxy_pose(0);
  to.position.y -= 0.005;
  sim.set_proxy_motion(0, ProxyMotion{0.0, 0.02, sim.proxy_pose(0), to});
  ASSERT_FALSE(sim.advance(0.02).fault);
  FrameEncoder frames(sim, "poke", 1, 2e-4);
  const Surface& s = frames.surface();
  ASSERT_EQ(s.bodies.size(), 1u);
  EXPECT_EQ(s.bodies[0].vertex_end, s.nodes.size());
  ASSERT_GT(s.nodes.size(), boundary) << "the sphere follows no interior node, so this shows less";
  // Each node once: the frame grows by the interior nodes, never by more than the body has.
  std::vector<uint32_t> sorted = s.nodes;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_EQ(std::unique(sorted.begin(), sorted.end()), sorted.end());
  EXPECT_TRUE(std::is_sorted(s.nodes.begin() + std::ptrdiff_t(boundary), s.nodes.end()));
  const auto* d = proto::GetEnvelope(frames.scene_description().data())->message_as_SceneDescription();
  ASSERT_NE(d, nullptr);
  ASSERT_NE(d->embedded(), nullptr);
  const proto::EmbeddedSurface& e = *d->embedded();
  const EmbeddedSurface& bound = *spec.surface;
  ASSERT_EQ(e.rest_positions()->size(), 3 * bound.rest.vertices.size());
  ASSERT_EQ(e.triangles()->size(), 3 * bound.rest.triangles.size());
  ASSERT_EQ(e.carriers()->size(), 4 * bound.rest.vertices.size());
  ASSERT_EQ(e.weights()->size(), 4 * bound.rest.vertices.size());
  ASSERT_EQ(d->rest_positions()->size(), 3 * s.nodes.size());
  // Placed from the frame's vertices: at rest from the description's, now from a state frame's.
  const auto* f = proto::GetEnvelope(frames.state_frame(0).data())->message_as_StateFrame();
  ASSERT_NE(f, nullptr);
  std::vector<Vec3> x(size_t(sim.n_nodes())), now(bound.rest.vertices.size());
  for (int32_t n = 0; n < sim.n_nodes(); ++n) x[size_t(n)] = spec.mesh.X[size_t(n)] + sim.displacement(n);
  compute_embedded_positions(bound, x, now);
  double moved = 0;
  for (uint32_t v = 0; v < bound.rest.vertices.size(); ++v) {
    Vec3 rest(0.0), placed(0.0);
    for (uint32_t k = 0; k < 4; ++k) {
      const uint32_t c = e.carriers()->Get(4 * v + k);
      ASSERT_LT(c, s.nodes.size());
      const float w = e.weights()->Get(4 * v + k);
      for (uint32_t a = 0; a < 3; ++a) {
        rest[int(a)] += w * d->rest_positions()->Get(3 * c + a);
        placed[int(a)] += w * f->positions()->Get(3 * c + a);
      }
    }
    for (int a = 0; a < 3; ++a) {
      ASSERT_NEAR(e.rest_positions()->Get(3 * v + uint32_t(a)), bound.rest.vertices[v][a], 1e-7) << v;
      ASSERT_NEAR(rest[a], bound.rest.vertices[v][a], 1e-6) << v;
      ASSERT_NEAR(placed[a], now[v][a], 1e-6) << v;
    }
    moved = std::max(moved, glm::length(now[v] - bound.rest.vertices[v]));
  }
  EXPECT_GT(moved, 1e-4) << "the poke moved no vertex of the sphere, so this shows less";
  // A scene without one sends none, and only its boundary.
  Simulation plain(poke_spec());
  FrameEncoder plain_frames(plain, "poke", 1, 2e-4);
  const auto* pd = proto::GetEnvelope(plain_frames.scene_description().data())->message_as_SceneDescription();
  EXPECT_EQ(pd->embedded(), nullptr);
  EXPECT_EQ(plain_frames.surface().nodes.size(), boundary);
}

// Per-vertex fields come only when asked for, each the rest-volume-weighted
// mean of its tets' values: under a homogeneous deformation F every vertex
// has F's own value (stretches 1.2, 1.0, 0.9 here), under any other the mean
// of its tets'. A frame asked for none carries none, and no scalar either
// (a viewer has the displacement from the positions).
TEST(FrameEncoder, FieldsComeOnlyWhenAskedForAsTheirTetsMeans) {
  ModelSpec spec = poke_spec({4, 2, 4});
  spec.essential.clear();
  spec.materials = {MaterialSpec{MaterialModel::NeoHookean, 3e4, 0.3, 1000}};
  // F = R diag(1.2, 0.9, 1.0): principal stretches 1.2, 1.0, 0.9 whatever the rotation R.
  const glm::dmat3 R = glm::mat3_cast(glm::angleAxis(0.5, glm::normalize(Vec3(1, 2, 0))));
  const glm::dmat3 G = R * glm::dmat3(1.2, 0, 0, 0, 0.9, 0, 0, 0, 1.0);
  auto start = [&](auto u_of) {
    Simulation sim(spec);
    std::vector<double> u(3 * size_t(sim.n_nodes())), v(u.size(), 0.0);
    for (size_t n = 0; n < size_t(sim.n_nodes()); ++n) {
      const Vec3 d = u_of(spec.mesh.X[n]);
      for (int c = 0; c < 3; ++c) u[3 * n + size_t(c)] = d[c];
    }
    sim.set_initial_state(u, v);
    return sim;
  };
  auto field = [](const proto::StateFrame* f, const char* name) -> const flatbuffers::Vector<float>* {
    if (f->fields())
      for (const proto::FrameField* x : *f->fields())
        if (x->name()->str() == name) return x->values();
    return nullptr;
  };
  const ViewFieldMask all = view_field_bit(ViewField::VonMises) | view_field_bit(ViewField::EnergyDensity) |
                            view_field_bit(ViewField::StretchMax) | view_field_bit(ViewField::StretchMin);
  {
    Simulation sim = start([&](const Vec3& X) { return G * X - X; });
    FrameEncoder frames(sim, "stretch", 1, 2e-4);
    const auto* none = proto::GetEnvelope(frames.state_frame(0).data())->message_as_StateFrame();
    EXPECT_EQ(none->fields(), nullptr);
    EXPECT_EQ(none->scalar(), nullptr);
    const auto* d = proto::GetEnvelope(frames.scene_description().data())->message_as_SceneDescription();
    ASSERT_NE(d->fields(), nullptr);
    EXPECT_EQ(d->fields()->size(), size_t(kViewFieldCount));
    EXPECT_EQ(d->scalar_name()->str(), "");
    const auto* f = proto::GetEnvelope(frames.state_frame(0, all).data())->message_as_StateFrame();
    double Fr[9];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) Fr[3 * i + j] = G[j][i];
    const Lame l = compute_lame(3e4, 0.3);
    const TetFields want = compute_tet_fields(MaterialModel::NeoHookean, Fr, l.lambda, l.mu);
    EXPECT_NEAR(want.stretches[0], 1.2, 1e-12);
    EXPECT_NEAR(want.stretches[1], 1.0, 1e-12);
    EXPECT_NEAR(want.stretches[2], 0.9, 1e-12);
    const size_t n = frames.surface().nodes.size();
    for (const char* name : {"von_mises", "energy_density", "stretch_max", "stretch_min"}) {
      const auto* values = field(f, name);
      ASSERT_NE(values, nullptr) << name;
      ASSERT_EQ(values->size(), n) << name;
      const double expected = std::string(name) == "von_mises"        ? want.von_mises
                              : std::string(name) == "energy_density" ? want.energy_density
                              : std::string(name) == "stretch_max"    ? 1.2
                                                                      : 0.9;
      for (uint32_t k = 0; k < n; ++k) ASSERT_NEAR(values->Get(k), expected, 1e-5 * expected) << name << " " << k;
    }
    EXPECT_GT(want.von_mises, 1e3) << "no stress, so this shows little";
    // Only those asked for.
    const auto* one = proto::GetEnvelope(frames.state_frame(0, view_field_bit(ViewField::StretchMin)).data())
                          ->message_as_StateFrame();
    ASSERT_NE(one->fields(), nullptr);
    EXPECT_EQ(one->fields()->size(), 1u);
    EXPECT_NE(field(one, "stretch_min"), nullptr);
  }
  // Bent, not homogeneous: each vertex the volume-weighted mean of its own tets' values.
  Simulation sim = start([](const Vec3& X) { return Vec3(0.0, 2.0 * (X.x - 0.02) * (X.x - 0.02), 0.1 * X.y * X.x); });
  FrameEncoder frames(sim, "bent", 1, 2e-4);
  const auto* f =
      proto::GetEnvelope(frames.state_frame(0, view_field_bit(ViewField::VonMises)).data())->message_as_StateFrame();
  const auto* values = field(f, "von_mises");
  ASSERT_NE(values, nullptr);
  const ElementFields per_tet = sim.compute_element_fields({.von_mises = true});
  const Surface& s = frames.surface();
  double spread = 0;
  for (uint32_t k = 0; k < s.nodes.size(); ++k) {
    double sum = 0, volume = 0, lo = 1e30, hi = -1e30;
    for (size_t e = 0; e < spec.mesh.tets.size(); ++e)
      for (int32_t node : spec.mesh.tets[e])
        if (uint32_t(node) == s.nodes[k]) {
          sum += sim.tet_volume()[e] * per_tet.von_mises[e];
          volume += sim.tet_volume()[e];
          lo = std::min(lo, per_tet.von_mises[e]);
          hi = std::max(hi, per_tet.von_mises[e]);
        }
    ASSERT_NEAR(values->Get(k), sum / volume, 1e-5 * hi) << k;
    spread = std::max(spread, (hi - lo) / hi);
  }
  EXPECT_GT(spread, 0.1) << "the tets around each vertex agree, so the mean shows nothing";
}

// A haptic frame's force is the mean of the per-step forces over its window,
// whether frames come every step or every few.
TEST(FrameEncoder, HapticForceIsTheMeanOverItsWindow) {
  Simulation sim(poke_spec());
  const double dt = 2e-4;
  FrameEncoder frames(sim, "poke", 1, dt, 0.8e-3);  // 4 steps
  ASSERT_EQ(frames.force_window_steps(), 4u);
  EXPECT_EQ(FrameEncoder(sim, "poke", 1, dt, 1e-3).force_window_steps(), 6u);  // 5 made even
  Pose to = sim.proxy_pose(0);
  to.position.y -= 0.004;
  sim.set_proxy_motion(0, ProxyMotion{sim.time(), sim.time() + 0.02, sim.proxy_pose(0), to});
  std::vector<double> fy;
  for (int k = 0; k < 150; ++k) {
    ASSERT_FALSE(sim.advance(dt).fault);
    frames.add_step_forces();
    const ProxyReport& r = sim.proxy_reports()[0];
    fy.push_back(r.impulse.y / r.elapsed);  // the advance's mean (it may have sub-steps)
    sim.clear_impulses();
    if (k % 7 != 6) continue;  // a frame every 7 steps: longer than the window
    const proto::HapticFrame* h = envelope(frames.haptic_frame(0, 0))->message_as_HapticFrame();
    double mean = 0;
    for (size_t i = fy.size() - std::min<size_t>(4, fy.size()); i < fy.size(); ++i) mean += fy[i];
    mean /= double(std::min<size_t>(4, fy.size()));
    EXPECT_NEAR(h->proxies()->Get(0)->force().y(), mean, 1e-6 + 1e-6 * std::fabs(mean)) << "step " << k;
    EXPECT_NEAR(h->devices()->Get(0)->force().y(), mean, 1e-6 + 1e-6 * std::fabs(mean)) << "step " << k;
  }
  double peak = 0;
  for (double f : fy) peak = std::max(peak, f);
  EXPECT_GT(peak, 0.05) << "the sphere should have been pushed up once pressed in";
}

// At a haptic rate below the step rate, a frame every ceil(1 / (rate x dt))
// steps, each stamped with the step it follows.
TEST(RealtimeLoop, HapticRateSendsEveryFewSteps) {
  Simulation sim(poke_spec());
  FrameEncoder frames(sim, "poke", 1, 2e-4, 1e-3);
  RealtimeOptions options;
  options.dt = 2e-4;
  options.haptic_rate_hz = 1500;  // 3.33 steps: every 4th
  RealtimeLoop loop(sim, frames, options);
  ASSERT_EQ(loop.haptic_every(), 4);
  std::vector<uint64_t> steps;
  loop.on_haptic([&](std::span<const uint8_t> m) { steps.push_back(envelope(m)->message_as_HapticFrame()->step()); });
  std::atomic<bool> stop{false};
  loop.run(stop, 0.1);
  const RealtimeStats s = loop.stats();
  ASSERT_GT(steps.size(), 100u);
  EXPECT_EQ(int64_t(steps.size()), s.haptic_frames);
  EXPECT_EQ(int64_t(steps.size()), s.steps / 4);
  for (size_t k = 1; k < steps.size(); ++k) EXPECT_EQ(steps[k] - steps[k - 1], 4u);
}

// Two channels: a hand of two tips on "glove", two lone spheres on "stylus".
// Each channel's frames carry its own newest input, and the pose of what it
// moves: the hand, or its first proxy.
ModelSpec two_channel_spec() {
  ModelSpec spec = poke_spec({2, 1, 2});
  spec.hands = {HandSpec{"right", "glove", Pose{}, {}}};
  spec.hands[0].pose.position = Vec3(0.02, 0.06, 0.02);
  ProxySpec tip = spec.proxies[0];
  spec.proxies.clear();
  const char* names[] = {"p0", "p1", "p2", "p3"};
  for (int k = 0; k < 4; ++k) {
    ProxySpec p = tip;
    p.name = names[k];
    p.device = k % 2 ? "stylus" : "";  // glove, stylus, glove, stylus
    p.hand = k % 2 ? "" : "right";
    p.pose.position = Vec3(0.01 * (k + 1), 0.05 + 0.01 * k, 0.02);
    spec.proxies.push_back(p);
  }
  return spec;
}

void expect_pose(const proto::ProxyPose& wire, const Pose& p) {
  EXPECT_FLOAT_EQ(wire.position().x(), float(p.position.x));
  EXPECT_FLOAT_EQ(wire.position().y(), float(p.position.y));
  EXPECT_FLOAT_EQ(wire.position().z(), float(p.position.z));
  EXPECT_FLOAT_EQ(wire.orientation().w(), float(p.orientation.w));
  EXPECT_FLOAT_EQ(wire.orientation().x(), float(p.orientation.x));
  EXPECT_FLOAT_EQ(wire.orientation().y(), float(p.orientation.y));
  EXPECT_FLOAT_EQ(wire.orientation().z(), float(p.orientation.z));
}

TEST(FrameEncoder, HapticFramesCarryEachChannelsPoseAndNewestInput) {
  Simulation sim(two_channel_spec());
  ASSERT_EQ(sim.devices(), (std::vector<std::string>{"glove", "stylus"}));
  FrameEncoder frames(sim, "two", 1, 1e-4);
  // The hand turns and moves, the stylus's first sphere moves, over 1 ms.
  Pose hand_to;
  hand_to.position = Vec3(0.025, 0.065, 0.015);
  hand_to.orientation = glm::angleAxis(0.3, glm::normalize(Vec3(1, 2, 3)));
  sim.set_hand_motion(0, ProxyMotion{sim.time(), sim.time() + 1e-3, sim.hand_pose(0), hand_to});
  const Vec3 stylus_from = sim.proxy_pose(1).position;
  Pose stylus_to = sim.proxy_pose(1);
  stylus_to.position += Vec3(0.002, -0.001, 0.003);
  sim.set_proxy_motion(1, ProxyMotion{sim.time(), sim.time() + 1e-3, sim.proxy_pose(1), stylus_to});
  sim.advance(4e-4);  // part of the way
  frames.add_step_forces();
  const std::vector<uint64_t> sequences = {7, 9};
  const proto::Envelope* e = envelope(frames.haptic_frame(123, 9, sequences));
  ASSERT_NE(e, nullptr);
  const proto::HapticFrame* h = e->message_as_HapticFrame();
  ASSERT_NE(h, nullptr);
  ASSERT_EQ(h->device_poses()->size(), 2u);
  expect_pose(*h->device_poses()->Get(0), sim.hand_pose(0));
  expect_pose(*h->device_poses()->Get(1), sim.proxy_pose(1));
  // A viewer's state frame places them the same.
  const proto::StateFrame* state = envelope(frames.state_frame(123))->message_as_StateFrame();
  ASSERT_EQ(state->device_poses()->size(), 2u);
  expect_pose(*state->device_poses()->Get(0), sim.hand_pose(0));
  expect_pose(*state->device_poses()->Get(1), sim.proxy_pose(1));
  EXPECT_NE(sim.hand_pose(0).position, sim.proxy_pose(0).position);        // the hand, not its first tip
  EXPECT_GT(glm::length(sim.proxy_pose(1).position - stylus_from), 1e-4);  // it did move
  ASSERT_EQ(h->device_input_sequences()->size(), 2u);
  EXPECT_EQ(h->device_input_sequences()->Get(0), 7u);
  EXPECT_EQ(h->device_input_sequences()->Get(1), 9u);
  EXPECT_EQ(h->last_input_sequence(), 9u);
  // Without per-channel sequences (before any input): zeros, one per channel.
  const proto::HapticFrame* none = envelope(frames.haptic_frame(124, 0))->message_as_HapticFrame();
  ASSERT_EQ(none->device_input_sequences()->size(), 2u);
  EXPECT_EQ(none->device_input_sequences()->Get(0), 0u);
  EXPECT_EQ(none->device_input_sequences()->Get(1), 0u);
}

// Through the live loop: inputs on both channels, each frame's sequences per
// channel, and each channel's pose arriving where its inputs sent it.
TEST(RealtimeLoop, EachChannelsNewestInputAndPoseComeBack) {
  Simulation sim(two_channel_spec());
  FrameEncoder frames(sim, "two", 1, 2e-4);
  RealtimeOptions options;
  options.dt = 2e-4;
  RealtimeLoop loop(sim, frames, options);
  std::vector<uint64_t> glove_seq, stylus_seq;
  glove_seq.reserve(4000);
  stylus_seq.reserve(4000);
  proto::ProxyPose last_glove, last_stylus;
  std::atomic<bool> started{false};
  loop.on_haptic([&](std::span<const uint8_t> m) {
    const proto::HapticFrame* h = proto::GetEnvelope(m.data())->message_as_HapticFrame();
    started = true;
    glove_seq.push_back(h->device_input_sequences()->Get(0));
    stylus_seq.push_back(h->device_input_sequences()->Get(1));
    last_glove = *h->device_poses()->Get(0);
    last_stylus = *h->device_poses()->Get(1);
  });
  const Vec3 glove_at(0.021, 0.07, 0.018), stylus_at(0.03, 0.08, 0.025);
  std::atomic<bool> stop{false};
  std::thread device([&] {
    // The inputs start after the loop's first step (a loaded host can start its thread late).
    while (!started) std::this_thread::sleep_for(std::chrono::microseconds(100));
    for (int k = 1; k <= 50; ++k) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      DeviceSample s;
      s.device = 0;  // glove: sequences 1000 + k
      s.sequence = 1000 + uint64_t(k);
      s.device_time_ns = int64_t(k) * 1000000;
      s.pose.position = glove_at;
      loop.post_input(s);
      if (k <= 20) {  // stylus: 1..20, then silent
        s.device = 1;
        s.sequence = uint64_t(k);
        s.pose.position = stylus_at;
        loop.post_input(s);
      }
    }
    // The last inputs glide in: 2.3 cm from where the stylus waited, at the approach speed (0.25 m/s).
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    stop = true;
  });
  loop.run(stop);
  device.join();
  ASSERT_GT(glove_seq.size(), 100u);
  EXPECT_EQ(glove_seq.front(), 0u);  // before any input
  EXPECT_EQ(glove_seq.back(), 1050u);
  EXPECT_EQ(stylus_seq.back(), 20u);  // its own, not the glove's
  EXPECT_TRUE(std::is_sorted(glove_seq.begin(), glove_seq.end()));
  EXPECT_TRUE(std::is_sorted(stylus_seq.begin(), stylus_seq.end()));
  // Each channel's pose is its device's (the coupling pulls toward it), and
  // the bodies, in free space, came to rest on them.
  EXPECT_NEAR(last_glove.position().y(), 0.07f, 1e-6f);
  EXPECT_NEAR(last_stylus.position().x(), 0.03f, 1e-6f);
  EXPECT_NEAR(last_stylus.position().y(), 0.08f, 1e-6f);
  EXPECT_LT(glm::distance(sim.hand_pose(0).position, glove_at), 1e-4);
  EXPECT_LT(glm::distance(sim.proxy_pose(1).position, stylus_at), 1e-4);
}

// A device that presses its coupled proxy into the block and lifts it off:
// while the proxy touches, the frames tell the device the stiffness it
// feels; once the proxy has touched nothing for 2 ms, none, whatever the
// fit of the device's force to its motion still holds from the press (K
// times the hand's motion since a state ms old would pull a lifting hand
// back toward the body).
TEST(FrameEncoder, AFreeCoupledProxyTellsItsDeviceNoStiffness) {
  Simulation sim(poke_spec());
  const double dt = 2e-4;
  FrameEncoder frames(sim, "poke", 1, dt);
  const DeviceLimits limits{4.0, 0.0, 2000.0};
  sim.couple_device(0, &limits);
  Pose device = sim.proxy_pose(0);
  int pressed = 0, told_pressing = 0, free_frames = 0, told_free = 0, untouched = 0;
  for (int k = 0; k < 1500; ++k) {  // 6 mm down over 0.1 s, held 0.1 s, up 12 mm over 0.1 s at 0.12 m/s
    ProxyMotion m;
    m.t0 = sim.time();
    m.t1 = m.t0 + dt;
    m.from = device;
    if (k < 500)
      device.position.y -= 0.006 / 500;
    else if (k >= 1000)
      device.position.y += 0.012 / 500;
    m.to = device;
    sim.set_proxy_motion(0, m);
    ASSERT_FALSE(sim.advance(dt).fault) << "step " << k;
    frames.add_step_forces();
    sim.clear_impulses();
    const proto::HapticFrame* h = envelope(frames.haptic_frame(0, 0))->message_as_HapticFrame();
    const proto::DeviceHaptics& d = *h->devices()->Get(0);
    const float kyy = d.stiffness().m11();
    if (k >= 500 && k < 1000 && d.contacts() > 0) {
      ++pressed;
      told_pressing += kyy < 0;
    }
    if (k == 999) {
      // Held in: the state frame shows the device where it is, below its
      // proxy, which the block holds up (a viewer draws both).
      const proto::StateFrame* f = envelope(frames.state_frame(0))->message_as_StateFrame();
      ASSERT_EQ(f->device_poses()->size(), 1u);
      expect_pose(*f->device_poses()->Get(0), device);
      EXPECT_GT(f->proxies()->Get(0)->position().y() - f->device_poses()->Get(0)->position().y(), 0.5e-3);
    }
    untouched = d.contacts() > 0 ? 0 : untouched + 1;
    if (k >= 1000 && untouched * dt > 2e-3 + 1e-9) {
      ++free_frames;
      told_free += kyy != 0 || d.stiffness().m00() != 0 || d.stiffness().m22() != 0;
    }
  }
  EXPECT_GT(pressed, 400) << "the proxy should rest on the block while the device holds it in";
  EXPECT_EQ(told_pressing, pressed);
  EXPECT_GT(free_frames, 100) << "the proxy should leave the block";
  EXPECT_EQ(told_free, 0) << "of " << free_frames << " frames of a free proxy";
}

// The local model (protocol 1.11) of a device pressing its coupled proxy
// into the block: while pressed, the normal points out of the block, the
// release plane lies where the model's normal force falls to zero, the
// damping is the coupling's time constant times the felt stiffness, and the
// model predicts a frame 5 ms later from the device's pose then better than
// the force held would; once free, it is the force alone.
TEST(FrameEncoder, ACoupledDevicesLocalModelPredictsTheForceAtALaterPose) {
  Simulation sim(poke_spec());
  const double dt = 2e-4;
  FrameEncoder frames(sim, "poke", 1, dt);
  const DeviceLimits limits{4.0, 0.0, 2000.0};
  sim.couple_device(0, &limits);
  Pose device = sim.proxy_pose(0);
  struct Seen {
    glm::dvec3 force, x0, v0, normal;
    glm::dmat3 K, D;
    double release, radius;
    uint32_t contacts;
  };
  std::vector<Seen> seen;
  for (int k = 0; k < 1500; ++k) {  // 6 mm down over 0.1 s, held 0.1 s, up 12 mm over 0.1 s at 0.12 m/s
    ProxyMotion m;
    m.t0 = sim.time();
    m.t1 = m.t0 + dt;
    m.from = device;
    if (k < 500)
      device.position.y -= 0.006 / 500;
    else if (k >= 1000)
      device.position.y += 0.012 / 500;
    m.to = device;
    sim.set_proxy_motion(0, m);
    ASSERT_FALSE(sim.advance(dt).fault) << "step " << k;
    frames.add_step_forces();
    sim.clear_impulses();
    const proto::HapticFrame* h = envelope(frames.haptic_frame(0, 0))->message_as_HapticFrame();
    ASSERT_EQ(h->device_models()->size(), 1u);
    const proto::DeviceHaptics& d = *h->devices()->Get(0);
    const proto::DeviceModel& dm = *h->device_models()->Get(0);
    const auto vec = [](const proto::Vec3f& v) { return glm::dvec3(v.x(), v.y(), v.z()); };
    const auto mat = [](const proto::Mat3f& a) {  // row-major on the wire, glm column-major
      return glm::transpose(
          glm::dmat3(a.m00(), a.m01(), a.m02(), a.m10(), a.m11(), a.m12(), a.m20(), a.m21(), a.m22()));
    };
    seen.push_back({vec(d.force()), vec(h->device_poses()->Get(0)->position()), vec(dm.velocity()), vec(dm.normal()),
                    mat(d.stiffness()), mat(dm.damping()), dm.release_m(), dm.radius_m(), d.contacts()});
  }
  const double radius = bounding_radius(sim.proxies()[0].geometry);
  int pressed = 0, free_frames = 0;
  double err_model = 0, err_hold = 0;
  const int ahead = 25;  // 5 ms
  for (size_t k = 0; k + ahead < seen.size(); ++k) {
    const Seen& s = seen[k];
    EXPECT_FLOAT_EQ(float(s.radius), float(std::clamp(0.5 * radius, 1e-3, 1e-2)));
    if (s.K[1][1] == 0) {  // free (or gliding): the force alone
      ++free_frames;
      EXPECT_EQ(s.normal, glm::dvec3(0.0));
      EXPECT_EQ(s.D, glm::dmat3(0.0));
      continue;
    }
    ++pressed;
    EXPECT_GT(s.normal.y, 0.99) << k;
    EXPECT_NEAR(glm::length(s.normal), 1.0, 1e-6);
    // The release plane: F0.n + n.K n release = 0 (float on the wire).
    EXPECT_NEAR(glm::dot(s.force, s.normal) + glm::dot(s.normal, s.K * s.normal) * s.release, 0.0,
                1e-5 + 1e-4 * glm::length(s.force));
    // The damper as felt: the same multiple of -K in every entry, a few milliseconds' worth.
    const double tau = s.D[1][1] / -s.K[1][1];
    EXPECT_GT(tau, 1e-4);
    EXPECT_LT(tau, 2e-2);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) EXPECT_NEAR(s.D[i][j], -tau * s.K[i][j], 1e-5 * std::abs(s.D[1][1])) << k;
    }
    if (k > 100 && k < 480) {
      EXPECT_NEAR(s.v0.y, -0.06, 1e-6) << k;  // the press's speed
    }
    // Prediction within the radius, while pressing in and holding.
    if (k < 100 || k >= 950 || seen[k + ahead].contacts == 0) continue;
    const Seen& later = seen[k + ahead];
    const glm::dvec3 dx = later.x0 - s.x0;
    if (glm::length(dx) > s.radius) continue;
    const glm::dvec3 predicted = s.force + s.K * dx - s.D * (later.v0 - s.v0);
    err_model += glm::length(predicted - later.force);
    err_hold += glm::length(s.force - later.force);
  }
  EXPECT_GT(pressed, 400);
  EXPECT_GT(free_frames, 100);
  EXPECT_LT(err_model, 0.5 * err_hold) << "the model's error over the press and hold, against holding the force: "
                                       << err_hold;
}

// The default: a device with its limits (its Hello) goes 5 mm into the
// block, 13 mm past where its sphere would touch. The proxy stops at the surface, sunk only as far as the
// device's 1 N presses it; each frame's device force is the coupling's,
// never above 1 N; the frames carry the device's pose, the body's, and a
// stiffness that pulls the device back toward the body (negative along y).
TEST(RealtimeLoop, ACoupledDeviceFeelsItsLimitAndItsProxyStaysOnTheSurface) {
  Simulation sim(poke_spec());
  FrameEncoder frames(sim, "poke", 1, 2e-4);
  RealtimeOptions options;
  options.dt = 2e-4;
  RealtimeLoop loop(sim, frames, options);
  std::atomic<bool> stop{false}, holding{false};
  float peak = 0, held_force = 0, device_y = 0, body_y = 0, k_yy = 0;
  bool coupled = false, saturated = false;
  loop.on_haptic([&](std::span<const uint8_t> m) {
    const proto::HapticFrame* h = proto::GetEnvelope(m.data())->message_as_HapticFrame();
    const proto::DeviceHaptics& d = *h->devices()->Get(0);
    const float f = std::hypot(d.force().x(), d.force().y(), d.force().z());
    peak = std::max(peak, f);
    const proto::DeviceCoupling& c = *h->device_couplings()->Get(0);
    coupled = c.coupled();
    if (!holding) return;
    held_force = d.force().y();
    saturated = c.saturated();
    device_y = h->device_poses()->Get(0)->position().y();
    body_y = c.body().position().y();
    k_yy = d.stiffness().m11();
  });
  std::thread device([&] {
    const Clock::time_point t0 = Clock::now();
    for (int k = 1; k <= 300; ++k) {  // down 14 mm over 0.2 s (from 1 mm above touching), then hold
      std::this_thread::sleep_until(t0 + std::chrono::milliseconds(k));
      DeviceSample s;
      s.device = 0;
      s.sequence = uint64_t(k);
      s.device_time_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t0).count();
      s.pose.position = Vec3(0.02, 0.029 - 0.014 * std::min(1.0, k / 200.0), 0.02);
      s.drive.has_limits = true;
      s.drive.limits = {1.0, 0.0, 2000.0};
      loop.post_input(s);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    holding = true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    stop = true;
  });
  loop.run(stop);
  device.join();
  EXPECT_TRUE(loop.stats().fault.empty()) << loop.stats().fault;
  EXPECT_TRUE(coupled);
  EXPECT_LE(peak, 1.0f + 1e-5f);
  EXPECT_TRUE(saturated);
  EXPECT_NEAR(held_force, 1.0f, 1e-3f) << "the device, 13 mm past touching, should feel its whole limit, upward";
  EXPECT_NEAR(device_y, 0.015f, 1e-6f);
  // The sphere (radius 8 mm) rests on the top (y = 0.02), pressed in a few millimetres by 1 N.
  EXPECT_GT(body_y, 0.028f - 0.006f);
  EXPECT_LT(body_y, 0.028f);
  EXPECT_LT(k_yy, 0.0f);
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
  // One body, over everything.
  ASSERT_EQ(d->bodies()->size(), 1u);
  EXPECT_EQ(d->bodies()->Get(0)->vertex_end(), 18u);
  EXPECT_EQ(d->bodies()->Get(0)->triangle_end(), d->triangles()->size() / 3);
}

// Two bodies, one with a fine surface: each body's frame vertices, triangles
// and fine surface are slices of the description's arrays, and each slice
// refers to its own body's only.
TEST(FrameEncoder, EachBodyIsASliceOfTheDescription) {
  BodyParts block;
  block.name = "block";
  block.mesh = make_box(Vec3(0.0), Vec3(0.04, 0.02, 0.04), {4, 2, 4});
  block.materials = {MaterialSpec{MaterialModel::StVK, 3e4, 0.3, 1000}};
  block.surface = std::make_shared<const EmbeddedSurface>(
      embed_surface(block.mesh, test::make_uv_sphere(Vec3(0.02, 0.01, 0.02), 0.0085, 16, 8), 0.001));
  BodyParts lid;
  lid.name = "lid";
  lid.mesh = make_box(Vec3(0.0, 0.03, 0.0), Vec3(0.04, 0.035, 0.04), {2, 1, 2});
  lid.materials = block.materials;
  ModelSpec spec;
  add_bodies(spec, {block, lid});
  Simulation sim(spec);
  FrameEncoder frames(sim, "two", 1, 2e-4);
  const auto* d = proto::GetEnvelope(frames.scene_description().data())->message_as_SceneDescription();
  ASSERT_NE(d, nullptr);
  ASSERT_EQ(d->bodies()->size(), 2u);
  uint32_t vertices = 0, triangles = 0, fine = 0, fine_triangles = 0;
  for (uint32_t b = 0; b < 2; ++b) {
    const proto::BodyInfo& info = *d->bodies()->Get(b);
    const BodySpec& body = spec.bodies[b];
    EXPECT_EQ(info.name()->str(), body.name);
    EXPECT_EQ(info.node_begin(), uint32_t(body.node_begin));
    EXPECT_EQ(info.vertex_begin(), vertices);  // slices follow each other
    EXPECT_EQ(info.triangle_begin(), triangles);
    EXPECT_EQ(info.fine_vertex_begin(), fine);
    EXPECT_EQ(info.fine_triangle_begin(), fine_triangles);
    EXPECT_GT(info.triangle_end(), info.triangle_begin());
    for (uint32_t v = info.vertex_begin(); v < info.vertex_end(); ++v) {
      const uint32_t n = d->surface_nodes()->Get(v);
      EXPECT_GE(n, uint32_t(body.node_begin));
      EXPECT_LT(n, uint32_t(body.node_end));
    }
    for (uint32_t k = 3 * info.triangle_begin(); k < 3 * info.triangle_end(); ++k) {
      EXPECT_GE(d->triangles()->Get(k), info.vertex_begin());
      EXPECT_LT(d->triangles()->Get(k), info.vertex_end());
    }
    for (uint32_t k = 4 * info.fine_vertex_begin(); k < 4 * info.fine_vertex_end(); ++k) {
      EXPECT_GE(d->embedded()->carriers()->Get(k), info.vertex_begin());
      EXPECT_LT(d->embedded()->carriers()->Get(k), info.vertex_end());
    }
    vertices = info.vertex_end();
    triangles = info.triangle_end();
    fine = info.fine_vertex_end();
    fine_triangles = info.fine_triangle_end();
  }
  EXPECT_EQ(vertices, d->surface_nodes()->size());
  EXPECT_EQ(triangles, d->triangles()->size() / 3);
  EXPECT_EQ(fine, d->embedded()->rest_positions()->size() / 3);  // the lid's boundary is its fine surface
  EXPECT_EQ(fine_triangles, d->embedded()->triangles()->size() / 3);
  EXPECT_GT(d->bodies()->Get(1)->fine_vertex_end(), d->bodies()->Get(1)->fine_vertex_begin());
}

}  // namespace
}  // namespace tactile
