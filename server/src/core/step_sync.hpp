// The lock-free hand-offs between the parts of a split step (core/stepper.cpp,
// elastic_part): a job run once whichever threads ask for it, a region's
// "forces complete" flag, and the middle chunks two parts of a pair share.
// Each sits on a cache line of its own, so that a thread polling one does not
// slow the thread writing its neighbour. Waits spin: a step lasts tens to
// hundreds of microseconds, and a futex wake-up costs as much as a pass
// (fem_bench --only=threads; docs/perf.md, Threads).
#pragma once

#include <atomic>
#include <cstdint>

namespace tactile {

// Between polls of a spinning wait.
inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

// A job to be run once per step: (epoch << 2) | 1 while a thread is at it,
// | 2 once done.
struct alignas(64) OnceClaim {
  std::atomic<uint64_t> state{0};
};

// Runs `work` once in step `epoch`, whichever threads ask: the first claims
// it and runs it; the others wait while it is at it and return once it is
// done. A thread never waits for a job nobody has started.
template <class Fn>
void run_once(OnceClaim& claim, uint32_t epoch, Fn&& work) {
  std::atomic<uint64_t>& state = claim.state;
  const uint64_t claimed = uint64_t(epoch) << 2 | 1, done = uint64_t(epoch) << 2 | 2;
  uint64_t v = state.load(std::memory_order_acquire);
  for (;;) {
    if (v == done) return;
    if (v == claimed) {  // another thread is at it
      cpu_relax();
      v = state.load(std::memory_order_acquire);
      continue;
    }
    if (!state.compare_exchange_weak(v, claimed, std::memory_order_acq_rel, std::memory_order_acquire)) continue;
    work();
    state.store(done, std::memory_order_release);
    return;
  }
}

// The step (epoch) whose forces a region holds in full.
struct alignas(64) RegionDone {
  std::atomic<uint32_t> epoch{0};

  void publish(uint32_t e) { epoch.store(e, std::memory_order_release); }
  bool done(uint32_t e) const { return epoch.load(std::memory_order_acquire) == e; }
  // Returns once the region is done in step e (a thread has claimed it).
  void wait(uint32_t e) const {
    while (!done(e)) cpu_relax();
  }
};

// The chunks of a pair's middle not yet claimed, [left, right) as indices
// into the plan's chunks (left in the low 32 bits). Side 1 claims from the
// left end, side 2 from the right, until the two meet.
struct alignas(64) PairShare {
  std::atomic<uint64_t> ends{0};

  // Before the step's jobs start; the pool's hand-off publishes it.
  void reset(int32_t left, int32_t right) {
    ends.store(uint64_t(uint32_t(right)) << 32 | uint32_t(left), std::memory_order_relaxed);
  }
  // The next chunk from `side`, or -1 once none is left.
  int32_t claim(int side) {
    uint64_t e = ends.load(std::memory_order_relaxed);
    for (;;) {
      const auto l = int32_t(uint32_t(e)), r = int32_t(e >> 32);
      if (l >= r) return -1;
      const uint64_t next =
          side == 1 ? (uint64_t(uint32_t(r)) << 32 | uint32_t(l + 1)) : (uint64_t(uint32_t(r - 1)) << 32 | uint32_t(l));
      if (ends.compare_exchange_weak(e, next, std::memory_order_relaxed)) return side == 1 ? l : r - 1;
    }
  }
};

}  // namespace tactile
