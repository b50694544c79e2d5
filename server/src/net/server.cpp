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

namespace {

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

Bytes copy_bytes(const uint8_t* data, size_t n) { return std::make_shared<const std::vector<uint8_t>>(data, data + n); }

// A string for a one-line log: control characters shown as '?'.
std::string printable_text(std::string out) {
  for (char& c : out)
    if (uint8_t(c) < 0x20 || c == 0x7f) c = '?';
  return out;
}

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

struct Server::Impl : std::enable_shared_from_this<Server::Impl>, SessionHost {
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
        core_(*server_, limits(server_->options), loopback, std::move(address), next_id_++, SessionClock::now()) {}

  ~WsSession() {
    server_->sessions.erase(this);
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
    return {o.token,        o.server_name,   o.viewer_rate_hz, o.max_messages_per_s, o.device_queue,
            o.max_safety_events_per_s, o.event_queue, o.control_queue};
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
  Session core_;
  static inline uint64_t next_id_ = 1;
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
    case wire::ControlCommand::Reset: return change(Change::Reset, &c);
    case wire::ControlCommand::LoadScene: return change(Change::Load, &c);
    case wire::ControlCommand::SetParameter: return change(Change::Parameter, &c);
    case wire::ControlCommand::StartRecording: {
      const wire::StartRecording* r = c.command_as_StartRecording();
      if (const std::string bad = start_recording(r && r->path() ? r->path()->str() : ""); !bad.empty())
        return from.send(make_error(bad.starts_with("a recording") ? wire::ErrorCode::Busy : wire::ErrorCode::BadRequest,
                                    bad, c.request_id()),
                         OutKind::Control);
      return;
    }
    case wire::ControlCommand::StopRecording:
      if (!recorder)
        return from.send(make_error(wire::ErrorCode::BadRequest, "StopRecording: no recording is under way",
                                    c.request_id()),
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

bool Server::Impl::make_room(const std::string& address) {
  size_t greeted = 0, waiting = 0, waiting_here = 0;
  WsSession *oldest = nullptr, *oldest_here = nullptr;
  for (WsSession* s : sessions) {
    if (s->core().greeted() && !s->core().closed()) ++greeted;
    if (!s->core().waiting()) continue;
    ++waiting;
    if (!oldest || s->core().id() < oldest->core().id()) oldest = s;
    if (s->core().address() != address) continue;
    ++waiting_here;
    if (!oldest_here || s->core().id() < oldest_here->core().id()) oldest_here = s;
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
    if (s->core().greeted()) s->send(t, OutKind::Control);
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
    if (s->core().greeted()) s->send(t, OutKind::Control);
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
    if (!s->core().greeted()) continue;
    if (s->core().role() == wire::Role::Viewer) ++viewers;
    else if (s->core().role() == wire::Role::Device) ++devices;
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
      if (s->core().greeted()) s->send(t, OutKind::Control);
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
  if (controller) controller->send(message, OutKind::Control);
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
