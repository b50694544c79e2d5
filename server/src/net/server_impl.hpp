// Inside the server (net/server.cpp and its parts: http_session.cpp,
// replay_serving.cpp, recording_taps.cpp): what the network thread keeps
// (the feed of the scene served, the connections, the recording), and the
// WebSocket shell around each connection's rules (net/session.hpp).
#pragma once

#include "net/server.hpp"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <deque>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <thread>
#include <unordered_set>

#include <sys/resource.h>

#include <glm/vector_relational.hpp>

#include <boost/asio.hpp>
#include <boost/asio/posix/stream_descriptor.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>

#include "net/admission.hpp"
#include "net/inbound.hpp"
#include "net/mailbox.hpp"
#include "net/session.hpp"
#include "record/recorder.hpp"
#include "record/replay.hpp"
#include "scene/parameters.hpp"
#include "tactile_generated.h"

namespace tactile {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
namespace fb = flatbuffers;
namespace wire = proto;
using tcp = asio::ip::tcp;

// The server's clock for stamps [ns] (steady).
inline int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

inline Bytes copy_bytes(const uint8_t* data, size_t n) {
  return std::make_shared<const std::vector<uint8_t>>(data, data + n);
}

// A string for a one-line log: control characters shown as '?'.
inline std::string printable_text(std::string out) {
  for (char& c : out)
    if (uint8_t(c) < 0x20 || c == 0x7f) c = '?';
  return out;
}

class WsSession;

// What a recording takes from the simulation thread: every frame, in rings
// that never overwrite (a full ring drops the new frame and counts it: a
// recording fault). Made when a recording first starts on a feed and kept
// with it, since the simulation thread may be pushing into it.
struct RecordTap {
  FrameRing states, haptics, applied;
  int64_t states_dropped = 0, haptics_dropped = 0, applied_dropped = 0;  // by the rings when the recording started
  RecordTap(size_t state_bytes, size_t haptic_bytes)
      : states(64, state_bytes),                 // two seconds of states at 30 Hz
        haptics(16384, haptic_bytes),            // 1.6 s of haptic frames at 10 kHz
        applied(16384, sizeof(AppliedInput)) {}  // of inputs at 10 kHz
};

// What the clients are served from for one scene: the mailboxes its loop
// publishes into (from the simulation thread) and its description.
// A replayed scene has no loop: its description alone (live == nullptr).
struct Feed {
  std::shared_ptr<LiveScene> live;
  FrameRing haptics;
  LatestBox states;
  Bytes description;
  std::string scene_name;
  std::vector<std::string> devices;  // channels, in the order haptic frames list them
  std::unique_ptr<RecordTap> tap;    // set before `recording` turns true, kept after
  std::atomic<bool> recording{false};

  Feed(std::shared_ptr<LiveScene> l, const std::vector<std::string>& scenes)
      : live(std::move(l)),
        // (a haptic frame: ~92 B per proxy, ~100 B per device channel, ~150 B besides)
        haptics(1024, haptic_bytes()),
        states(state_bytes()),
        scene_name(live->scene().name),
        devices(live->sim().devices()) {
    const std::vector<uint8_t> d = live->describe(scenes);
    description = copy_bytes(d.data(), d.size());
  }
  // A recorded SceneDescription (Envelope bytes, verified by the caller).
  explicit Feed(Bytes recorded) : haptics(1, 0), states(0), description(std::move(recorded)) {
    const wire::SceneDescription* d = wire::GetEnvelope(description->data())->message_as_SceneDescription();
    if (d->scene_name()) scene_name = d->scene_name()->str();
    if (d->devices())
      for (const fb::String* name : *d->devices()) devices.push_back(name->str());
  }
  // The most a state frame takes: positions and up to four fields per vertex, poses and forces per proxy.
  size_t state_bytes() const {
    return 256 + 20 * 3 * live->frames().surface().nodes.size() + 64 * live->sim().proxies().size();
  }
  size_t haptic_bytes() const { return 512 + 128 * live->sim().proxies().size() + 160 * live->sim().devices().size(); }
};

struct Server::Impl : std::enable_shared_from_this<Server::Impl>, SessionHost {
  asio::io_context& ioc;
  Director* director;  // the live session, or
  Replay* replay;      // a recording played back (one of the two)
  ServerOptions options;
  tcp::acceptor acceptor;
  asio::steady_timer accept_timer;  // a failed accept waits on it before the next
  bool stopped = false;

