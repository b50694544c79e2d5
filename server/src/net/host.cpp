#include "net/host.hpp"

#include <cstdio>

#include "net/ws_connection.hpp"

namespace tactile {

void Host::stop() {
  stopped_ = true;
  std::vector<WsConnection*> all(connections_.begin(), connections_.end());
  for (WsConnection* s : all) s->close();
}

void Host::leave(WsConnection* s) {
  connections_.erase(s);
  if (controller_ == s) controller_ = nullptr;
  if (s->core().view_fields()) view_fields_changed();
}

WsConnection* Host::shell_of(const Connection& s) const {
  for (WsConnection* w : connections_)
    if (&w->core() == &s) return w;
  return nullptr;
}

uint64_t Host::driver_of(const std::string& channel, const Connection& asking) const {
  for (const WsConnection* w : connections_)
    if (&w->core() != &asking && w->core().drives(channel)) return w->core().id();
  return 0;
}

bool Host::claim_controller(Connection& s) {
  if (controller_) return false;
  controller_ = shell_of(s);
  return true;
}

void Host::relay(const Bytes& message, OutKind kind) {
  for (WsConnection* w : connections_)
    if (w->core().reads(kind)) w->send(message, kind);
}

void Host::send_each(const Bytes& message, OutKind kind, const std::function<bool(const Connection&)>& to) {
  for (WsConnection* w : connections_)
    if (w->core().greeted() && (!to || to(w->core()))) w->send(message, kind);
}

void Host::send_to(const Connection& s, const Bytes& message, OutKind kind) {
  if (WsConnection* w = shell_of(s)) w->send(message, kind);
}

void Host::send_to_controller(const Bytes& message) {
  if (controller_) controller_->send(message, OutKind::Control);
}

void Host::serve_scene(Served next) {
  served_ = std::move(next);
  for (WsConnection* w : connections_) {
    if (!w->core().greeted()) continue;
    w->send(served_.description, OutKind::Control);
    if (w->core().role() == proto::Role::Device) w->rebind();
  }
}

ViewFieldMask Host::fields_asked() const {
  ViewFieldMask asked = 0;
  for (const WsConnection* w : connections_)
    if (w->core().greeted()) asked |= w->core().view_fields();
  return asked;
}

size_t Host::count_greeted(proto::Role role) const {
  size_t n = 0;
  for (const WsConnection* w : connections_)
    if (w->core().greeted() && w->core().role() == role) ++n;
  return n;
}

size_t Host::count_haptic_readers() const {
  size_t n = 0;
  for (const WsConnection* w : connections_)
    if (w->core().reads_haptic()) ++n;
  return n;
}

Admission Host::admit(const std::string& address) {
  const ConnectionClock::time_point now = ConnectionClock::now();
  size_t greeted = 0;
  std::vector<WaitingSlot> waiting;
  for (const WsConnection* w : connections_) {
    if (w->core().greeted() && !w->core().closed()) ++greeted;
    if (w->core().waiting()) waiting.push_back({w->core().id(), w->core().address(), w->core().since()});
  }
  Admission a =
      decide_admission(waiting, greeted, now, {options_.max_connections, options_.max_waiting, options_.hello_grace_s});
  if (a.evict)
    for (WsConnection* w : connections_)
      if (w->core().id() == a.evict) {
        log_admission(now,
                      "evicted connection " + std::to_string(a.evict) + " (" + w->core().address() + "): " + a.reason);
        w->evict(a.reason);
        break;
      }
  if (!a.admit) log_admission(now, "refused a connection from " + address + ": " + a.reason);
  return a;
}

void Host::log_admission(ConnectionClock::time_point now, const std::string& line) {
  if (!admission_log_.take(now)) return;
  const int64_t more = admission_log_.held_back();
  std::fprintf(stderr, "server: %s%s\n", line.c_str(),
               more ? (" (and " + std::to_string(more) + " more evicted or refused in the last second)").c_str() : "");
}

}  // namespace tactile
