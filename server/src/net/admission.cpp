#include "net/admission.hpp"

#include <cstdio>
#include <map>

namespace tactile {

namespace {

std::string seconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f s", s);
  return buf;
}

}  // namespace

Admission decide_admission(std::span<const WaitingSlot> waiting, size_t greeted, SessionClock::time_point now,
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

bool LogBudget::take(SessionClock::time_point now) {
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