  // Signalled from the simulation thread after each publication.
  std::shared_ptr<Wakeup> wakeup = std::make_shared<Wakeup>();
  asio::posix::stream_descriptor wake_fd;
  uint64_t wake_value = 0;

  std::shared_ptr<Feed> feed;      // the scene clients are served
  std::shared_ptr<Feed> incoming;  // handed to the director, not yet running
  bool changing = false;           // a load, reset or parameter change under way, until its scene is served
  uint32_t fault_resets = 0;       // resets the server made after a fault (reset_on_fault)

  std::unordered_set<WsSession*> sessions;
  WsSession* controller = nullptr;
  WsSession* shell_of(const Session& s) const;

  // ---- SessionHost: what a connection's rules (net/session.hpp) need of the server ----
  int64_t now_ns() const override { return tactile::now_ns(); }
  const Bytes& description() const override { return feed->description; }
  const std::vector<std::string>& devices() const override { return feed->devices; }
  const std::string& scene_name() const override { return feed->scene_name; }
  bool workspace(Vec3& lo, Vec3& hi) const override {
    if (!feed->live) return false;
    lo = feed->live->loop().workspace_lo();
    hi = feed->live->loop().workspace_hi();
    return true;
  }
  uint64_t driver_of(const std::string& channel, const Session& asking) const override;
  bool claim_controller(Session& s) override;
  void post_input(const DeviceSample& s) override {
    if (feed->live) feed->live->loop().post_input(s);  // a full queue drops it and counts; a replay moves nothing
  }
  void relay(const Bytes& message, OutKind kind) override;
  void record(Topic topic, std::span<const uint8_t> m, int64_t time_ns) override {
    record(topic, m.data(), m.size(), time_ns);
  }
  void control(const wire::Control& c, Session& from) override;
  void greeted(Session& s) override;
  // The fields the loops' state frames carry: their scene's and every greeted connection's.
  void view_fields_changed() override;
  asio::steady_timer telemetry_timer;

  asio::steady_timer replay_timer;
  Replay::Clock::time_point replay_status_due{};
  bool replay_started = false;
  void tick_replay();
  Bytes replay_status();
  void serve_replayed(const Replay::Item& item);
  void show_replay_position();  // the scene and state at the position, after a seek
  void replay_control(const wire::Control& c, WsSession& from);
  void live_control(const wire::Control& c, WsSession& from);

  std::unique_ptr<Recorder> recorder;                // the recording under way
  std::vector<std::unique_ptr<Recorder>> finishing;  // stopped, closing their files

  Impl(asio::io_context& io, Director* d, Replay* r, ServerOptions o)
      : ioc(io),
        director(d),
        replay(r),
        options(std::move(o)),
        acceptor(io),
        accept_timer(io),
        wake_fd(io, ::dup(wakeup->fd())),
        telemetry_timer(io),
        replay_timer(io) {
    if (d) {
      d->set_library(options.scenes_dir, options.live);
      feed = std::make_shared<Feed>(d->current(), d->scenes());
      attach(*feed);
    } else {
      feed = std::make_shared<Feed>(copy_bytes(r->first_scene().bytes.data(), r->first_scene().bytes.size()));
    }
  }

  // The loop's sinks: copy into the feed's mailboxes and wake the network
  // thread. The feed outlives the loop's runs: it is released only once the
  // director has switched away from its scene (installed()).
  void attach(Feed& f) {
    Feed* target = &f;
    std::shared_ptr<Wakeup> wake = wakeup;
    f.live->loop().on_haptic([target, wake](std::span<const uint8_t> m) {
      target->haptics.push(m.data(), m.size());
      if (target->recording.load(std::memory_order_acquire)) target->tap->haptics.push(m.data(), m.size());
      wake->signal();
    });
    f.live->loop().on_state([target, wake](std::span<const uint8_t> m) {
      target->states.put(m.data(), m.size());
      if (target->recording.load(std::memory_order_acquire)) target->tap->states.push(m.data(), m.size());
      wake->signal();
    });
    f.live->loop().on_applied([target](const AppliedInput& a) {
      if (target->recording.load(std::memory_order_acquire))
        target->tap->applied.push(reinterpret_cast<const uint8_t*>(&a), sizeof a);
    });
  }

