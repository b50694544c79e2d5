// Who gets in, without sockets (sans-I/O, like net/connection.hpp): the
// browser Origin of a WebSocket, the Host of a plain HTTP request, and a
// WebSocket slot. The shell (net/http_connection.cpp) asks before it answers;
// the tests (server/tests/net/admission_test.cpp) ask directly, one test
// per rule.
//
// Origin (a browser's WebSocket): pages of this server itself
// (http://localhost, 127.0.0.1 or [::1] at its port) and those named with
// --allow-origin, exactly; a client that sends none (the bridge) is not
// checked. Host (the page, its files, the recordings): a loopback name, the
// bound address or the host of an --allow-origin, any port, any case; else
// 421, for a page of another site whose name was made to resolve here (DNS
// rebinding).
//
// A WebSocket slot: a connection "waits" from its upgrade until its Hello.
// The rules:
//   - the greeted connections fill max_connections: the newcomer is refused;
//   - the waiting pool has room: admitted, nobody evicted (a crowd behind
//     one address, a NAT or `kubectl port-forward`, all get in);
//   - the pool is full: the oldest connection that has waited longer than
//     hello_grace_s is evicted, taken from the address holding the most
//     waiting connections (a flood pays for itself before anyone else
//     does); a connection inside its grace is never evicted, so a client
//     that says Hello promptly keeps its slot;
//   - the pool is full of connections inside their grace (a flood faster
//     than the grace lets age): the newcomer is refused, to try again.
// The refused and the evicted are told why (WebSocket close 1013, "try
// again later", with the reason) and the server logs it, at most once a
// second (LogBudget).
#pragma once

#include <chrono>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "net/connection.hpp"

namespace tactile {

// Whether a browser page of `origin` may open a WebSocket to a server on `port`.
bool origin_allowed(std::string_view origin, uint16_t port, const std::vector<std::string>& allowed_origins);
// Whether `host` (a Host header: a name or address, with or without a port)
// names this server, bound to `bind`.
bool host_allowed(std::string_view host, std::string_view bind, const std::vector<std::string>& allowed_origins);

struct AdmissionLimits {
  size_t max_connections = 256;  // greeted connections
  size_t max_waiting = 1024;     // upgraded, no Hello yet
  double hello_grace_s = 1.0;    // waiting for less than this [s]: never evicted
};

// A connection waiting for its Hello: who, from where, since when.
struct WaitingSlot {
  uint64_t id = 0;
  std::string_view address;  // the peer's IP address
  ConnectionClock::time_point since{};
};

struct Admission {
  bool admit = false;
  uint64_t evict = 0;  // a waiting connection to close first (0: none)
  std::string reason;  // why the newcomer is refused, or why `evict` is closed
};

// The verdict on a newcomer, given the connections waiting and the number
// greeted (open, not closing). Where it comes from changes nothing: every
// address is served alike, and only the waiting are weighed by address.
Admission decide_admission(std::span<const WaitingSlot> waiting, size_t greeted, ConnectionClock::time_point now,
                           const AdmissionLimits& limits);

// A log line at most once per `period_s`; the lines held back in between are
// counted, for the next line to say.
class LogBudget {
 public:
  explicit LogBudget(double period_s = 1.0) : period_(period_s) {}
  // True when a line may be written now; then held_back() tells how many
  // were not since the last one (and starts counting again).
  bool take(ConnectionClock::time_point now);
  int64_t held_back() const { return held_back_; }

 private:
  std::chrono::duration<double> period_;
  ConnectionClock::time_point last_{};
  bool any_ = false;
  int64_t held_back_ = 0, counting_ = 0;
};

}  // namespace tactile
