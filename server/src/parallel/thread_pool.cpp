#include "parallel/thread_pool.hpp"

#include <immintrin.h>

namespace tactile {

namespace {

// Between polls of a spinning wait: a hint to the core (and its hyperthread sibling).
inline void relax() { _mm_pause(); }

// How many polls a worker spins for the next job before it blocks: far
// longer than the gaps between a step's passes, short enough that an idle
// pool soon costs nothing; a blocked worker wakes through the futex, much
// later (docs/perf.md, Threads; guarded by `fem_bench --only=threads`).
constexpr int kSpinPolls = 2000;

}  // namespace

ThreadPool::ThreadPool(int32_t workers) : workers_(workers < 1 ? 1 : workers) {
  threads_.reserve(size_t(workers_ - 1));
  for (int32_t k = 1; k < workers_; ++k) threads_.emplace_back([this] { work(); });
}

ThreadPool::~ThreadPool() {
  stop_.store(true);
  generation_.fetch_add(1);
  generation_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void ThreadPool::run(int32_t n, void (*fn)(void*, int32_t), void* ctx) {
  if (n <= 0) return;
  if (threads_.empty() || n == 1) {
    for (int32_t i = 0; i < n; ++i) fn(ctx, i);
    return;
  }
  fn_ = fn;
  ctx_ = ctx;
  n_ = n;
  done_.store(0, std::memory_order_relaxed);
  const uint32_t g = generation_.load(std::memory_order_relaxed) + 1;
  claim_.store(uint64_t(g) << 32 | uint32_t(n), std::memory_order_release);
  generation_.store(g, std::memory_order_release);  // publishes the job
  generation_.notify_all();
  drain(g);
  // The caller's own claims ran out: wait for the tasks still running.
  while (done_.load(std::memory_order_acquire) < n) relax();
}

void ThreadPool::drain(uint32_t generation) {
  uint64_t c = claim_.load(std::memory_order_acquire);
  for (;;) {
    const auto left = uint32_t(c);
    if (uint32_t(c >> 32) != generation || left == 0) return;
    if (!claim_.compare_exchange_weak(c, c - 1, std::memory_order_acq_rel, std::memory_order_acquire)) continue;
    // Claimed: the job cannot finish, nor the next one start, before this index is done.
    fn_(ctx_, n_ - int32_t(left));
    done_.fetch_add(1, std::memory_order_release);
    c = claim_.load(std::memory_order_acquire);
  }
}

void ThreadPool::work() {
  uint32_t seen = 0;
  for (;;) {
    uint32_t g = generation_.load(std::memory_order_acquire);
    for (int k = 0; g == seen && k < kSpinPolls; ++k) {
      relax();
      g = generation_.load(std::memory_order_acquire);
    }
    while (g == seen) {
      generation_.wait(seen, std::memory_order_acquire);
      g = generation_.load(std::memory_order_acquire);
    }
    seen = g;
    if (stop_.load()) return;
    drain(g);
  }
}

}  // namespace tactile
