#include "record/recorder.hpp"

#include <flatbuffers/idl.h>
#include <pthread.h>

#include <array>
#include <cctype>
#include <cstdio>
#include <cstring>
#include <memory>
#include <set>
#include <string_view>

#include <nlohmann/json.hpp>

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

namespace {
constexpr char kBase64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
}  // namespace

std::string to_base64(std::span<const uint8_t> bytes) {
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (size_t i = 0; i < bytes.size(); i += 3) {
    const size_t n = std::min<size_t>(3, bytes.size() - i);
    const uint32_t v =
        uint32_t(bytes[i]) << 16 | (n > 1 ? uint32_t(bytes[i + 1]) << 8 : 0u) | (n > 2 ? uint32_t(bytes[i + 2]) : 0u);
    for (size_t k = 0; k < 4; ++k) out += k <= n ? kBase64[(v >> (18 - 6 * k)) & 63] : '=';
  }
  return out;
}

std::vector<uint8_t> from_base64(std::string_view text) {
  std::array<int, 256> value;
  value.fill(-1);
  for (int k = 0; k < 64; ++k) value[size_t(uint8_t(kBase64[k]))] = k;
  if (text.size() % 4 != 0) return {};
  std::vector<uint8_t> out;
  out.reserve(text.size() / 4 * 3);
  for (size_t i = 0; i < text.size(); i += 4) {
    uint32_t v = 0;
    int pad = 0;
    for (size_t k = 0; k < 4; ++k) {
      const char c = text[i + k];
      if (c == '=' && i + 4 == text.size() && k >= 2) {
        ++pad;
        v <<= 6;
        continue;
      }
      const int d = value[size_t(uint8_t(c))];
      if (d < 0 || pad > 0) return {};
      v = v << 6 | uint32_t(d);
    }
    out.push_back(uint8_t(v >> 16));
    if (pad < 2) out.push_back(uint8_t(v >> 8));
    if (pad < 1) out.push_back(uint8_t(v));
  }
  return out;
}

void restore_envelopes(mcap::Recording& rec) {
  for (const auto& [id, channel] : rec.channels) {
    if (const auto it = channel.metadata.find("envelope_offset"); it != channel.metadata.end()) {
      const size_t at = size_t(std::stoul(it->second));
      for (mcap::Message& m : rec.messages)
        if (m.channel == id) m.data.erase(m.data.begin(), m.data.begin() + std::ptrdiff_t(std::min(at, m.data.size())));
    } else if (const auto f = channel.metadata.find("envelope_field"); f != channel.metadata.end()) {
      for (mcap::Message& m : rec.messages) {
        if (m.channel != id) continue;
        const auto j = nlohmann::json::parse(m.data.begin(), m.data.end(), nullptr, false);
        m.data = j.is_object() && j.contains(f->second) && j[f->second].is_string()
                     ? from_base64(j[f->second].get<std::string>())
                     : std::vector<uint8_t>{};
      }
    }
  }
}

namespace {

// FlatBuffers' text writes a non-finite double as nan, inf or -inf, which
// JSON has not: outside strings each becomes the string "NaN", "Infinity"
// or "-Infinity" (as Python's and JavaScript's JSON name them), so that a
// Control carrying one (a SetParameter of NaN, which the server refuses) is
// still recorded, its Envelope with it.
std::string quote_non_finite(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  bool in_string = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      out += c;
      if (c == '\\' && i + 1 < text.size())
        out += text[++i];
      else if (c == '"')
        in_string = false;
      continue;
    }
    if (c == '"') {
      in_string = true;
      out += c;
      continue;
    }
    size_t end = i;
    while (end < text.size() && (std::isalnum(static_cast<unsigned char>(text[end])) || text[end] == '+' ||
                                 text[end] == '-' || text[end] == '.'))
      ++end;
    std::string word = text.substr(i, end - i);
    for (char& ch : word) ch = char(std::tolower(static_cast<unsigned char>(ch)));
    const bool negative = word.starts_with('-');
    if (word.starts_with('-') || word.starts_with('+')) word.erase(0, 1);
    if (word == "nan") {
      out += "\"NaN\"";
    } else if (word == "inf" || word == "infinity") {
      out += negative ? "\"-Infinity\"" : "\"Infinity\"";
    } else {
      out.append(text, i, end - i);
      if (end == i) out += c;
    }
    i = end > i ? end - 1 : i;
  }
  return out;
}

