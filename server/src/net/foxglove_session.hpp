// The live session in the Foxglove WebSocket protocol (foxglove.websocket.v1,
// github.com/foxglove/ws-protocol docs/spec.md), for a Foxglove or
// Lichtblick that connects to a running server: the same channels, schemas
// and views a recording has (proto/RECORDING.md), live. Sans-I/O, as
// net/connection.hpp: the WebSocket shell (net/ws_connection.hpp) greets the
// connection's rules as a viewer that also reads haptic frames, hands each
// message they queue to translate(), and writes what comes out; a client's
// text messages go to on_text().
//
// What the session offers: serverInfo, then one advertise of every channel;
// a subscribe starts a channel's messages, an unsubscribe stops them. A
// FlatBuffers channel's message is its Envelope behind the root header
// (kEnvelopeOffset), as in a recording, and its schema is advertised in
// base64, as the spec asks of binary schemas; a JSON channel's schema is its
// JSON Schema's text. Anything else a client sends is answered with a
// status message naming it (this server takes no publishing, parameters or
// services).
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "record/foxglove_views.hpp"

namespace tactile {

inline constexpr const char* kFoxgloveSubprotocol = "foxglove.websocket.v1";

// Whether an upgrade's Sec-WebSocket-Protocol list names the Foxglove one.
bool asks_for_foxglove(std::string_view protocols);

class FoxgloveSession {
 public:
  struct Channel {
    uint32_t id;
    std::string topic, encoding, schema_name, schema_encoding, schema;
  };
  // A frame to write: text (JSON) or binary.
  struct Frame {
    bool text;
    std::vector<uint8_t> bytes;
  };

  explicit FoxgloveSession(std::string server_name);

  // What the client is sent first: serverInfo, then the advertise.
  std::vector<Frame> greeting() const;
  const std::vector<Channel>& channels() const { return channels_; }

  // A client's text message: subscriptions change; a status frame when it
  // is not one this server takes or does not parse (nullopt otherwise).
  std::optional<Frame> on_text(std::string_view text);
  // A binary message from the client: this server advertises no client
  // publishing, so a status says so.
  Frame on_binary() const;

  // The frames an Envelope the server sent this connection makes for the
  // client's subscriptions at `unix_ns` (message data: opcode 1, the
  // subscription id, the time, the payload), appended to `out`.
  void translate(std::span<const uint8_t> envelope, uint64_t unix_ns, std::vector<Frame>& out);

  size_t subscriptions() const { return subscriptions_.size(); }
  // A status message (level 0 info, 1 warning, 2 error).
  Frame status(int level, const std::string& message) const;

 private:
  std::optional<uint32_t> channel_of(const std::string& topic) const;
  void emit(uint32_t channel, uint64_t unix_ns, std::span<const uint8_t> head, std::span<const uint8_t> payload,
            std::vector<Frame>& out) const;

  std::string server_name_;
  std::vector<Channel> channels_;
  std::map<uint32_t, uint32_t> subscriptions_;  // subscription id -> channel id
  FoxgloveViews views_;
  std::optional<uint64_t> last_upright_ns_;
};

}  // namespace tactile
