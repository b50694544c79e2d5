#include "net/replay_host.hpp"

#include <cmath>
#include <filesystem>
#include <stdexcept>

namespace tactile {

namespace fb = flatbuffers;
namespace wire = proto;

namespace {

// A recorded SceneDescription (Envelope bytes, verified by the replay).
ReplayHost::Served recorded(Bytes description) {
  const wire::SceneDescription* d = wire::GetEnvelope(description->data())->message_as_SceneDescription();
  ReplayHost::Served s{std::move(description), "", {}};
  if (d->scene_name()) s.scene_name = d->scene_name()->str();
  if (d->devices())
    for (const fb::String* name : *d->devices()) s.devices.push_back(name->str());
  return s;
}

}  // namespace

ReplayHost::ReplayHost(asio::io_context& io, Replay& replay, ServerOptions options)
    : Host(io, std::move(options)), replay_(replay), timer_(io) {
  served_ = recorded(copy_bytes(replay.first_scene().bytes.data(), replay.first_scene().bytes.size()));
}

void ReplayHost::stop() {
  if (stopped_) return;
  timer_.cancel();
  Host::stop();
}

void ReplayHost::greeted(Connection& s) {
  if (!started_) {  // the first client starts the playback
    started_ = true;
    replay_.play(Replay::Clock::now());
    status_due_ = Replay::Clock::now();
    timer_.cancel();
    tick();
  }
  // Where the replay is: the body as it was there, and the playback.
  if (const Replay::Item* st = replay_.state_before(); st && s.role() != wire::Role::Device)
    send_to(s, copy_bytes(st->bytes.data(), st->bytes.size()), OutKind::State);
  if (s.reads_replay_status()) send_to(s, status(), OutKind::Control);
}

void ReplayHost::tick() {
  const auto now = Replay::Clock::now();
  replay_.due(now, [&](const Replay::Item& item) { serve_item(item); });
  if (now >= status_due_) {
    const Bytes st = status();
    send_each(st, OutKind::Control, [](const Connection& s) { return s.reads_replay_status(); });
    status_due_ = now + std::chrono::milliseconds(100);
  }
  // Until the next message is due or the next status, whichever is first.
  const auto wait = std::min<Replay::Clock::duration>(
      std::chrono::duration_cast<Replay::Clock::duration>(std::chrono::duration<double>(replay_.next_due_in(now))),
      status_due_ - now);
  timer_.expires_after(std::max<Replay::Clock::duration>(wait, std::chrono::microseconds(50)));
  timer_.async_wait([self = std::static_pointer_cast<ReplayHost>(shared_from_this())](boost::system::error_code ec) {
    if (!ec && !self->stopped_) self->tick();
  });
}

void ReplayHost::serve_item(const Replay::Item& item) {
  const Bytes m = copy_bytes(item.bytes.data(), item.bytes.size());
  auto is_device = [](const Connection& s) { return s.role() == wire::Role::Device; };
  switch (item.topic) {
    case Topic::Scene:
      if (*m == *served_.description) return;
      return serve_scene(recorded(m));
    case Topic::State: return send_each(m, OutKind::State, [&](const Connection& s) { return !is_device(s); });
    case Topic::Haptic:  // a bridge plays the recorded forces to its device, under its safety rules
      return send_each(m, OutKind::Haptic, [](const Connection& s) { return s.reads_haptic(); });
    case Topic::Telemetry: return send_each(m, OutKind::Control);
    case Topic::Safety: return relay(m, OutKind::Event);
    case Topic::DeviceStatus: return relay(m, OutKind::Status);
    case Topic::Input:
    case Topic::Control:
    case Topic::Error:
    case Topic::Applied: return;  // what clients sent, what the simulation applied: kept in the file, not served
  }
}

void ReplayHost::show_position() {
  if (const Replay::Item* scene = replay_.scene_before()) serve_item(*scene);
  if (const Replay::Item* state = replay_.state_before()) serve_item(*state);
}

Bytes ReplayHost::status() {
  fb::FlatBufferBuilder b;
  const auto now = Replay::Clock::now();
  return seal(
      b, wire::Message::ReplayStatus,
      wire::CreateReplayStatusDirect(b, std::filesystem::path(replay_.path()).filename().string().c_str(),
                                     replay_.duration(), replay_.position(now), replay_.speed(), replay_.paused()));
}

void ReplayHost::control(const wire::Control& c, Connection& from) {
  const auto now = Replay::Clock::now();
  auto refuse = [&](const std::string& why) {
    send_to(from, make_error(wire::ErrorCode::BadRequest, why, c.request_id()), OutKind::Control);
  };
  switch (c.command_type()) {
    case wire::ControlCommand::Pause: replay_.pause(now); break;
    case wire::ControlCommand::Resume: replay_.play(now); break;
    case wire::ControlCommand::Seek: {
      const double t = c.command_as_Seek() ? c.command_as_Seek()->time_s() : 0;
      if (!std::isfinite(t)) return refuse("Seek: time_s is not finite");
      replay_.seek(t, now);
      show_position();
      break;
    }
    case wire::ControlCommand::SetSpeed:
      try {
        replay_.set_speed(c.command_as_SetSpeed() ? c.command_as_SetSpeed()->speed() : 0, now);
      } catch (const std::invalid_argument& e) {
        return refuse(std::string("SetSpeed: ") + e.what());
      }
      break;
    default:
      return refuse(std::string(wire::EnumNameControlCommand(c.command_type())) +
                    " needs a live session; this server replays the recording '" +
                    std::filesystem::path(replay_.path()).filename().string() + "'");
  }
  // The change, to everyone at once (and the timer re-armed for the new pace).
  status_due_ = now;
  timer_.cancel();
  tick();
}

}  // namespace tactile
