// A server that replays a recording (record/replay.hpp) as the live server
// served it: the same messages at their recorded pace. Viewers get its
// states, devices its haptic frames, a controller may Pause, Resume, Seek
// and SetSpeed, and every client of protocol 1.4 gets a ReplayStatus ten
// times a second. Playing starts when the first client says Hello.
#pragma once

#include <memory>

#include <boost/asio/steady_timer.hpp>

#include "net/host.hpp"
#include "record/replay.hpp"

namespace tactile {

class ReplayHost final : public Host {
 public:
  // The replay must outlive the host.
  ReplayHost(asio::io_context& io, Replay& replay, ServerOptions options);

  void start() override { tick(); }
  void stop() override;

  // ---- ConnectionHost ----
  bool workspace(Vec3&, Vec3&) const override { return false; }  // nothing simulated
  void post_input(const DeviceSample&) override {}               // moves nothing
  void record(Topic, std::span<const uint8_t>, int64_t) override {}
  void control(const proto::Control& c, Connection& from) override;
  void greeted(Connection& s) override;
  void view_fields_changed() override {}  // the fields are those recorded

 private:
  void tick();  // serves what is due, and a status when due; re-arms the timer
  void serve_item(const Replay::Item& item);
  void show_position();  // the scene and state at the position, after a seek
  Bytes status();

  Replay& replay_;
  boost::asio::steady_timer timer_;
  Replay::Clock::time_point status_due_{};
  bool started_ = false;
};

}  // namespace tactile
