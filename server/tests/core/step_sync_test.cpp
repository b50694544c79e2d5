// The split step's hand-offs (core/step_sync.hpp), on real threads: a job
// asked for by every thread runs exactly once per step, and no thread goes on
// before it is done; two threads claiming a pair's middle from its two ends
// take every chunk exactly once, whichever is faster.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <thread>
#include <vector>

#include "core/step_sync.hpp"

namespace tactile {
namespace {

TEST(StepSync, AJobAskedForByEveryThreadRunsOnceAStepAndAllWaitForIt) {
  constexpr int kThreads = 3, kSteps = 500;  // (the harness yields: this machine may have 2 cores)
  OnceClaim claim;
  std::atomic<int> runs{0};
  std::atomic<int> early{0};  // threads that returned before the job was done
  std::vector<int> done_in(kSteps + 1, 0);
  std::atomic<uint32_t> go{0};
  std::atomic<int> arrived{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&] {
      for (uint32_t epoch = 1; epoch <= kSteps; ++epoch) {
        while (go.load(std::memory_order_acquire) < epoch) std::this_thread::yield();
        run_once(claim, epoch, [&] {
          runs.fetch_add(1, std::memory_order_relaxed);
          done_in[epoch] = 1;
        });
        if (done_in[epoch] != 1) early.fetch_add(1, std::memory_order_relaxed);
        arrived.fetch_add(1, std::memory_order_acq_rel);
      }
    });
  }
  for (uint32_t epoch = 1; epoch <= kSteps; ++epoch) {
    go.store(epoch, std::memory_order_release);
    while (arrived.load(std::memory_order_acquire) < int(epoch) * kThreads) std::this_thread::yield();
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(runs.load(), kSteps);
  EXPECT_EQ(early.load(), 0);
}

TEST(StepSync, TwoSidesOfAPairTakeEveryChunkOnce) {
  constexpr int32_t kChunks = 1000;
  for (int round = 0; round < 50; ++round) {
    PairShare share;
    share.reset(0, kChunks);
    std::vector<std::atomic<int>> taken(kChunks);
    std::vector<int32_t> mine[2];
    std::atomic<bool> go{false};
    auto side = [&](int s) {
      while (!go.load(std::memory_order_acquire)) cpu_relax();
      for (int32_t c; (c = share.claim(s)) >= 0;) {
        taken[size_t(c)].fetch_add(1, std::memory_order_relaxed);
        mine[s - 1].push_back(c);
      }
    };
    std::thread left(side, 1), right(side, 2);
    go.store(true, std::memory_order_release);
    left.join();
    right.join();
    for (int32_t c = 0; c < kChunks; ++c) ASSERT_EQ(taken[size_t(c)].load(), 1) << "chunk " << c << ", round " << round;
    // Each side took a contiguous run from its own end.
    for (size_t k = 0; k < mine[0].size(); ++k) ASSERT_EQ(mine[0][k], int32_t(k));
    for (size_t k = 0; k < mine[1].size(); ++k) ASSERT_EQ(mine[1][k], kChunks - 1 - int32_t(k));
    EXPECT_EQ(share.claim(1), -1);
    EXPECT_EQ(share.claim(2), -1);
  }
}

TEST(StepSync, ARegionIsDoneOnlyInTheStepItWasPublishedIn) {
  RegionDone r;
  EXPECT_FALSE(r.done(1));
  r.publish(1);
  EXPECT_TRUE(r.done(1));
  EXPECT_FALSE(r.done(2));
  std::atomic<bool> passed{false};
  std::thread waiter([&] {
    r.wait(2);
    passed.store(true, std::memory_order_release);
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_FALSE(passed.load(std::memory_order_acquire)) << "went on before the region was done";
  r.publish(2);
  waiter.join();
  EXPECT_TRUE(passed.load());
}

}  // namespace
}  // namespace tactile
