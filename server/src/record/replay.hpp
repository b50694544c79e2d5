// A recording played back: its messages in log-time order, due as a clock
// that can pause, seek and change speed passes their times. No threads and
// no sockets: the server asks what is due (net/replay_host.cpp, on its own
// thread) and serves it as it served the live session.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "record/mcap.hpp"
#include "record/recorder.hpp"

namespace tactile {

class Replay {
 public:
  using Clock = std::chrono::steady_clock;

  struct Item {
    Topic topic;
    int64_t t_ns;  // from the recording's first message
    std::vector<uint8_t> bytes;
  };

  // Reads the whole recording; throws mcap::McapError when it is not MCAP
  // or holds no scene. A file cut short plays up to where it ends (problems()).
  explicit Replay(const std::string& path);

  const std::string& path() const { return path_; }
  double duration() const { return double(items_.empty() ? 0 : items_.back().t_ns) * 1e-9; }
  const std::vector<std::string>& problems() const { return problems_; }
  const std::vector<Item>& items() const { return items_; }

  // The playback clock. Starts paused at 0 (play() starts it).
  double position(Clock::time_point now) const;  // [s] from the first message
  double speed() const { return speed_; }
  bool paused() const { return paused_; }
  void play(Clock::time_point now);
  void pause(Clock::time_point now);
  // Speed in (0, 16]; throws std::invalid_argument naming the range otherwise.
  void set_speed(double speed, Clock::time_point now);
  // To `t` seconds (clamped to the recording). What comes due next is the
  // first message at or after t; catch_up() gives what the view needs there.
  void seek(double t, Clock::time_point now);
  // At the end, playback pauses there.

  // Calls fn(item) for each message now due, in order, and moves past them.
  template <class Fn>
  void due(Clock::time_point now, Fn&& fn) {
    const int64_t until = int64_t(position(now) * 1e9);
    while (next_ < items_.size() && items_[next_].t_ns <= until) fn(items_[next_++]);
    if (next_ == items_.size() && !paused_) pause(now);
  }

  // After a seek: the newest scene description and the newest state at or
  // before the position (nullptr when there is none), so that a view shows
  // the body where the recording was at once.
  const Item* scene_before() const { return newest_before(Topic::Scene); }
  const Item& first_scene() const;  // (a replay has one: the constructor checks)
  // Seconds of wall time until the next message is due (1e9 when paused or at the end).
  double next_due_in(Clock::time_point now) const;
  const Item* state_before() const { return newest_before(Topic::State); }

 private:
  const Item* newest_before(Topic topic) const;

  std::string path_;
  std::vector<Item> items_;
  std::vector<std::string> problems_;
  size_t next_ = 0;
  // position = base_ + (now - since_) * speed_ while playing; base_ while paused.
  double base_ = 0, speed_ = 1;
  bool paused_ = true;
  Clock::time_point since_{};
};

}  // namespace tactile
