#include "record/recorder.hpp"

#include <cstdio>
#include <string_view>

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

namespace {

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
  const uint16_t schema = writer_.add_schema("tactile.proto.Envelope", "flatbuffer", tactile_bfbs());
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
  for (int t = 0; t < kTopicCount; ++t)
    channel_[t] = Topic(t) == Topic::Applied ? writer_.add_channel(applied, topic_name(Topic(t)), "json")
                                             : writer_.add_channel(schema, topic_name(Topic(t)), "flatbuffer");
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
  uint64_t late = 0;
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
        writer_.write(channel_[int(item.topic)], uint64_t(item.log_ns), uint64_t(item.publish_ns), item.bytes);
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
  stats_.finished = true;
}

}  // namespace tactile
