#include "record/recorder.hpp"

#include <flatbuffers/idl.h>

#include <cstdio>
#include <cstring>
#include <string_view>

#include "tactile_generated.h"

namespace tactile {

const char* topic_name(Topic t) {
  switch (t) {
    case Topic::Scene: return "/scene";
    case Topic::State: return "/state";
    case Topic::Haptic: return "/haptic";
    case Topic::Input: return "/input";
    case Topic::Control: return "/control";
    case Topic::Error: return "/error";
    case Topic::Telemetry: return "/telemetry";
    case Topic::Safety: return "/safety";
    case Topic::DeviceStatus: return "/device_status";
    case Topic::Applied: return "/applied";
  }
  return "?";
}

const char* message_type_name(Topic t) {
  switch (t) {
    case Topic::Scene: return "SceneDescription";
    case Topic::State: return "StateFrame";
    case Topic::Haptic: return "HapticFrame";
    case Topic::Input: return "DeviceInput";
    case Topic::Control: return "Control";
    case Topic::Error: return "Error";
    case Topic::Telemetry: return "Telemetry";
    case Topic::Safety: return "SafetyEvent";
    case Topic::DeviceStatus: return "DeviceStatus";
    case Topic::Applied: return "";
  }
  return "";
}

void restore_envelopes(mcap::Recording& rec) {
  for (const auto& [id, channel] : rec.channels) {
    const auto it = channel.metadata.find("envelope_offset");
    if (it == channel.metadata.end()) continue;
    const size_t at = size_t(std::stoul(it->second));
    for (mcap::Message& m : rec.messages)
      if (m.channel == id) m.data.erase(m.data.begin(), m.data.begin() + std::ptrdiff_t(std::min(at, m.data.size())));
  }
}

namespace {

// Whether a topic's channel carries its Envelopes behind a root header
// rooted at their message type. Not /control: a Control holds a union,
// which Foxglove's FlatBuffers reader does not decode either way.
bool rooted_at_message(Topic t) { return t != Topic::Applied && t != Topic::Control; }

// The protocol's schema with `type` as its root table, serialised as a
// binary schema (what flatc --binary --schema writes for a root_type).
std::vector<uint8_t> schema_rooted_at(flatbuffers::Parser& parser, const std::string& type) {
  if (!parser.SetRootType(("tactile.proto." + type).c_str()))
    throw mcap::McapError("the protocol schema has no table tactile.proto." + type);
  parser.Serialize();
  return {parser.builder_.GetBufferPointer(), parser.builder_.GetBufferPointer() + parser.builder_.GetSize()};
}

int64_t steady_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}
int64_t unix_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace

Recorder::Recorder(const std::string& path, const mcap::Map& metadata, RecorderOptions options)
    : path_(path), options_(options), writer_(path, "", "tactile-server"),
      epoch_offset_ns_(unix_now_ns() - steady_now_ns()) {
  const uint16_t envelope = writer_.add_schema("tactile.proto.Envelope", "flatbuffer", tactile_bfbs());
  static constexpr char kAppliedSchema[] =
      R"({"title":"tactile.AppliedInput","type":"object","properties":{)"
      R"("loop_step":{"type":"integer","description":"steps the loop had taken when it applied the input"},)"
      R"("device":{"type":"integer","description":"channel index, SceneDescription.devices order"},)"
      R"("sequence":{"type":"integer","description":"the DeviceInput's sequence"},)"
      R"("direct":{"type":"boolean","description":"its device drove the proxy directly (kinematic); absent: coupled"},)"
      R"("limits":{"type":"array","items":{"type":"number"},"minItems":3,"maxItems":3,)"
      R"("description":"the coupling limits its device gave: max force [N], max torque [N m], stiffness [N/m]; absent: none"}}})";
  const std::string_view applied_schema(kAppliedSchema);
  const uint16_t applied = writer_.add_schema(
      "tactile.AppliedInput", "jsonschema",
      {reinterpret_cast<const uint8_t*>(applied_schema.data()), applied_schema.size()});
  flatbuffers::Parser parser;
  const std::span<const uint8_t> fbs = tactile_fbs();
  if (!parser.Parse(std::string(reinterpret_cast<const char*>(fbs.data()), fbs.size()).c_str()))
    throw mcap::McapError("the embedded protocol schema does not parse: " + parser.error_);
  for (int t = 0; t < kTopicCount; ++t) {
    const Topic topic = Topic(t);
    if (topic == Topic::Applied) {
      channel_[t] = writer_.add_channel(applied, topic_name(topic), "json");
    } else if (rooted_at_message(topic)) {
      const std::string type = message_type_name(topic);
      const uint16_t schema = writer_.add_schema("tactile.proto." + type, "flatbuffer", schema_rooted_at(parser, type));
      channel_[t] = writer_.add_channel(schema, topic_name(topic), "flatbuffer",
                                        {{"envelope_offset", std::to_string(kEnvelopeOffset)}});
    } else {
      channel_[t] = writer_.add_channel(envelope, topic_name(topic), "flatbuffer");
    }
  }
  mcap::Map meta = metadata;
  meta["started_unix_ns"] = std::to_string(unix_now_ns());
  writer_.add_metadata("tactile", meta);
  stats_.path = path;
  thread_ = std::thread([this] { run(); });
}

Recorder::~Recorder() {
  stop();
  wait();
}

bool Recorder::post(Topic topic, int64_t steady_ns, int64_t publish_ns, std::span<const uint8_t> bytes) {
  std::unique_lock<std::mutex> lock(mutex_);
  if (options_.wait_for_room)
    room_.wait(lock, [&] { return stopping_ || queued_bytes_ == 0 || queued_bytes_ + bytes.size() <= options_.queue_bytes; });
  if (stopping_) return false;
  if (queued_bytes_ + bytes.size() > options_.queue_bytes) {
    stats_.fault = "the recording could not keep up with the session (" + std::to_string(queued_bytes_ >> 20) +
                   " MiB waiting for the disk): stopped, what was written stays readable";
    stopping_ = true;
    wake_.notify_one();
    return false;
  }
  const int64_t log_ns = steady_ns + epoch_offset_ns_;
  queue_.push_back({topic, log_ns, publish_ns ? publish_ns + epoch_offset_ns_ : log_ns,
                    std::vector<uint8_t>(bytes.begin(), bytes.end())});
  queued_bytes_ += bytes.size();
  wake_.notify_one();
  return true;
}

void Recorder::fail(const std::string& fault) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (stopping_) return;
  stats_.fault = fault;
  stopping_ = true;
  wake_.notify_one();
}