// Whether a topic's channel carries its Envelopes behind a root header
// rooted at their message type. Not /control: a Control holds a union,
// which Foxglove's FlatBuffers reader does not decode either way; it is
// JSON, with its Envelope in base64 beside the decoded fields.
bool rooted_at_message(Topic t) { return t != Topic::Applied && t != Topic::Control; }

std::span<const uint8_t> bytes_of(std::string_view text) {
  return {reinterpret_cast<const uint8_t*>(text.data()), text.size()};
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

// The protocol's schema with `type` as its root table, holding only the
// tables, structs and enums `type` reaches, serialised as a binary schema
// (what flatc --binary --schema writes for a root_type). Only what it
// reaches: Foxglove builds a datatype for every object of a channel's
// schema before it decodes a message (parseFlatbufferSchema in its
// mcap-support), and refuses a union anywhere, so Envelope and Control,
// which hold the protocol's two unions, must stay out of the channels they
// are not part of (tests/test_foxglove.py runs that pass).
std::vector<uint8_t> channel_schema(const std::string& type) {
  const std::span<const uint8_t> text = tactile_fbs();
  const std::string fbs(reinterpret_cast<const char*>(text.data()), text.size());
  // What is cut from the parser's tables outlives the parser, which deletes
  // only what its tables still hold.
  std::vector<std::unique_ptr<flatbuffers::StructDef>> cut_objects;
  std::vector<std::unique_ptr<flatbuffers::EnumDef>> cut_enums;
  flatbuffers::Parser parser;
  if (!parser.Parse(fbs.c_str()))
    throw mcap::McapError("the embedded protocol schema does not parse: " + parser.error_);
  if (!parser.SetRootType(("tactile.proto." + type).c_str()))
    throw mcap::McapError("the protocol schema has no table tactile.proto." + type);
  std::set<const flatbuffers::StructDef*> objects;
  std::set<const flatbuffers::EnumDef*> enums;
  std::vector<const flatbuffers::StructDef*> todo{parser.root_struct_def_};
  const auto reach = [&](const flatbuffers::Type& t) {
    if (t.struct_def && objects.insert(t.struct_def).second) todo.push_back(t.struct_def);
    if (t.enum_def && enums.insert(t.enum_def).second)
      for (const flatbuffers::EnumVal* v : t.enum_def->Vals())  // a union's members
        if (v->union_type.struct_def && objects.insert(v->union_type.struct_def).second)
          todo.push_back(v->union_type.struct_def);
  };
  objects.insert(parser.root_struct_def_);
  while (!todo.empty()) {
    const flatbuffers::StructDef* def = todo.back();
    todo.pop_back();
    for (const flatbuffers::FieldDef* f : def->fields.vec) reach(f->value.type);
  }
  const auto prune = [](auto& table, const auto& keep, auto& cut) {
    std::erase_if(table.dict, [&](const auto& entry) { return !keep.contains(entry.second); });
    std::erase_if(table.vec, [&](auto* def) {
      if (keep.contains(def)) return false;
      cut.emplace_back(def);
      return true;
    });
  };
  prune(parser.structs_, objects, cut_objects);
  prune(parser.enums_, enums, cut_enums);
  parser.Serialize();  // (indexes what is left afresh)
  return {parser.builder_.GetBufferPointer(), parser.builder_.GetBufferPointer() + parser.builder_.GetSize()};
}

bool root_header(std::span<const uint8_t> envelope, std::array<uint8_t, kEnvelopeOffset>& head) {
  flatbuffers::Verifier v(envelope.data(), envelope.size());
  if (!proto::VerifyEnvelopeBuffer(v) || !proto::GetEnvelope(envelope.data())->message()) return false;
  const auto* table = static_cast<const uint8_t*>(proto::GetEnvelope(envelope.data())->message());
  const uint32_t root = uint32_t(kEnvelopeOffset + size_t(table - envelope.data()));
  std::memcpy(head.data(), &root, 4);  // little-endian, as FlatBuffers are on every target we build for
  std::memcpy(head.data() + 4, proto::EnvelopeIdentifier(), 4);
  return true;
}

Recorder::Recorder(const std::string& path, const mcap::Map& metadata, RecorderOptions options)
    : path_(path),
      options_(options),
      writer_(path, "", "tactile-server", options.compression),
      epoch_offset_ns_(unix_now_ns() - steady_now_ns()) {
  static constexpr char kAppliedSchema[] =
      R"({"title":"tactile.AppliedInput","type":"object","properties":{)"
      R"("loop_step":{"type":"integer","description":"steps the loop had taken when it applied the input"},)"
      R"("device":{"type":"integer","description":"channel index, SceneDescription.devices order"},)"
      R"("sequence":{"type":"integer","description":"the DeviceInput's sequence"},)"
      R"("direct":{"type":"boolean","description":"its device drove the proxy directly (kinematic); absent: coupled"},)"
      R"("limits":{"type":"array","items":{"type":"number"},"minItems":3,"maxItems":3,)"
      R"("description":"the coupling limits its device gave: max force [N], max torque [N m], stiffness [N/m]; absent: none"}}})";
  const uint16_t applied = writer_.add_schema("tactile.AppliedInput", "jsonschema", bytes_of(kAppliedSchema));
  static constexpr char kControlSchema[] =
      R"({"title":"tactile.Control","type":"object","properties":{)"
      R"("request_id":{"type":"integer","description":"echoed in the server's answer"},)"
      R"("command_type":{"type":"string","description":"the ControlCommand it holds"},)"
      R"("command":{"type":"object","properties":{},"description":"its fields, named as in proto/tactile.fbs"},)"
      R"("envelope":{"type":"string","contentEncoding":"base64",)"
      R"("description":"the Control's Envelope as it came, for replay"}}})";
  const uint16_t control = writer_.add_schema("tactile.Control", "jsonschema", bytes_of(kControlSchema));
  const std::span<const uint8_t> fbs = tactile_fbs();
  const std::string_view fbs_text(reinterpret_cast<const char*>(fbs.data()), fbs.size());
  schema_ = std::make_unique<flatbuffers::Parser>();
  schema_->opts.strict_json = true;
  schema_->opts.indent_step = -1;  // one line
  if (!schema_->Parse(std::string(fbs_text).c_str()))
    throw mcap::McapError("the embedded protocol schema does not parse: " + schema_->error_);
  for (int t = 0; t < kTopicCount; ++t) {
    const Topic topic = Topic(t);
    if (topic == Topic::Applied) {
      channel_[t] = writer_.add_channel(applied, topic_name(topic), "json");
    } else if (topic == Topic::Control) {
      channel_[t] = writer_.add_channel(control, topic_name(topic), "json", {{"envelope_field", "envelope"}});
    } else if (rooted_at_message(topic)) {
      const std::string type = message_type_name(topic);
      const uint16_t schema = writer_.add_schema("tactile.proto." + type, "flatbuffer", channel_schema(type));
      channel_[t] = writer_.add_channel(schema, topic_name(topic), "flatbuffer",
                                        {{"envelope_offset", std::to_string(kEnvelopeOffset)}});
    }
  }
  // Foxglove's own schemas, for its 3D and Log panels (foxglove_views.hpp).
  const uint16_t scene_update =
      writer_.add_schema("foxglove.SceneUpdate", "jsonschema", bytes_of(scene_update_json_schema()));
  body_channel_ = writer_.add_channel(scene_update, "/foxglove/body", "json");
  surface_channel_ = writer_.add_channel(scene_update, "/foxglove/surface", "json");
  log_channel_ = writer_.add_channel(writer_.add_schema("foxglove.Log", "jsonschema", bytes_of(log_json_schema())),
                                     "/foxglove/log", "json");
  transform_channel_ = writer_.add_channel(
      writer_.add_schema("foxglove.FrameTransform", "jsonschema", bytes_of(frame_transform_json_schema())),
      "/foxglove/transform", "json");
  mcap::Map meta = metadata;
  meta["started_unix_ns"] = std::to_string(unix_now_ns());
  writer_.add_metadata("tactile", meta);
  stats_.path = path;
  thread_ = std::thread([this] {
    pthread_setname_np(pthread_self(), "tactile-record");  // (what a profiler and recording_bench.py find it by)
    run();
  });
}

Recorder::~Recorder() {
  stop();
  wait();
}

bool Recorder::post(Topic topic, int64_t steady_ns, int64_t publish_ns, std::span<const uint8_t> bytes) {
  std::unique_lock<std::mutex> lock(mutex_);
  if (options_.wait_for_room)
    room_.wait(lock,
               [&] { return stopping_ || queued_bytes_ == 0 || queued_bytes_ + bytes.size() <= options_.queue_bytes; });
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

// Writes one message on its channel: an Envelope behind its root header
// (and Foxglove's views of it), a Control as JSON with its Envelope, the
// rest as they came. False, writing nothing, for one that does not verify.
bool Recorder::write_item(const Item& item) {
  if (rooted_at_message(item.topic)) {
    // The root header: offset of the message table (behind the header),
    // then the file identifier. Envelopes come from the server's own
    // encoders and its verified inputs; one that does not verify here
    // is left out, counted.
    std::array<uint8_t, kEnvelopeOffset> head;
    if (!root_header(item.bytes, head)) return false;
    writer_.write(channel_[int(item.topic)], uint64_t(item.log_ns), uint64_t(item.publish_ns), item.bytes, head);
    // Foxglove's views of it, at the same time.
    const proto::Envelope* e = proto::GetEnvelope(item.bytes.data());
    std::optional<std::string> view;
    uint16_t to = log_channel_;
    // The transform that stands the bodies upright: at each scene, and
    // with a body drawn a second or more after the last.
    const auto upright = [&] {
      writer_.write(transform_channel_, uint64_t(item.log_ns), uint64_t(item.publish_ns),
                    bytes_of(FoxgloveViews::upright(item.log_ns)));
      last_upright_ns_ = item.log_ns;
    };
    if (const auto* scene = e->message_as_SceneDescription()) {
      views_.scene(*scene);
      upright();
    } else if (const auto* state = e->message_as_StateFrame()) {
      view = views_.body(*state, item.log_ns);
      to = body_channel_;
      if (view && (!last_upright_ns_ || item.log_ns - *last_upright_ns_ >= FoxgloveViews::kUprightEveryNs)) upright();
      if (const std::optional<std::string> fine = views_.surface(*state, item.log_ns))
        writer_.write(surface_channel_, uint64_t(item.log_ns), uint64_t(item.publish_ns), bytes_of(*fine));
    } else if (const auto* safety = e->message_as_SafetyEvent()) {
      view = FoxgloveViews::log(*safety, item.log_ns);
    } else if (const auto* err = e->message_as_Error()) {
      view = FoxgloveViews::log(*err, item.log_ns);
    }
    if (view) writer_.write(to, uint64_t(item.log_ns), uint64_t(item.publish_ns), bytes_of(*view));
  } else if (item.topic == Topic::Control) {
    // {"request_id", "command_type", "command", "envelope"}: the
    // Control's fields as flatbuffers' text generator writes them, and
    // its Envelope for replay.
    flatbuffers::Verifier v(item.bytes.data(), item.bytes.size());
    const proto::Control* c =
        proto::VerifyEnvelopeBuffer(v) ? proto::GetEnvelope(item.bytes.data())->message_as_Control() : nullptr;
    std::string text;
    nlohmann::json j;
    if (c && flatbuffers::GenerateTextFromTable(*schema_, c, "tactile.proto.Control", &text))
      j = nlohmann::json::parse(quote_non_finite(text), nullptr, false);
    if (!j.is_object()) {
      return false;
    }
    j["envelope"] = to_base64(item.bytes);
    writer_.write(channel_[int(item.topic)], uint64_t(item.log_ns), uint64_t(item.publish_ns), bytes_of(j.dump()));
  } else {
    writer_.write(channel_[int(item.topic)], uint64_t(item.log_ns), uint64_t(item.publish_ns), item.bytes);
  }
  return true;
}

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
        until = chunk_opened +
                std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(options_.chunk_seconds));
      if (!waiting.empty() && !options_.wait_for_room)
        until = std::min(until, Clock::now() + std::chrono::nanoseconds(std::max<int64_t>(
                                                   0, waiting.begin()->first + hold_ns - log_now_ns())));
      if (until == Clock::time_point::max())
        wake_.wait(lock, ready);
      else
        wake_.wait_until(lock, until, ready);
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
        if (!write_item(item)) ++unreadable;
        waiting.erase(waiting.begin());
        if (writer_.chunk_bytes() >= options_.chunk_bytes) writer_.close_chunk();
      }
      if (!writer_.chunk_empty() &&
          Clock::now() - chunk_opened >= std::chrono::duration<double>(options_.chunk_seconds))
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
