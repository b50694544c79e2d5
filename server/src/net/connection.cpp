#include "net/connection.hpp"

#include <algorithm>
#include <cstdio>

#include <glm/vector_relational.hpp>

#include "net/inbound.hpp"

namespace tactile {

namespace fb = flatbuffers;
namespace wire = proto;

namespace {

// A string for a one-line log: control characters shown as '?'.
std::string printable(const fb::String* s) {
  std::string out = s ? s->str() : "";
  for (char& c : out)
    if (uint8_t(c) < 0x20 || c == 0x7f) c = '?';
  return out;
}

}  // namespace

Bytes make_error(wire::ErrorCode code, const std::string& message, uint32_t request_id) {
  fb::FlatBufferBuilder b(64 + message.size());
  const std::string text = utf8_text(message);  // it may quote what a client sent
  const auto body = wire::CreateError(b, code, b.CreateString(text), request_id);
  return seal(b, wire::Message::Error, body);
}

bool Connection::Bucket::take(ConnectionClock::time_point now) {
  tokens = std::min(rate, tokens + rate * std::chrono::duration<double>(now - last).count());
  last = now;
  if (tokens < 1) return false;
  tokens -= 1;
  return true;
}

Connection::Connection(ConnectionHost& host, const ConnectionLimits& limits, bool loopback, std::string address,
                       uint64_t id, ConnectionClock::time_point now)
    : host_(host),
      limits_(limits),
      loopback_(loopback),
      address_(std::move(address)),
      id_(id),
      since_(now),
      // Full at the first message: a second's burst.
      messages_{limits.max_messages_per_s, 1e18, now},
      safety_{limits.max_safety_events_per_s, 1e18, now},
      status_{10.0, 1e18, now},
      coalescing_{3 * limits.max_messages_per_s, 1e18, now} {}

// ---- in ---------------------------------------------------------------------------------

void Connection::receive(std::span<const uint8_t> bytes, bool binary, ConnectionClock::time_point now) {
  if (!messages_.take(now)) {
    // A device's inputs over the rate are coalesced (the latest of each
    // channel waits for a token); anything else, or past the coalescing
    // bucket, is a flood.
    const auto flood = [&] {
      refuse(wire::ErrorCode::RateLimited,
             "more than " + std::to_string(int64_t(limits_.max_messages_per_s)) + " messages per second");
    };
    if (!(greeted_ && role_ == wire::Role::Device && binary && coalescing_.take(now))) return flood();
    const Inbound inbound = read_inbound(bytes.data(), bytes.size());
    const wire::DeviceInput* in = inbound ? inbound.envelope->message_as_DeviceInput() : nullptr;
    if (!in) return flood();
    const std::string name = in->device() ? in->device()->str() : "";
    const auto it = std::find(device_names_.begin(), device_names_.end(), name);
    if (it == device_names_.end()) return;  // not its channel: nothing to keep (said when the rate allows)
    std::vector<uint8_t>& slot = waiting_input_[size_t(it - device_names_.begin())];
    if (slot.empty())
      ++pending_inputs_;
    else
      ++inputs_coalesced_;
    slot.assign(bytes.begin(), bytes.end());
    return;
  }
  if (!binary) return reply(wire::ErrorCode::Malformed, "text message: the protocol is binary FlatBuffers");
  const Inbound inbound = read_inbound(bytes.data(), bytes.size());
  if (!inbound) return reply(inbound.error, inbound.message);
  dispatch(*inbound.envelope, bytes, now);
}

ConnectionClock::time_point Connection::flush_at() const {
  // When the bucket has a token again.
  const double wait = std::max(0.0, 1.0 - messages_.tokens) / messages_.rate + 1e-6;  // (past rounding)
  return messages_.last + std::chrono::duration_cast<ConnectionClock::duration>(std::chrono::duration<double>(wait));
}

void Connection::flush(ConnectionClock::time_point now) {
  for (std::vector<uint8_t>& slot : waiting_input_) {
    if (slot.empty() || closed_) continue;
    if (!messages_.take(now)) return;
    flushing_.swap(slot);  // (the slot keeps a buffer for the next input over the rate)
    slot.clear();
    --pending_inputs_;
    on_input(*wire::GetEnvelope(flushing_.data())->message_as_DeviceInput(), flushing_);  // (verified when it came)
  }
}

void Connection::hello_timed_out() {
  if (!greeted_) refuse(wire::ErrorCode::BadRequest, "no Hello within the hello timeout");
}

void Connection::dispatch(const wire::Envelope& e, std::span<const uint8_t> raw, ConnectionClock::time_point now) {
  if (!greeted_ && e.message_type() != wire::Message::Hello && e.message_type() != wire::Message::Ping)
    return refuse(wire::ErrorCode::WrongRole,
                  std::string("the first message must be Hello, got ") + wire::EnumNameMessage(e.message_type()));
  switch (e.message_type()) {
    case wire::Message::Hello: return on_hello(*e.message_as_Hello());
    case wire::Message::Ping: {
      const wire::Ping& p = *e.message_as_Ping();
      const int64_t received = host_.now_ns();
      fb::FlatBufferBuilder b;
      return send(
          seal(b, wire::Message::Pong, wire::CreatePong(b, p.id(), p.client_time_ns(), received, host_.now_ns())),
          OutKind::Control, now);
    }
    case wire::Message::DeviceInput: return on_input(*e.message_as_DeviceInput(), raw);
    case wire::Message::Control: return on_control(*e.message_as_Control(), raw);
    case wire::Message::SafetyEvent: return on_safety_event(*e.message_as_SafetyEvent(), now);
    case wire::Message::DeviceStatus: return on_device_status(*e.message_as_DeviceStatus(), now);
    case wire::Message::ViewFields: return on_view_fields(*e.message_as_ViewFields());
    default:
      return reply(wire::ErrorCode::WrongRole,
                   std::string("a client may not send ") + wire::EnumNameMessage(e.message_type()));
  }
}

namespace {

// The mask of the fields `names` lists, or "" and `*bad` naming the first it does not know.
ViewFieldMask read_view_fields(const fb::Vector<fb::Offset<fb::String>>* names, const std::string& where,
                               std::string* bad) {
  ViewFieldMask mask = 0;
  if (names)
    for (const fb::String* n : *names) {
      ViewField f;
      if (!parse_view_field(n->string_view(), &f)) {
        *bad = where + ": no field '" + n->str() + "' (this server sends " + view_field_names() + ")";
        return 0;
      }
      mask |= view_field_bit(f);
    }
  return mask;
}

}  // namespace

void Connection::on_view_fields(const wire::ViewFields& v) {
  std::string bad;
  const ViewFieldMask mask = read_view_fields(v.fields(), "ViewFields.fields", &bad);
  if (!bad.empty()) return reply(wire::ErrorCode::BadRequest, bad);
  if (mask == view_fields_) return;
  view_fields_ = mask;
  host_.view_fields_changed();
}

void Connection::on_hello(const wire::Hello& h) {
  if (greeted_) return reply(wire::ErrorCode::BadRequest, "Hello sent twice");
  const int major = int(wire::ProtocolMajor::Current), minor = int(wire::ProtocolMinor::Current);
  if (h.protocol_major() != major)
    return refuse(wire::ErrorCode::VersionMismatch, "client speaks protocol " + std::to_string(h.protocol_major()) +
                                                        "." + std::to_string(h.protocol_minor()) + ", this server " +
                                                        std::to_string(major) + "." + std::to_string(minor));
  if (h.role() > wire::Role::MAX)
    return refuse(wire::ErrorCode::BadRequest,
                  "Hello.role " + std::to_string(int(h.role())) + " is not a role (0 viewer, 1 device, 2 controller)");
  const std::string token = h.token() ? h.token()->str() : "";
  const bool needs_token = h.role() != wire::Role::Viewer || !loopback_;
  if (needs_token && (limits_.token.empty() || token != limits_.token))
    return refuse(wire::ErrorCode::Unauthorized,
                  std::string(limits_.token.empty() ? "this server has no token set: the "
                                                    : "a wrong or missing token for the ") +
                      wire::EnumNameRole(h.role()) + " role" +
                      (loopback_ ? "" : " (off loopback every role needs it)"));
  if (h.role() == wire::Role::Device) {
    if (const std::string bad = check_device_limits(h); !bad.empty()) return refuse(wire::ErrorCode::BadRequest, bad);
    const std::vector<std::string>& names = host_.devices();
    if (h.devices())
      for (const fb::String* d : *h.devices()) {
        if (std::find(names.begin(), names.end(), d->str()) == names.end())
          return refuse(wire::ErrorCode::BadRequest, "no device channel '" + d->str() + "' in this scene");
        // One device drives a channel: two would pull its proxy both ways.
        if (const uint64_t other = host_.driver_of(d->str(), *this))
          return refuse(wire::ErrorCode::Busy, "device channel '" + d->str() +
                                                   "' is driven by another device (connection " +
                                                   std::to_string(other) + ")");
        device_names_.push_back(d->str());
        waiting_input_.emplace_back();
        DeviceDrive drive;
        if (h.device_limits() && h.device_limits()->size() > drives_.size()) {
          const wire::DeviceLimits& l = *h.device_limits()->Get(uint32_t(drives_.size()));
          drive.direct = l.direct();
          drive.has_limits = true;
          drive.limits = {double(l.max_force_N()), double(l.max_torque_Nm()), double(l.stiffness_N_per_m())};
        }
        drives_.push_back(drive);
        outside_.push_back(false);
      }
  }
  const double rate = double(h.max_rate_hz());
  if (!std::isfinite(rate) || rate < 0)
    return refuse(wire::ErrorCode::BadRequest,
                  "Hello.max_rate_hz must be 0 (the server's rate) or a positive number of frames per second, got " +
                      std::to_string(rate));
  std::string bad_fields;
  const ViewFieldMask fields = read_view_fields(h.fields(), "Hello.fields", &bad_fields);
  if (!bad_fields.empty()) return refuse(wire::ErrorCode::BadRequest, bad_fields);
  if (h.role() == wire::Role::Controller && !host_.claim_controller(*this))
    return refuse(wire::ErrorCode::Busy, "another controller is connected");
  greeted_ = true;
  role_ = h.role();
  protocol_minor_ = h.protocol_minor();
  max_rate_hz_ = rate;
  if (role_ == wire::Role::Device) bind_devices();
  fb::FlatBufferBuilder b;
  send(seal(b, wire::Message::Welcome,
            wire::CreateWelcomeDirect(b, uint16_t(major), uint16_t(minor), role_, limits_.server_name.c_str(), id_,
                                      host_.now_ns())),
       OutKind::Control);
  send(host_.description(), OutKind::Control);
  host_.greeted(*this);
  view_fields_ = fields;
  if (fields) host_.view_fields_changed();
}

void Connection::bind_devices() {
  const std::vector<std::string>& names = host_.devices();
  devices_.clear();
  for (const std::string& d : device_names_) {
    const auto it = std::find(names.begin(), names.end(), d);
    devices_.push_back(it == names.end() ? -1 : int32_t(it - names.begin()));
    if (it == names.end())
      reply(wire::ErrorCode::BadRequest, "scene '" + host_.scene_name() + "' has no device channel '" + d +
                                             "': its inputs are dropped until a scene has it");
  }
}

bool Connection::named(const std::string& channel) const {
  return std::find(device_names_.begin(), device_names_.end(), channel) != device_names_.end();
}

bool Connection::drives(const std::string& channel) const {
  return greeted_ && role_ == wire::Role::Device && named(channel);
}

void Connection::on_input(const wire::DeviceInput& in, std::span<const uint8_t> raw) {
  if (role_ != wire::Role::Device) return reply(wire::ErrorCode::WrongRole, "DeviceInput needs the device role");
  const std::string name = in.device() ? in.device()->str() : "";
  const auto it = std::find(device_names_.begin(), device_names_.end(), name);
  if (it == device_names_.end())
    return reply(wire::ErrorCode::BadRequest,
                 "DeviceInput for channel '" + name + "', which this connection did not name in its Hello");
  const size_t k = size_t(it - device_names_.begin());
  if (!waiting_input_[k].empty()) {  // an older one coalesced over the rate: this one is newer
    waiting_input_[k].clear();
    --pending_inputs_;
    ++inputs_coalesced_;
  }
  if (devices_[k] < 0) return;  // not in this scene (said at the switch)
  if (const std::string bad = check_device_input(in); !bad.empty()) return reply(wire::ErrorCode::BadRequest, bad);
  // Outside the workspace the loop holds the proxy at the edge; said once per excursion.
  if (Vec3 lo, hi; host_.workspace(lo, hi)) {
    const Vec3 x(in.position()->x(), in.position()->y(), in.position()->z());
    const bool outside = glm::any(glm::lessThan(x, lo)) || glm::any(glm::greaterThan(x, hi));
    if (outside && !outside_[k]) {
      char text[320];
      std::snprintf(text, sizeof text,
                    "DeviceInput.position (%.4g, %.4g, %.4g) m for channel '%s' is outside the scene's workspace "
                    "[%.3g, %.3g] x [%.3g, %.3g] x [%.3g, %.3g] m: its proxy is held at the edge",
                    x.x, x.y, x.z, utf8_text(name).c_str(), lo.x, hi.x, lo.y, hi.y, lo.z, hi.z);
      reply(wire::ErrorCode::BadRequest, text);
    }
    outside_[k] = outside;
  }
  // Recorded first: stamped before the simulation can apply it.
  host_.record(Topic::Input, raw, host_.now_ns());
  host_.post_input(device_sample(in, devices_[k], drives_[k]));
}

void Connection::on_safety_event(const wire::SafetyEvent& ev, ConnectionClock::time_point now) {
  if (role_ != wire::Role::Device)
    return reply(wire::ErrorCode::WrongRole,
                 std::string("SafetyEvent needs the Device role; this connection has the ") +
                     wire::EnumNameRole(role_) + " role");
  if (const std::string bad = check_safety_event(ev); !bad.empty()) return reply(wire::ErrorCode::BadRequest, bad);
  const std::string name = ev.device()->str();  // UTF-8 and bounded: checked
  if (!named(name))
    return reply(wire::ErrorCode::BadRequest,
                 "SafetyEvent for channel '" + name + "', which this connection did not name in its Hello");
  // Beyond its bucket an event is dropped and counted, and the device told once per run of drops.
  if (!safety_.take(now)) {
    ++safety_dropped_;
    if (!safety_limited_)
      reply(wire::ErrorCode::RateLimited, "more than " + std::to_string(int64_t(safety_.rate)) +
                                              " safety events per second: dropped, not relayed (" +
                                              std::to_string(safety_dropped_) + " so far)");
    safety_limited_ = true;
    return;
  }
  safety_limited_ = false;
  fb::FlatBufferBuilder b(128 + name.size() + (ev.message() ? ev.message()->size() : 0));
  const auto device = b.CreateString(ev.device());
  const auto message = b.CreateString(ev.message());
  const Bytes relayed =
      seal(b, wire::Message::SafetyEvent,
           wire::CreateSafetyEvent(b, device, ev.device_time_ns(), host_.now_ns(), ev.kind(), message, ev.force_N()));
  std::fprintf(stderr, "safety: %s %s %s (%.3f N)\n", printable(ev.device()).c_str(),
               wire::EnumNameSafetyKind(ev.kind()), printable(ev.message()).c_str(), double(ev.force_N()));
  host_.relay(relayed, OutKind::Event);
  host_.record(Topic::Safety, *relayed, host_.now_ns());
}

void Connection::on_device_status(const wire::DeviceStatus& st, ConnectionClock::time_point now) {
  if (role_ != wire::Role::Device)
    return reply(wire::ErrorCode::WrongRole,
                 std::string("DeviceStatus needs the Device role; this connection has the ") +
                     wire::EnumNameRole(role_) + " role");
  if (const std::string bad = check_device_status(st); !bad.empty()) return reply(wire::ErrorCode::BadRequest, bad);
  const std::string name = st.device()->str();
  if (!named(name))
    return reply(wire::ErrorCode::BadRequest,
                 "DeviceStatus for channel '" + name + "', which this connection did not name in its Hello");
  if (!status_.take(now)) return;  // a figure, not an event: more than a few a second are dropped
  fb::FlatBufferBuilder b(256 + name.size());
  const auto device = b.CreateString(st.device());
  const auto mode = b.CreateString(st.mode());
  const Bytes relayed = seal(
      b, wire::Message::DeviceStatus,
      wire::CreateDeviceStatus(b, device, st.device_time_ns(), host_.now_ns(), st.tick_rate_hz(), st.lateness_p99_us(),
                               st.lateness_max_us(), st.missed_ticks(), st.display_delay_ms(), st.state_interval_ms(),
                               st.jitter_allowance_ms(), mode, st.force_N()));
  host_.relay(relayed, OutKind::Status);
  host_.record(Topic::DeviceStatus, *relayed, host_.now_ns());
}

void Connection::on_control(const wire::Control& c, std::span<const uint8_t> raw) {
  if (role_ != wire::Role::Controller)
    return reply(wire::ErrorCode::WrongRole, "Control needs the controller role", c.request_id());
  host_.record(Topic::Control, raw, host_.now_ns());
  host_.control(c, *this);
}

// ---- out --------------------------------------------------------------------------------

void Connection::reply(wire::ErrorCode code, const std::string& message, uint32_t request_id) {
  send(make_error(code, message, request_id), OutKind::Control);
}

void Connection::refuse(wire::ErrorCode code, const std::string& message) {
  reply(code, message);
  close_after_write_ = true;
}

bool Connection::reads(OutKind kind) const {
  switch (kind) {
    case OutKind::Event: return greeted_ && role_ != wire::Role::Device && protocol_minor_ >= 2;
    case OutKind::Status: return greeted_ && role_ != wire::Role::Device && protocol_minor_ >= 3;
    default: return true;
  }
}

void Connection::send(const Bytes& message, OutKind kind, ConnectionClock::time_point now) {
  if (kind == OutKind::Control && role_ == wire::Role::Controller && greeted_ &&
      wire::GetEnvelope(message->data())->message_type() == wire::Message::Error)
    host_.record(Topic::Error, *message, host_.now_ns());
  if (closed_ || disconnect_) return;
  if (kind == OutKind::State || kind == OutKind::Haptic) {
    // Latest wins, at the client's rate on average: each frame passed sets
    // the next one's due time a period on, and a frame a little early (a
    // quarter period: the simulation's publishing jitters) still passes, or
    // frames made at exactly the client's rate would lose every other one.
    // A frame not yet written when the next passes is replaced by it: what
    // the client reads is the newest, never a backlog.
    const bool state = kind == OutKind::State;
    const double rate =
        state ? (max_rate_hz_ > 0 ? std::min(max_rate_hz_, limits_.viewer_rate_hz) : limits_.viewer_rate_hz)
              : max_rate_hz_;  // (0: every haptic frame the server makes)
    ConnectionClock::time_point& due = state ? next_state_due_ : next_haptic_due_;
    const auto period =
        rate > 0 ? std::chrono::duration_cast<ConnectionClock::duration>(std::chrono::duration<double>(1.0 / rate))
                 : ConnectionClock::duration::zero();
    if (now + period / 4 < due) return;
    // Told once, when over a second it let more than half the frames that
    // passed be replaced unread: not for the few a connection's first
    // moments replace while the scene description goes out.
    LagWindow& lag = state ? state_lag_ : haptic_lag_;
    if (now - lag.start >= std::chrono::seconds(1)) {
      if (!told_lagging_ && protocol_minor_ >= 10 && greeted_ && lag.replaced >= 10 && 2 * lag.replaced > lag.passed) {
        told_lagging_ = true;
        reply(wire::ErrorCode::Lagging,
              std::string("this client reads ") + (state ? "state" : "haptic") +
                  " frames slower than they come: an unread frame is replaced by the newest (said once; "
                  "Hello.max_rate_hz asks for fewer)");
      }
      lag = {now, 0, 0};
    }
    ++lag.passed;
    Bytes& pending = state ? pending_state_ : pending_haptic_;
    if (pending) {
      pending = message;  // replaces the one not yet written
      ++lag.replaced;
      if (state) {
        ++states_replaced_;
      } else {
        ++haptics_dropped_;
      }
      return;
    }
    due = std::max(due, now - period) + period;
    pending = message;
    queue_.push_back(nullptr);  // a marker: the pending frame of its kind goes here
  } else if (kind != OutKind::Control) {
    // A reader too slow: its oldest waiting message of the kind goes (not
    // the one being written), so what it does read is the newest.
    size_t& queued = kind == OutKind::Event ? events_queued_ : statuses_queued_;
    if (queued >= limits_.event_queue)
      for (size_t k = writing_ ? 1 : 0; k < queue_.size(); ++k)
        if (kinds_[k] == kind) {
          queue_.erase(queue_.begin() + long(k));
          kinds_.erase(kinds_.begin() + long(k));
          --queued;
          ++events_dropped_;
          break;
        }
    ++queued;
    queue_.push_back(message);
  } else {
    if (controls_queued_ >= limits_.control_queue) {
      std::fprintf(stderr, "connection %llu (%s, %s) let %zu control messages wait unread: disconnected\n",
                   (unsigned long long)id_, wire::EnumNameRole(role_), address_.c_str(), controls_queued_);
      disconnect_ = true;
      return;
    }
    ++controls_queued_;
    queue_.push_back(message);
  }
  kinds_.push_back(kind);
}

const Bytes* Connection::next_write() {
  if (writing_ || queue_.empty() || closed_) return nullptr;
  writing_ = true;
  if (queue_.front()) {
    current_ = queue_.front();
  } else {
    Bytes& pending = kinds_.front() == OutKind::State ? pending_state_ : pending_haptic_;
    current_ = std::move(pending);
    pending.reset();
  }
  return &current_;
}

void Connection::written() {
  writing_ = false;
  switch (kinds_.front()) {
    case OutKind::Haptic: break;
    case OutKind::Event: --events_queued_; break;
    case OutKind::Status: --statuses_queued_; break;
    case OutKind::Control: --controls_queued_; break;
    case OutKind::State: break;
  }
  queue_.pop_front();
  kinds_.pop_front();
  current_.reset();
}

}  // namespace tactile
