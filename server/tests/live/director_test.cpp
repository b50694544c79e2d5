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

namespace tactile {
namespace {

// What a change asks for is checked before anything is built, and built on
// the director's own thread: a load names a scene of its folder, a parameter
// one the scene has; a reset takes a new id, a parameter change the same.
TEST(Director, ChangesAreCheckedThenBuiltOffTheCallersThread) {
  LiveOptions options;
  options.dt = 2e-4;
  auto first = std::make_shared<LiveScene>(block_scene(), 4, options);
  Director director(first);
  director.set_library(TACTILE_SCENE_DIR, options);
  EXPECT_NE(std::find(director.scenes().begin(), director.scenes().end(), "poke.json"), director.scenes().end());
  EXPECT_EQ(std::find(director.scenes().begin(), director.scenes().end(), "scene.schema.json"),
            director.scenes().end());

  std::atomic<bool> stop{false};
  std::thread sim([&] { director.run(stop); });

  // Each change is answered once: with its scene once the simulation thread
  // runs it, or with what went wrong.
  struct Result {
    std::mutex mutex;
    std::shared_ptr<LiveScene> scene;
    double time_at_install = -1;
    int answers = 0;
    std::string error;
    std::thread::id thread;
  } r;
  auto done = [&r](std::shared_ptr<LiveScene> s, const std::string& error) {
    std::lock_guard<std::mutex> lock(r.mutex);
    if (s) r.time_at_install = s->sim().time();
    r.scene = std::move(s), r.error = error, ++r.answers, r.thread = std::this_thread::get_id();
  };
  auto take = [&r] {
    EXPECT_TRUE(wait_for([&] {
      std::lock_guard<std::mutex> lock(r.mutex);
      return r.answers > 0;
    }));
    std::this_thread::sleep_for(20ms);  // a second answer would come by now
    std::lock_guard<std::mutex> lock(r.mutex);
    EXPECT_EQ(r.answers, 1);
    r.answers = 0;
    EXPECT_NE(r.thread, std::this_thread::get_id());
  };

  Director::Change load;
  load.kind = Director::Change::Kind::Load;
  load.scene = "nowhere.json";
  const std::string no = director.request(load, done);
  EXPECT_NE(no.find("no scene 'nowhere.json' on this server; it has: "), std::string::npos) << no;
  EXPECT_NE(no.find("poke.json"), std::string::npos) << no;

  Director::Change parameter;
  parameter.kind = Director::Change::Kind::Parameter;
  parameter.parameter = "material.X";
  EXPECT_NE(director.request(parameter, done), "");

  ASSERT_TRUE(wait_for([&] { return first->sim().time() > 0.01; }));
  parameter.parameter = "material.E";
  parameter.value = 6e4;
  ASSERT_EQ(director.request(parameter, done), "");
  take();
  ASSERT_NE(r.scene, nullptr) << r.error;
  EXPECT_EQ(director.current(), r.scene);
  EXPECT_GT(r.time_at_install, 0.01) << "the body carried on";
  EXPECT_EQ(r.scene->id(), 4u);  // the same timeline
  EXPECT_NE(r.scene->outbox(), nullptr) << "published";

  ASSERT_EQ(director.request(Director::Change{}, done), "");  // a reset
  take();
  ASSERT_NE(r.scene, nullptr) << r.error;
  EXPECT_EQ(r.time_at_install, 0.0) << "from rest";
  EXPECT_EQ(r.scene->id(), 5u);

  load.scene = "poke.json";
  ASSERT_EQ(director.request(load, done), "");
  // While the load builds (meshing a 12 k-tet block takes far longer than
  // this call), another change is refused as busy.
  bool busy = false;
  EXPECT_EQ(director.request(Director::Change{}, done, &busy),
            "a scene change is under way: wait for its SceneDescription");
  EXPECT_TRUE(busy);
  take();
  ASSERT_NE(r.scene, nullptr) << r.error;
  EXPECT_EQ(r.scene->scene().name, "poke");
  EXPECT_EQ(r.scene->id(), 6u);
  stop = true;
  sim.join();
}

// A replacement replaced before it ran is answered so; the viewers' fields
// reach the running scene and every one installed after it.
TEST(Director, AReplacedChangeIsAnsweredAndViewFieldsCarryOver) {
  LiveOptions options;
  options.dt = 2e-4;
  auto first = std::make_shared<LiveScene>(block_scene(), 1, options);
  Director director(first);
  director.set_view_fields(view_field_bit(ViewField::VonMises));
  EXPECT_EQ(first->loop().view_fields(), first->scene().view_fields | view_field_bit(ViewField::VonMises));

  std::string first_answer = "none";
  auto a = std::make_shared<LiveScene>(block_scene(), 2, options);
  director.replace(a, false, [&](std::shared_ptr<LiveScene> s, const std::string& error) {
    first_answer = s ? "installed" : error;
  });
  std::atomic<int> second{0};
  auto b = std::make_shared<LiveScene>(block_scene(), 3, options);
  director.replace(b, false, [&](std::shared_ptr<LiveScene> s, const std::string&) {
    if (s == b) ++second;
  });
  EXPECT_EQ(first_answer, "replaced by a later change before it ran");
  std::atomic<bool> stop{false};
  std::thread sim([&] { director.run(stop); });
  ASSERT_TRUE(wait_for([&] { return second.load() == 1; }));
  EXPECT_EQ(director.current(), b);
  EXPECT_EQ(b->loop().view_fields(), b->scene().view_fields | view_field_bit(ViewField::VonMises));
  stop = true;
  sim.join();
  EXPECT_EQ(second.load(), 1);
}

}  // namespace
}  // namespace tactile
