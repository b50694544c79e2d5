#include "net/server.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <chrono>
#include <cstring>
#include <ctime>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <thread>
#include <unordered_set>

#include <glm/vector_relational.hpp>

#include <boost/asio.hpp>
#include <boost/asio/posix/stream_descriptor.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>

#include "net/inbound.hpp"
#include "net/mailbox.hpp"
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
using Bytes = std::shared_ptr<const std::vector<uint8_t>>;

namespace {

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

Bytes copy_bytes(const uint8_t* data, size_t n) { return std::make_shared<const std::vector<uint8_t>>(data, data + n); }

template <class T>
Bytes seal(fb::FlatBufferBuilder& b, wire::Message type, fb::Offset<T> body) {
  b.Finish(wire::CreateEnvelope(b, type, body.Union()), wire::EnvelopeIdentifier());
  return copy_bytes(b.GetBufferPointer(), b.GetSize());
}

Bytes make_error(wire::ErrorCode code, const std::string& message, uint32_t request_id = 0) {
  fb::FlatBufferBuilder b;
  const std::string text = utf8_text(message);
  const auto body = wire::CreateError(b, code, b.CreateString(text), request_id);
  return seal(b, wire::Message::Error, body);
}

// A string for a one-line log: control characters shown as '?'.
std::string printable_text(std::string out) {
  for (char& c : out)
    if (uint8_t(c) < 0x20 || c == 0x7f) c = '?';
  return out;
}
std::string printable(const fb::String* s) { return printable_text(s ? s->str() : ""); }

const char* content_type(const std::filesystem::path& p) {
  const std::string ext = p.extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js" || ext == ".mjs") return "text/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  if (ext == ".json") return "application/json";
  if (ext == ".png") return "image/png";
  if (ext == ".svg") return "image/svg+xml";
  if (ext == ".map") return "application/json";
  return "application/octet-stream";
}

// The scenes LoadScene may name: the JSON files of the scene folder (not the schema).
std::vector<std::string> list_scenes(const std::string& dir) {
  std::vector<std::string> names;
  if (dir.empty()) return names;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (entry.is_regular_file() && entry.path().extension() == ".json" && name.find(".schema.") == std::string::npos)
      names.push_back(name);
  }
  std::sort(names.begin(), names.end());
  return names;
}

}  // namespace

class WsSession;

// What a recording takes from the simulation thread: every frame, in rings
// that never overwrite (a full ring drops the new frame and counts it: a
// recording fault). Made when a recording first starts on a feed and kept
// with it, since the simulation thread may be pushing into it.
struct RecordTap {
  FrameRing states, haptics, applied;
  int64_t states_dropped = 0, haptics_dropped = 0, applied_dropped = 0;  // by the rings when the recording started
  RecordTap(size_t state_bytes, size_t haptic_bytes)
      : states(64, state_bytes),         // two seconds of states at 30 Hz
        haptics(16384, haptic_bytes),    // 1.6 s of haptic frames at 10 kHz
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
  std::vector<std::string> devices;   // channels, in the order haptic frames list them
  std::unique_ptr<RecordTap> tap;     // set before `recording` turns true, kept after
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
  // The most a state frame takes: positions and scalar per surface vertex, poses and forces per proxy.
  size_t state_bytes() const {
    return 256 + 20 * 3 * live->frames().surface().nodes.size() + 64 * live->sim().proxies().size();
  }
  size_t haptic_bytes() const { return 512 + 128 * live->sim().proxies().size() + 160 * live->sim().devices().size(); }
};

struct Server::Impl : std::enable_shared_from_this<Server::Impl> {
  asio::io_context& ioc;
  Director* director;  // the live session, or
  Replay* replay;      // a recording played back (one of the two)
  ServerOptions options;
  tcp::acceptor acceptor;
  bool stopped = false;

  // Signalled from the simulation thread after each publication.
  std::shared_ptr<Wakeup> wakeup = std::make_shared<Wakeup>();
  asio::posix::stream_descriptor wake_fd;
  uint64_t wake_value = 0;

  std::shared_ptr<Feed> feed;      // the scene clients are served
  std::shared_ptr<Feed> incoming;  // handed to the director, not yet running
  std::vector<std::string> scene_names;
  bool changing = false;           // a load, reset or parameter change under way
  uint32_t fault_resets = 0;       // resets the server made after a fault (reset_on_fault)
  uint32_t next_scene_id;
  std::thread builder;             // builds the scene a change asks for

  std::unordered_set<WsSession*> sessions;
  WsSession* controller = nullptr;
  asio::steady_timer telemetry_timer;

  asio::steady_timer replay_timer;
  Replay::Clock::time_point replay_status_due{};
  bool replay_started = false;
  void tick_replay();
  Bytes replay_status();
  void serve_replayed(const Replay::Item& item);
  void show_replay_position();  // the scene and state at the position, after a seek
  void replay_control(const wire::Control& c, WsSession& from);

  std::unique_ptr<Recorder> recorder;               // the recording under way
  std::vector<std::unique_ptr<Recorder>> finishing;  // stopped, closing their files

  Impl(asio::io_context& io, Director* d, Replay* r, ServerOptions o)
      : ioc(io),
        director(d),
        replay(r),
        options(std::move(o)),
        acceptor(io),
        wake_fd(io, ::dup(wakeup->fd())),
        scene_names(d ? list_scenes(options.scenes_dir) : std::vector<std::string>{}),
        next_scene_id(d ? d->current()->id() + 1 : 0),
        telemetry_timer(io),
        replay_timer(io) {
    if (d) {
      feed = std::make_shared<Feed>(d->current(), scene_names);
      attach(*feed);
    } else {
      feed = std::make_shared<Feed>(copy_bytes(r->first_scene().bytes.data(), r->first_scene().bytes.size()));
    }
  }
  ~Impl() {
    if (builder.joinable()) builder.join();
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

  enum class Change { Reset, Load, Parameter };
  // A change a controller asked for (c), or the server itself (nullptr: a
  // reset after a fault, ServerOptions::reset_on_fault).
  void change(Change kind, const wire::Control* c);
  void built(std::shared_ptr<LiveScene> live, bool carry);
  void installed(const std::shared_ptr<LiveScene>& live);
  void send_to_controller(const Bytes& message);

  void listen();
  void accept();
  void wait_wakeup();
  void deliver();
  void tick_telemetry();
  Bytes telemetry_message(const std::string& extra_fault);
  bool origin_allowed(const std::string& origin) const;
  bool host_allowed(std::string_view host) const;
  // Room for one more WebSocket from `address`: false when the greeted
  // sessions fill max_connections. Connections that have not said Hello
  // hold waiting slots, max_waiting_per_address per address and
  // max_waiting in all; a new one takes the slot of the oldest waiting one
  // from its own address when that address has its fill, else of the
  // oldest of all when all are taken. So no flood of upgrades that never
  // say Hello keeps a client out who says it at once.
  bool make_room(const std::string& address);
  void close_all();
};

// ---- WebSocket sessions ----------------------------------------------------------------

class WsSession : public std::enable_shared_from_this<WsSession> {
 public:
  WsSession(std::shared_ptr<Server::Impl> server, tcp::socket socket, bool loopback, std::string address)
      : server_(std::move(server)),
        ws_(std::move(socket)),
        hello_timer_(server_->ioc),
        loopback_(loopback),
        address_(std::move(address)) {}

