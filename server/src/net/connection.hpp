// The rules of one client connection, without sockets (sans-I/O): bytes and
// times in, messages to write and actions on the server out. The WebSocket
// shell (WsConnection, net/ws_connection.hpp) feeds it what it reads and writes what it queues;
// the tests (server/tests/net/connection_test.cpp) drive it directly.
//
// The rules, in the order a message meets them:
//   - a token bucket of max_messages_per_s (a second's burst): over it, an
//     Error RateLimited and the connection closes; except a greeted
//     device's DeviceInputs, which over it are coalesced, up to three times
//     the rate more: the latest of each channel waits and is taken when a
//     token comes (flush()), older ones are dropped and counted (a 10 kHz
//     device is served at the rate, its newest pose never lost);
//   - a text message is answered Malformed (the protocol is binary);
//   - the bytes are verified (net/inbound.hpp): Malformed or UnknownMessage;
//   - before Hello only Hello and Ping are taken (WrongRole and closed);
//   - Hello: a major version other than ours (VersionMismatch), a role out
//     of range, a missing or wrong token (Unauthorized: every role but a
//     viewer on loopback needs it), a second controller (Busy), a device's
//     limits or channels the scene lacks (BadRequest), a channel another
//     device drives (Busy) refuse and close; else Welcome and the scene;
//   - DeviceInput, SafetyEvent, DeviceStatus need the device role and a
//     channel named in its Hello; safety events have their own bucket
//     (max_safety_events_per_s; over it dropped, said once per run) and
//     statuses one of 10 a second (over it dropped silently);
//   - Control needs the controller role; the server carries it out;
//   - ViewFields (and Hello.fields) name per-vertex fields for the state
//     frames: an unknown name is BadRequest (in a Hello, refused and closed).
// What a slow reader loses is the outbound queue's rule (send()).
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "live/realtime.hpp"
#include "record/recorder.hpp"
#include "tactile_generated.h"

namespace tactile {

using Bytes = std::shared_ptr<const std::vector<uint8_t>>;
using ConnectionClock = std::chrono::steady_clock;

// A sealed message: the Envelope of `body`, finished with the file identifier.
template <class T>
Bytes seal(flatbuffers::FlatBufferBuilder& b, proto::Message type, flatbuffers::Offset<T> body) {
  proto::FinishEnvelopeBuffer(b, proto::CreateEnvelope(b, type, body.Union()));
  return std::make_shared<const std::vector<uint8_t>>(b.GetBufferPointer(), b.GetBufferPointer() + b.GetSize());
}
Bytes make_error(proto::ErrorCode code, const std::string& message, uint32_t request_id = 0);

// What a slow reader loses (Connection::send): a State or a Haptic frame not
// yet written is replaced by the next (the newest wins, at the rate the
// client asked for in its Hello: 1.10), an Event (SafetyEvent) or a Status
// (DeviceStatus) beyond its bound drops the oldest of its kind waiting, a Control message
// (replies, Telemetry, ReplayStatus) is never dropped: a reader that lets
// control_queue of them wait is disconnected.
enum class OutKind { Control, State, Haptic, Event, Status };

// The bounds the rules hold a connection to (ServerOptions' share).
struct ConnectionLimits {
  std::string token;  // "" : no token set, so only loopback viewers are let in
  std::string server_name = "tactile";
  double viewer_rate_hz = 30;            // states per second at most
  double max_messages_per_s = 5000;      // inbound (a second's burst)
  double max_safety_events_per_s = 100;  // relayed (a second's burst)
  size_t event_queue = 256;              // safety events (and statuses) waiting before the oldest drops
  size_t control_queue = 1024;           // control messages waiting unread: disconnected
};

class Connection;

// What the rules need of the server around them: the scene it serves, the
// other connections, and where what a client sends goes. The shell
// implements it over the live loop or a replay; the tests with a fake.
class ConnectionHost {
 public:
  virtual ~ConnectionHost() = default;
  virtual int64_t now_ns() const = 0;  // the server's clock, for stamps
  // The scene being served: its SceneDescription, its device channels and name.
  virtual const Bytes& description() const = 0;
  virtual const std::vector<std::string>& devices() const = 0;
  virtual const std::string& scene_name() const = 0;
  // The live loop's workspace [m] (false for a replay, which simulates nothing).
  virtual bool workspace(Vec3& lo, Vec3& hi) const = 0;
  // Another greeted connection that drives `channel` (its id), or 0.
  virtual uint64_t driver_of(const std::string& channel, const Connection& asking) const = 0;
  // Makes `s` the controller; false when another one is.
  virtual bool claim_controller(Connection& s) = 0;
  virtual void post_input(const DeviceSample& s) = 0;  // to the live loop (a replay drops it)
  // A safety event (OutKind::Event) or a device status (Status), stamped,
  // for every reader of it.
  virtual void relay(const Bytes& message, OutKind kind) = 0;
  virtual void record(Topic topic, std::span<const uint8_t> message, int64_t time_ns) = 0;
  virtual void control(const proto::Control& c, Connection& from) = 0;  // a controller's command
  virtual void greeted(Connection& s) = 0;  // after its Welcome and scene (a replay starts, or shows its position)
  // A greeted connection's view_fields() changed (its Hello asked for some, or a ViewFields).
  virtual void view_fields_changed() = 0;
};

class Connection {
 public:
  Connection(ConnectionHost& host, const ConnectionLimits& limits, bool loopback, std::string address, uint64_t id,
             ConnectionClock::time_point now);

