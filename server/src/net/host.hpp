// What a server serves from, and what its two modes share: the connections
// (each a WsConnection shell around its rules, net/connection.hpp), the one
// controller, the admission of new ones (net/admission.hpp), and the scene
// being served. A LiveHost (net/live_host.hpp) serves a director's scenes as
// they run; a ReplayHost (net/replay_host.hpp) a recording as it was served.
// The Server (net/server.hpp) makes one of the two and a Listener
// (net/listener.hpp) that hands it the connections. All on the network thread.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <unordered_set>
#include <vector>

#include <boost/asio/io_context.hpp>

#include "net/admission.hpp"
#include "net/connection.hpp"
#include "net/server.hpp"

namespace tactile {

namespace asio = boost::asio;

// The server's clock for stamps [ns] (steady).
inline int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

inline Bytes copy_bytes(const uint8_t* data, size_t n) {
  return std::make_shared<const std::vector<uint8_t>>(data, data + n);
}

class WsConnection;

class Host : public ConnectionHost, public std::enable_shared_from_this<Host> {
 public:
  // The scene served: its SceneDescription (Envelope bytes), name and device channels.
  struct Served {
    Bytes description;
    std::string scene_name;
    std::vector<std::string> devices;  // in the order haptic frames list them
  };

  Host(asio::io_context& io, ServerOptions options) : io_(io), options_(std::move(options)) {}

  virtual void start() = 0;  // once the listener is bound: timers, wakeups, a first recording
  virtual void stop();       // closes every connection (a mode stops its own parts first)

  asio::io_context& io() { return io_; }
  const ServerOptions& options() const { return options_; }
  bool stopped() const { return stopped_; }

  // The connections: a shell joins when its upgrade starts and leaves when
  // it is destroyed (the controller's role is then free).
  void join(WsConnection* s) { connections_.insert(s); }
  void leave(WsConnection* s);
  // The verdict on one more WebSocket from `address` (net/admission.hpp);
  // a connection it evicts is closed here, with the reason.
  Admission admit(const std::string& address);
  // A line on stderr for an eviction, a refusal or a failed accept: one a
  // second at most, with a count of those held back.
  void log_admission(ConnectionClock::time_point now, const std::string& line);

  // ---- ConnectionHost: what every mode answers alike ----
  int64_t now_ns() const override { return tactile::now_ns(); }
  const Bytes& description() const override { return served_.description; }
  const std::vector<std::string>& devices() const override { return served_.devices; }
  const std::string& scene_name() const override { return served_.scene_name; }
  uint64_t driver_of(const std::string& channel, const Connection& asking) const override;
  bool claim_controller(Connection& s) override;
  void relay(const Bytes& message, OutKind kind) override;

 protected:
  Served served_;

  // Queues `message` as `kind` to each greeted connection `to` picks (all without).
  void send_each(const Bytes& message, OutKind kind, const std::function<bool(const Connection&)>& to = nullptr);
  void send_to(const Connection& s, const Bytes& message, OutKind kind);
  void send_to_controller(const Bytes& message);
  // Serves `next` from now on: its description to every greeted connection,
  // and the devices' channels mapped onto its own.
  void serve_scene(Served next);
  ViewFieldMask fields_asked() const;  // by the greeted connections, together
  size_t count_greeted(proto::Role role) const;
  size_t count_haptic_readers() const;  // devices, and viewers that read haptic frames (Foxglove)

  bool stopped_ = false;

 private:
  WsConnection* shell_of(const Connection& s) const;

  asio::io_context& io_;
  ServerOptions options_;
  std::unordered_set<WsConnection*> connections_;
  WsConnection* controller_ = nullptr;
  LogBudget admission_log_;  // evictions and refusals: a line a second at most
};

}  // namespace tactile
