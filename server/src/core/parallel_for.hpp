// How the core's passes are split over threads without the core starting
// any: the application layer implements it (parallel/thread_pool.hpp).
#pragma once

#include <cstdint>

namespace tactile {

// Runs fn(ctx, i) for i in [0, n) and returns when all calls are done.
class ParallelFor {
 public:
  virtual ~ParallelFor() = default;
  virtual int32_t workers() const = 0;
  virtual void run(int32_t n, void (*fn)(void* ctx, int32_t i), void* ctx) = 0;
};

// Runs fn(ctx, i) for i in [0, n) on `parallel`, or in order on the calling
// thread when there is none (or one index).
inline void run_parallel(ParallelFor* parallel, int32_t n, void (*fn)(void* ctx, int32_t i), void* ctx) {
  if (parallel && n > 1) {
    parallel->run(n, fn, ctx);
    return;
  }
  for (int32_t i = 0; i < n; ++i) fn(ctx, i);
}

}  // namespace tactile
