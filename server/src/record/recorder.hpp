// A recording of a live session (proto/RECORDING.md): every message the
// server publishes or receives, each as its protocol bytes, written to an
// MCAP file on a thread of its own, so that neither the simulation nor the
// network ever waits on the disk.
//
// The network thread post()s each message (the simulation's frames reach
// it through the feed's recording rings, which never overwrite); a queue
// over its bound is a fault that stops the recording, reported, never
// silent loss. Messages wait order_seconds before they are written, so that
// the two sources (the simulation's frames, the network's messages), whose
// stamps interleave out of order, reach the file in log-time order across
// channels. Chunks close at chunk_bytes or chunk_seconds after their first
// message, each in one write: a process killed mid-recording loses at most
// the messages still waiting and the chunk it had open.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "record/foxglove_views.hpp"
#include "record/mcap.hpp"

namespace flatbuffers {
class Parser;
}

namespace tactile {

// Each an Envelope of the protocol (flatbuffer), but Applied: a JSON object
// {"loop_step", "device", "sequence"} per input the simulation applied, in
// the order applied (what a re-simulation replays).
enum class Topic : uint8_t { Scene, State, Haptic, Input, Control, Error, Telemetry, Safety, DeviceStatus, Applied };
inline constexpr int kTopicCount = 10;
const char* topic_name(Topic t);  // "/scene", "/state", ...

struct RecorderOptions {
  // Chunks close at 1 MiB (uncompressed; Foxglove advises at most 4 MiB,
  // the MCAP C++ writer's default is 768 KiB) or a quarter second.
  size_t chunk_bytes = 1 << 20;
  double chunk_seconds = 0.25;
  mcap::Compression compression = mcap::Compression::Zstd;
  // How long a message waits for earlier-stamped ones [s]: frames are
  // stamped when the simulation made them and network messages when they
  // came, and the two reach the recorder up to ~50 ms apart under load
  // (tests/test_recording.py, a session beside busy processes).
  double order_seconds = 0.2;
  size_t queue_bytes = size_t(256) << 20;  // posted, not yet written, before it is a fault
  // An offline writer (a re-simulation) waits for room instead: post() blocks.
  bool wait_for_room = false;
};

struct RecorderStats {
  std::string path;
  uint64_t messages = 0;  // written (in the file or its open chunk)
  uint64_t bytes = 0;
  // Messages that came after a later-stamped one had been written: each is
  // written with its log time raised to that one's (its publish time keeps
  // its own stamp), so that the file stays in log-time order.
  uint64_t late = 0;
  uint64_t unreadable = 0;  // Envelopes that did not verify: left out
  std::string fault;        // what stopped it early, "" if nothing
  bool finished = false;    // the file is closed
};

class Recorder {
 public:
  // Creates the file and writes its header, schema, channels and the
  // `tactile` metadata; throws mcap::McapError naming the path.
  Recorder(const std::string& path, const mcap::Map& metadata, RecorderOptions options = {});
  ~Recorder();  // stop() and wait for the file to close
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // From one thread: a message at `steady_ns` (steady_clock), publish_ns
  // its own server time (0: the same). False when the recording no longer
  // takes messages (stopped, or its fault).
  bool post(Topic topic, int64_t steady_ns, int64_t publish_ns, std::span<const uint8_t> bytes);
  // Records that the simulation dropped frames this recording needed.
  void fail(const std::string& fault);

  // Writes what was posted, closes the file; returns at once. The writer
  // thread ends once the file is closed (stats().finished).
  void stop();
  void wait();  // until the file is closed

  RecorderStats stats() const;
  const std::string& path() const { return path_; }

 private:
  struct Item {
    Topic topic;
    int64_t log_ns, publish_ns;
    std::vector<uint8_t> bytes;
  };
  void run();
  bool write_item(const Item& item);  // false for one that does not verify (nothing written)
  int64_t log_now_ns() const;         // the steady clock as log time

  std::string path_;
  RecorderOptions options_;
  mcap::Writer writer_;
  std::unique_ptr<flatbuffers::Parser> schema_;  // the protocol schema, for /control's JSON
  FoxgloveViews views_;                          // /foxglove/body, /foxglove/surface and /foxglove/log
  uint16_t body_channel_ = 0, surface_channel_ = 0, log_channel_ = 0, transform_channel_ = 0;
  std::optional<int64_t> last_upright_ns_;  // when /foxglove/transform was last written (log time)
  uint16_t channel_[kTopicCount] = {};
  int64_t epoch_offset_ns_;  // steady -> Unix time, fixed at the start

  mutable std::mutex mutex_;
  std::condition_variable wake_, room_;
  std::deque<Item> queue_;
  size_t queued_bytes_ = 0;
  bool stopping_ = false;
  RecorderStats stats_;
  std::thread thread_;
};

// The protocol schema's text (proto/tactile.fbs), embedded at build time.
std::span<const uint8_t> tactile_fbs();

// The layout of a message on a FlatBuffers channel whose metadata has
// "envelope_offset" (RECORDING.md): an 8-byte root header (a root offset to
// the message table inside the Envelope, and the file identifier), then the
// Envelope's bytes as they went over the wire. The header makes the channel's
// message type the buffer's root, which is how Foxglove decodes a channel
// (by its schema's root table); dropping it gives the Envelope back.
inline constexpr size_t kEnvelopeOffset = 8;

// The message type a topic's Envelopes hold ("StateFrame", ...); "" for
// the JSON topic (/applied).
const char* message_type_name(Topic t);

// The binary schema (flatbuffer, "tactile.proto.<type>") of a channel of
// `type`'s messages: rooted at it and holding only what it reaches
// (RECORDING.md), as a recording and the live Foxglove view advertise it.
// Throws mcap::McapError for a type the protocol lacks.
std::vector<uint8_t> channel_schema(const std::string& type);

// The root header that makes `envelope`'s message the buffer's root
// (kEnvelopeOffset); false when the bytes are no Envelope holding a message.
bool root_header(std::span<const uint8_t> envelope, std::array<uint8_t, kEnvelopeOffset>& head);

// A recording read back as Envelopes, whatever its layout: each message of a
// channel with "envelope_offset" loses its root header; each of a JSON
// channel with "envelope_field" (/control) is that field's Envelope (base64).
// A message that holds none is left empty (it no longer verifies).
void restore_envelopes(mcap::Recording& rec);

// RFC 4648 base64 (with padding), for /control's Envelopes in JSON.
std::string to_base64(std::span<const uint8_t> bytes);
// Empty for text that is not base64.
std::vector<uint8_t> from_base64(std::string_view text);

}  // namespace tactile
