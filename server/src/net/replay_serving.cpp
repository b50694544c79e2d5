#include "net/server_impl.hpp"

namespace tactile {

// ---- replay: a recording served as the live session was ------------------------------------

void Server::Impl::tick_replay() {
  const auto now = Replay::Clock::now();
  replay->due(now, [&](const Replay::Item& item) { serve_replayed(item); });
  if (now >= replay_status_due) {
    const Bytes status = replay_status();
    for (WsSession* s : sessions)
      if (s->core().reads_replay_status()) s->send(status, OutKind::Control);
    replay_status_due = now + std::chrono::milliseconds(100);
  }
  // Until the next message is due or the next status, whichever is first.
  const auto wait = std::min<Replay::Clock::duration>(
      std::chrono::duration_cast<Replay::Clock::duration>(std::chrono::duration<double>(replay->next_due_in(now))),
      replay_status_due - now);
  replay_timer.expires_after(std::max<Replay::Clock::duration>(wait, std::chrono::microseconds(50)));
  replay_timer.async_wait([self = shared_from_this()](beast::error_code ec) {
    if (!ec && !self->stopped) self->tick_replay();
  });
}

void Server::Impl::serve_replayed(const Replay::Item& item) {
  const Bytes m = copy_bytes(item.bytes.data(), item.bytes.size());
  switch (item.topic) {
    case Topic::Scene:
      if (*m == *feed->description) return;
      feed = std::make_shared<Feed>(m);
      for (WsSession* s : sessions) {
        if (!s->core().greeted()) continue;
        s->send(m, OutKind::Control);
        if (s->core().role() == wire::Role::Device) s->rebind();
      }
      return;
    case Topic::State:
      for (WsSession* s : sessions)
        if (s->core().greeted() && s->core().role() != wire::Role::Device) s->send(m, OutKind::State);
      return;
    case Topic::Haptic:  // a bridge plays the recorded forces to its device, under its safety rules
      for (WsSession* s : sessions)
        if ((s->core().greeted() && s->core().role() == wire::Role::Device)) s->send(m, OutKind::Haptic);
      return;
    case Topic::Telemetry:
      for (WsSession* s : sessions)
        if (s->core().greeted()) s->send(m, OutKind::Control);
      return;
    case Topic::Safety:
      for (WsSession* s : sessions)
        if (s->core().reads(OutKind::Event)) s->send(m, OutKind::Event);
      return;
    case Topic::DeviceStatus:
      for (WsSession* s : sessions)
        if (s->core().reads(OutKind::Status)) s->send(m, OutKind::Status);
      return;
    case Topic::Input:
    case Topic::Control:
    case Topic::Error:
    case Topic::Applied: return;  // what clients sent, what the simulation applied: kept in the file, not served
  }
}

void Server::Impl::show_replay_position() {
  if (const Replay::Item* scene = replay->scene_before()) serve_replayed(*scene);
  if (const Replay::Item* state = replay->state_before()) serve_replayed(*state);
}

Bytes Server::Impl::replay_status() {
  fb::FlatBufferBuilder b;
  const auto now = Replay::Clock::now();
  return seal(
      b, wire::Message::ReplayStatus,
      wire::CreateReplayStatusDirect(b, std::filesystem::path(replay->path()).filename().string().c_str(),
                                     replay->duration(), replay->position(now), replay->speed(), replay->paused()));
}

void Server::Impl::replay_control(const wire::Control& c, WsSession& from) {
  const auto now = Replay::Clock::now();
  switch (c.command_type()) {
    case wire::ControlCommand::Pause: replay->pause(now); break;
    case wire::ControlCommand::Resume: replay->play(now); break;
    case wire::ControlCommand::Seek: {
      const double t = c.command_as_Seek() ? c.command_as_Seek()->time_s() : 0;
      if (!std::isfinite(t))
        return from.send(make_error(wire::ErrorCode::BadRequest, "Seek: time_s is not finite", c.request_id()),
                         OutKind::Control);
      replay->seek(t, now);
      show_replay_position();
      break;
    }
    case wire::ControlCommand::SetSpeed:
      try {
        replay->set_speed(c.command_as_SetSpeed() ? c.command_as_SetSpeed()->speed() : 0, now);
      } catch (const std::invalid_argument& e) {
        return from.send(make_error(wire::ErrorCode::BadRequest, std::string("SetSpeed: ") + e.what(), c.request_id()),
                         OutKind::Control);
      }
      break;
    default:
      return from.send(make_error(wire::ErrorCode::BadRequest,
                                  std::string(wire::EnumNameControlCommand(c.command_type())) +
                                      " needs a live session; this server replays the recording '" +
                                      std::filesystem::path(replay->path()).filename().string() + "'",
                                  c.request_id()),
                       OutKind::Control);
  }
  // The change, to everyone at once (and the timer re-armed for the new pace).
  replay_status_due = now;
  replay_timer.cancel();
  tick_replay();
}

}  // namespace tactile
