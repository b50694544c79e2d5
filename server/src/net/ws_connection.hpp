// The WebSocket shell (Boost.Beast) around one connection's rules
// (net/connection.hpp): it feeds them what it reads and the timers' ticks, and
// writes what they queue, one message at a time. Joins its host
// (net/host.hpp) when its upgrade starts and leaves it when destroyed.
#pragma once

#include <deque>
#include <memory>
#include <string>

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>

#include "net/connection.hpp"
#include "net/foxglove_session.hpp"

namespace tactile {

class Host;

class WsConnection : public std::enable_shared_from_this<WsConnection> {
 public:
  using Stream = boost::beast::websocket::stream<boost::beast::tcp_stream>;

  WsConnection(std::shared_ptr<Host> host, boost::asio::ip::tcp::socket socket, bool loopback, std::string address);
  ~WsConnection();

  // Completes the upgrade `req` asked for and starts reading. An upgrade
  // that offers the Foxglove subprotocol is served in it
  // (net/foxglove_session.hpp): its rules greeted at once as a viewer that
  // reads haptic frames, with the ?token= of its URL.
  void start(boost::beast::http::request<boost::beast::http::string_body> req);

  Connection& core() { return core_; }
  const Connection& core() const { return core_; }
  // After a scene change: its channels mapped onto the new scene's.
  void rebind();
  // Queues a message under its kind's rule (net/connection.hpp) and writes.
  void send(const Bytes& message, OutKind kind);
  // Closes the socket at once: its pending operations end, and with them the shell.
  void drop();
  // Closes a waiting connection whose slot the server needs (Host::admit):
  // close code 1013 (try again later) with the reason, and the socket
  // within a second whether or not the peer answers.
  void evict(const std::string& reason);
  void close();  // a normal close, once what is queued is written

  // Close code 1013 (try again later) with `reason`, cut to the 123 bytes a close frame holds.
  static boost::beast::websocket::close_reason try_again_later(const std::string& reason);

 private:
  void arm_hello_timer();
  void arm_flush_timer();  // inputs coalesced over the rate wait for a token (Connection::flush)
  void read();
  void pump();            // writes what the rules queued; closes when they say
  bool hold_for_drain();  // a frame waits for the socket to drain (then pump() again)

  std::shared_ptr<Host> host_;
  Stream ws_;
  boost::beast::flat_buffer in_;
  boost::asio::steady_timer hello_timer_;
  boost::asio::steady_timer flush_timer_;
  bool flush_armed_ = false;
  // A frame held back while the socket has more than unsent_bound_ bytes
  // unsent (0: the platform cannot tell, and nothing is held back).
  int unsent();
  int unsent_bound_ = 0;
  bool awaiting_drain_ = false;
  Connection core_;
  // A Foxglove client's session, and the frames it made that wait to be
  // written (null: the protocol's own client).
  std::unique_ptr<FoxgloveSession> fox_;
  std::deque<FoxgloveSession::Frame> fox_out_;
  bool writing_fox_ = false;
  void pump_foxglove();
  void start_foxglove(const std::string& target);
};

}  // namespace tactile
