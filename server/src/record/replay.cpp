#include "record/replay.hpp"

#include <algorithm>
#include <stdexcept>

#include "tactile_generated.h"

namespace tactile {
namespace {

// The message type a topic carries.
proto::Message message_of(Topic t) {
  switch (t) {
    case Topic::Scene: return proto::Message::SceneDescription;
    case Topic::State: return proto::Message::StateFrame;
    case Topic::Haptic: return proto::Message::HapticFrame;
    case Topic::Input: return proto::Message::DeviceInput;
    case Topic::Control: return proto::Message::Control;
    case Topic::Error: return proto::Message::Error;
    case Topic::Telemetry: return proto::Message::Telemetry;
    case Topic::Safety: return proto::Message::SafetyEvent;
    case Topic::DeviceStatus: return proto::Message::DeviceStatus;
    case Topic::Applied: return proto::Message::NONE;  // JSON, for re-simulation: not served
  }
  return proto::Message::NONE;
}

}  // namespace

Replay::Replay(const std::string& path) : path_(path) {
  mcap::Recording rec = mcap::read_file(path);
  restore_envelopes(rec);
  problems_ = rec.problems;
  // Topic of each channel; channels of other topics are not served.
  std::vector<std::pair<uint16_t, Topic>> topics;
  for (int t = 0; t < kTopicCount; ++t)
    if (const uint16_t id = rec.channel_of(topic_name(Topic(t)))) topics.emplace_back(id, Topic(t));
  uint64_t first = UINT64_MAX;
  for (const mcap::Message& m : rec.messages) first = std::min(first, m.log_time);
  size_t bad = 0;
  for (mcap::Message& m : rec.messages) {
    const auto it = std::find_if(topics.begin(), topics.end(), [&](const auto& p) { return p.first == m.channel; });
    if (it == topics.end() || it->second == Topic::Applied) continue;
    // Served to clients as they are: each must be a whole Envelope of its topic's type.
    flatbuffers::Verifier v(m.data.data(), m.data.size());
    if (!proto::VerifyEnvelopeBuffer(v) ||
        proto::GetEnvelope(m.data.data())->message_type() != message_of(it->second)) {
      ++bad;
      continue;
    }
    items_.push_back({it->second, int64_t(m.log_time - first), std::move(m.data)});
  }
  if (bad > 0) problems_.push_back(std::to_string(bad) + " messages are not what their topic carries: left out");
  // In log-time order already, but in recordings made before the recorder
  // merged its two sources (frames stamped when made, network messages when
  // they came), which interleave slightly out of order.
  std::stable_sort(items_.begin(), items_.end(), [](const Item& a, const Item& b) { return a.t_ns < b.t_ns; });
  if (!std::any_of(items_.begin(), items_.end(), [](const Item& i) { return i.topic == Topic::Scene; })) {
    // What the reader could not read says why (a chunk compressed another way, damaged, cut short).
    std::string why = "recording '" + path + "' holds no scene description (/scene): nothing to replay";
    for (size_t k = 0; k < problems_.size() && k < 3; ++k) why += "; " + problems_[k];
    if (problems_.size() > 3) why += "; and " + std::to_string(problems_.size() - 3) + " more";
    throw mcap::McapError(why);
  }
}

double Replay::position(Clock::time_point now) const {
  if (paused_) return base_;
  return std::min(duration(), base_ + std::chrono::duration<double>(now - since_).count() * speed_);
}

void Replay::play(Clock::time_point now) {
  if (!paused_) return;
  if (base_ >= duration()) seek(0, now);  // played to the end: from the start again
  paused_ = false;
  since_ = now;
}

void Replay::pause(Clock::time_point now) {
  if (paused_) return;
  base_ = position(now);
  paused_ = true;
}

void Replay::set_speed(double speed, Clock::time_point now) {
  if (!(speed > 0 && speed <= 16))
    throw std::invalid_argument("replay speed must be in (0, 16], got " + std::to_string(speed));
  base_ = position(now);
  since_ = now;
  speed_ = speed;
}

void Replay::seek(double t, Clock::time_point now) {
  base_ = std::clamp(t, 0.0, duration());
  since_ = now;
  const int64_t at = int64_t(base_ * 1e9);
  next_ =
      size_t(std::lower_bound(items_.begin(), items_.end(), at, [](const Item& i, int64_t v) { return i.t_ns < v; }) -
             items_.begin());
}

const Replay::Item& Replay::first_scene() const {
  return *std::find_if(items_.begin(), items_.end(), [](const Item& i) { return i.topic == Topic::Scene; });
}

double Replay::next_due_in(Clock::time_point now) const {
  if (paused_ || next_ >= items_.size()) return 1e9;
  return std::max(0.0, (double(items_[next_].t_ns) * 1e-9 - position(now)) / speed_);
}

const Replay::Item* Replay::newest_before(Topic topic) const {
  for (size_t k = next_; k-- > 0;)
    if (items_[k].topic == topic) return &items_[k];
  return nullptr;
}

}  // namespace tactile
