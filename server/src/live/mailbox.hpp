// Hand-offs from the simulation thread to the network thread that never make
// the simulation wait or allocate (live/outbox.hpp holds a scene's):
// FrameRing keeps every message, in order, in a bounded ring of bytes;
// when the reader falls behind, new messages are dropped and counted. It is
// single-producer single-consumer. The producer wakes the network thread
// through an eventfd (Wakeup: one write, no allocation).
#pragma once

#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <vector>

namespace tactile {

// An eventfd the simulation thread signals and the network thread waits on.
class Wakeup {
 public:
  Wakeup() : fd_(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)) {
    if (fd_ < 0) throw std::runtime_error("eventfd failed");
  }
  ~Wakeup() { ::close(fd_); }
  Wakeup(const Wakeup&) = delete;
  Wakeup& operator=(const Wakeup&) = delete;
  int fd() const { return fd_; }
  void signal() {
    const uint64_t one = 1;
    [[maybe_unused]] const ssize_t n = ::write(fd_, &one, sizeof one);
  }
  void drain() {
    uint64_t value;
    [[maybe_unused]] const ssize_t n = ::read(fd_, &value, sizeof value);
  }

 private:
  int fd_;
};

// Frames of any size up to max_frame, each at its own size: a record is an
// 8-byte header (the frame's length) and the frame, padded to 8 bytes, so
// every frame starts 8-aligned (a FlatBuffer reads in place). A record that
// would not fit before the end of the buffer leaves a wrap mark there and
// starts at the beginning. Head and tail count bytes from the start.
class FrameRing {
 public:
  // `capacity` bytes of records (rounded up to 8), left unwritten: no page is
  // touched until a frame lands there.
  FrameRing(size_t capacity, size_t max_frame)
      : capacity_((std::max<size_t>(capacity, 8 + align(max_frame)) + 7) & ~size_t(7)),
        max_frame_(max_frame),
        data_(new uint8_t[capacity_]) {}

  // Producer. False (and counted) when the ring has no room or the frame is too big.
  bool push(const uint8_t* bytes, size_t n) {
    const uint64_t head = head_.load(std::memory_order_relaxed);
    const size_t at = size_t(head % capacity_);
    const size_t need = kHeader + align(n);
    const size_t skip = capacity_ - at < need ? capacity_ - at : 0;  // to the start, past a wrap mark
    if (n > max_frame_ || head + skip + need - tail_.load(std::memory_order_acquire) > capacity_) {
      dropped_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    if (skip) store_length(at, kWrap);
    const size_t start = skip ? 0 : at;
    store_length(start, uint32_t(n));
    std::memcpy(data_.get() + start + kHeader, bytes, n);
    head_.store(head + skip + need, std::memory_order_release);
    return true;
  }

  // Consumer: calls fn(bytes, n) for each frame in order, then frees them.
  template <class Fn>
  size_t drain(Fn&& fn) {
    uint64_t tail = tail_.load(std::memory_order_relaxed);
    const uint64_t head = head_.load(std::memory_order_acquire);
    size_t count = 0;
    while (tail < head) {
      const size_t at = size_t(tail % capacity_);
      const uint32_t n = load_length(at);
      if (n == kWrap) {
        tail += capacity_ - at;
        continue;
      }
      fn(static_cast<const uint8_t*>(data_.get() + at + kHeader), size_t(n));
      tail += kHeader + align(n);
      ++count;
    }
    tail_.store(tail, std::memory_order_release);
    return count;
  }

  int64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }

 private:
  static constexpr size_t kHeader = 8;
  static constexpr uint32_t kWrap = 0xffffffffu;
  static size_t align(size_t n) { return (n + 7) & ~size_t(7); }
  void store_length(size_t at, uint32_t n) { std::memcpy(data_.get() + at, &n, sizeof n); }
  uint32_t load_length(size_t at) const {
    uint32_t n;
    std::memcpy(&n, data_.get() + at, sizeof n);
    return n;
  }

  size_t capacity_;
  size_t max_frame_;
  std::unique_ptr<uint8_t[]> data_;
  alignas(64) std::atomic<uint64_t> head_{0};
  alignas(64) std::atomic<uint64_t> tail_{0};
  std::atomic<int64_t> dropped_{0};
};

}  // namespace tactile