  ~WsSession() {
    server_->sessions.erase(this);
    if (server_->controller == this) server_->controller = nullptr;
    if (safety_dropped_ > 0)
      std::fprintf(stderr, "safety: connection %llu sent %lld events over the limit of %g per second: dropped\n",
                   (unsigned long long)id_, (long long)safety_dropped_, server_->options.max_safety_events_per_s);
    if (events_dropped_ > 0)
      std::fprintf(stderr, "safety: connection %llu (%s) read too slowly and missed %lld safety events\n",
                   (unsigned long long)id_, wire::EnumNameRole(role_), (long long)events_dropped_);
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

  wire::Role role() const { return role_; }
  bool greeted() const { return greeted_; }
  // Upgraded and not yet greeted: it holds a waiting slot (Impl::make_room).
  bool waiting() const { return !greeted_ && !closing_; }
  const std::string& address() const { return address_; }
  uint64_t id() const { return id_; }
  // Closes the socket at once (a waiting slot given to a newer connection):
  // its pending operations end, and with them the session.
  void drop() {
    if (closing_) return;
    closing_ = true;
    hello_timer_.cancel();
    beast::get_lowest_layer(ws_).close();
  }
  // SafetyEvent came in 1.2: a 1.1 codec refuses a message type it does not know.
  bool reads_safety_events() const { return greeted_ && role_ != wire::Role::Device && protocol_minor_ >= 2; }
  // DeviceStatus came in 1.3.
  bool reads_device_status() const { return greeted_ && role_ != wire::Role::Device && protocol_minor_ >= 3; }
  // ReplayStatus in 1.4.
  bool reads_replay_status() const { return greeted_ && protocol_minor_ >= 4; }
  bool drives_devices() const { return greeted_ && role_ == wire::Role::Device; }
  bool drives(const std::string& channel) const {
    return drives_devices() && std::find(device_names_.begin(), device_names_.end(), channel) != device_names_.end();
  }

  // Queues a message; `kind` decides what a slow reader loses: a State is
  // replaced by the next, a Haptic frame, an Event (SafetyEvent) or a Status
  // (DeviceStatus) beyond its bound drops the oldest of its kind waiting
  // (counted), a Control message (replies: Pong, Error, Welcome; Telemetry,
  // ReplayStatus) is never dropped: a reader that lets control_queue of
  // them wait is not reading, and is disconnected.
  enum class Kind { Control, State, Haptic, Event, Status };
  void send(const Bytes& message, Kind kind) {
    if (kind == Kind::Control && role_ == wire::Role::Controller && greeted_ &&
        wire::GetEnvelope(message->data())->message_type() == wire::Message::Error)
      server_->record(Topic::Error, message);
    if (closing_) return;
    if (kind == Kind::State) {
      // Latest wins, at the viewer's rate on average: each state passed sets
      // the next one's due time a period on, and a state a little early (a
      // quarter period: the simulation's publishing jitters) still passes,
      // or states made at exactly the viewer's rate would lose every other one.
      const auto now = std::chrono::steady_clock::now();
      const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
          std::chrono::duration<double>(1.0 / server_->options.viewer_rate_hz));
      if (now + period / 4 < next_state_due_) return;
      if (pending_state_) {
        pending_state_ = message;  // replaces the one not yet sent
        return;
      }
      next_state_due_ = std::max(next_state_due_, now - period) + period;
      pending_state_ = message;
      queue_.push_back(nullptr);  // a marker: the pending state goes here
    } else if (kind == Kind::Haptic || kind == Kind::Event || kind == Kind::Status) {
      // A reader too slow: its oldest waiting message of the kind goes (not
      // the one being written), so what it does read is the newest.
      const bool haptic = kind == Kind::Haptic;
      size_t& queued = haptic ? haptics_queued_ : kind == Kind::Event ? events_queued_ : statuses_queued_;
      if (queued >= (haptic ? server_->options.device_queue : server_->options.event_queue))
        for (size_t k = writing_ ? 1 : 0; k < queue_.size(); ++k)
          if (kinds_[k] == kind) {
            queue_.erase(queue_.begin() + long(k));
            kinds_.erase(kinds_.begin() + long(k));
            --queued;
            ++(haptic ? haptics_dropped_ : events_dropped_);
            break;
          }
      ++queued;
      queue_.push_back(message);
    } else {
      if (controls_queued_ >= server_->options.control_queue) {
        std::fprintf(stderr, "connection %llu (%s, %s) let %zu control messages wait unread: disconnected\n",
                     (unsigned long long)id_, wire::EnumNameRole(role_), address_.c_str(), controls_queued_);
        return drop();
      }
      ++controls_queued_;
      queue_.push_back(message);
    }
    kinds_.push_back(kind);
    write();
  }

  // Sends an error, then closes.
  void refuse(wire::ErrorCode code, const std::string& message) {
    send(make_error(code, message), Kind::Control);
    close_after_write_ = true;
    write();
  }

  void close() {
    if (closing_) return;
    closing_ = true;
    hello_timer_.cancel();
    ws_.async_close(websocket::close_code::normal, [self = shared_from_this()](beast::error_code) {});
  }

 private:
  void arm_hello_timer() {
    hello_timer_.expires_after(std::chrono::milliseconds(int64_t(server_->options.hello_timeout_s * 1000)));
    hello_timer_.async_wait([weak = weak_from_this()](beast::error_code ec) {
      auto self = weak.lock();
      if (ec || !self || self->greeted_) return;
      self->refuse(wire::ErrorCode::BadRequest, "no Hello within the hello timeout");
    });
  }

  void read() {
    ws_.async_read(in_, [self = shared_from_this()](beast::error_code ec, size_t) {
      if (ec) {
        self->closing_ = true;  // closed, timed out, or too big (Beast sends close code 1009)
        self->hello_timer_.cancel();
        return;
      }
      self->on_message();
      if (!self->closing_) self->read();
    });
  }

  void on_message() {
    const auto* data = static_cast<const uint8_t*>(in_.data().data());
    const size_t size = in_.size();
    // Rate limit: a token bucket of max_messages_per_s, a second's burst.
    const auto now = std::chrono::steady_clock::now();
    const double rate = server_->options.max_messages_per_s;
    tokens_ = std::min(rate, tokens_ + rate * std::chrono::duration<double>(now - last_message_).count());
    last_message_ = now;
    if ((tokens_ -= 1) < 0) {
      in_.consume(size);
      return refuse(wire::ErrorCode::RateLimited, "more than " + std::to_string(int64_t(rate)) + " messages per second");
    }
    if (!ws_.got_binary()) {
      in_.consume(size);
      return send(make_error(wire::ErrorCode::Malformed, "text message: the protocol is binary FlatBuffers"),
                  Kind::Control);
    }
    const Inbound inbound = read_inbound(data, size);
    if (!inbound) {
      in_.consume(size);
      return send(make_error(inbound.error, inbound.message), Kind::Control);
    }
    const wire::Envelope* e = inbound.envelope;
    raw_ = {data, size};  // what a recording keeps of an input or a control
    dispatch(*e);
    raw_ = {};
    in_.consume(size);
  }

