#include "net/live_host.hpp"

#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <boost/asio/post.hpp>

namespace tactile {

namespace fb = flatbuffers;
namespace wire = proto;

namespace {

// A double as text that reads back to the same bits.
std::string exact(double v) {
  char s[32];
  std::snprintf(s, sizeof s, "%.17g", v);
  return s;
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return in ? std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>()) : "";
}

}  // namespace

LiveHost::LiveHost(asio::io_context& io, Director& director, ServerOptions options)
    : Host(io, std::move(options)),
      director_(director),
      switch_(*this, this->options().reset_on_fault),
      wake_fd_(io, ::dup(director.wakeup()->fd())),
      telemetry_timer_(io) {
  director_.set_library(this->options().scenes_dir, this->options().live);
  live_ = director_.current();
  served_ = describe(*live_);
}

LiveHost::Served LiveHost::describe(LiveScene& live) const {
  const std::vector<uint8_t> d = live.describe(director_.scenes());
  return {copy_bytes(d.data(), d.size()), live.scene().name, live.sim().devices()};
}

void LiveHost::start() {
  if (!options().record.empty())
    if (const std::string bad = start_recording(options().record, true); !bad.empty()) throw ServerError(bad);
  wait_wakeup();
  tick_telemetry();
}

void LiveHost::stop() {
  if (stopped_) return;
  stopped_ = true;
  director_.finish_building();
  boost::system::error_code ec;
  wake_fd_.close(ec);
  telemetry_timer_.cancel();
  stop_recording();
  recording_.finish();  // closed files, with their summaries
  Host::stop();
}

bool LiveHost::workspace(Vec3& lo, Vec3& hi) const {
  lo = live_->loop().workspace_lo();
  hi = live_->loop().workspace_hi();
  return true;
}

void LiveHost::control(const wire::Control& c, Connection& from) {
  auto refuse = [&](wire::ErrorCode code, const std::string& why) {
    send_to(from, make_error(code, why, c.request_id()), OutKind::Control);
  };
  switch (c.command_type()) {
    // A pause sent while a change is under way is carried over to the new scene.
    case wire::ControlCommand::Pause: return director_.current()->loop().set_paused(true);
    case wire::ControlCommand::Resume: return director_.current()->loop().set_paused(false);
    case wire::ControlCommand::Reset:
    case wire::ControlCommand::LoadScene:
    case wire::ControlCommand::SetParameter: return switch_.ask(SceneSwitch::change_of(c), c.request_id());
    case wire::ControlCommand::StartRecording: {
      const wire::StartRecording* r = c.command_as_StartRecording();
      if (const std::string bad = start_recording(r && r->path() ? r->path()->str() : "", false); !bad.empty())
        refuse(bad.starts_with("a recording") ? wire::ErrorCode::Busy : wire::ErrorCode::BadRequest, bad);
      return;
    }
    case wire::ControlCommand::StopRecording:
      if (!recording_.active()) return refuse(wire::ErrorCode::BadRequest, "StopRecording: no recording is under way");
      return stop_recording();
    default:
      return refuse(wire::ErrorCode::BadRequest,
                    std::string("control command ") + wire::EnumNameControlCommand(c.command_type()) +
                        " is for a server replaying a recording; this one runs a live scene");
  }
}

// ---- what the scene publishes ------------------------------------------------------------

void LiveHost::wait_wakeup() {
  wake_fd_.async_read_some(
      asio::buffer(&wake_value_, sizeof wake_value_),
      [self = std::static_pointer_cast<LiveHost>(shared_from_this())](boost::system::error_code ec, size_t) {
        if (ec || self->stopped_) return;
        self->deliver();
        self->wait_wakeup();
      });
}

void LiveHost::deliver() {
  Outbox& out = *live_->outbox();
  const bool recording = recording_.active();
  auto reads_haptic = [](const Connection& s) { return s.reads_haptic(); };
  const bool devices = count_greeted(wire::Role::Device) > 0 || count_haptic_readers() > 0;
  // Every haptic frame, to the devices and the recording, stamped with its own server time.
  out.haptics.drain([&](const uint8_t* data, size_t n) {
    if (recording)
      recording_.post(Topic::Haptic, {data, n}, wire::GetEnvelope(data)->message_as_HapticFrame()->server_time_ns());
    if (devices) send_each(copy_bytes(data, n), OutKind::Haptic, reads_haptic);
  });
  // Every state to the recording; the newest to the clients.
  bool state = false;
  out.states.drain([&](const uint8_t* data, size_t n) {
    if (recording)
      recording_.post(Topic::State, {data, n}, wire::GetEnvelope(data)->message_as_StateFrame()->server_time_ns());
    newest_state_.assign(data, data + n);
    state = true;
  });
  if (state) send_each(copy_bytes(newest_state_.data(), newest_state_.size()), OutKind::State);
  const int64_t now = now_ns();
  out.applied.drain([&](const uint8_t* data, size_t) {
    if (!recording) return;
    AppliedInput a;
    std::memcpy(&a, data, sizeof a);
    char json[256];
    const int n = format_applied(a, json, sizeof json);
    recording_.post(Topic::Applied, {reinterpret_cast<const uint8_t*>(json), size_t(n)}, now);
  });
  const int64_t dropped[3] = {out.haptics.dropped(), out.states.dropped(), out.applied.dropped()};
  const int64_t lost[3] = {dropped[0] - dropped_[0], dropped[1] - dropped_[1], dropped[2] - dropped_[2]};
  std::memcpy(dropped_, dropped, sizeof dropped_);
  if (recording && (lost[0] > 0 || lost[1] > 0 || lost[2] > 0))
    recording_.fail("the simulation published frames faster than the recording took them (" + std::to_string(lost[0]) +
                    " haptic and " + std::to_string(lost[1]) + " state frames, " + std::to_string(lost[2]) +
                    " applied inputs had no room): stopped, what was written stays readable");
}