  // Recording (record/recorder.hpp): each returns "" or what is wrong.
  // `name`: a file name in the recordings folder ("" picks one); with
  // any_path, a path (the command line's --record).
  std::string start_recording(const std::string& name, bool any_path = false);
  void stop_recording();
  void record(Topic topic, const uint8_t* data, size_t n, int64_t time_ns);
  void record(Topic topic, const Bytes& m) { record(topic, m->data(), m->size(), now_ns()); }
  void drain_tap(Feed& f);
  void tap_feed(Feed& f);
  std::string check_recorder();  // a fault that stopped the recording, once

  // A change a controller asked for (c), or the server itself (nullptr: a
  // reset after a fault, ServerOptions::reset_on_fault).
  void change(Director::Change::Kind kind, const wire::Control* c);
  void built(std::shared_ptr<LiveScene> live, bool carry);
  void installed(const std::shared_ptr<LiveScene>& live);
  void send_to_controller(const Bytes& message);

  void ensure_descriptors() const;
  void listen();
  void accept();
  void wait_wakeup();
  void deliver();
  void tick_telemetry();
  Bytes telemetry_message(const std::string& extra_fault);
  bool origin_allowed(const std::string& origin) const;
  bool host_allowed(std::string_view host) const;
  // The verdict on one more WebSocket from `address` (net/admission.hpp);
  // a connection it evicts is closed here, with the reason.
  Admission admit(const std::string& address);
  LogBudget admission_log;  // evictions and refusals: a line a second at most
  void log_admission(SessionClock::time_point now, const std::string& line);
  void close_all();
};

// ---- WebSocket sessions ----------------------------------------------------------------

class WsSession : public std::enable_shared_from_this<WsSession> {
 public:
  WsSession(std::shared_ptr<Server::Impl> server, tcp::socket socket, bool loopback, std::string address)
      : server_(std::move(server)),
        ws_(std::move(socket)),
        hello_timer_(server_->ioc),
        flush_timer_(server_->ioc),
        core_(*server_, limits(server_->options), loopback, std::move(address), next_id_++, SessionClock::now()) {}

  ~WsSession() {
    server_->sessions.erase(this);
    if (core_.view_fields()) server_->view_fields_changed();
    if (server_->controller == this) server_->controller = nullptr;
    if (core_.safety_dropped() > 0)
      std::fprintf(stderr, "safety: connection %llu sent %lld events over the limit of %g per second: dropped\n",
                   (unsigned long long)core_.id(), (long long)core_.safety_dropped(),
                   server_->options.max_safety_events_per_s);
    if (core_.events_dropped() > 0)
      std::fprintf(stderr, "safety: connection %llu (%s) read too slowly and missed %lld safety events\n",
                   (unsigned long long)core_.id(), wire::EnumNameRole(core_.role()), (long long)core_.events_dropped());
  }

  static SessionLimits limits(const ServerOptions& o) {
    return {o.token,          o.server_name,
            o.viewer_rate_hz, o.max_messages_per_s,
            o.device_queue,   o.max_safety_events_per_s,
            o.event_queue,    o.control_queue};
  }

  void start(http::request<http::string_body> req) {
    server_->sessions.insert(this);
    beast::get_lowest_layer(ws_).expires_never();
    // Without it, Nagle's algorithm holds each small haptic frame until the
    // peer's next message acks the previous one: a whole input period of latency.
    beast::error_code ignored;
    beast::get_lowest_layer(ws_).socket().set_option(tcp::no_delay(true), ignored);
    websocket::stream_base::timeout t = websocket::stream_base::timeout::suggested(beast::role_type::server);
    t.idle_timeout = std::chrono::milliseconds(int64_t(server_->options.idle_timeout_s * 1000));
    t.keep_alive_pings = true;
    ws_.set_option(t);
    ws_.read_message_max(server_->options.max_message_bytes);
    ws_.binary(true);
    ws_.async_accept(req, [self = shared_from_this()](beast::error_code ec) {
      if (ec) return;
      self->arm_hello_timer();
      self->read();
    });
  }

  Session& core() { return core_; }
  const Session& core() const { return core_; }
  // After a scene change: its channels mapped onto the new scene's.
  void rebind() {
    core_.bind_devices();
    pump();
  }

