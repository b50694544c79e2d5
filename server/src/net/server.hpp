// The WebSocket endpoint (Boost.Beast) and the static HTTP files on the same
// port, on its own thread (one io_context), fed by the real-time loop
// through its scene's outbox, which it never waits on (live/outbox.hpp).
// Its parts: a host, live (net/live_host.hpp) or replaying
// (net/replay_host.hpp), chosen by the constructor; the listener
// (net/listener.hpp) and HTTP (net/http_connection.cpp); each connection's
// shell (net/ws_connection.hpp) and rules (net/connection.hpp); the admission
// rules (net/admission.hpp) and the scene-change rules (net/scene_switch.hpp).
//
// Roles (granted at Hello, proto/tactile.fbs):
//   viewer      the scene description, then state frames at up to the state
//               rate, latest wins; telemetry once a second; the devices'
//               safety events as they come.
//   device      a haptic frame after every step; sends DeviceInput and
//               SafetyEvent for the channels it named in Hello (its safety
//               events, stamped with the server clock and logged on stderr,
//               go to every viewer and controller). Needs the token.
//   controller  one at a time: pause, resume, reset, load a scene from the
//               server's scene folder, set a parameter. Needs the token.
//               A change is answered by a new SceneDescription to every
//               client (or an Error naming what is wrong). Gets the
//               devices' safety events too.
// Every client may Ping (answered with Pong at once).
//
// Safety of the service: listens on loopback unless told otherwise, and off
// loopback only with a token, which then every role needs; browser Origins
// are checked against an allow-list; message size, message rate and the
// number of connections are bounded; a client that has not said Hello in
// time, or has gone silent, is closed. Each refusal is an Error naming what
// is wrong (or an HTTP status with a message). A slow client loses frames
// (latest wins for states, bounded queues for haptic frames and safety
// events): it never slows the simulation or another client.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <boost/asio/io_context.hpp>

#include "live/director.hpp"
#include "record/replay.hpp"

namespace tactile {

struct ServerOptions {
  std::string bind = "127.0.0.1";
  uint16_t port = 8765;                      // 0: any free port
  std::string token;                         // needed by devices and controllers (by all roles off loopback)
  std::vector<std::string> allowed_origins;  // extra browser Origins (its own http://host:port always allowed)
  std::string static_dir;                    // served over HTTP (client-web); "" for none
  double viewer_rate_hz = 30;                // state frames per second per viewer at most
  size_t max_connections = 256;              // greeted WebSocket connections
  size_t max_waiting = 1024;                 // upgraded, no Hello yet (net/admission.hpp: who makes room)
  double hello_grace_s = 1;                  // a connection waiting for less is never evicted
  size_t max_message_bytes = 64 * 1024;      // inbound
  size_t unsent_frames_bytes = 4096;         // a frame waits while more than this is unsent in the socket
  double max_messages_per_s = 5000;          // inbound per connection (burst: a second's worth)
  double max_safety_events_per_s = 100;      // relayed per device connection (burst: a second's worth); more drop
  size_t event_queue = 256;                  // safety events queued per reader before the oldest drop
  size_t control_queue = 1024;               // control messages (replies, telemetry) unread: disconnected
  double hello_timeout_s = 5;
  double idle_timeout_s = 30;
  std::string server_name = "tactile";
  std::string scenes_dir;      // where LoadScene finds scenes ("" for none)
  std::string recordings_dir;  // where StartRecording writes ("" refuses it)
  std::string record;          // a recording to start with the server (any path), "" for none
  mcap::Compression record_compression = mcap::Compression::Zstd;  // of every recording's chunks
  LiveOptions live;                                                // how loaded and reset scenes run
  bool reset_on_fault = false;  // a fault resets the scene (once a telemetry has named it)
};

// What the server refuses to start with (a bind off loopback without a
// token, a port in use...), with a message naming it.
struct ServerError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class Server {
 public:
  // Serves the director's scenes as they run (they publish into their
  // outboxes). The director must outlive the server; it runs on its own thread.
  Server(boost::asio::io_context& ioc, Director& director, ServerOptions options);
  // Serves a recording as the live session was served (the same messages,
  // at their recorded pace): viewers get its states, devices its haptic
  // frames, a controller may Pause, Resume, Seek and SetSpeed, and every
  // client of protocol 1.4 gets a ReplayStatus ten times a second. Starts
  // playing when the first client says Hello; at the end it pauses. The
  // replay must outlive the server.
  Server(boost::asio::io_context& ioc, Replay& replay, ServerOptions options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  uint16_t port() const;  // the port bound
  void stop();            // closes the acceptor and every connection

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tactile
