// Hand-offs from the simulation thread to the network thread that never make
// the simulation wait or allocate:
//   FrameRing  every message kept, in order (haptic frames): a bounded ring
//              of byte slots; when the reader falls behind, new frames are
//              dropped and counted.
//   LatestBox  only the newest message kept (state frames): a triple buffer.
// Both are single-producer single-consumer. The producer wakes the network
// thread through an eventfd (one write, no allocation).
#pragma once

#include <sys/eventfd.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <cstring>
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

class FrameRing {
 public:
  FrameRing(size_t slots, size_t slot_bytes) : slot_bytes_(slot_bytes), data_(slots * slot_bytes), size_(slots) {}

  // Producer. False (and counted) when the ring is full or the frame too big.
  bool push(const uint8_t* bytes, size_t n) {
    const uint64_t head = head_.load(std::memory_order_relaxed);
    if (n > slot_bytes_ || head - tail_.load(std::memory_order_acquire) >= size_.size()) {
      dropped_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    const size_t slot = size_t(head % size_.size());
    std::memcpy(data_.data() + slot * slot_bytes_, bytes, n);
    size_[slot] = uint32_t(n);
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  // Consumer: calls fn(bytes, n) for each frame in order, then frees them.
  template <class Fn>
  size_t drain(Fn&& fn) {
    uint64_t tail = tail_.load(std::memory_order_relaxed);
    const uint64_t head = head_.load(std::memory_order_acquire);
    const size_t count = size_t(head - tail);
    for (; tail < head; ++tail) {
      const size_t slot = size_t(tail % size_.size());
      fn(data_.data() + slot * slot_bytes_, size_t(size_[slot]));
    }
    tail_.store(tail, std::memory_order_release);
    return count;
  }

  int64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }

 private:
  size_t slot_bytes_;
  std::vector<uint8_t> data_;
  std::vector<uint32_t> size_;
  alignas(64) std::atomic<uint64_t> head_{0};
  alignas(64) std::atomic<uint64_t> tail_{0};
  std::atomic<int64_t> dropped_{0};
};

class LatestBox {
 public:
  explicit LatestBox(size_t capacity) {
    for (auto& b : buffers_) b.reserve(capacity);
  }

  // Producer: the newest message replaces any the consumer has not taken.
  // Allocation-free while messages fit the capacity given.
  void put(const uint8_t* bytes, size_t n) {
    std::vector<uint8_t>& back = buffers_[back_];
    back.assign(bytes, bytes + n);
    // Publish the back buffer; take the one that was waiting (or stale) as the new back.
    const uint8_t previous = state_.exchange(uint8_t(back_ | kFresh), std::memory_order_acq_rel);
    back_ = previous & kIndex;
  }

  // Consumer: the newest message, if one arrived since the last take.
  const std::vector<uint8_t>* take() {
    if (!(state_.load(std::memory_order_acquire) & kFresh)) return nullptr;
    const uint8_t previous = state_.exchange(front_, std::memory_order_acq_rel);
    front_ = previous & kIndex;
    return &buffers_[front_];
  }

 private:
  static constexpr uint8_t kIndex = 3, kFresh = 4;
  std::vector<uint8_t> buffers_[3];
  uint8_t back_ = 0;               // producer's
  uint8_t front_ = 1;              // consumer's
  std::atomic<uint8_t> state_{2};  // the middle buffer's index, | kFresh when it holds a new message
};

}  // namespace tactile
