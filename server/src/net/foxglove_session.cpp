#include "net/foxglove_session.hpp"

#include <array>
#include <cstring>

#include <nlohmann/json.hpp>

#include "record/recorder.hpp"
#include "tactile_generated.h"
#include "tactile_version.hpp"

namespace tactile {
namespace {

using nlohmann::json;

// The topic a message type goes out on, as in a recording; nullptr for the
// messages only a session has (Welcome, Pong, ReplayStatus...).
const char* topic_of(proto::Message type) {
  switch (type) {
    case proto::Message::SceneDescription: return "/scene";
    case proto::Message::StateFrame: return "/state";
    case proto::Message::HapticFrame: return "/haptic";
    case proto::Message::Telemetry: return "/telemetry";
    case proto::Message::SafetyEvent: return "/safety";
    case proto::Message::DeviceStatus: return "/device_status";
    case proto::Message::Error: return "/error";
    default: return nullptr;
  }
}

FoxgloveSession::Frame text_frame(const json& j) {
  const std::string s = j.dump();
  return {true, std::vector<uint8_t>(s.begin(), s.end())};
}

}  // namespace

bool asks_for_foxglove(std::string_view protocols) {
  // A comma-separated list (RFC 6455 4.1), tokens with optional spaces.
  size_t at = 0;
  while (at <= protocols.size()) {
    size_t end = protocols.find(',', at);
    if (end == std::string_view::npos) end = protocols.size();
    std::string_view token = protocols.substr(at, end - at);
    while (!token.empty() && (token.front() == ' ' || token.front() == '\t')) token.remove_prefix(1);
    while (!token.empty() && (token.back() == ' ' || token.back() == '\t')) token.remove_suffix(1);
    if (token == kFoxgloveSubprotocol) return true;
    at = end + 1;
  }
  return false;
}

FoxgloveSession::FoxgloveSession(std::string server_name) : server_name_(std::move(server_name)) {
  uint32_t id = 1;
  for (const auto& [topic, type] :
       std::initializer_list<std::pair<const char*, const char*>>{{"/scene", "SceneDescription"},
                                                                  {"/state", "StateFrame"},
                                                                  {"/haptic", "HapticFrame"},
                                                                  {"/telemetry", "Telemetry"},
                                                                  {"/safety", "SafetyEvent"},
                                                                  {"/device_status", "DeviceStatus"},
                                                                  {"/error", "Error"}}) {
    const std::vector<uint8_t> schema = channel_schema(type);
    channels_.push_back(
        {id++, topic, "flatbuffer", std::string("tactile.proto.") + type, "flatbuffer", to_base64(schema)});
  }
  const auto view = [&](const char* topic, const char* name, const std::string& schema) {
    channels_.push_back({id++, topic, "json", name, "jsonschema", schema});
  };
  view("/foxglove/body", "foxglove.SceneUpdate", scene_update_json_schema());
  view("/foxglove/surface", "foxglove.SceneUpdate", scene_update_json_schema());
  view("/foxglove/log", "foxglove.Log", log_json_schema());
  view("/foxglove/transform", "foxglove.FrameTransform", frame_transform_json_schema());
}

std::vector<FoxgloveSession::Frame> FoxgloveSession::greeting() const {
  json info{{"op", "serverInfo"},
            {"name", server_name_},
            {"capabilities", json::array()},
            {"supportedEncodings", json::array()},
            {"metadata", {{"version", kVersion}, {"protocol", kProtocolVersion}}}};
  json list = json::array();
  for (const Channel& c : channels_)
    list.push_back({{"id", c.id},
                    {"topic", c.topic},
                    {"encoding", c.encoding},
                    {"schemaName", c.schema_name},
                    {"schemaEncoding", c.schema_encoding},
                    {"schema", c.schema}});
  return {text_frame(info), text_frame({{"op", "advertise"}, {"channels", std::move(list)}})};
}

FoxgloveSession::Frame FoxgloveSession::status(int level, const std::string& message) const {
  return text_frame({{"op", "status"}, {"level", level}, {"message", message}});
}

std::optional<FoxgloveSession::Frame> FoxgloveSession::on_text(std::string_view text) {
  const json j = json::parse(text, nullptr, false);
  if (!j.is_object() || !j.contains("op") || !j["op"].is_string())
    return status(2, "a message that is no JSON object with an \"op\": ignored");
  const std::string op = j["op"].get<std::string>();
  try {
    if (op == "subscribe") {
      std::string unknown;
      for (const json& s : j.at("subscriptions")) {
        const auto id = s.at("id").get<uint32_t>();
        const auto channel = s.at("channelId").get<uint32_t>();
        if (channel == 0 || channel > channels_.size()) {
          unknown += (unknown.empty() ? "" : ", ") + std::to_string(channel);
          continue;
        }
        subscriptions_[id] = channel;
      }
      if (!unknown.empty()) return status(2, "subscribe: no channel " + unknown + " is advertised");
      return std::nullopt;
    }
    if (op == "unsubscribe") {
      for (const json& id : j.at("subscriptionIds")) subscriptions_.erase(id.get<uint32_t>());
      return std::nullopt;
    }
  } catch (const json::exception& e) {
    return status(2, op + ": " + e.what());
  }
  return status(1, "\"" + op + "\" is not taken here: this server advertises channels to subscribe to, no more");
}

FoxgloveSession::Frame FoxgloveSession::on_binary() const {
  return status(1, "a binary message: this server takes no client publishing (clientPublish is not a capability)");
}

std::optional<uint32_t> FoxgloveSession::channel_of(const std::string& topic) const {
  for (const Channel& c : channels_)
    if (c.topic == topic) return c.id;
  return std::nullopt;
}

void FoxgloveSession::emit(uint32_t channel, uint64_t unix_ns, std::span<const uint8_t> head,
                           std::span<const uint8_t> payload, std::vector<Frame>& out) const {
  for (const auto& [sub, ch] : subscriptions_) {
    if (ch != channel) continue;
    Frame f{false, {}};
    f.bytes.resize(1 + 4 + 8 + head.size() + payload.size());
    uint8_t* p = f.bytes.data();
    p[0] = 0x01;                  // message data
    std::memcpy(p + 1, &sub, 4);  // little-endian, as on every target we build for
    std::memcpy(p + 5, &unix_ns, 8);
    if (!head.empty()) std::memcpy(p + 13, head.data(), head.size());
    if (!payload.empty()) std::memcpy(p + 13 + head.size(), payload.data(), payload.size());
    out.push_back(std::move(f));
  }
}

void FoxgloveSession::translate(std::span<const uint8_t> envelope, uint64_t unix_ns, std::vector<Frame>& out) {
  std::array<uint8_t, kEnvelopeOffset> head;
  if (!root_header(envelope, head)) return;
  const proto::Envelope* e = proto::GetEnvelope(envelope.data());
  const auto subscribed = [&](const char* topic) -> std::optional<uint32_t> {
    const std::optional<uint32_t> c = channel_of(topic);
    for (const auto& [sub, ch] : subscriptions_)
      if (c && ch == *c) return c;
    return std::nullopt;
  };
  const auto json_out = [&](uint32_t channel, const std::string& text) {
    emit(channel, unix_ns, {}, {reinterpret_cast<const uint8_t*>(text.data()), text.size()}, out);
  };
  const int64_t log_ns = int64_t(unix_ns);
  const auto upright = [&] {
    if (const auto c = subscribed("/foxglove/transform")) json_out(*c, FoxgloveViews::upright(log_ns));
    last_upright_ns_ = unix_ns;
  };
  if (const char* topic = topic_of(e->message_type()))
    if (const auto c = subscribed(topic)) emit(*c, unix_ns, head, envelope, out);
  if (const auto* scene = e->message_as_SceneDescription()) {
    views_.scene(*scene);
    upright();
  } else if (const auto* state = e->message_as_StateFrame()) {
    const auto body = subscribed("/foxglove/body");
    if (body) {
      if (const std::optional<std::string> view = views_.body(*state, log_ns)) {
        if (!last_upright_ns_ || unix_ns - *last_upright_ns_ >= uint64_t(FoxgloveViews::kUprightEveryNs)) upright();
        json_out(*body, *view);
      }
    }
    if (const auto c = subscribed("/foxglove/surface"))
      if (const std::optional<std::string> fine = views_.surface(*state, log_ns)) json_out(*c, *fine);
  } else if (const auto* safety = e->message_as_SafetyEvent()) {
    if (const auto c = subscribed("/foxglove/log")) json_out(*c, FoxgloveViews::log(*safety, log_ns));
  } else if (const auto* err = e->message_as_Error()) {
    if (const auto c = subscribed("/foxglove/log")) json_out(*c, FoxgloveViews::log(*err, log_ns));
  }
}

}  // namespace tactile
