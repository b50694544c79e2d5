// A bounded single-producer single-consumer ring: one thread pushes (the
// network thread that reads a device), one pops (the simulation thread).
// Lock-free and allocation-free after construction; push fails when full,
// so a flood of inputs is dropped and counted, never waited for.
#pragma once

#include <atomic>
#include <cstddef>
#include <vector>

namespace tactile {

template <class T>
class SpscRing {
 public:
  explicit SpscRing(size_t capacity) : slots_(capacity + 1) {}

  bool push(const T& value) {
    const size_t head = head_.load(std::memory_order_relaxed);
    const size_t next = head + 1 == slots_.size() ? 0 : head + 1;
    if (next == tail_.load(std::memory_order_acquire)) return false;  // full
    slots_[head] = value;
    head_.store(next, std::memory_order_release);
    return true;
  }

  bool pop(T& out) {
    const size_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_.load(std::memory_order_acquire)) return false;  // empty
    out = slots_[tail];
    tail_.store(tail + 1 == slots_.size() ? 0 : tail + 1, std::memory_order_release);
    return true;
  }

 private:
  std::vector<T> slots_;
  alignas(64) std::atomic<size_t> head_{0};  // next slot to write (producer)
  alignas(64) std::atomic<size_t> tail_{0};  // next slot to read (consumer)
};

}  // namespace tactile
