// A fixed pool of threads that runs the core's parallel passes (ParallelFor).
//
// Built for a step of a few microseconds to a few milliseconds run thousands
// of times a second: the caller thread takes part in every run, workers spin
// briefly between runs (a step's passes follow one another within
// microseconds) and then block, so an idle pool costs no CPU. A run
// allocates nothing and takes no lock.
#pragma once

#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

#include "core/stepper.hpp"

namespace tactile {

class ThreadPool final : public ParallelFor {
 public:
  // `workers` threads take part in each run, the caller's included: workers - 1
  // are started here. workers < 1 counts as 1 (no thread started).
  explicit ThreadPool(int32_t workers);
  ~ThreadPool() override;
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int32_t workers() const override { return workers_; }
  // Runs fn(ctx, i) for i in [0, n), spread over the workers, and returns when
  // all have returned. fn must not throw. Not reentrant: one run at a time.
  void run(int32_t n, void (*fn)(void* ctx, int32_t i), void* ctx) override;

 private:
  void work();
  // Claims and runs indices of job `generation` until none is left.
  void drain(uint32_t generation);

  int32_t workers_;
  std::vector<std::thread> threads_;

  // The current job, written by run() before it publishes the generation and
  // read by a worker only after it has claimed an index of that job (so
  // never while the next job is written).
  void (*fn_)(void*, int32_t) = nullptr;
  void* ctx_ = nullptr;
  int32_t n_ = 0;

  // Generation (high 32 bits) and indices left to claim (low 32 bits), taken
  // one at a time by compare-and-swap: a worker that woke late for an earlier
  // job sees another generation, or none left, and takes nothing.
  alignas(64) std::atomic<uint64_t> claim_{0};
  alignas(64) std::atomic<uint32_t> generation_{0};  // published job; workers wait on it
  alignas(64) std::atomic<int32_t> done_{0};         // indices of the current job finished
  std::atomic<bool> stop_{false};
};

}  // namespace tactile
