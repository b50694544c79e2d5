#include "net/server.hpp"

#include "net/listener.hpp"
#include "net/live_host.hpp"
#include "net/replay_host.hpp"

namespace tactile {

// One host, live or replaying, chosen here, and the listener that feeds it.
struct Server::Impl {
  std::shared_ptr<Host> host;
  std::shared_ptr<Listener> listener;

  explicit Impl(std::shared_ptr<Host> h) : host(std::move(h)), listener(std::make_shared<Listener>(host)) {
    listener->listen();
    host->start();
    listener->accept();
  }
};

Server::Server(boost::asio::io_context& ioc, Director& director, ServerOptions options)
    : impl_(std::make_unique<Impl>(std::make_shared<LiveHost>(ioc, director, std::move(options)))) {}

Server::Server(boost::asio::io_context& ioc, Replay& replay, ServerOptions options)
    : impl_(std::make_unique<Impl>(std::make_shared<ReplayHost>(ioc, replay, std::move(options)))) {}

Server::~Server() { stop(); }

uint16_t Server::port() const { return impl_->listener->port(); }

void Server::stop() {
  impl_->listener->stop();
  impl_->host->stop();
}

}  // namespace tactile