  // ---- in: what the client sent, and the hello timer ----
  void receive(std::span<const uint8_t> bytes, bool binary, ConnectionClock::time_point now);
  void hello_timed_out();  // no Hello within the hello timeout: refused
  // Inputs coalesced over the rate wait: the shell calls flush() at
  // flush_at() (or later), which takes them if the bucket has a token.
  bool flush_due() const { return pending_inputs_ > 0; }
  ConnectionClock::time_point flush_at() const;
  void flush(ConnectionClock::time_point now);

  // ---- out: what to write, and whether to close ----
  // Queues a message under `kind`'s rule (OutKind).
  void send(const Bytes& message, OutKind kind, ConnectionClock::time_point now = ConnectionClock::now());
  void refuse(proto::ErrorCode code, const std::string& message);  // an Error, then close
  // The message to write now, or null (nothing queued, or one being written).
  const Bytes* next_write();
  void written();  // the one next_write() gave is out
  bool idle() const { return !writing_ && queue_.empty(); }
  // Close once the queue is written (a refusal), or at once (a reader that
  // lets its control messages pile up, a waiting slot given away).
  bool close_after_write() const { return close_after_write_; }
  bool disconnect() const { return disconnect_; }
  void mark_closed() { closed_ = true; }  // the socket is gone: nothing more is queued
  bool closed() const { return closed_; }

  // ---- what it is ----
  uint64_t id() const { return id_; }
  const std::string& address() const { return address_; }
  ConnectionClock::time_point since() const { return since_; }  // when it was upgraded
  proto::Role role() const { return role_; }
  bool greeted() const { return greeted_; }
  uint16_t protocol_minor() const { return protocol_minor_; }
  ViewFieldMask view_fields() const { return view_fields_; }  // what its state frames should carry
  // Upgraded, not greeted, not closing: it holds a waiting slot.
  bool waiting() const { return !greeted_ && !closed_ && !close_after_write_ && !disconnect_; }
  // SafetyEvent came in 1.2, DeviceStatus in 1.3, ReplayStatus in 1.4: an
  // older codec refuses a message type it does not know.
  bool reads(OutKind kind) const;
  bool reads_replay_status() const { return greeted_ && protocol_minor_ >= 4; }
  bool drives(const std::string& channel) const;
  // A viewer that also reads haptic frames (a Foxglove client, net/foxglove_session.hpp), at its Hello's rate.
  bool reads_haptic() const { return greeted_ && (role_ == proto::Role::Device || reads_haptic_); }
  void set_reads_haptic(bool on) { reads_haptic_ = on; }
  // Maps the channels it named onto the scene's (after a scene change);
  // those the scene lacks are said once and their inputs dropped.
  void bind_devices();