// ---- telemetry -----------------------------------------------------------------------------

Bytes LiveHost::telemetry_message(const std::string& extra_fault) {
  const RealtimeLoop& loop = live_->loop();
  const RealtimeStats st = loop.stats();
  fb::FlatBufferBuilder b;
  std::vector<fb::Offset<fb::String>> faults;
  if (!st.fault.empty()) faults.push_back(b.CreateString(st.fault));
  if (!extra_fault.empty()) faults.push_back(b.CreateString(extra_fault));
  const RecorderStats rec = recording_.stats();
  std::vector<fb::Offset<wire::EffectCost>> costs;  // per pass of the step; those a scene lacks cost 0 and are left out
  for (int p = 0; p < kPassCount; ++p)
    if (st.pass_ns[size_t(p)] > 0)
      costs.push_back(wire::CreateEffectCostDirect(b, live_->sim().pass_name(Pass(p)), float(st.pass_ns[size_t(p)])));
  return seal(b, wire::Message::Telemetry,
              wire::CreateTelemetryDirect(
                  b, now_ns(), uint64_t(st.steps), st.clock, float(st.step_mean_us), float(st.step_max_us),
                  float(st.real_time_factor), uint64_t(st.missed_deadlines), &costs,
                  uint32_t(count_greeted(wire::Role::Viewer)), uint32_t(count_greeted(wire::Role::Device)),
                  uint32_t(count_greeted(wire::Role::Controller)), &faults, loop.paused(),
                  std::filesystem::path(rec.path).filename().string().c_str(), rec.messages, rec.bytes,
                  switch_.fault_resets()));
}

void LiveHost::tick_telemetry() {
  telemetry_timer_.expires_after(std::chrono::seconds(1));
  telemetry_timer_.async_wait(
      [self = std::static_pointer_cast<LiveHost>(shared_from_this())](boost::system::error_code ec) {
        if (ec || self->stopped_) return;
        const Bytes t = self->telemetry_message(self->recording_.check());
        self->send_each(t, OutKind::Control);
        self->recording_.post(Topic::Telemetry, *t, tactile::now_ns());
        // Once a telemetry has told every client (and the recording) the
        // fault's cause, the scene starts again from rest, as a controller's
        // Reset would start it; the bridges re-engage through their soft start.
        self->switch_.after_telemetry();
        self->tick_telemetry();
      });
}

// ---- scene changes (net/scene_switch.hpp) ------------------------------------------------

std::string LiveHost::request(const Director::Change& change, Director::Done done, bool* busy) {
  return director_.request(
      change,
      [weak = weak_from_this(), &io = io(), done = std::move(done)](std::shared_ptr<LiveScene> scene,
                                                                    const std::string& error) {
        asio::post(io, [weak, done, scene = std::move(scene), error] {
          auto self = weak.lock();
          if (self && !self->stopped()) done(scene, error);
        });
      },
      busy);
}

// The last frames of the old scene go out, then every client gets the new
// description, then the new scene's frames.
void LiveHost::serve_installed(std::shared_ptr<LiveScene> scene) {
  deliver();
  live_ = std::move(scene);
  std::memset(dropped_, 0, sizeof dropped_);  // a new outbox
  Served next = describe(*live_);
  recording_.post(Topic::Scene, *next.description, now_ns());
  serve_scene(std::move(next));
  deliver();
}

// ---- recording (record/recording.hpp) -------------------------------------------------------

std::string LiveHost::start_recording(const std::string& name, bool any_path) {
  if (recording_.active()) return "a recording is under way ('" + recording_.path() + "'): stop it first";
  std::string path = name;
  if (!any_path) {
    std::string error;
    path = Recording::path_in(options().recordings_dir, name, std::chrono::system_clock::now(), &error);
    if (path.empty()) return error;
  }
  const Scene& scene = live_->scene();
  const mcap::Map meta{{"scene_name", scene.name},
                       {"scene_path", scene.path},
                       {"scene_file", read_text(scene.path)},
                       {"variant", scene.variant},
                       {"scene_id", std::to_string(live_->id())},
                       {"dt", exact(live_->loop().dt())},
                       {"state_rate_hz", exact(options().live.state_rate_hz)},
                       {"haptic_rate_hz", exact(options().live.haptic_rate_hz)},
                       {"force_window", exact(options().live.force_window)},
                       {"server", options().server_name}};
  deliver();  // frames published before the start are not the recording's
  if (const std::string bad = recording_.start(path, meta, {.compression = options().record_compression}); !bad.empty())
    return bad;
  recording_.post(Topic::Scene, *served_.description, now_ns());
  send_telemetry();
  return "";
}

void LiveHost::stop_recording() {
  if (!recording_.active()) return;
  deliver();  // every frame published until now is the recording's
  recording_.stop();
  send_telemetry();
}

}  // namespace tactile
