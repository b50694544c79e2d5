// The live session in Foxglove's WebSocket protocol, without sockets: the
// subprotocol offered, the greeting, subscriptions and the message frames a
// server message makes. (Through Foxglove's own client library against a
// running server: tests/test_foxglove.py.)
#include "net/foxglove_session.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "record/recorder.hpp"
#include "tactile_generated.h"

namespace tactile {
namespace {

using nlohmann::json;

std::vector<uint8_t> state_frame(uint64_t step) {
  proto::EnvelopeT e;
  proto::StateFrameT m;
  m.step = step;
  e.message.Set(std::move(m));
  flatbuffers::FlatBufferBuilder b;
  proto::FinishEnvelopeBuffer(b, proto::Envelope::Pack(b, &e));
  return {b.GetBufferPointer(), b.GetBufferPointer() + b.GetSize()};
}

json text_of(const FoxgloveSession::Frame& f) {
  EXPECT_TRUE(f.text);
  return json::parse(std::string(f.bytes.begin(), f.bytes.end()));
}

uint32_t channel(const FoxgloveSession& s, const std::string& topic) {
  for (const FoxgloveSession::Channel& c : s.channels())
    if (c.topic == topic) return c.id;
  return 0;
}

TEST(FoxgloveSession, TheSubprotocolIsFoundInTheOfferedList) {
  EXPECT_TRUE(asks_for_foxglove("foxglove.websocket.v1"));
  EXPECT_TRUE(asks_for_foxglove("chat, foxglove.websocket.v1 ,other"));
  EXPECT_FALSE(asks_for_foxglove(""));
  EXPECT_FALSE(asks_for_foxglove("foxglove.websocket.v10"));
  EXPECT_FALSE(asks_for_foxglove("xfoxglove.websocket.v1"));
}

TEST(FoxgloveSession, TheGreetingIsServerInfoThenEveryChannelWithItsSchema) {
  const FoxgloveSession s("tactile");
  const std::vector<FoxgloveSession::Frame> g = s.greeting();
  ASSERT_EQ(g.size(), 2u);
  const json info = text_of(g[0]), advertise = text_of(g[1]);
  EXPECT_EQ(info["op"], "serverInfo");
  EXPECT_EQ(info["name"], "tactile");
  EXPECT_EQ(advertise["op"], "advertise");
  ASSERT_EQ(advertise["channels"].size(), s.channels().size());
  for (const json& c : advertise["channels"]) {
    if (c["encoding"] == "flatbuffer") {
      // A binary schema in base64: what a recording's channel of that type carries.
      const std::string type = c["schemaName"].get<std::string>().substr(std::string("tactile.proto.").size());
      EXPECT_EQ(from_base64(c["schema"].get<std::string>()), channel_schema(type)) << c["topic"];
      EXPECT_EQ(c["schemaEncoding"], "flatbuffer");
    } else {
      EXPECT_EQ(c["encoding"], "json");
      EXPECT_EQ(c["schemaEncoding"], "jsonschema");
      EXPECT_TRUE(json::parse(c["schema"].get<std::string>()).is_object()) << c["topic"];
    }
  }
}

TEST(FoxgloveSession, ASubscribedChannelGetsEachMessageBehindItsHeaderAndAnUnsubscribedOneNothing) {
  FoxgloveSession s("tactile");
  const std::vector<uint8_t> frame = state_frame(42);
  std::vector<FoxgloveSession::Frame> out;
  s.translate(frame, 1234, out);
  EXPECT_TRUE(out.empty()) << "no subscription yet";
  const uint32_t state = channel(s, "/state");
  ASSERT_NE(state, 0u);
  EXPECT_FALSE(s.on_text(json{{"op", "subscribe"}, {"subscriptions", {{{"id", 9}, {"channelId", state}}}}}.dump()));
  s.translate(frame, 1234, out);
  ASSERT_EQ(out.size(), 1u);
  const std::vector<uint8_t>& b = out[0].bytes;
  EXPECT_FALSE(out[0].text);
  ASSERT_EQ(b.size(), 13 + kEnvelopeOffset + frame.size());
  uint32_t sub = 0;
  uint64_t t = 0;
  std::memcpy(&sub, b.data() + 1, 4);
  std::memcpy(&t, b.data() + 5, 8);
  EXPECT_EQ(b[0], 1);
  EXPECT_EQ(sub, 9u);
  EXPECT_EQ(t, 1234u);
  // The StateFrame is the buffer's root behind the header, and the Envelope follows whole.
  const uint8_t* payload = b.data() + 13;
  EXPECT_EQ(flatbuffers::GetRoot<proto::StateFrame>(payload)->step(), 42u);
  EXPECT_EQ(std::vector<uint8_t>(payload + kEnvelopeOffset, payload + kEnvelopeOffset + frame.size()), frame);
  out.clear();
  EXPECT_FALSE(s.on_text(json{{"op", "unsubscribe"}, {"subscriptionIds", {9}}}.dump()));
  s.translate(frame, 1235, out);
  EXPECT_TRUE(out.empty());
}

TEST(FoxgloveSession, WhatItDoesNotTakeIsAnsweredByAStatusNamingIt) {
  FoxgloveSession s("tactile");
  const auto said = [](const std::optional<FoxgloveSession::Frame>& f) {
    return f ? text_of(*f)["message"].get<std::string>() : std::string("(nothing)");
  };
  EXPECT_NE(said(s.on_text("{")).find("no JSON object"), std::string::npos);
  EXPECT_NE(said(s.on_text(R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":99}]})")).find("no channel 99"),
            std::string::npos);
  EXPECT_NE(said(s.on_text(R"({"op":"subscribe","subscriptions":[{"channelId":1}]})")).find("subscribe:"),
            std::string::npos);
  EXPECT_NE(said(s.on_text(R"({"op":"advertise","channels":[]})")).find("\"advertise\" is not taken"),
            std::string::npos);
  EXPECT_NE(text_of(s.on_binary())["message"].get<std::string>().find("no client publishing"), std::string::npos);
  EXPECT_EQ(s.subscriptions(), 0u);
}

}  // namespace
}  // namespace tactile
