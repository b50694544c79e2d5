#include "net/listener.hpp"

#include <algorithm>
#include <cstdio>

#include <sys/resource.h>

namespace tactile {

using tcp = asio::ip::tcp;

Listener::Listener(std::shared_ptr<Host> host)
    : host_(std::move(host)), acceptor_(host_->io()), accept_timer_(host_->io()) {}

// Every connection holds a descriptor: the soft limit is raised (up to the
// hard one) to cover max_connections greeted, max_waiting waiting and the
// refused ones closing, with 64 to spare for files; short of that, said once.
void Listener::ensure_descriptors() const {
  const ServerOptions& o = host_->options();
  rlimit lim{};
  if (::getrlimit(RLIMIT_NOFILE, &lim) != 0) return;
  const rlim_t want = rlim_t(2 * (o.max_connections + o.max_waiting) + 64);
  if (lim.rlim_cur >= want) return;
  const rlim_t before = lim.rlim_cur;
  lim.rlim_cur = lim.rlim_max == RLIM_INFINITY ? want : std::min(want, lim.rlim_max);
  if (::setrlimit(RLIMIT_NOFILE, &lim) != 0) lim.rlim_cur = before;
  if (lim.rlim_cur < want)
    std::fprintf(stderr,
                 "server: %llu file descriptors allowed (ulimit -n), %llu wanted for %zu connections and %zu "
                 "waiting: past that, new connections fail until some close\n",
                 (unsigned long long)lim.rlim_cur, (unsigned long long)want, o.max_connections, o.max_waiting);
}

void Listener::listen() {
  const ServerOptions& o = host_->options();
  ensure_descriptors();
  boost::system::error_code ec;
  const asio::ip::address address = asio::ip::make_address(o.bind, ec);
  if (ec) throw ServerError("bind address '" + o.bind + "' is not an IP address");
  if (!address.is_loopback() && o.token.empty())
    throw ServerError("refusing to listen on " + o.bind +
                      " without a token: off loopback every client must present one (--token)");
  const tcp::endpoint endpoint(address, o.port);
  acceptor_.open(endpoint.protocol());
  acceptor_.set_option(asio::socket_base::reuse_address(true));
  acceptor_.bind(endpoint, ec);
  if (ec) throw ServerError("cannot listen on " + o.bind + ":" + std::to_string(o.port) + ": " + ec.message());
  acceptor_.listen(asio::socket_base::max_listen_connections);
}

void Listener::accept() {
  acceptor_.async_accept([self = shared_from_this()](boost::system::error_code ec, tcp::socket socket) {
    if (self->stopped_) return;
    if (!ec) {
      serve_http(self->host_, self->port(), std::move(socket));
      return self->accept();
    }
    // Out of descriptors (EMFILE) or the like: the connection stays in the
    // backlog, so accepting again at once would spin; wait for some to close.
    self->host_->log_admission(ConnectionClock::now(), "cannot accept a connection: " + ec.message());
    self->accept_timer_.expires_after(std::chrono::milliseconds(50));
    self->accept_timer_.async_wait([self](boost::system::error_code wait_ec) {
      if (!wait_ec && !self->stopped_) self->accept();
    });
  });
}

void Listener::stop() {
  stopped_ = true;
  boost::system::error_code ec;
  acceptor_.close(ec);
  accept_timer_.cancel();
}

uint16_t Listener::port() const {
  boost::system::error_code ec;
  return acceptor_.local_endpoint(ec).port();
}

}  // namespace tactile
