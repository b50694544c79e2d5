// The port a server listens on: it accepts TCP connections and hands each to
// an HTTP exchange (net/http_connection.cpp), which serves a static file or a
// recording, or upgrades to a WebSocket that its host admits
// (Host::admit) or refuses.
#pragma once

#include <cstdint>
#include <memory>

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>

#include "net/host.hpp"

namespace tactile {

class Listener : public std::enable_shared_from_this<Listener> {
 public:
  explicit Listener(std::shared_ptr<Host> host);

  // Binds the options' address and port: throws ServerError for an address
  // off loopback without a token, or one it cannot bind.
  void listen();
  void accept();  // from now on, until stop()
  void stop();
  uint16_t port() const;  // the port bound

 private:
  void ensure_descriptors() const;

  std::shared_ptr<Host> host_;
  boost::asio::ip::tcp::acceptor acceptor_;
  boost::asio::steady_timer accept_timer_;  // a failed accept waits on it before the next
  bool stopped_ = false;
};

// Serves one accepted connection for `host`, whose listener has `port`:
// static files over HTTP, the recordings folder, or the upgrade to a
// WebSocket (net/http_connection.cpp).
void serve_http(std::shared_ptr<Host> host, uint16_t port, boost::asio::ip::tcp::socket socket);

}  // namespace tactile