  // Queues a message under its kind's rule (net/session.hpp) and writes.
  void send(const Bytes& message, OutKind kind) {
    core_.send(message, kind);
    pump();
  }
  // Closes the socket at once (a waiting slot given to a newer connection):
  // its pending operations end, and with them the session.
  void drop() {
    if (core_.closed()) return;
    core_.mark_closed();
    hello_timer_.cancel();
    beast::get_lowest_layer(ws_).close();
  }
  // Closes a waiting connection whose slot the server needs (Server::Impl::
  // admit): close code 1013 (try again later) with the reason, and the socket
  // within a second whether or not the peer answers.
  void evict(const std::string& reason) {
    if (core_.closed()) return;
    core_.mark_closed();
    hello_timer_.cancel();
    websocket::stream_base::timeout t = websocket::stream_base::timeout::suggested(beast::role_type::server);
    t.handshake_timeout = std::chrono::seconds(1);
    ws_.set_option(t);
    ws_.async_close(close_reason(reason), [self = shared_from_this()](beast::error_code) {});
  }
  // A close frame's reason holds 123 bytes at most.
  static websocket::close_reason close_reason(const std::string& reason) {
    return websocket::close_reason(websocket::close_code::try_again_later,
                                   beast::string_view(reason.data(), std::min<size_t>(reason.size(), 123)));
  }
  void close() {
    if (core_.closed()) return;
    core_.mark_closed();
    hello_timer_.cancel();
    ws_.async_close(websocket::close_code::normal, [self = shared_from_this()](beast::error_code) {});
  }

 private:
  void arm_hello_timer() {
    hello_timer_.expires_after(std::chrono::milliseconds(int64_t(server_->options.hello_timeout_s * 1000)));
    hello_timer_.async_wait([weak = weak_from_this()](beast::error_code ec) {
      auto self = weak.lock();
      if (ec || !self) return;
      self->core_.hello_timed_out();
      self->pump();
    });
  }

  // Inputs coalesced over the rate wait for a token (Session::flush).
  void arm_flush_timer() {
    if (!core_.flush_due() || flush_armed_) return;
    flush_armed_ = true;
    flush_timer_.expires_at(core_.flush_at());
    flush_timer_.async_wait([weak = weak_from_this()](beast::error_code ec) {
      auto self = weak.lock();
      if (ec || !self) return;
      self->flush_armed_ = false;
      self->core_.flush(SessionClock::now());
      self->arm_flush_timer();
      self->pump();
    });
  }

  void read() {
    ws_.async_read(in_, [self = shared_from_this()](beast::error_code ec, size_t) {
      if (ec) {
        self->core_.mark_closed();  // closed, timed out, or too big (Beast sends close code 1009)
        self->hello_timer_.cancel();
        return;
      }
      const auto* data = static_cast<const uint8_t*>(self->in_.data().data());
      self->core_.receive({data, self->in_.size()}, self->ws_.got_binary(), SessionClock::now());
      self->in_.consume(self->in_.size());
      if (self->core_.greeted()) self->hello_timer_.cancel();
      self->arm_flush_timer();
      self->pump();
      if (!self->core_.closed()) self->read();
    });
  }

  // Writes what the rules queued, one message at a time; closes when they say.
  void pump() {
    if (core_.disconnect()) return drop();
    if (const Bytes* message = core_.next_write()) {
      ws_.async_write(asio::buffer(**message), [self = shared_from_this()](beast::error_code ec, size_t) {
        self->core_.written();
        if (ec) return self->core_.mark_closed();
        self->pump();
      });
      return;
    }
    if (core_.idle() && core_.close_after_write()) close();
  }

  std::shared_ptr<Server::Impl> server_;
  websocket::stream<beast::tcp_stream> ws_;
  beast::flat_buffer in_;
  asio::steady_timer hello_timer_;
  asio::steady_timer flush_timer_;
  bool flush_armed_ = false;
  Session core_;
  static inline uint64_t next_id_ = 1;
};

// Serves one accepted connection: static files over HTTP, or the upgrade to
// a WebSocket (http_session.cpp).
void serve_http(std::shared_ptr<Server::Impl> server, tcp::socket socket);

}  // namespace tactile