  void dispatch(const wire::Envelope& e) {
    if (!greeted_ && e.message_type() != wire::Message::Hello && e.message_type() != wire::Message::Ping)
      return refuse(wire::ErrorCode::WrongRole, std::string("the first message must be Hello, got ") +
                                                    wire::EnumNameMessage(e.message_type()));
    switch (e.message_type()) {
      case wire::Message::Hello: return on_hello(*e.message_as_Hello());
      case wire::Message::Ping: return on_ping(*e.message_as_Ping());
      case wire::Message::DeviceInput: return on_input(*e.message_as_DeviceInput());
      case wire::Message::Control: return on_control(*e.message_as_Control());
      case wire::Message::SafetyEvent: return on_safety_event(*e.message_as_SafetyEvent());
      case wire::Message::DeviceStatus: return on_device_status(*e.message_as_DeviceStatus());
      default:
        return send(make_error(wire::ErrorCode::WrongRole, std::string("a client may not send ") +
                                                               wire::EnumNameMessage(e.message_type())),
                    Kind::Control);
    }
  }

  void on_hello(const wire::Hello& h) {
    if (greeted_) return send(make_error(wire::ErrorCode::BadRequest, "Hello sent twice"), Kind::Control);
    const int major = int(wire::ProtocolMajor::Current), minor = int(wire::ProtocolMinor::Current);
    if (h.protocol_major() != major)
      return refuse(wire::ErrorCode::VersionMismatch,
                    "client speaks protocol " + std::to_string(h.protocol_major()) + "." +
                        std::to_string(h.protocol_minor()) + ", this server " + std::to_string(major) + "." +
                        std::to_string(minor));
    if (h.role() > wire::Role::MAX)
      return refuse(wire::ErrorCode::BadRequest, "Hello.role " + std::to_string(int(h.role())) +
                                                     " is not a role (0 viewer, 1 device, 2 controller)");
    const std::string token = h.token() ? h.token()->str() : "";
    const bool needs_token = h.role() != wire::Role::Viewer || !loopback_;
    if (needs_token && (server_->options.token.empty() || token != server_->options.token))
      return refuse(wire::ErrorCode::Unauthorized,
                    std::string(server_->options.token.empty() ? "this server has no token set: the "
                                                               : "a wrong or missing token for the ") +
                        wire::EnumNameRole(h.role()) + " role" + (loopback_ ? "" : " (off loopback every role needs it)"));
    if (h.role() == wire::Role::Controller) {
      if (server_->controller) return refuse(wire::ErrorCode::Busy, "another controller is connected");
      server_->controller = this;
    }
    if (h.role() == wire::Role::Device) {
      if (const std::string bad = check_device_limits(h); !bad.empty()) return refuse(wire::ErrorCode::BadRequest, bad);
      const std::vector<std::string>& names = server_->feed->devices;
      if (h.devices())
        for (const fb::String* d : *h.devices()) {
          if (std::find(names.begin(), names.end(), d->str()) == names.end())
            return refuse(wire::ErrorCode::BadRequest, "no device channel '" + d->str() + "' in this scene");
          // One device drives a channel: two would pull its proxy both ways.
          for (const WsSession* other : server_->sessions)
            if (other != this && other->drives(d->str()))
              return refuse(wire::ErrorCode::Busy, "device channel '" + d->str() + "' is driven by another device "
                                                   "(connection " + std::to_string(other->id_) + ")");
          device_names_.push_back(d->str());
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
      bind_devices();
    }
    greeted_ = true;
    role_ = h.role();
    protocol_minor_ = h.protocol_minor();
    hello_timer_.cancel();
    fb::FlatBufferBuilder b;
    send(seal(b, wire::Message::Welcome,
              wire::CreateWelcomeDirect(b, uint16_t(major), uint16_t(minor), role_,
                                        server_->options.server_name.c_str(), id_, now_ns())),
         Kind::Control);
    send(server_->feed->description, Kind::Control);
    if (server_->replay && !server_->replay_started) {  // the first client starts the playback
      server_->replay_started = true;
      server_->replay->play(Replay::Clock::now());
      server_->replay_status_due = Replay::Clock::now();
      server_->replay_timer.cancel();
      server_->tick_replay();
    }
    if (server_->replay) {  // where the replay is: the body as it was there, and the playback
      if (const Replay::Item* st = server_->replay->state_before(); st && role_ != wire::Role::Device)
        send(copy_bytes(st->bytes.data(), st->bytes.size()), Kind::State);
      if (reads_replay_status()) send(server_->replay_status(), Kind::Control);
    }
  }

  // The current scene's channel index for each channel this device named
  // (-1 for one the scene lacks: its inputs are dropped, said once here).
  void bind_devices() {
    const std::vector<std::string>& names = server_->feed->devices;
    devices_.clear();
    for (const std::string& d : device_names_) {
      const auto it = std::find(names.begin(), names.end(), d);
      devices_.push_back(it == names.end() ? -1 : int32_t(it - names.begin()));
      if (it == names.end())
        send(make_error(wire::ErrorCode::BadRequest, "scene '" + server_->feed->scene_name +
                                                         "' has no device channel '" + d +
                                                         "': its inputs are dropped until a scene has it"),
             Kind::Control);
    }
  }

  void on_ping(const wire::Ping& p) {
    const int64_t received = now_ns();
    fb::FlatBufferBuilder b;
    send(seal(b, wire::Message::Pong, wire::CreatePong(b, p.id(), p.client_time_ns(), received, now_ns())),
         Kind::Control);
  }

  void on_input(const wire::DeviceInput& in) {
    if (role_ != wire::Role::Device)
      return send(make_error(wire::ErrorCode::WrongRole, "DeviceInput needs the device role"), Kind::Control);
    const std::string name = in.device() ? in.device()->str() : "";
    const auto named = std::find(device_names_.begin(), device_names_.end(), name);
    if (named == device_names_.end())
      return send(make_error(wire::ErrorCode::BadRequest, "DeviceInput for channel '" + name +
                                                              "', which this connection did not name in its Hello"),
                  Kind::Control);
    const int32_t index = devices_[size_t(named - device_names_.begin())];
    if (index < 0) return;  // not in this scene (said at the switch)
    if (const std::string bad = check_device_input(in); !bad.empty())
      return send(make_error(wire::ErrorCode::BadRequest, bad), Kind::Control);
    const size_t k = size_t(named - device_names_.begin());
    if (server_->feed->live) {  // outside the workspace: the loop holds it at the edge; said once per excursion
      const RealtimeLoop& loop = server_->feed->live->loop();
      const Vec3 x(in.position()->x(), in.position()->y(), in.position()->z());
      const bool outside = glm::any(glm::lessThan(x, loop.workspace_lo())) ||
                           glm::any(glm::greaterThan(x, loop.workspace_hi()));
      if (outside && !outside_[k]) {
        char text[320];
        const Vec3 lo = loop.workspace_lo(), hi = loop.workspace_hi();
        std::snprintf(text, sizeof text,
                      "DeviceInput.position (%.4g, %.4g, %.4g) m for channel '%s' is outside the scene's workspace "
                      "[%.3g, %.3g] x [%.3g, %.3g] x [%.3g, %.3g] m: its proxy is held at the edge",
                      x.x, x.y, x.z, utf8_text(name).c_str(), lo.x, hi.x, lo.y, hi.y, lo.z, hi.z);
        send(make_error(wire::ErrorCode::BadRequest, text), Kind::Control);
      }
      outside_[k] = outside;
    }
    const DeviceSample s = device_sample(in, index, drives_[k]);
    // Recorded first: stamped before the simulation can apply it.
    server_->record(Topic::Input, raw_.data(), raw_.size(), now_ns());
    // (A replay simulates nothing: its inputs move nothing.)
    if (server_->feed->live) server_->feed->live->loop().post_input(s);  // a full queue drops it and counts
  }

  // A device's safety event: checked, rate limited, stamped with the server
  // clock, logged, and relayed to every viewer and controller (of protocol
  // 1.2 or later: see reads_safety_events).
  void on_safety_event(const wire::SafetyEvent& ev) {
    if (role_ != wire::Role::Device)
      return send(make_error(wire::ErrorCode::WrongRole,
                             std::string("SafetyEvent needs the Device role; this connection has the ") +
                                 wire::EnumNameRole(role_) + " role"),
                  Kind::Control);
    if (const std::string bad = check_safety_event(ev); !bad.empty())
      return send(make_error(wire::ErrorCode::BadRequest, bad), Kind::Control);
    const std::string name = ev.device()->str();  // UTF-8 and bounded: checked
    if (std::find(device_names_.begin(), device_names_.end(), name) == device_names_.end())
      return send(make_error(wire::ErrorCode::BadRequest, "SafetyEvent for channel '" + name +
                                                              "', which this connection did not name in its Hello"),
                  Kind::Control);
    // A token bucket of max_safety_events_per_s, a second's burst; beyond it
    // events are dropped and counted, and the device is told once per run of drops.
    const auto now = std::chrono::steady_clock::now();
    const double rate = server_->options.max_safety_events_per_s;
    safety_tokens_ = std::min(rate, safety_tokens_ + rate * std::chrono::duration<double>(now - last_safety_).count());
    last_safety_ = now;
    if (safety_tokens_ < 1) {
      ++safety_dropped_;
      if (!safety_limited_)
        send(make_error(wire::ErrorCode::RateLimited, "more than " + std::to_string(int64_t(rate)) +
                                                          " safety events per second: dropped, not relayed (" +
                                                          std::to_string(safety_dropped_) + " so far)"),
             Kind::Control);
      safety_limited_ = true;
      return;
    }
    safety_tokens_ -= 1;
    safety_limited_ = false;
    fb::FlatBufferBuilder b(128 + name.size() + (ev.message() ? ev.message()->size() : 0));
    const auto device = b.CreateString(ev.device());
    const auto message = b.CreateString(ev.message());
    const Bytes relayed = seal(b, wire::Message::SafetyEvent,
                               wire::CreateSafetyEvent(b, device, ev.device_time_ns(), now_ns(), ev.kind(), message,
                                                       ev.force_N()));
    std::fprintf(stderr, "safety: %s %s %s (%.3f N)\n", printable(ev.device()).c_str(),
                 wire::EnumNameSafetyKind(ev.kind()), printable(ev.message()).c_str(), double(ev.force_N()));
    for (WsSession* s : server_->sessions)
      if (s->reads_safety_events()) s->send(relayed, Kind::Event);
    server_->record(Topic::Safety, relayed);
  }

  // A device's status (how its loop keeps time): checked, at most a few a
  // second per connection (more are dropped: it is a figure, not an event),
  // stamped with the server clock and relayed to every viewer and controller
  // of protocol 1.3 or later.
  void on_device_status(const wire::DeviceStatus& st) {
    if (role_ != wire::Role::Device)
      return send(make_error(wire::ErrorCode::WrongRole,
                             std::string("DeviceStatus needs the Device role; this connection has the ") +
                                 wire::EnumNameRole(role_) + " role"),
                  Kind::Control);
    if (const std::string bad = check_device_status(st); !bad.empty())
      return send(make_error(wire::ErrorCode::BadRequest, bad), Kind::Control);
    const std::string name = st.device()->str();
    if (std::find(device_names_.begin(), device_names_.end(), name) == device_names_.end())
      return send(make_error(wire::ErrorCode::BadRequest, "DeviceStatus for channel '" + name +
                                                              "', which this connection did not name in its Hello"),
                  Kind::Control);
    const auto now = std::chrono::steady_clock::now();
    constexpr double kRate = 10;  // per second, a second's burst
    status_tokens_ = std::min(kRate, status_tokens_ + kRate * std::chrono::duration<double>(now - last_status_).count());
    last_status_ = now;
    if (status_tokens_ < 1) return;
    status_tokens_ -= 1;
    fb::FlatBufferBuilder b(256 + name.size());
    const auto device = b.CreateString(st.device());
    const auto mode = b.CreateString(st.mode());
    const Bytes relayed =
        seal(b, wire::Message::DeviceStatus,
             wire::CreateDeviceStatus(b, device, st.device_time_ns(), now_ns(), st.tick_rate_hz(), st.lateness_p99_us(),
                                      st.lateness_max_us(), st.missed_ticks(), st.display_delay_ms(),
                                      st.state_interval_ms(), st.jitter_allowance_ms(), mode, st.force_N()));
    for (WsSession* s : server_->sessions)
      if (s->reads_device_status()) s->send(relayed, Kind::Status);
    server_->record(Topic::DeviceStatus, relayed);
  }

  void on_control(const wire::Control& c) {
    if (role_ != wire::Role::Controller)
      return send(make_error(wire::ErrorCode::WrongRole, "Control needs the controller role", c.request_id()),
                  Kind::Control);
    server_->record(Topic::Control, raw_.data(), raw_.size(), now_ns());
    if (server_->replay) return server_->replay_control(c, *this);
    switch (c.command_type()) {
      // A pause sent while a change is under way is carried over to the new scene.
      case wire::ControlCommand::Pause: return server_->director->current()->loop().set_paused(true);
      case wire::ControlCommand::Resume: return server_->director->current()->loop().set_paused(false);
      case wire::ControlCommand::Reset: return server_->change(Server::Impl::Change::Reset, &c);
      case wire::ControlCommand::LoadScene: return server_->change(Server::Impl::Change::Load, &c);
      case wire::ControlCommand::SetParameter: return server_->change(Server::Impl::Change::Parameter, &c);
      case wire::ControlCommand::StartRecording: {
        const wire::StartRecording* r = c.command_as_StartRecording();
        if (const std::string bad = server_->start_recording(r && r->path() ? r->path()->str() : ""); !bad.empty())
          return send(make_error(bad.starts_with("a recording") ? wire::ErrorCode::Busy : wire::ErrorCode::BadRequest,
                                 bad, c.request_id()),
                      Kind::Control);
        return;
      }
      case wire::ControlCommand::StopRecording:
        if (!server_->recorder)
          return send(make_error(wire::ErrorCode::BadRequest, "StopRecording: no recording is under way",
                                 c.request_id()),
                      Kind::Control);
        return server_->stop_recording();
      default:
        return send(make_error(wire::ErrorCode::BadRequest,
                               std::string("control command ") + wire::EnumNameControlCommand(c.command_type()) +
                                   " is for a server replaying a recording; this one runs a live scene",
                               c.request_id()),
                    Kind::Control);
    }
  }

  void write() {
    if (writing_ || queue_.empty()) {
      if (!writing_ && queue_.empty() && close_after_write_) close();
      return;
    }
    writing_ = true;
    Bytes message = queue_.front() ? queue_.front() : pending_state_;
    if (!queue_.front()) pending_state_.reset();
    current_ = message;
    ws_.async_write(asio::buffer(*current_), [self = shared_from_this()](beast::error_code ec, size_t) {
      self->writing_ = false;
      if (self->kinds_.front() == Kind::Haptic) --self->haptics_queued_;
      if (self->kinds_.front() == Kind::Event) --self->events_queued_;
      if (self->kinds_.front() == Kind::Status) --self->statuses_queued_;
      if (self->kinds_.front() == Kind::Control) --self->controls_queued_;
      self->queue_.pop_front();
      self->kinds_.pop_front();
      self->current_.reset();
      if (ec) {
        self->closing_ = true;
        return;
      }
      self->write();
    });
  }

  std::shared_ptr<Server::Impl> server_;
  websocket::stream<beast::tcp_stream> ws_;
  beast::flat_buffer in_;
  asio::steady_timer hello_timer_;
  bool loopback_;
  std::string address_;  // the peer's IP address
  bool greeted_ = false, closing_ = false, writing_ = false, close_after_write_ = false;
  wire::Role role_ = wire::Role::Viewer;
  uint16_t protocol_minor_ = 0;            // the client's, from its Hello
  std::vector<std::string> device_names_;  // channels named in Hello
  std::vector<DeviceDrive> drives_;        // how each drives its channel (Hello.device_limits)
  std::vector<int32_t> devices_;           // their index in the current scene, -1 if absent
  std::vector<bool> outside_;              // each one's latest input was outside the workspace
  std::span<const uint8_t> raw_;           // the message being dispatched
  std::deque<Bytes> queue_;          // null entries stand for pending_state_
  std::deque<Kind> kinds_;          // per queue entry
  Bytes pending_state_, current_;
  size_t haptics_queued_ = 0, events_queued_ = 0, statuses_queued_ = 0, controls_queued_ = 0;
  int64_t haptics_dropped_ = 0, events_dropped_ = 0;  // (events: safety events relayed to this reader)
  std::chrono::steady_clock::time_point next_state_due_{}, last_message_ = std::chrono::steady_clock::now();
  double tokens_ = 1e18;  // clamped to the burst at the first message
  // Safety events this device sent: their own bucket, and those dropped over it.
  std::chrono::steady_clock::time_point last_safety_ = std::chrono::steady_clock::now();
  double safety_tokens_ = 1e18;
  std::chrono::steady_clock::time_point last_status_ = std::chrono::steady_clock::now();
  double status_tokens_ = 1e18;  // (clamped to the burst at the first status)
  bool safety_limited_ = false;
  int64_t safety_dropped_ = 0;
  uint64_t id_ = next_id_++;
  static inline uint64_t next_id_ = 1;

  friend struct Server::Impl;
};

// ---- HTTP: static files, or the upgrade to a WebSocket -------------------------------------

class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(std::shared_ptr<Server::Impl> server, tcp::socket socket)
      : server_(std::move(server)), stream_(std::move(socket)) {}

