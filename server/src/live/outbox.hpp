// What a live scene publishes for the threads that serve and record it: every
// haptic frame, every state frame and every input as the loop applied it, in
// rings the simulation thread never waits on (live/mailbox.hpp). The loop's
// sinks push; the network thread drains, sends to its clients and hands the
// same messages to the recording (record/recording.hpp), so a recording holds
// what was served. A full ring drops the new message and counts it: a reader
// that fell more than its depth behind loses messages, and a recording under
// way says so. The depths: 4 MiB of haptic frames (a frame of one proxy and
// one device takes ~350 B: 1.1 s at 10 kHz), 32 of the largest state frames
// (1 s at 30 Hz; plain positions take a fifth of that), 4096 inputs (4 s at
// 1 kHz). Pages are touched as frames land, so a quiet ring costs nothing.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>

#include "live/mailbox.hpp"
#include "live/realtime.hpp"

namespace tactile {

class Outbox {
 public:
  // `state_bytes`, `haptic_bytes`: the most one frame takes (a bigger one is dropped and counted).
  Outbox(size_t state_bytes, size_t haptic_bytes, std::shared_ptr<Wakeup> wakeup)
      : haptics(size_t(4) << 20, haptic_bytes),
        states(32 * (state_bytes + 8), state_bytes),
        applied(4096 * (sizeof(AppliedInput) + 16), sizeof(AppliedInput)),
        wakeup_(std::move(wakeup)) {}
  Outbox(const Outbox&) = delete;
  Outbox& operator=(const Outbox&) = delete;

  // Makes this the loop's sinks (on the simulation thread from then on).
  void attach(RealtimeLoop& loop) {
    loop.on_haptic([this](std::span<const uint8_t> m) {
      haptics.push(m.data(), m.size());
      wakeup_->signal();
    });
    loop.on_state([this](std::span<const uint8_t> m) {
      states.push(m.data(), m.size());
      wakeup_->signal();
    });
    loop.on_applied([this](const AppliedInput& a) { applied.push(reinterpret_cast<const uint8_t*>(&a), sizeof a); });
  }

  FrameRing haptics;  // HapticFrame Envelopes
  FrameRing states;   // StateFrame Envelopes
  FrameRing applied;  // AppliedInput, as the loop applied them

 private:
  std::shared_ptr<Wakeup> wakeup_;
};

}  // namespace tactile
