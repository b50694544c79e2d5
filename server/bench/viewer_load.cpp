// Viewer load for the live server benchmark: N viewer connections from one
// thread that read every message and discard it, so that the load on the
// machine is the server's sending, not the clients' decoding (50 Python
// viewers decoding at 30 Hz take a sixth of a core on their own). Prints
// the state frames each viewer got per second. Used by server_bench.py.
//
//   viewer_load --port N [--host 127.0.0.1] [--viewers 50] [--seconds 5]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <flatbuffers/flatbuffers.h>
#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>

#include "app/command_line.hpp"
#include "tactile_generated.h"

namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace websocket = beast::websocket;
namespace fb = flatbuffers;
namespace wire = tactile::proto;
using tcp = asio::ip::tcp;

struct Viewer : std::enable_shared_from_this<Viewer> {
  explicit Viewer(asio::io_context& ioc) : ws(ioc) {}
  websocket::stream<beast::tcp_stream> ws;
  beast::flat_buffer in;
  long states = 0, messages = 0, state_bytes = 0;
  bool failed = false;

  void read() {
    ws.async_read(in, [self = shared_from_this()](beast::error_code ec, size_t) {
      if (ec) {
        self->failed = true;
        return;
      }
      // The envelope's type, without decoding the frame: what a viewer must at least do.
      const auto* data = static_cast<const uint8_t*>(self->in.data().data());
      if (self->in.size() >= 8 && wire::EnvelopeBufferHasIdentifier(data) &&
          wire::GetEnvelope(data)->message_type() == wire::Message::StateFrame) {
        ++self->states;
        self->state_bytes += long(self->in.size());
      }
      ++self->messages;
      self->in.consume(self->in.size());
      self->read();
    });
  }
};

}  // namespace

int main(int argc, char** argv) {
  std::string host = "127.0.0.1", port;
  int n = 50;
  double seconds = 5;
  std::vector<std::string> fields;
  CLI::App app(
      "Opens N viewer connections to a running tactile-server from one thread, reads and discards every "
      "message, and prints the state frames each viewer got per second.",
      "viewer_load");
  tactile::configure_command_line(app);
  app.add_option("--host", host, "the server's address")->capture_default_str();
  app.add_option("--port", port, "the server's port")->required();
  app.add_option("--viewers", n, "viewer connections, >= 1")
      ->capture_default_str()
      ->check(tactile::number_where([](double v) { return v >= 1; }, ">= 1"));
  app.add_option("--seconds", seconds, "how long to read, > 0 [s]")
      ->capture_default_str()
      ->check(tactile::positive_number());
  app.add_option("--fields", fields, "per-vertex fields each viewer asks for (the server names those it has)");
  if (const std::optional<int> status = tactile::parse_command_line(app, argc, argv)) return *status;
  try {
    asio::io_context ioc(1);
    tcp::resolver resolver(ioc);
    const auto endpoints = resolver.resolve(host, port);
    fb::FlatBufferBuilder b;
    std::vector<fb::Offset<fb::String>> asked;
    for (const std::string& f : fields) asked.push_back(b.CreateString(f));
    b.Finish(wire::CreateEnvelope(b, wire::Message::Hello,
                                  wire::CreateHelloDirect(b, uint16_t(wire::ProtocolMajor::Current),
                                                          uint16_t(wire::ProtocolMinor::Current), wire::Role::Viewer,
                                                          "", "viewer_load", nullptr, nullptr, &asked)
                                      .Union()),
             wire::EnvelopeIdentifier());
    std::vector<std::shared_ptr<Viewer>> viewers;
    for (int k = 0; k < n; ++k) {
      auto v = std::make_shared<Viewer>(ioc);
      beast::get_lowest_layer(v->ws).connect(endpoints);
      v->ws.handshake(host + ":" + port, "/ws");
      v->ws.binary(true);
      v->ws.write(asio::buffer(b.GetBufferPointer(), b.GetSize()));
      viewers.push_back(v);
    }
    for (auto& v : viewers) v->read();
    ioc.run_for(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<double>(seconds)));
    long states = 0, failed = 0, bytes = 0;
    for (auto& v : viewers) {
      states += v->states;
      bytes += v->state_bytes;
      failed += v->failed ? 1 : 0;
    }
    std::printf(
        "viewers %d, state frames per viewer per second %.1f, state bytes per viewer per second %.0f (%.0f a frame), "
        "connections lost %ld\n",
        n, double(states) / n / seconds, double(bytes) / n / seconds, states ? double(bytes) / double(states) : 0.0,
        failed);
    return failed ? 1 : 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "viewer_load: %s\n", e.what());
    return 1;
  }
}
