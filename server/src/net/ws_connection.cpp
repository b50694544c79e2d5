#include "net/ws_connection.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>

#ifdef __linux__
#include <linux/sockios.h>
#include <netinet/tcp.h>
#include <sys/ioctl.h>
#endif

#include "net/host.hpp"

namespace tactile {

namespace beast = boost::beast;
namespace websocket = beast::websocket;
namespace wire = proto;
using tcp = asio::ip::tcp;

namespace {

ConnectionLimits limits(const ServerOptions& o) {
  return {o.token,       o.server_name,  o.viewer_rate_hz, o.max_messages_per_s, o.max_safety_events_per_s,
          o.event_queue, o.control_queue};
}

uint64_t next_id = 1;  // on the network thread

}  // namespace

WsConnection::WsConnection(std::shared_ptr<Host> host, tcp::socket socket, bool loopback, std::string address)
    : host_(std::move(host)),
      ws_(std::move(socket)),
      hello_timer_(host_->io()),
      flush_timer_(host_->io()),
      core_(*host_, limits(host_->options()), loopback, std::move(address), next_id++, ConnectionClock::now()) {}

WsConnection::~WsConnection() {
  host_->leave(this);
  if (core_.safety_dropped() > 0)
    std::fprintf(stderr, "safety: connection %llu sent %lld events over the limit of %g per second: dropped\n",
                 (unsigned long long)core_.id(), (long long)core_.safety_dropped(),
                 host_->options().max_safety_events_per_s);
  if (core_.events_dropped() > 0)
    std::fprintf(stderr, "safety: connection %llu (%s) read too slowly and missed %lld safety events\n",
                 (unsigned long long)core_.id(), wire::EnumNameRole(core_.role()), (long long)core_.events_dropped());
}

void WsConnection::start(beast::http::request<beast::http::string_body> req) {
  host_->join(this);
  beast::get_lowest_layer(ws_).expires_never();
  // Without it, Nagle's algorithm holds each small haptic frame until the
  // peer's next message acks the previous one: a whole input period of latency.
  beast::error_code ignored;
  beast::get_lowest_layer(ws_).socket().set_option(tcp::no_delay(true), ignored);
#ifdef __linux__
  // What waits in the kernel for a slow reader is a few frames, not seconds
  // of them: the socket is writable again only once less than this is
  // unsent, and pump() holds a frame back until then (the newest replaces it
  // as it waits: Connection::send).
  unsent_bound_ = int(host_->options().unsent_frames_bytes);
  const int fd = beast::get_lowest_layer(ws_).socket().native_handle();
  if (::setsockopt(fd, IPPROTO_TCP, TCP_NOTSENT_LOWAT, &unsent_bound_, sizeof unsent_bound_) != 0) unsent_bound_ = 0;
#endif
  websocket::stream_base::timeout t = websocket::stream_base::timeout::suggested(beast::role_type::server);
  t.idle_timeout = std::chrono::milliseconds(int64_t(host_->options().idle_timeout_s * 1000));
  t.keep_alive_pings = true;
  ws_.set_option(t);
  ws_.read_message_max(host_->options().max_message_bytes);
  ws_.binary(true);
  if (asks_for_foxglove(std::string(req[beast::http::field::sec_websocket_protocol]))) {
    fox_ = std::make_unique<FoxgloveSession>(host_->options().server_name);
    ws_.set_option(websocket::stream_base::decorator([](websocket::response_type& res) {
      res.set(beast::http::field::sec_websocket_protocol, kFoxgloveSubprotocol);
    }));
  }
  ws_.async_accept(req, [self = shared_from_this(), target = std::string(req.target())](beast::error_code ec) {
    if (ec) return;
    self->arm_hello_timer();
    if (self->fox_) self->start_foxglove(target);
    self->read();
  });
}

// The Foxglove client's greeting, and its rules greeted as a viewer that
// reads haptic frames at most kFoxgloveHapticHz (a panel draws far fewer).
void WsConnection::start_foxglove(const std::string& target) {
  constexpr float kFoxgloveHapticHz = 250;
  for (FoxgloveSession::Frame& f : fox_->greeting()) fox_out_.push_back(std::move(f));
  const size_t q = target.find("token=");
  const std::string token = q == std::string::npos ? "" : target.substr(q + 6, target.find('&', q) - q - 6);
  flatbuffers::FlatBufferBuilder b;
  const Bytes hello =
      seal(b, wire::Message::Hello,
           wire::CreateHelloDirect(b, uint16_t(wire::ProtocolMajor::Current), uint16_t(wire::ProtocolMinor::Current),
                                   wire::Role::Viewer, token.c_str(), "foxglove", nullptr, nullptr, nullptr,
                                   kFoxgloveHapticHz));
  core_.set_reads_haptic(true);
  core_.receive(*hello, true, ConnectionClock::now());
  if (core_.greeted()) hello_timer_.cancel();
  pump();
}

void WsConnection::rebind() {
  core_.bind_devices();
  pump();
}

void WsConnection::send(const Bytes& message, OutKind kind) {
  core_.send(message, kind);
  pump();
}

void WsConnection::drop() {
  if (core_.closed()) return;
  core_.mark_closed();
  hello_timer_.cancel();
  beast::get_lowest_layer(ws_).close();
}

void WsConnection::evict(const std::string& reason) {
  if (core_.closed()) return;
  core_.mark_closed();
  hello_timer_.cancel();
  websocket::stream_base::timeout t = websocket::stream_base::timeout::suggested(beast::role_type::server);
  t.handshake_timeout = std::chrono::seconds(1);
  ws_.set_option(t);
  ws_.async_close(try_again_later(reason), [self = shared_from_this()](beast::error_code) {});
}

websocket::close_reason WsConnection::try_again_later(const std::string& reason) {
  return websocket::close_reason(websocket::close_code::try_again_later,
                                 beast::string_view(reason.data(), std::min<size_t>(reason.size(), 123)));
}

void WsConnection::close() {
  if (core_.closed()) return;
  core_.mark_closed();
  hello_timer_.cancel();
  ws_.async_close(websocket::close_code::normal, [self = shared_from_this()](beast::error_code) {});
}

void WsConnection::arm_hello_timer() {
  hello_timer_.expires_after(std::chrono::milliseconds(int64_t(host_->options().hello_timeout_s * 1000)));
  hello_timer_.async_wait([weak = weak_from_this()](beast::error_code ec) {
    auto self = weak.lock();
    if (ec || !self) return;
    self->core_.hello_timed_out();
    self->pump();
  });
}

void WsConnection::arm_flush_timer() {
  if (!core_.flush_due() || flush_armed_) return;
  flush_armed_ = true;
  flush_timer_.expires_at(core_.flush_at());
  flush_timer_.async_wait([weak = weak_from_this()](beast::error_code ec) {
    auto self = weak.lock();
    if (ec || !self) return;
    self->flush_armed_ = false;
    self->core_.flush(ConnectionClock::now());
    self->arm_flush_timer();
    self->pump();
  });
}

void WsConnection::read() {
  ws_.async_read(in_, [self = shared_from_this()](beast::error_code ec, size_t) {
    if (ec) {
      self->core_.mark_closed();  // closed, timed out, or too big (Beast sends close code 1009)
      self->hello_timer_.cancel();
      return;
    }
    const auto* data = static_cast<const uint8_t*>(self->in_.data().data());
    if (self->fox_) {
      // Its subscriptions; a client that lets the answers pile up unread is dropped, as the rules drop one.
      if (!self->ws_.got_binary()) {
        if (auto f = self->fox_->on_text({reinterpret_cast<const char*>(data), self->in_.size()}))
          self->fox_out_.push_back(std::move(*f));
      } else {
        self->fox_out_.push_back(self->fox_->on_binary());
      }
      self->in_.consume(self->in_.size());
      if (self->fox_out_.size() > self->host_->options().control_queue) return self->drop();
      self->pump();
      return self->read();
    }
    self->core_.receive({data, self->in_.size()}, self->ws_.got_binary(), ConnectionClock::now());
    self->in_.consume(self->in_.size());
    if (self->core_.greeted()) self->hello_timer_.cancel();
    self->arm_flush_timer();
    self->pump();
    if (!self->core_.closed()) self->read();
  });
}

// Bytes written to the socket that TCP has not sent yet (0 where it cannot tell).
int WsConnection::unsent() {
#ifdef __linux__
  int n = 0;
  if (unsent_bound_ > 0 && ::ioctl(beast::get_lowest_layer(ws_).socket().native_handle(), SIOCOUTQNSD, &n) == 0)
    return n;
#endif
  return 0;
}

// A frame waits for the socket to drain below the bound (TCP_NOTSENT_LOWAT
// makes it writable then); newer frames replace it meanwhile. True when it
// waits (pump() runs again once the socket drains).
bool WsConnection::hold_for_drain() {
  if (!core_.frame_next() || unsent() <= unsent_bound_) return false;
  awaiting_drain_ = true;
  beast::get_lowest_layer(ws_).socket().async_wait(tcp::socket::wait_write,
                                                   [weak = weak_from_this()](beast::error_code ec) {
                                                     auto self = weak.lock();
                                                     if (!self) return;
                                                     self->awaiting_drain_ = false;
                                                     if (ec || self->core_.closed()) return;
                                                     self->pump();
                                                   });
  return true;
}

void WsConnection::pump() {
  if (core_.disconnect()) return drop();
  if (awaiting_drain_) return;
  if (fox_) return pump_foxglove();
  if (hold_for_drain()) return;
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

// As pump(), for a Foxglove client: each message the rules queue is
// translated into the frames of its subscriptions (none when it has none),
// which are written one by one; a frame waits for the socket to drain as
// there, newer ones replacing it in the rules' queue meanwhile.
void WsConnection::pump_foxglove() {
  while (fox_out_.empty()) {
    if (hold_for_drain()) return;
    const Bytes* message = core_.next_write();
    if (!message) break;
    const Bytes m = *message;
    core_.written();
    const uint64_t unix_ns = uint64_t(
        std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
            .count());
    std::vector<FoxgloveSession::Frame> frames;
    fox_->translate(*m, unix_ns, frames);
    // A refusal (a wrong token) comes before any subscription: said as a status.
    const wire::Envelope* e = wire::GetEnvelope(m->data());
    if (!core_.greeted() && e->message_type() == wire::Message::Error && e->message_as_Error()->message())
      frames.push_back(fox_->status(2, e->message_as_Error()->message()->str()));
    for (FoxgloveSession::Frame& f : frames) fox_out_.push_back(std::move(f));
  }
  if (fox_out_.empty()) {
    if (core_.idle() && core_.close_after_write()) close();
    return;
  }
  if (writing_fox_) return;
  writing_fox_ = true;
  ws_.text(fox_out_.front().text);
  ws_.async_write(asio::buffer(fox_out_.front().bytes), [self = shared_from_this()](beast::error_code ec, size_t) {
    self->writing_fox_ = false;
    self->fox_out_.pop_front();
    if (ec) return self->core_.mark_closed();
    self->pump();
  });
}

}  // namespace tactile