void Recorder::stop() {
  std::lock_guard<std::mutex> lock(mutex_);
  stopping_ = true;
  wake_.notify_one();
}

void Recorder::wait() {
  if (thread_.joinable()) thread_.join();
}

RecorderStats Recorder::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

int64_t Recorder::log_now_ns() const { return steady_now_ns() + epoch_offset_ns_; }

void Recorder::run() {
  using Clock = std::chrono::steady_clock;
  const int64_t hold_ns = int64_t(options_.order_seconds * 1e9);
  std::deque<Item> batch;
  // Posted, waiting for earlier-stamped messages, by log time (equal
  // stamps in the order posted).
  std::multimap<int64_t, Item> waiting;
  int64_t newest = INT64_MIN;   // the latest log time posted
  int64_t written = INT64_MIN;  // the log time last written
  uint64_t late = 0, unreadable = 0;
  Clock::time_point chunk_opened{};
  bool stopping = false;
  std::string error;
  while (!stopping) {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      const auto ready = [&] { return stopping_ || !queue_.empty(); };
      // Wake for new messages, for the open chunk's deadline, and (live) for
      // the moment the earliest waiting message may go.
      Clock::time_point until = Clock::time_point::max();
      if (!writer_.chunk_empty())
        until = chunk_opened + std::chrono::duration_cast<Clock::duration>(
                                   std::chrono::duration<double>(options_.chunk_seconds));
      if (!waiting.empty() && !options_.wait_for_room)
        until = std::min(until, Clock::now() + std::chrono::nanoseconds(
                                                   std::max<int64_t>(0, waiting.begin()->first + hold_ns - log_now_ns())));
      if (until == Clock::time_point::max()) wake_.wait(lock, ready);
      else wake_.wait_until(lock, until, ready);
      batch.swap(queue_);
      queued_bytes_ = 0;
      stopping = stopping_;
    }
    room_.notify_all();
    for (Item& item : batch) {
      newest = std::max(newest, item.log_ns);
      const int64_t key = item.log_ns;
      waiting.emplace(key, std::move(item));
    }
    batch.clear();
    // What may go: all once stopping; else what is older than the hold,
    // reckoned from the clock live, from the newest message offline (a
    // re-simulation posts faster than real time).
    const int64_t due = stopping ? INT64_MAX : (options_.wait_for_room ? newest : log_now_ns()) - hold_ns;
    try {
      while (!waiting.empty() && waiting.begin()->first <= due) {
        Item& item = waiting.begin()->second;
        if (item.log_ns < written) {
          item.log_ns = written;
          ++late;
        }
        written = item.log_ns;
        if (writer_.chunk_empty()) chunk_opened = Clock::now();
        if (rooted_at_message(item.topic)) {
          // The root header: offset of the message table (behind the header),
          // then the file identifier. Envelopes come from the server's own
          // encoders and its verified inputs; one that does not verify here
          // is left out, counted.
          flatbuffers::Verifier v(item.bytes.data(), item.bytes.size());
          if (!proto::VerifyEnvelopeBuffer(v) || !proto::GetEnvelope(item.bytes.data())->message()) {
            ++unreadable;
            waiting.erase(waiting.begin());
            continue;
          }
          const auto* table = static_cast<const uint8_t*>(proto::GetEnvelope(item.bytes.data())->message());
          const uint32_t root = uint32_t(kEnvelopeOffset + size_t(table - item.bytes.data()));
          uint8_t head[kEnvelopeOffset];
          std::memcpy(head, &root, 4);  // little-endian, as FlatBuffers are on every target we build for
          std::memcpy(head + 4, proto::EnvelopeIdentifier(), 4);
          writer_.write(channel_[int(item.topic)], uint64_t(item.log_ns), uint64_t(item.publish_ns), item.bytes,
                        {head, kEnvelopeOffset});
        } else {
          writer_.write(channel_[int(item.topic)], uint64_t(item.log_ns), uint64_t(item.publish_ns), item.bytes);
        }
        waiting.erase(waiting.begin());
        if (writer_.chunk_bytes() >= options_.chunk_bytes) writer_.close_chunk();
      }
      if (!writer_.chunk_empty() && Clock::now() - chunk_opened >= std::chrono::duration<double>(options_.chunk_seconds))
        writer_.close_chunk();
    } catch (const mcap::McapError& e) {
      error = e.what();
      break;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    stats_.messages = writer_.messages();
    stats_.bytes = writer_.bytes();
    stats_.late = late;
    stats_.unreadable = unreadable;
  }
  try {
    if (error.empty()) writer_.finish();
  } catch (const mcap::McapError& e) {
    error = e.what();
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (!error.empty() && stats_.fault.empty()) stats_.fault = error;
  stopping_ = true;
  room_.notify_all();
  queue_.clear();
  stats_.messages = writer_.messages();
  stats_.bytes = writer_.bytes();
  stats_.late = late;
  stats_.unreadable = unreadable;
  stats_.finished = true;
}

}  // namespace tactile
