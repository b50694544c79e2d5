#include "net/server_impl.hpp"

namespace tactile {

// ---- what a connection's rules ask of the server ---------------------------------------------

WsSession* Server::Impl::shell_of(const Session& s) const {
  for (WsSession* w : sessions)
    if (&w->core() == &s) return w;
  return nullptr;
}

uint64_t Server::Impl::driver_of(const std::string& channel, const Session& asking) const {
  for (const WsSession* w : sessions)
    if (&w->core() != &asking && w->core().drives(channel)) return w->core().id();
  return 0;
}

bool Server::Impl::claim_controller(Session& s) {
  if (controller) return false;
  controller = shell_of(s);
  return true;
}

void Server::Impl::relay(const Bytes& message, OutKind kind) {
  for (WsSession* w : sessions)
    if (w->core().reads(kind)) w->send(message, kind);
}

void Server::Impl::greeted(Session& s) {
  if (!replay) return;
  if (!replay_started) {  // the first client starts the playback
    replay_started = true;
    replay->play(Replay::Clock::now());
    replay_status_due = Replay::Clock::now();
    replay_timer.cancel();
    tick_replay();
  }
  // Where the replay is: the body as it was there, and the playback.
  WsSession* w = shell_of(s);
  if (const Replay::Item* st = replay->state_before(); st && s.role() != wire::Role::Device)
    w->send(copy_bytes(st->bytes.data(), st->bytes.size()), OutKind::State);
  if (s.reads_replay_status()) w->send(replay_status(), OutKind::Control);
}

void Server::Impl::view_fields_changed() {
  ViewFieldMask asked = 0;
  for (const WsSession* s : sessions)
    if (s->core().greeted()) asked |= s->core().view_fields();
  for (const std::shared_ptr<Feed>& f : {feed, incoming})
    if (f && f->live) f->live->loop().set_view_fields(f->live->scene().view_fields | asked);
}

void Server::Impl::control(const wire::Control& c, Session& from) {
  WsSession& w = *shell_of(from);
  if (replay) return replay_control(c, w);
  live_control(c, w);
}

void Server::Impl::live_control(const wire::Control& c, WsSession& from) {
  switch (c.command_type()) {
    // A pause sent while a change is under way is carried over to the new scene.
    case wire::ControlCommand::Pause: return director->current()->loop().set_paused(true);
    case wire::ControlCommand::Resume: return director->current()->loop().set_paused(false);
    case wire::ControlCommand::Reset: return change(Director::Change::Kind::Reset, &c);
    case wire::ControlCommand::LoadScene: return change(Director::Change::Kind::Load, &c);
    case wire::ControlCommand::SetParameter: return change(Director::Change::Kind::Parameter, &c);
    case wire::ControlCommand::StartRecording: {
      const wire::StartRecording* r = c.command_as_StartRecording();
      if (const std::string bad = start_recording(r && r->path() ? r->path()->str() : ""); !bad.empty())
        return from.send(
            make_error(bad.starts_with("a recording") ? wire::ErrorCode::Busy : wire::ErrorCode::BadRequest, bad,
                       c.request_id()),
            OutKind::Control);
      return;
    }
    case wire::ControlCommand::StopRecording:
      if (!recorder)
        return from.send(
            make_error(wire::ErrorCode::BadRequest, "StopRecording: no recording is under way", c.request_id()),
            OutKind::Control);
      return stop_recording();
    default:
      return from.send(make_error(wire::ErrorCode::BadRequest,
                                  std::string("control command ") + wire::EnumNameControlCommand(c.command_type()) +
                                      " is for a server replaying a recording; this one runs a live scene",
                                  c.request_id()),
                       OutKind::Control);
  }
}

// ---- the server ------------------------------------------------------------------------------

Admission Server::Impl::admit(const std::string& address) {
  const SessionClock::time_point now = SessionClock::now();
  size_t greeted = 0;
  std::vector<WaitingSlot> waiting;
  for (const WsSession* s : sessions) {
    if (s->core().greeted() && !s->core().closed()) ++greeted;
    if (s->core().waiting()) waiting.push_back({s->core().id(), s->core().address(), s->core().since()});
  }
  Admission a =
      decide_admission(waiting, greeted, now, {options.max_connections, options.max_waiting, options.hello_grace_s});
  if (a.evict)
    for (WsSession* s : sessions)
      if (s->core().id() == a.evict) {
        log_admission(now,
                      "evicted connection " + std::to_string(a.evict) + " (" + s->core().address() + "): " + a.reason);
        s->evict(a.reason);
        break;
      }
  if (!a.admit) log_admission(now, "refused a connection from " + address + ": " + a.reason);
  return a;
}

void Server::Impl::log_admission(SessionClock::time_point now, const std::string& line) {
  if (!admission_log.take(now)) return;
  const int64_t more = admission_log.held_back();
  std::fprintf(stderr, "server: %s%s\n", line.c_str(),
               more ? (" (and " + std::to_string(more) + " more evicted or refused in the last second)").c_str() : "");
}

bool Server::Impl::host_allowed(std::string_view host) const {
  return tactile::host_allowed(host, options.bind, options.allowed_origins);
}

bool Server::Impl::origin_allowed(const std::string& origin) const {
  return tactile::origin_allowed(origin, acceptor.local_endpoint().port(), options.allowed_origins);
}

// Every connection holds a descriptor: the soft limit is raised (up to the
// hard one) to cover max_connections greeted, max_waiting waiting and the
// refused ones closing, with 64 to spare for files; short of that, said once.
void Server::Impl::ensure_descriptors() const {
  rlimit lim{};
  if (::getrlimit(RLIMIT_NOFILE, &lim) != 0) return;
  const rlim_t want = rlim_t(2 * (options.max_connections + options.max_waiting) + 64);
  if (lim.rlim_cur >= want) return;
  const rlim_t before = lim.rlim_cur;
  lim.rlim_cur = lim.rlim_max == RLIM_INFINITY ? want : std::min(want, lim.rlim_max);
  if (::setrlimit(RLIMIT_NOFILE, &lim) != 0) lim.rlim_cur = before;
  if (lim.rlim_cur < want)
    std::fprintf(stderr,
                 "server: %llu file descriptors allowed (ulimit -n), %llu wanted for %zu connections and %zu "
                 "waiting: past that, new connections fail until some close\n",
                 (unsigned long long)lim.rlim_cur, (unsigned long long)want, options.max_connections,
                 options.max_waiting);
}

void Server::Impl::listen() {
  ensure_descriptors();
  beast::error_code ec;
  const asio::ip::address address = asio::ip::make_address(options.bind, ec);
  if (ec) throw ServerError("bind address '" + options.bind + "' is not an IP address");
  if (!address.is_loopback() && options.token.empty())
    throw ServerError("refusing to listen on " + options.bind +
                      " without a token: off loopback every client must present one (--token)");
  const tcp::endpoint endpoint(address, options.port);
  acceptor.open(endpoint.protocol());
  acceptor.set_option(asio::socket_base::reuse_address(true));
  acceptor.bind(endpoint, ec);
  if (ec)
    throw ServerError("cannot listen on " + options.bind + ":" + std::to_string(options.port) + ": " + ec.message());
  acceptor.listen(asio::socket_base::max_listen_connections);
}

void Server::Impl::accept() {
  acceptor.async_accept([self = shared_from_this()](beast::error_code ec, tcp::socket socket) {
    if (self->stopped) return;
    if (!ec) {
      serve_http(self, std::move(socket));
      return self->accept();
    }
    // Out of descriptors (EMFILE) or the like: the connection stays in the
    // backlog, so accepting again at once would spin; wait for some to close.
    self->log_admission(SessionClock::now(), "cannot accept a connection: " + ec.message());
    self->accept_timer.expires_after(std::chrono::milliseconds(50));
    self->accept_timer.async_wait([self](beast::error_code wait_ec) {
      if (!wait_ec && !self->stopped) self->accept();
    });
  });
}

void Server::Impl::wait_wakeup() {
  wake_fd.async_read_some(asio::buffer(&wake_value, sizeof wake_value),
                          [self = shared_from_this()](beast::error_code ec, size_t) {
                            if (ec || self->stopped) return;
                            self->deliver();
                            self->wait_wakeup();
                          });
}

void Server::Impl::deliver() {
  if (!feed->live) return;  // a replay sends as it goes (tick_replay)
  drain_tap(*feed);
  std::vector<WsSession*> devices, viewers;
  for (WsSession* s : sessions) {
    if (!s->core().greeted()) continue;
    (s->core().role() == wire::Role::Device ? devices : viewers).push_back(s);
  }
  feed->haptics.drain([&](const uint8_t* data, size_t n) {
    if (devices.empty()) return;
    const Bytes frame = copy_bytes(data, n);
    for (WsSession* s : devices) s->send(frame, OutKind::Haptic);
  });
  if (const std::vector<uint8_t>* state = feed->states.take()) {
    const Bytes frame = copy_bytes(state->data(), state->size());
    for (WsSession* s : sessions)
      if (s->core().greeted()) s->send(frame, OutKind::State);
  }
}

Bytes Server::Impl::telemetry_message(const std::string& extra_fault) {
  const RealtimeLoop& loop = feed->live->loop();
  const RealtimeStats st = loop.stats();
  uint32_t viewers = 0, devices = 0, controllers = 0;
  for (WsSession* s : sessions) {
    if (!s->core().greeted()) continue;
    if (s->core().role() == wire::Role::Viewer)
      ++viewers;
    else if (s->core().role() == wire::Role::Device)
      ++devices;
    else
      ++controllers;
  }
  fb::FlatBufferBuilder b;
  std::vector<fb::Offset<fb::String>> faults;
  if (!st.fault.empty()) faults.push_back(b.CreateString(st.fault));
  if (!extra_fault.empty()) faults.push_back(b.CreateString(extra_fault));
  const RecorderStats rec = recorder ? recorder->stats() : RecorderStats{};
  std::vector<fb::Offset<wire::EffectCost>> costs;  // per pass of the step; those a scene lacks cost 0 and are left out
  for (int p = 0; p < kPassCount; ++p)
    if (st.pass_ns[size_t(p)] > 0)
      costs.push_back(wire::CreateEffectCostDirect(b, to_string(Pass(p)), float(st.pass_ns[size_t(p)])));
  return seal(b, wire::Message::Telemetry,
              wire::CreateTelemetryDirect(b, now_ns(), uint64_t(st.steps), st.clock, float(st.step_mean_us),
                                          float(st.step_max_us), float(st.real_time_factor),
                                          uint64_t(st.missed_deadlines), &costs, viewers, devices, controllers, &faults,
                                          loop.paused(), std::filesystem::path(rec.path).filename().string().c_str(),
                                          rec.messages, rec.bytes, fault_resets));
}

void Server::Impl::tick_telemetry() {
  telemetry_timer.expires_after(std::chrono::seconds(1));
  telemetry_timer.async_wait([self = shared_from_this()](beast::error_code ec) {
    if (ec || self->stopped) return;
    const Bytes t = self->telemetry_message(self->check_recorder());
    for (WsSession* s : self->sessions)
      if (s->core().greeted()) s->send(t, OutKind::Control);
    self->record(Topic::Telemetry, t);
    // Once a telemetry has told every client (and the recording) the
    // fault's cause, the scene starts again from rest, as a controller's
    // Reset would start it; the bridges re-engage through their soft start.
    if (self->options.reset_on_fault && self->director && !self->changing && !self->director->fault().empty()) {
      ++self->fault_resets;
      std::fprintf(stderr, "tactile-server: resetting the scene after the fault (--on-fault reset; %u so far)\n",
                   self->fault_resets);
      self->change(Director::Change::Kind::Reset, nullptr);
    }
    self->tick_telemetry();
  });
}

void Server::Impl::close_all() {
  std::vector<WsSession*> all(sessions.begin(), sessions.end());
  for (WsSession* s : all) s->close();
}

// ---- control: reset, load, set a parameter ------------------------------------------------

void Server::Impl::send_to_controller(const Bytes& message) {
  if (controller) controller->send(message, OutKind::Control);
}

// The director checks the change and builds its scene (live/director.hpp);
// the network thread attaches the new scene's sinks, then hands it over.
void Server::Impl::change(Director::Change::Kind kind, const wire::Control* c) {
  const uint32_t request = c ? c->request_id() : 0;
  if (changing)
    return send_to_controller(
        make_error(wire::ErrorCode::Busy, "a scene change is under way: wait for its SceneDescription", request));
  Director::Change ask;
  ask.kind = kind;
  if (const wire::LoadScene* l = c ? c->command_as_LoadScene() : nullptr; l && l->path()) ask.scene = l->path()->str();
  if (const wire::SetParameter* p = c ? c->command_as_SetParameter() : nullptr) {
    ask.parameter = p->name() ? p->name()->str() : "";
    ask.value = p->value();
  }
  bool busy = false;
  const std::string refused = director->request(
      ask,
      [weak = weak_from_this(), &io = ioc, request](std::shared_ptr<LiveScene> live, bool carry,
                                                    const std::string& error) {
        asio::post(io, [weak, live = std::move(live), carry, error, request] {
          auto self = weak.lock();
          if (!self) return;
          if (live) return self->built(live, carry);
          self->changing = false;
          self->send_to_controller(make_error(wire::ErrorCode::BadRequest, error, request));
        });
      },
      &busy);
  if (!refused.empty())
    return send_to_controller(make_error(busy ? wire::ErrorCode::Busy : wire::ErrorCode::BadRequest, refused, request));
  changing = true;
}

void Server::Impl::built(std::shared_ptr<LiveScene> live, bool carry) {
  if (stopped) return;
  incoming = std::make_shared<Feed>(live, director->scenes());
  attach(*incoming);
  view_fields_changed();
  if (recorder) tap_feed(*incoming);
  director->replace(std::move(live), carry);
}

// On the network thread, once the simulation thread runs `live`: the last
// frames of the old scene go out, then every client gets the new description.
void Server::Impl::installed(const std::shared_ptr<LiveScene>& live) {
  if (stopped || !incoming || incoming->live != live) return;
  deliver();
  feed = std::move(incoming);
  changing = false;
  record(Topic::Scene, feed->description);
  for (WsSession* s : sessions) {
    if (!s->core().greeted()) continue;
    s->send(feed->description, OutKind::Control);
    if (s->core().role() == wire::Role::Device) s->rebind();
  }
  deliver();
}

Server::Server(asio::io_context& ioc, Replay& replay, ServerOptions options)
    : impl_(std::make_shared<Impl>(ioc, nullptr, &replay, std::move(options))) {
  impl_->listen();
  impl_->accept();
  impl_->tick_replay();
}

Server::Server(asio::io_context& ioc, Director& director, ServerOptions options)
    : impl_(std::make_shared<Impl>(ioc, &director, nullptr, std::move(options))) {
  impl_->listen();
  if (!impl_->options.record.empty())
    if (const std::string bad = impl_->start_recording(impl_->options.record, true); !bad.empty())
      throw ServerError(bad);
  director.on_installed([weak = std::weak_ptr<Impl>(impl_), &ioc](const std::shared_ptr<LiveScene>& live) {
    asio::post(ioc, [weak, live] {
      if (auto self = weak.lock()) self->installed(live);
    });
  });
  impl_->accept();
  impl_->wait_wakeup();
  impl_->tick_telemetry();
}

Server::~Server() { stop(); }

uint16_t Server::port() const { return impl_->acceptor.local_endpoint().port(); }

void Server::stop() {
  if (impl_->stopped) return;
  impl_->stopped = true;
  if (impl_->director) impl_->director->finish_building();
  beast::error_code ec;
  impl_->acceptor.close(ec);
  impl_->wake_fd.close(ec);
  impl_->telemetry_timer.cancel();
  impl_->replay_timer.cancel();
  impl_->accept_timer.cancel();
  impl_->stop_recording();
  for (auto& r : impl_->finishing) r->wait();  // closed files, with their summaries
  impl_->finishing.clear();
  impl_->close_all();
}

}  // namespace tactile
