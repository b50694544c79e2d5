// The director switches scenes between two steps: a reset starts a new
// timeline from rest, a parameter change carries the body on in the same
// one, the paused state survives either, and a fault waits for a replacement.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "live/director.hpp"
#include "mesh/primitives.hpp"
#include "scene/parameters.hpp"

namespace tactile {
namespace {

using namespace std::chrono_literals;

// A soft block on a fixed base, sagging under gravity.
Scene block_scene() {
  Scene s;
  s.name = "block";
  s.spec.mesh = make_box(Vec3(0.0), Vec3(0.04, 0.02, 0.04), {4, 2, 4});
  s.spec.materials = {MaterialSpec{MaterialModel::StVK, 3e4, 0.3, 1000}};
  EssentialBc base;
  base.where.kind = NodeSelector::Kind::Box;
  base.where.hi = Vec3(0.04, 0.0, 0.04);
  s.spec.essential = {base};
  s.spec.effects.gravity = true;
  return s;
}

struct Installs {
  std::mutex mutex;
  std::vector<uint32_t> ids;
  void add(uint32_t id) {
    std::lock_guard<std::mutex> lock(mutex);
    ids.push_back(id);
  }
  size_t size() {
    std::lock_guard<std::mutex> lock(mutex);
    return ids.size();
  }
};

bool wait_for(const std::function<bool()>& done, std::chrono::milliseconds limit = 5000ms) {
  const auto end = std::chrono::steady_clock::now() + limit;
  while (!done()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(1ms);
  }
  return true;
}

TEST(Director, ResetStartsAgainAndAParameterChangeCarriesTheBodyOn) {
  LiveOptions options;
  options.dt = 2e-4;
  auto first = std::make_shared<LiveScene>(block_scene(), 1, options);
  Director director(first);
  Installs installs;
  director.on_installed([&](const std::shared_ptr<LiveScene>& s) { installs.add(s->id()); });
  std::atomic<bool> stop{false};
  std::thread sim([&] { director.run(stop); });

  ASSERT_TRUE(wait_for([&] { return first->loop().stats().clock > 0.05; }));
  // A parameter change: the body goes on from where it was, in the same timeline.
  Scene stiffer = first->scene();
  apply_parameter(stiffer.spec, "material.E", 6e4);
  auto carried = std::make_shared<LiveScene>(stiffer, 1, options);
  director.replace(carried, true);
  ASSERT_TRUE(wait_for([&] { return installs.size() == 1; }));
  EXPECT_EQ(director.current(), carried);
  const double t_switch = first->loop().stats().clock;
  ASSERT_TRUE(wait_for([&] { return carried->loop().stats().steps > first->loop().stats().steps; }));
  EXPECT_GE(carried->loop().stats().clock, t_switch) << "the same timeline goes on";
  EXPECT_EQ(first->loop().stats().clock, t_switch) << "the old scene steps no more";

  // Paused, then reset: the new scene starts from rest and stays paused.
  carried->loop().set_paused(true);
  auto reset = std::make_shared<LiveScene>(stiffer, 2, options);
  director.replace(reset, false);
  ASSERT_TRUE(wait_for([&] { return installs.size() == 2; }));
  EXPECT_TRUE(reset->loop().paused());
  std::this_thread::sleep_for(30ms);
  EXPECT_EQ(reset->sim().time(), 0.0) << "paused: no step";
  reset->loop().set_paused(false);
  ASSERT_TRUE(wait_for([&] { return reset->loop().stats().clock > 0.01; }));
  EXPECT_LT(reset->loop().stats().clock, t_switch) << "a reset starts a new timeline from rest";

  stop = true;
  sim.join();
  EXPECT_EQ(installs.ids, (std::vector<uint32_t>{1, 2}));
  EXPECT_EQ(director.fault(), "");
}

TEST(Director, AFaultedSceneWaitsForItsReplacement) {
  LiveOptions options;
  options.dt = 2e-4;
  // A fixed step far above the critical step, refused: the first step faults.
  Scene bad = block_scene();
  bad.spec.integrator.dt = 0.01;
  bad.spec.integrator.unstable = UnstablePolicy::Refuse;
  auto first = std::make_shared<LiveScene>(bad, 1, LiveOptions{});
  Director director(first);
  std::atomic<int> installs{0};
  director.on_installed([&](const std::shared_ptr<LiveScene>&) { ++installs; });
  std::atomic<bool> stop{false};
  std::thread sim([&] { director.run(stop); });
  ASSERT_TRUE(wait_for([&] { return !director.fault().empty(); }));
  EXPECT_NE(director.fault().find("refused"), std::string::npos) << director.fault();

  auto good = std::make_shared<LiveScene>(block_scene(), 2, options);
  director.replace(good, true);  // nothing to carry from a faulted body: it starts from rest
  ASSERT_TRUE(wait_for([&] { return good->loop().stats().clock > 0.01; }));
  EXPECT_EQ(director.fault(), "");
  EXPECT_EQ(installs.load(), 1);
  stop = true;
  sim.join();
}

}  // namespace
}  // namespace tactile
