// The simulation thread's hand-off (live/mailbox.hpp): frames of any size
// come out whole, in order, 8-aligned, across the end of the buffer; a full
// ring or a frame too big drops the new one and counts it; a producer and a
// consumer on two threads lose nothing the ring had room for.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <cstring>
#include <thread>
#include <vector>

#include "live/mailbox.hpp"

namespace tactile {
namespace {

std::vector<uint8_t> frame(uint32_t i) {
  std::vector<uint8_t> f(4 + (i * 37) % 200);
  for (size_t k = 0; k < f.size(); ++k) f[k] = uint8_t(i + k * 7);
  std::memcpy(f.data(), &i, 4);
  return f;
}

TEST(FrameRing, FramesOfAnySizeComeOutWholeInOrderAcrossTheEnd) {
  FrameRing ring(1024, 256);
  uint32_t pushed = 0, taken = 0;
  for (int round = 0; round < 200; ++round) {  // many times round a 1 KiB buffer
    for (int k = 0; k < 3; ++k) {
      const std::vector<uint8_t> f = frame(pushed);
      ASSERT_TRUE(ring.push(f.data(), f.size())) << "frame " << pushed;
      ++pushed;
    }
    ring.drain([&](const uint8_t* data, size_t n) {
      EXPECT_EQ(reinterpret_cast<uintptr_t>(data) % 8, 0u);
      EXPECT_EQ(std::vector<uint8_t>(data, data + n), frame(taken)) << "frame " << taken;
      ++taken;
    });
  }
  EXPECT_EQ(taken, pushed);
  EXPECT_EQ(ring.dropped(), 0);
}

TEST(FrameRing, AFullRingAndAFrameTooBigDropTheNewOneAndCountIt) {
  FrameRing ring(256, 64);
  const std::vector<uint8_t> f(56, 1);  // 64 B a record
  int pushed = 0;
  while (ring.push(f.data(), f.size())) ++pushed;
  EXPECT_EQ(pushed, 4);
  EXPECT_EQ(ring.dropped(), 1);
  const std::vector<uint8_t> big(65, 2);
  ring.drain([](const uint8_t*, size_t) {});
  EXPECT_FALSE(ring.push(big.data(), big.size()));
  EXPECT_EQ(ring.dropped(), 2);
  std::vector<size_t> sizes;
  EXPECT_TRUE(ring.push(f.data(), 3));
  ring.drain([&](const uint8_t*, size_t n) { sizes.push_back(n); });
  EXPECT_EQ(sizes, std::vector<size_t>{3}) << "the dropped ones left nothing behind";
}

TEST(FrameRing, TwoThreadsLoseNothingTheRingHadRoomFor) {
  FrameRing ring(4096, 256);
  constexpr uint32_t kFrames = 200000;
  std::atomic<bool> done{false};
  std::vector<uint32_t> seen;
  std::thread consumer([&] {
    auto take = [&](const uint8_t* data, size_t n) {
      uint32_t i;
      std::memcpy(&i, data, 4);
      if (std::vector<uint8_t>(data, data + n) != frame(i)) i = UINT32_MAX;  // torn
      seen.push_back(i);
    };
    while (!done.load()) ring.drain(take);
    ring.drain(take);
  });
  uint32_t accepted = 0;
  for (uint32_t i = 0; i < kFrames; ++i) {
    const std::vector<uint8_t> f = frame(i);
    if (ring.push(f.data(), f.size())) ++accepted;
  }
  done = true;
  consumer.join();
  EXPECT_EQ(seen.size(), accepted);
  EXPECT_EQ(int64_t(kFrames - accepted), ring.dropped());
  for (size_t k = 1; k < seen.size(); ++k) ASSERT_LT(seen[k - 1], seen[k]) << "out of order or torn at " << k;
}

}  // namespace
}  // namespace tactile
