// What a client sent, checked before the server acts on it: the bytes
// verified as a tactile Envelope holding a message, and the values the
// server will use in range. Pure (no I/O, no state), so that a fuzzer and the
// tests can drive it directly (server/fuzz/).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "tactile_generated.h"

namespace tactile {

struct Inbound {
  const proto::Envelope* envelope = nullptr;  // into the bytes given; null when refused
  proto::ErrorCode error = proto::ErrorCode::Malformed;
  std::string message;  // what is wrong, when refused
  explicit operator bool() const { return envelope != nullptr; }
};

// Verifies the bytes (FlatBuffers verifier: every offset, length and string
// inside them) and refuses an Envelope without a message.
Inbound read_inbound(const uint8_t* data, size_t size);

// "" when a device input is usable: a finite position and an orientation
// that normalizes (|q| within [0.5, 2]); else what is wrong.
std::string check_device_input(const proto::DeviceInput& in);
// What a device Hello's device_limits say, or why they cannot be taken: one
// entry per named channel at most, each bound finite and >= 0.
std::string check_device_limits(const proto::Hello& h);

// Text as valid UTF-8 without control characters, for what leaves the
// server quoting a client (an Error naming a channel, a path, a parameter):
// each byte that is not part of a valid sequence (RFC 3629), and each
// control character but newline and tab, becomes \xNN. Valid text passes.
std::string utf8_text(std::string_view in);

// What a SafetyEvent's strings may hold [bytes]: a channel name, a cause.
constexpr size_t kMaxSafetyDeviceBytes = 128;
constexpr size_t kMaxSafetyMessageBytes = 512;

// "" when a safety event may be relayed: a channel named, strings of UTF-8
// within their bounds, a kind this version knows, a finite force magnitude
// (>= 0); else what is wrong. (Whether the sender drives that channel is the
// connection's to check.)
std::string check_safety_event(const proto::SafetyEvent& ev);
// What is wrong with a DeviceStatus (a channel, UTF-8 strings within bounds,
// figures finite and >= 0, a known mode), or "" when nothing is.
std::string check_device_status(const proto::DeviceStatus& st);

}  // namespace tactile