  void start() {
    parser_.emplace();
    parser_->header_limit(16 * 1024);
    parser_->body_limit(16 * 1024);
    stream_.expires_after(std::chrono::seconds(10));
    http::async_read(stream_, buffer_, *parser_, [self = shared_from_this()](beast::error_code ec, size_t) {
      if (ec) return;  // closed, timed out or malformed: nothing to answer
      self->on_request(self->parser_->release());
    });
  }

 private:
  void on_request(http::request<http::string_body> req) {
    if (websocket::is_upgrade(req)) {
      const std::string origin(req[http::field::origin]);
      if (!origin.empty() && !server_->origin_allowed(origin))
        return respond(req, http::status::forbidden, "Origin '" + origin + "' is not allowed to connect\n");
      beast::error_code ec;
      const asio::ip::address peer = stream_.socket().remote_endpoint(ec).address();
      if (ec) return;  // gone already
      if (!server_->make_room(peer.to_string()))
        return respond(req, http::status::service_unavailable, "too many connections\n");
      auto session = std::make_shared<WsSession>(server_, stream_.release_socket(), peer.is_loopback(), peer.to_string());
      session->start(std::move(req));
      return;
    }
    // Files and recordings only to pages that name this server: a page of
    // another site whose name was made to resolve here (DNS rebinding) sends
    // its own name as Host. (An upgrade is guarded by its Origin and token.)
    const std::string host(req[http::field::host]);
    if (!server_->host_allowed(host))
      return respond(req, http::status::misdirected_request,
                     "Host '" + utf8_text(host) + "' is not a name of this server: loopback names, the bound "
                     "address, or a host of --allow-origin\n");
    if (req.method() != http::verb::get && req.method() != http::verb::head)
      return respond(req, http::status::method_not_allowed, "only GET and HEAD\n");
    const std::string full(req.target());
    if (full.starts_with("/recordings/")) return serve_recording(req, full.substr(12, full.find('?') - 12));
    if (server_->options.static_dir.empty())
      return respond(req, http::status::not_found, "this server serves no files (no static folder set)\n");
    std::string target(req.target().substr(0, req.target().find('?')));
    if (target.empty() || target[0] != '/' || target.find("..") != std::string::npos)
      return respond(req, http::status::bad_request, "bad path\n");
    if (target.back() == '/') target += "index.html";
    const std::filesystem::path path = std::filesystem::path(server_->options.static_dir) / target.substr(1);
    std::ifstream in(path, std::ios::binary);
    if (!in || std::filesystem::is_directory(path)) return respond(req, http::status::not_found, "not found\n");
    std::string body((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    respond(req, http::status::ok, std::move(body), content_type(path));
  }

  // The recordings folder: "/recordings/" lists its MCAP files (JSON: name,
  // bytes), "/recordings/NAME" downloads one (Foxglove opens it).
  void serve_recording(const http::request<http::string_body>& req, const std::string& name) {
    const std::string& dir = server_->options.recordings_dir;
    if (dir.empty()) return respond(req, http::status::not_found, "this server keeps no recordings (--recordings)\n");
    // A recording holds a whole session: off loopback, only with the token (?token=...), as every role needs.
    beast::error_code peer_ec;
    const bool loopback = stream_.socket().remote_endpoint(peer_ec).address().is_loopback() && !peer_ec;
    if (!loopback) {
      const std::string target(req.target());
      const size_t q = target.find("token=");
      const std::string given = q == std::string::npos ? "" : target.substr(q + 6, target.find('&', q) - q - 6);
      if (server_->options.token.empty() || given != server_->options.token)
        return respond(req, http::status::unauthorized, "recordings need the token off loopback (?token=...)\n");
    }
    std::error_code ec;
    if (name.empty()) {
      std::vector<std::pair<std::string, uintmax_t>> files;
      for (const auto& entry : std::filesystem::directory_iterator(dir, ec))
        if (entry.is_regular_file() && entry.path().extension() == ".mcap")
          files.emplace_back(entry.path().filename().string(), entry.file_size(ec));
      std::sort(files.begin(), files.end());
      std::string body = "[";
      for (const auto& [n, size] : files)
        body += std::string(body.size() > 1 ? "," : "") + "{\"name\":\"" + n + "\",\"bytes\":" + std::to_string(size) + "}";
      return respond(req, http::status::ok, body + "]\n", "application/json");
    }
    const bool plain = name[0] != '.' && std::all_of(name.begin(), name.end(), [](char ch) {
      return std::isalnum(static_cast<unsigned char>(ch)) || ch == '.' || ch == '_' || ch == '-';
    });
    if (!plain || !name.ends_with(".mcap")) return respond(req, http::status::bad_request, "not a recording's name\n");
    std::ifstream in(std::filesystem::path(dir) / name, std::ios::binary);
    if (!in) return respond(req, http::status::not_found, "no recording '" + name + "'\n");
    std::string body((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    respond(req, http::status::ok, std::move(body), "application/octet-stream");
  }

  void respond(const http::request<http::string_body>& req, http::status status, std::string body,
               const char* type = "text/plain; charset=utf-8") {
    auto res = std::make_shared<http::response<http::string_body>>(status, req.version());
    res->set(http::field::server, server_->options.server_name);
    res->set(http::field::content_type, type);
    res->set(http::field::cache_control, "no-cache");
    res->keep_alive(false);
    if (req.method() != http::verb::head) res->body() = std::move(body);
    res->prepare_payload();
    http::async_write(stream_, *res, [self = shared_from_this(), res](beast::error_code, size_t) {
      beast::error_code ignored;
      self->stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    });
  }

  std::shared_ptr<Server::Impl> server_;
  beast::tcp_stream stream_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
};

// ---- the server ------------------------------------------------------------------------------

bool Server::Impl::make_room(const std::string& address) {
  size_t greeted = 0, waiting = 0, waiting_here = 0;
  WsSession *oldest = nullptr, *oldest_here = nullptr;
  for (WsSession* s : sessions) {
    if (s->greeted() && !s->closing_) ++greeted;
    if (!s->waiting()) continue;
    ++waiting;
    if (!oldest || s->id() < oldest->id()) oldest = s;
    if (s->address() != address) continue;
    ++waiting_here;
    if (!oldest_here || s->id() < oldest_here->id()) oldest_here = s;
  }
  if (greeted >= options.max_connections) return false;
  if (waiting_here >= options.max_waiting_per_address) oldest_here->drop();
  else if (waiting >= options.max_waiting) oldest->drop();
  return true;
}

bool Server::Impl::host_allowed(std::string_view host) const {
  // The name without its port ("[::1]:8765", "localhost:8765", "example.org").
  std::string_view name = host;
  if (name.starts_with('[')) name = name.substr(0, name.find(']') + 1);
  else if (const size_t colon = name.rfind(':'); colon != std::string_view::npos) name = name.substr(0, colon);
  std::string lower(name);
  for (char& c : lower) c = char(std::tolower(uint8_t(c)));
  if (lower.empty()) return false;
  for (const char* loopback : {"127.0.0.1", "localhost", "[::1]"})
    if (lower == loopback) return true;
  if (lower == options.bind) return true;
  for (const std::string& origin : options.allowed_origins) {  // "scheme://name[:port]"
    std::string_view o = origin;
    if (const size_t scheme = o.find("://"); scheme != std::string_view::npos) o = o.substr(scheme + 3);
    if (o.starts_with('[')) o = o.substr(0, o.find(']') + 1);
    else o = o.substr(0, o.find(':'));
    std::string allowed(o);
    for (char& c : allowed) c = char(std::tolower(uint8_t(c)));
    if (allowed == lower) return true;
  }
  return false;
}

bool Server::Impl::origin_allowed(const std::string& origin) const {
  const uint16_t port = acceptor.local_endpoint().port();
  for (const char* host : {"127.0.0.1", "localhost", "[::1]"})
    if (origin == "http://" + std::string(host) + ":" + std::to_string(port)) return true;
  return std::find(options.allowed_origins.begin(), options.allowed_origins.end(), origin) !=
         options.allowed_origins.end();
}

void Server::Impl::listen() {
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
  if (ec) throw ServerError("cannot listen on " + options.bind + ":" + std::to_string(options.port) + ": " + ec.message());
  acceptor.listen(asio::socket_base::max_listen_connections);
}

void Server::Impl::accept() {
  acceptor.async_accept([self = shared_from_this()](beast::error_code ec, tcp::socket socket) {
    if (self->stopped) return;
    if (!ec) std::make_shared<HttpSession>(self, std::move(socket))->start();
    self->accept();
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
    if (!s->greeted()) continue;
    (s->role() == wire::Role::Device ? devices : viewers).push_back(s);
  }
  feed->haptics.drain([&](const uint8_t* data, size_t n) {
    if (devices.empty()) return;
    const Bytes frame = copy_bytes(data, n);
    for (WsSession* s : devices) s->send(frame, WsSession::Kind::Haptic);
  });
  if (const std::vector<uint8_t>* state = feed->states.take()) {
    const Bytes frame = copy_bytes(state->data(), state->size());
    for (WsSession* s : sessions)
      if (s->greeted()) s->send(frame, WsSession::Kind::State);
  }
}

// ---- replay: a recording served as the live session was ------------------------------------

void Server::Impl::tick_replay() {
  const auto now = Replay::Clock::now();
  replay->due(now, [&](const Replay::Item& item) { serve_replayed(item); });
  if (now >= replay_status_due) {
    const Bytes status = replay_status();
    for (WsSession* s : sessions)
      if (s->reads_replay_status()) s->send(status, WsSession::Kind::Control);
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
        if (!s->greeted()) continue;
        s->send(m, WsSession::Kind::Control);
        if (s->role() == wire::Role::Device) s->bind_devices();
      }
      return;
    case Topic::State:
      for (WsSession* s : sessions)
        if (s->greeted() && s->role() != wire::Role::Device) s->send(m, WsSession::Kind::State);
      return;
    case Topic::Haptic:  // a bridge plays the recorded forces to its device, under its safety rules
      for (WsSession* s : sessions)
        if (s->drives_devices()) s->send(m, WsSession::Kind::Haptic);
      return;
    case Topic::Telemetry:
      for (WsSession* s : sessions)
        if (s->greeted()) s->send(m, WsSession::Kind::Control);
      return;
    case Topic::Safety:
      for (WsSession* s : sessions)
        if (s->reads_safety_events()) s->send(m, WsSession::Kind::Event);
      return;
    case Topic::DeviceStatus:
      for (WsSession* s : sessions)
        if (s->reads_device_status()) s->send(m, WsSession::Kind::Status);
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
  return seal(b, wire::Message::ReplayStatus,
              wire::CreateReplayStatusDirect(b, std::filesystem::path(replay->path()).filename().string().c_str(),
                                             replay->duration(), replay->position(now), replay->speed(),
                                             replay->paused()));
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
                         WsSession::Kind::Control);
      replay->seek(t, now);
      show_replay_position();
      break;
    }
    case wire::ControlCommand::SetSpeed:
      try {
        replay->set_speed(c.command_as_SetSpeed() ? c.command_as_SetSpeed()->speed() : 0, now);
      } catch (const std::invalid_argument& e) {
        return from.send(make_error(wire::ErrorCode::BadRequest, std::string("SetSpeed: ") + e.what(), c.request_id()),
                         WsSession::Kind::Control);
      }
      break;
    default:
      return from.send(make_error(wire::ErrorCode::BadRequest,
                                  std::string(wire::EnumNameControlCommand(c.command_type())) +
                                      " needs a live session; this server replays the recording '" +
                                      std::filesystem::path(replay->path()).filename().string() + "'",
                                  c.request_id()),
                       WsSession::Kind::Control);
  }
  // The change, to everyone at once (and the timer re-armed for the new pace).
  replay_status_due = now;
  replay_timer.cancel();
  tick_replay();
}

// ---- recording ---------------------------------------------------------------------------

void Server::Impl::record(Topic topic, const uint8_t* data, size_t n, int64_t time_ns) {
  if (recorder) recorder->post(topic, time_ns, 0, {data, n});
}

void Server::Impl::tap_feed(Feed& f) {
  if (!f.tap) f.tap = std::make_unique<RecordTap>(f.state_bytes(), f.haptic_bytes());
  // Frames left from an earlier recording's last moments are not this one's.
  f.tap->states.drain([](const uint8_t*, size_t) {});
  f.tap->haptics.drain([](const uint8_t*, size_t) {});
  f.tap->applied.drain([](const uint8_t*, size_t) {});
  f.tap->states_dropped = f.tap->states.dropped();
  f.tap->haptics_dropped = f.tap->haptics.dropped();
  f.tap->applied_dropped = f.tap->applied.dropped();
  f.recording.store(true, std::memory_order_release);
}

// Every frame the simulation published since the last drain, stamped with
// its own server time.
void Server::Impl::drain_tap(Feed& f) {
  if (!recorder || !f.tap) return;
  f.tap->haptics.drain([&](const uint8_t* data, size_t n) {
    record(Topic::Haptic, data, n, wire::GetEnvelope(data)->message_as_HapticFrame()->server_time_ns());
  });
  f.tap->states.drain([&](const uint8_t* data, size_t n) {
    record(Topic::State, data, n, wire::GetEnvelope(data)->message_as_StateFrame()->server_time_ns());
  });
  const int64_t now = now_ns();
  f.tap->applied.drain([&](const uint8_t* data, size_t) {
    AppliedInput a;
    std::memcpy(&a, data, sizeof a);
    char json[256];
    const int n = format_applied(a, json, sizeof json);
    record(Topic::Applied, reinterpret_cast<const uint8_t*>(json), size_t(n), now);
  });
  const int64_t lost_h = f.tap->haptics.dropped() - f.tap->haptics_dropped;
  const int64_t lost_s = f.tap->states.dropped() - f.tap->states_dropped;
  const int64_t lost_a = f.tap->applied.dropped() - f.tap->applied_dropped;
  if (lost_h > 0 || lost_s > 0 || lost_a > 0)
    recorder->fail("the simulation published frames faster than the recording took them (" +
                   std::to_string(lost_h) + " haptic and " + std::to_string(lost_s) + " state frames, " +
                   std::to_string(lost_a) + " applied inputs had no room): stopped, what was written stays readable");
}

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

std::string Server::Impl::start_recording(const std::string& name, bool any_path) {
  if (recorder) return "a recording is under way ('" + recorder->path() + "'): stop it first";
  std::string path = name;
  if (!any_path) {
    if (options.recordings_dir.empty())
      return "StartRecording: this server has no recordings folder (start it with --recordings DIR)";
    std::string file = name;
    if (file.empty()) {
      const std::time_t t = std::time(nullptr);
      char stamp[32];
      std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", std::gmtime(&t));
      file = std::string("session-") + stamp + ".mcap";
    }
    const bool plain = file.size() <= 128 && file[0] != '.' &&
                       std::all_of(file.begin(), file.end(), [](char ch) {
                         return std::isalnum(static_cast<unsigned char>(ch)) || ch == '.' || ch == '_' || ch == '-';
                       });
    if (!plain)
      return "StartRecording: '" + printable_text(file) +
             "' is not a plain file name (letters, digits, '.', '_', '-'; not starting with '.'; at most 128)";
    if (!file.ends_with(".mcap")) file += ".mcap";
    std::error_code ec;
    std::filesystem::create_directories(options.recordings_dir, ec);
    path = (std::filesystem::path(options.recordings_dir) / file).string();
    if (std::filesystem::exists(path, ec))
      return "StartRecording: '" + file + "' is already in the recordings folder: pick another name";
  }
  const Scene& scene = feed->live->scene();
  mcap::Map meta{{"scene_name", scene.name},
                 {"scene_path", scene.path},
                 {"scene_file", read_text(scene.path)},
                 {"variant", scene.variant},
                 {"scene_id", std::to_string(feed->live->id())},
                 {"dt", exact(feed->live->loop().dt())},
                 {"state_rate_hz", exact(options.live.state_rate_hz)},
                 {"haptic_rate_hz", exact(options.live.haptic_rate_hz)},
                 {"force_window", exact(options.live.force_window)},
                 {"server", options.server_name}};
  try {
    recorder = std::make_unique<Recorder>(path, meta);
  } catch (const mcap::McapError& e) {
    return std::string("StartRecording: ") + e.what();
  }
  std::fprintf(stderr, "recording: %s\n", path.c_str());
  record(Topic::Scene, feed->description);
  tap_feed(*feed);
  if (incoming) tap_feed(*incoming);
  const Bytes t = telemetry_message("");
  for (WsSession* s : sessions)
    if (s->greeted()) s->send(t, WsSession::Kind::Control);
  return "";
}

void Server::Impl::stop_recording() {
  if (!recorder) return;
  for (Feed* f : {feed.get(), incoming.get()}) {
    if (!f) continue;
    f->recording.store(false, std::memory_order_release);
    drain_tap(*f);
  }
  recorder->stop();
  const RecorderStats st = recorder->stats();
  std::fprintf(stderr, "recording: stopped %s\n", st.path.c_str());
  finishing.push_back(std::move(recorder));
  const Bytes t = telemetry_message("");
  for (WsSession* s : sessions)
    if (s->greeted()) s->send(t, WsSession::Kind::Control);
}

std::string Server::Impl::check_recorder() {
  std::erase_if(finishing, [](const std::unique_ptr<Recorder>& r) {
    const RecorderStats st = r->stats();
    if (!st.finished) return false;
    r->wait();
    std::fprintf(stderr, "recording: closed %s: %llu messages, %llu bytes", st.path.c_str(),
                 static_cast<unsigned long long>(st.messages), static_cast<unsigned long long>(st.bytes));
    if (st.late > 0)
      std::fprintf(stderr, "; %llu came after a later-stamped one and carry its log time",
                   static_cast<unsigned long long>(st.late));
    if (st.unreadable > 0)
      std::fprintf(stderr, "; %llu did not verify as Envelopes and are left out",
                   static_cast<unsigned long long>(st.unreadable));
    std::fprintf(stderr, "\n");
    return true;
  });
  if (!recorder) return "";
  const std::string fault = recorder->stats().fault;
  if (fault.empty()) return "";
  std::fprintf(stderr, "recording: %s: %s\n", recorder->path().c_str(), fault.c_str());
  stop_recording();
  return "recording: " + fault;
}

Bytes Server::Impl::telemetry_message(const std::string& extra_fault) {
  const RealtimeLoop& loop = feed->live->loop();
  const RealtimeStats st = loop.stats();
  uint32_t viewers = 0, devices = 0, controllers = 0;
  for (WsSession* s : sessions) {
    if (!s->greeted()) continue;
    if (s->role() == wire::Role::Viewer) ++viewers;
    else if (s->role() == wire::Role::Device) ++devices;
    else ++controllers;
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
                                          uint64_t(st.missed_deadlines), &costs, viewers, devices, controllers,
                                          &faults, loop.paused(),
                                          std::filesystem::path(rec.path).filename().string().c_str(), rec.messages,
                                          rec.bytes, fault_resets));
}

void Server::Impl::tick_telemetry() {
  telemetry_timer.expires_after(std::chrono::seconds(1));
  telemetry_timer.async_wait([self = shared_from_this()](beast::error_code ec) {
    if (ec || self->stopped) return;
    const Bytes t = self->telemetry_message(self->check_recorder());
    for (WsSession* s : self->sessions)
      if (s->greeted()) s->send(t, WsSession::Kind::Control);
    self->record(Topic::Telemetry, t);
    // Once a telemetry has told every client (and the recording) the
    // fault's cause, the scene starts again from rest, as a controller's
    // Reset would start it; the bridges re-engage through their soft start.
    if (self->options.reset_on_fault && self->director && !self->changing && !self->director->fault().empty()) {
      ++self->fault_resets;
      std::fprintf(stderr, "tactile-server: resetting the scene after the fault (--on-fault reset; %u so far)\n",
                   self->fault_resets);
      self->change(Change::Reset, nullptr);
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
  if (controller) controller->send(message, WsSession::Kind::Control);
}

void Server::Impl::change(Change kind, const wire::Control* c) {
  const uint32_t request = c ? c->request_id() : 0;
  if (changing)
    return send_to_controller(make_error(wire::ErrorCode::Busy,
                                         "a scene change is under way: wait for its SceneDescription", request));
  Scene scene = feed->live->scene();
  std::string load_path;
  bool carry = false;
  uint32_t id = next_scene_id;
  if (kind == Change::Load) {
    const wire::LoadScene* l = c ? c->command_as_LoadScene() : nullptr;
    const std::string name = l && l->path() ? l->path()->str() : "";
    if (std::find(scene_names.begin(), scene_names.end(), name) == scene_names.end()) {
      std::string known;
      for (const std::string& n : scene_names) known += (known.empty() ? "" : ", ") + n;
      return send_to_controller(make_error(
          wire::ErrorCode::BadRequest,
          "no scene '" + name + "' on this server; it has: " + (known.empty() ? "none (no scene folder)" : known),
          request));
    }
    load_path = (std::filesystem::path(options.scenes_dir) / name).string();
  } else if (kind == Change::Parameter) {
    const wire::SetParameter* p = c ? c->command_as_SetParameter() : nullptr;
    const std::string name = p && p->name() ? p->name()->str() : "";
    try {
      apply_parameter(scene.spec, name, p ? p->value() : 0.0);
    } catch (const SceneError& e) {
      return send_to_controller(make_error(wire::ErrorCode::BadRequest, e.what(), request));
    }
    // The body goes on under the new parameter, in the same timeline; after
    // a fault there is no body to carry, and it starts again from rest.
    carry = director->fault().empty();
    if (carry) id = feed->live->id();
  }
  if (id == next_scene_id) ++next_scene_id;
  changing = true;
  if (builder.joinable()) builder.join();
  // Meshing and model building take from milliseconds to seconds: on their
  // own thread, never the network's or the simulation's.
  builder = std::thread([weak = weak_from_this(), &io = ioc, scene = std::move(scene), load_path, id, carry, request,
                         live_options = options.live]() mutable {
    try {
      if (!load_path.empty()) scene = load_scene(load_path).front();
      auto live = std::make_shared<LiveScene>(std::move(scene), id, live_options);
      asio::post(io, [weak, live, carry] {
        if (auto self = weak.lock()) self->built(live, carry);
      });
    } catch (const std::exception& e) {
      asio::post(io, [weak, message = std::string(e.what()), request] {
        if (auto self = weak.lock()) {
          self->changing = false;
          self->send_to_controller(make_error(wire::ErrorCode::BadRequest, message, request));
        }
      });
    }
  });
}

void Server::Impl::built(std::shared_ptr<LiveScene> live, bool carry) {
  if (stopped) return;
  incoming = std::make_shared<Feed>(live, scene_names);
  attach(*incoming);
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
    if (!s->greeted()) continue;
    s->send(feed->description, WsSession::Kind::Control);
    if (s->role() == wire::Role::Device) s->bind_devices();
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
    if (const std::string bad = impl_->start_recording(impl_->options.record, true); !bad.empty()) throw ServerError(bad);
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
  if (impl_->builder.joinable()) impl_->builder.join();
  beast::error_code ec;
  impl_->acceptor.close(ec);
  impl_->wake_fd.close(ec);
  impl_->telemetry_timer.cancel();
  impl_->replay_timer.cancel();
  impl_->stop_recording();
  for (auto& r : impl_->finishing) r->wait();  // closed files, with their summaries
  impl_->finishing.clear();
  impl_->close_all();
}

}  // namespace tactile
