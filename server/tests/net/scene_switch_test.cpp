// The rules of a scene change and of the reset after a fault
// (net/scene_switch.hpp), on a fake port: one test per rule, without a
// director, a socket or a thread. The port records what the rules asked of
// it; each test answers the change as the director would.
#include <gtest/gtest.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "flatbuffers/flatbuffers.h"
#include "net/scene_switch.hpp"

namespace tactile {
namespace {

namespace wire = proto;

struct FakePort : SceneSwitch::Port {
  std::vector<Director::Change> requests;
  Director::Done pending;  // the last change's answer, for the test to call
  std::string refuse;      // a refusal for the next request ("" starts it)
  bool refuse_busy = false;
  std::string running_fault;  // what fault() says
  std::vector<std::shared_ptr<LiveScene>> served;
  std::vector<Bytes> answers;

  std::string request(const Director::Change& change, Director::Done done, bool* busy) override {
    requests.push_back(change);
    *busy = refuse_busy;
    if (!refuse.empty()) return refuse;
    pending = std::move(done);
    return "";
  }
  std::string fault() const override { return running_fault; }
  void serve_installed(std::shared_ptr<LiveScene> scene) override { served.push_back(std::move(scene)); }
  void answer(const Bytes& error) override { answers.push_back(error); }

  const wire::Error* answer_at(size_t i) const { return wire::GetEnvelope(answers.at(i)->data())->message_as_Error(); }
};

Director::Change reset() { return Director::Change{}; }
Director::Change load(const std::string& scene) {
  Director::Change c;
  c.kind = Director::Change::Kind::Load;
  c.scene = scene;
  return c;
}

// A LiveScene stands for itself only by address: the rules never look inside.
std::shared_ptr<LiveScene> some_scene() {
  return std::shared_ptr<LiveScene>(reinterpret_cast<LiveScene*>(16), [](LiveScene*) {});
}

TEST(SceneSwitch, AChangeWhileOneIsUnderWayIsAnsweredBusy) {
  FakePort port;
  SceneSwitch rules(port, false);
  rules.ask(reset(), 1);
  EXPECT_TRUE(rules.changing());
  rules.ask(load("poke.json"), 2);
  ASSERT_EQ(port.requests.size(), 1u) << "the second never reached the director";
  ASSERT_EQ(port.answers.size(), 1u);
  EXPECT_EQ(port.answer_at(0)->code(), wire::ErrorCode::Busy);
  EXPECT_EQ(port.answer_at(0)->request_id(), 2u);
  EXPECT_EQ(port.answer_at(0)->message()->str(), "a scene change is under way: wait for its SceneDescription");
}

TEST(SceneSwitch, AnInstalledSceneIsServedAndEndsTheChange) {
  FakePort port;
  SceneSwitch rules(port, false);
  rules.ask(load("poke.json"), 3);
  ASSERT_EQ(port.requests.size(), 1u);
  EXPECT_EQ(port.requests[0].kind, Director::Change::Kind::Load);
  EXPECT_EQ(port.requests[0].scene, "poke.json");
  const auto scene = some_scene();
  port.pending(scene, "");
  EXPECT_FALSE(rules.changing());
  ASSERT_EQ(port.served.size(), 1u);
  EXPECT_EQ(port.served[0], scene);
  EXPECT_TRUE(port.answers.empty()) << "a SceneDescription to everyone answers it, not an Error";
  rules.ask(reset(), 4);
  EXPECT_EQ(port.requests.size(), 2u) << "the next change is taken";
}

TEST(SceneSwitch, AChangeTheDirectorRefusesIsAnsweredWithWhyAndLeavesNoneUnderWay) {
  FakePort port;
  SceneSwitch rules(port, false);
  port.refuse = "no scene 'x.json' on this server; it has: poke.json";
  rules.ask(load("x.json"), 5);
  EXPECT_FALSE(rules.changing());
  ASSERT_EQ(port.answers.size(), 1u);
  EXPECT_EQ(port.answer_at(0)->code(), wire::ErrorCode::BadRequest);
  EXPECT_EQ(port.answer_at(0)->request_id(), 5u);
  EXPECT_EQ(port.answer_at(0)->message()->str(), port.refuse);
}

TEST(SceneSwitch, ADirectorStillBuildingIsAnsweredBusy) {
  FakePort port;
  SceneSwitch rules(port, false);
  port.refuse = "a scene change is under way: wait for its SceneDescription";
  port.refuse_busy = true;
  rules.ask(reset(), 6);
  EXPECT_FALSE(rules.changing());
  ASSERT_EQ(port.answers.size(), 1u);
  EXPECT_EQ(port.answer_at(0)->code(), wire::ErrorCode::Busy);
}

TEST(SceneSwitch, AFailedBuildIsAnsweredWithItsErrorAndServesNothing) {
  FakePort port;
  SceneSwitch rules(port, false);
  rules.ask(load("broken.json"), 7);
  port.pending(nullptr, "mesh: tetgen failed on broken.json");
  EXPECT_FALSE(rules.changing());
  EXPECT_TRUE(port.served.empty());
  ASSERT_EQ(port.answers.size(), 1u);
  EXPECT_EQ(port.answer_at(0)->code(), wire::ErrorCode::BadRequest);
  EXPECT_EQ(port.answer_at(0)->request_id(), 7u);
  EXPECT_EQ(port.answer_at(0)->message()->str(), "mesh: tetgen failed on broken.json");
}

TEST(SceneSwitch, AControlIsReadAsTheChangeItNames) {
  using Make = std::function<flatbuffers::Offset<void>(flatbuffers::FlatBufferBuilder&)>;
  auto read = [](wire::ControlCommand type, const Make& command) {
    flatbuffers::FlatBufferBuilder b;
    const flatbuffers::Offset<void> body = command(b);
    b.Finish(wire::CreateControl(b, 9, type, body));
    return SceneSwitch::change_of(*flatbuffers::GetRoot<wire::Control>(b.GetBufferPointer()));
  };
  const Director::Change l = read(wire::ControlCommand::LoadScene, [](flatbuffers::FlatBufferBuilder& b) {
    return wire::CreateLoadSceneDirect(b, "poke.json").Union();
  });
  EXPECT_EQ(l.kind, Director::Change::Kind::Load);
  EXPECT_EQ(l.scene, "poke.json");
  const Director::Change p = read(wire::ControlCommand::SetParameter, [](flatbuffers::FlatBufferBuilder& b) {
    return wire::CreateSetParameterDirect(b, "material.E", 6e4).Union();
  });
  EXPECT_EQ(p.kind, Director::Change::Kind::Parameter);
  EXPECT_EQ(p.parameter, "material.E");
  EXPECT_EQ(p.value, 6e4);
  const Director::Change r =
      read(wire::ControlCommand::Reset, [](flatbuffers::FlatBufferBuilder& b) { return wire::CreateReset(b).Union(); });
  EXPECT_EQ(r.kind, Director::Change::Kind::Reset);
}

// ---- the reset after a fault (ServerOptions::reset_on_fault) ----

TEST(FaultReset, NoneUnlessTheServerIsToldTo) {
  FakePort port;
  port.running_fault = "step 812: the body inverted";
  SceneSwitch rules(port, false);
  EXPECT_FALSE(rules.after_telemetry());
  EXPECT_TRUE(port.requests.empty());
  EXPECT_EQ(rules.fault_resets(), 0u);
}

TEST(FaultReset, NoneWhileTheSceneRuns) {
  FakePort port;
  SceneSwitch rules(port, true);
  EXPECT_FALSE(rules.after_telemetry());
  EXPECT_TRUE(port.requests.empty());
}

TEST(FaultReset, NoneWhileAChangeIsUnderWay) {
  FakePort port;
  SceneSwitch rules(port, true);
  rules.ask(load("poke.json"), 1);
  port.running_fault = "step 812: the body inverted";
  EXPECT_FALSE(rules.after_telemetry());
  EXPECT_EQ(port.requests.size(), 1u) << "the load already under way replaces the faulted scene";
}

TEST(FaultReset, AFaultResetsOnceUntilTheResetIsAnsweredAndIsCounted) {
  FakePort port;
  SceneSwitch rules(port, true);
  port.running_fault = "step 812: the body inverted";
  EXPECT_TRUE(rules.after_telemetry());
  ASSERT_EQ(port.requests.size(), 1u);
  EXPECT_EQ(port.requests[0].kind, Director::Change::Kind::Reset);
  EXPECT_EQ(rules.fault_resets(), 1u);
  EXPECT_FALSE(rules.after_telemetry()) << "one reset at a time";
  port.pending(some_scene(), "");
  port.running_fault.clear();
  EXPECT_FALSE(rules.after_telemetry());
  port.running_fault = "step 90: the body inverted";
  EXPECT_TRUE(rules.after_telemetry());
  EXPECT_EQ(rules.fault_resets(), 2u);
  EXPECT_TRUE(port.answers.empty());
}

}  // namespace
}  // namespace tactile
