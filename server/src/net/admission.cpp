#include "net/admission.hpp"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <map>

namespace tactile {

namespace {

std::string seconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f s", s);
  return buf;
}

// The host of "scheme://host[:port]" or "host[:port]", without the port
// ("[::1]" keeps its brackets), in lower case.
std::string host_part(std::string_view s) {
  if (const size_t scheme = s.find("://"); scheme != std::string_view::npos) s = s.substr(scheme + 3);
  if (s.starts_with('['))
    s = s.substr(0, s.find(']') + 1);
  else if (const size_t colon = s.rfind(':'); colon != std::string_view::npos)
    s = s.substr(0, colon);
  std::string out(s);
  for (char& ch : out) ch = char(std::tolower(uint8_t(ch)));
  return out;
}

}  // namespace

bool origin_allowed(std::string_view origin, uint16_t port, const std::vector<std::string>& allowed_origins) {
  for (const char* host : {"127.0.0.1", "localhost", "[::1]"})
    if (origin == "http://" + std::string(host) + ":" + std::to_string(port)) return true;
  return std::find(allowed_origins.begin(), allowed_origins.end(), origin) != allowed_origins.end();
}

bool host_allowed(std::string_view host, std::string_view bind, const std::vector<std::string>& allowed_origins) {
  const std::string name = host_part(host);
  if (name.empty()) return false;
  for (const char* loopback : {"127.0.0.1", "localhost", "[::1]"})
    if (name == loopback) return true;
  if (name == bind) return true;
  for (const std::string& origin : allowed_origins)
    if (host_part(origin) == name) return true;
  return false;
}

Admission decide_admission(std::span<const WaitingSlot> waiting, size_t greeted, ConnectionClock::time_point now,
                           const AdmissionLimits& limits) {
  Admission a;
  if (greeted >= limits.max_connections) {
    a.reason = "server full: " + std::to_string(greeted) + " connections (max_connections); try again later";
    return a;
  }
  if (waiting.size() < limits.max_waiting) {
    a.admit = true;
    return a;
  }
  // The pool is full. Per address: how many wait, and its oldest past the grace.
  struct Holder {
    size_t waiting = 0;
    const WaitingSlot* oldest_stale = nullptr;
  };
  std::map<std::string_view, Holder> by_address;
  const auto grace = std::chrono::duration<double>(limits.hello_grace_s);
  for (const WaitingSlot& w : waiting) {
    Holder& h = by_address[w.address];
    ++h.waiting;
    if (now - w.since < grace) continue;
    if (!h.oldest_stale || w.since < h.oldest_stale->since ||
        (w.since == h.oldest_stale->since && w.id < h.oldest_stale->id))
      h.oldest_stale = &w;
  }
  std::string_view from;
  const Holder* pick = nullptr;
  for (const auto& [addr, h] : by_address) {
    if (!h.oldest_stale) continue;
    if (!pick || h.waiting > pick->waiting ||
        (h.waiting == pick->waiting && h.oldest_stale->since < pick->oldest_stale->since)) {
      pick = &h;
      from = addr;
    }
  }
  if (!pick) {
    a.reason = std::to_string(waiting.size()) + " connections are waiting to say Hello (max_waiting), none for " +
               seconds(limits.hello_grace_s) + " yet; try again later";
    return a;
  }
  a.admit = true;
  a.evict = pick->oldest_stale->id;
  a.reason = "no Hello after " + seconds(std::chrono::duration<double>(now - pick->oldest_stale->since).count()) +
             ", and the server needed the slot (" + std::to_string(waiting.size()) + " waiting, " +
             std::to_string(pick->waiting) + " from " + std::string(from) + ")";
  return a;
}

bool LogBudget::take(ConnectionClock::time_point now) {
  if (any_ && now - last_ < period_) {
    ++counting_;
    return false;
  }
  any_ = true;
  last_ = now;
  held_back_ = counting_;
  counting_ = 0;
  return true;
}

}  // namespace tactile