  // What it lost as a slow reader, and what it sent over its bounds.
  int64_t haptics_dropped() const { return haptics_dropped_; }  // replaced unwritten by a newer one
  int64_t states_replaced() const { return states_replaced_; }
  double max_rate_hz() const { return max_rate_hz_; }  // Hello.max_rate_hz (0: the server's rate)
  // Whether the message next_write() would give is a frame (State or
  // Haptic), which the shell holds back while the socket has more unsent
  // than a few frames: the newest then replaces it as it waits.
  bool frame_next() const {
    return !writing_ && !queue_.empty() && (kinds_.front() == OutKind::State || kinds_.front() == OutKind::Haptic);
  }
  int64_t events_dropped() const { return events_dropped_; }
  int64_t safety_dropped() const { return safety_dropped_; }
  int64_t inputs_coalesced() const { return inputs_coalesced_; }  // dropped for a newer one over the rate

 private:
  void dispatch(const proto::Envelope& e, std::span<const uint8_t> raw, ConnectionClock::time_point now);
  void on_hello(const proto::Hello& h);
  void on_input(const proto::DeviceInput& in, std::span<const uint8_t> raw);
  void on_safety_event(const proto::SafetyEvent& ev, ConnectionClock::time_point now);
  void on_device_status(const proto::DeviceStatus& st, ConnectionClock::time_point now);
  void on_control(const proto::Control& c, std::span<const uint8_t> raw);
  void on_view_fields(const proto::ViewFields& v);
  bool named(const std::string& channel) const;  // in its Hello
  void reply(proto::ErrorCode code, const std::string& message, uint32_t request_id = 0);

  ConnectionHost& host_;
  ConnectionLimits limits_;
  bool loopback_;
  std::string address_;  // the peer's IP address
  uint64_t id_;
  ConnectionClock::time_point since_;
  bool greeted_ = false, close_after_write_ = false, disconnect_ = false, closed_ = false, writing_ = false;
  proto::Role role_ = proto::Role::Viewer;
  uint16_t protocol_minor_ = 0;
  bool reads_haptic_ = false;
  ViewFieldMask view_fields_ = 0;
  std::vector<std::string> device_names_;  // channels named in Hello
  std::vector<DeviceDrive> drives_;        // how each drives its channel (Hello.device_limits)
  std::vector<int32_t> devices_;           // their index in the current scene, -1 if absent
  std::vector<bool> outside_;              // each one's latest input was outside the workspace

  // The outbound queue: null entries stand for the pending frame of their kind.
  std::deque<Bytes> queue_;
  std::deque<OutKind> kinds_;
  Bytes pending_state_, pending_haptic_, current_;
  size_t events_queued_ = 0, statuses_queued_ = 0, controls_queued_ = 0;
  int64_t haptics_dropped_ = 0, states_replaced_ = 0, events_dropped_ = 0;
  ConnectionClock::time_point next_state_due_{}, next_haptic_due_{};
  double max_rate_hz_ = 0;
  // Per kind of frame, over the current second: frames passed by the rate,
  // and of them those replaced unread (Lagging is told from these).
  struct LagWindow {
    ConnectionClock::time_point start{};
    int64_t passed = 0, replaced = 0;
  };
  LagWindow state_lag_, haptic_lag_;
  bool told_lagging_ = false;

  // Token buckets: inbound messages, safety events, statuses.
  struct Bucket {
    double rate, tokens;
    ConnectionClock::time_point last;
    bool take(ConnectionClock::time_point now);  // refills at `rate` up to a second's burst, then takes one
  };
  Bucket messages_, safety_, status_;
  Bucket coalescing_;  // DeviceInputs over messages_' rate: coalesced within it, a flood past it
  // Per channel named in Hello: its latest input over the rate, waiting (empty: none).
  std::vector<std::vector<uint8_t>> waiting_input_;
  std::vector<uint8_t> flushing_;  // the one flush() is taking
  size_t pending_inputs_ = 0;
  int64_t inputs_coalesced_ = 0;
  bool safety_limited_ = false;
  int64_t safety_dropped_ = 0;
};

}  // namespace tactile
