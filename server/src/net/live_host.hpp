// A server that runs a simulation: it serves the director's scene as it
// runs (live/director.hpp). What the loop publishes into the scene's outbox
// (live/outbox.hpp) goes, on each wakeup, to the devices (haptic frames), the
// viewers (the newest state) and the recording under way
// (record/recording.hpp), which gets every message. A controller pauses,
// resumes, changes the scene (net/scene_switch.hpp) and records; a telemetry
// goes to every client once a second.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <boost/asio/posix/stream_descriptor.hpp>
#include <boost/asio/steady_timer.hpp>

#include "live/director.hpp"
#include "net/host.hpp"
#include "net/scene_switch.hpp"
#include "record/recording.hpp"

namespace tactile {

class LiveHost final : public Host, private SceneSwitch::Port {
 public:
  // The director must outlive the host; it runs on its own thread.
  LiveHost(asio::io_context& io, Director& director, ServerOptions options);

  void start() override;  // the command line's recording (throws ServerError if refused), wakeups, telemetry
  void stop() override;

  // ---- ConnectionHost ----
  bool workspace(Vec3& lo, Vec3& hi) const override;
  void post_input(const DeviceSample& s) override { live_->loop().post_input(s); }  // a full queue drops and counts
  void record(Topic topic, std::span<const uint8_t> m, int64_t time_ns) override { recording_.post(topic, m, time_ns); }
  void control(const proto::Control& c, Connection& from) override;
  void greeted(Connection&) override {}
  void view_fields_changed() override { director_.set_view_fields(fields_asked()); }

 private:
  // ---- SceneSwitch::Port ----
  std::string request(const Director::Change& change, Director::Done done, bool* busy) override;
  std::string fault() const override { return director_.fault(); }
  void serve_installed(std::shared_ptr<LiveScene> scene) override;
  void answer(const Bytes& error) override { send_to_controller(error); }

  Served describe(LiveScene& live) const;
  void wait_wakeup();
  void deliver();  // what the outbox holds, to the clients and the recording
  void tick_telemetry();
  Bytes telemetry_message(const std::string& extra_fault);
  void send_telemetry() { send_each(telemetry_message(""), OutKind::Control); }
  // "" or what is wrong. `name`: a file name in the recordings folder ("" picks
  // one); with any_path, a path (the command line's --record).
  std::string start_recording(const std::string& name, bool any_path);
  void stop_recording();

  Director& director_;
  std::shared_ptr<LiveScene> live_;  // the scene served
  SceneSwitch switch_;
  Recording recording_;
  boost::asio::posix::stream_descriptor wake_fd_;  // the director's wakeup
  uint64_t wake_value_ = 0;
  boost::asio::steady_timer telemetry_timer_;
  int64_t dropped_[3] = {0, 0, 0};     // by the outbox's rings (haptic, state, applied), as last seen
  std::vector<uint8_t> newest_state_;  // the newest state frame of a drain
};

}  // namespace tactile
