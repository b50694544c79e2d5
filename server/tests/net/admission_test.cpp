// Who gets in (net/admission.hpp), without a socket: one test per rule, on
// Origins, Hosts and waiting pools written inline.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "net/admission.hpp"

namespace tactile {
namespace {

using namespace std::chrono_literals;

// ---- Origin and Host ---------------------------------------------------------------------

const std::vector<std::string> none;

TEST(OriginAllowed, ThisServersOwnPagesAtItsPortOnly) {
  for (const char* o : {"http://localhost:8765", "http://127.0.0.1:8765", "http://[::1]:8765"})
    EXPECT_TRUE(origin_allowed(o, 8765, none)) << o;
  for (const char* o : {"http://localhost:8766", "https://localhost:8765", "http://localhost", "http://evil.example",
                        "null", "http://127.0.0.1:8765.evil.example"})
    EXPECT_FALSE(origin_allowed(o, 8765, none)) << o;
}

TEST(OriginAllowed, AnAllowedOriginExactlyAsNamed) {
  const std::vector<std::string> allowed{"http://sim.lab:8765"};
  EXPECT_TRUE(origin_allowed("http://sim.lab:8765", 8765, allowed));
  EXPECT_FALSE(origin_allowed("http://sim.lab:9999", 8765, allowed));
  EXPECT_FALSE(origin_allowed("http://SIM.lab:8765.evil", 8765, allowed));
}

TEST(HostAllowed, LoopbackNamesAtAnyPortAndInAnyCase) {
  for (const char* h : {"localhost:8765", "LOCALHOST", "127.0.0.1:1", "[::1]:8765", "[::1]"})
    EXPECT_TRUE(host_allowed(h, "127.0.0.1", none)) << h;
}

TEST(HostAllowed, TheBoundAddressAndTheHostsOfAllowedOrigins) {
  const std::vector<std::string> allowed{"http://sim.lab:8765", "http://[fd00::7]:8765"};
  EXPECT_TRUE(host_allowed("10.0.0.5:8765", "10.0.0.5", allowed));
  EXPECT_TRUE(host_allowed("Sim.Lab:8765", "0.0.0.0", allowed));
  EXPECT_TRUE(host_allowed("[fd00::7]:8765", "0.0.0.0", allowed));
}

TEST(HostAllowed, AnotherSitesNameIsRefused) {
  // A page of another site whose name was made to resolve here (DNS rebinding) sends its own name.
  const std::vector<std::string> allowed{"http://sim.lab:8765"};
  for (const char* h : {"evil.example:8765", "sim.lab.evil.example", "", ":8765", "0.0.0.0:8765"})
    EXPECT_FALSE(host_allowed(h, "10.0.0.5", allowed)) << "'" << h << "'";
}

// ---- waiting slots -----------------------------------------------------------------------

const ConnectionClock::time_point t0{};
const AdmissionLimits small{.max_connections = 10, .max_waiting = 4, .hello_grace_s = 1.0};

TEST(Admission, AGreetedServerAtMaxConnectionsRefusesAndSaysSo) {
  const Admission a = decide_admission({}, 10, t0, small);
  EXPECT_FALSE(a.admit);
  EXPECT_EQ(a.evict, 0u);
  EXPECT_NE(a.reason.find("server full: 10 connections"), std::string::npos) << a.reason;
}

TEST(Admission, ACrowdFromOneAddressIsAdmittedWhileThePoolHasRoom) {
  // Three waiting from the newcomer's own address, all past their grace: no
  // one is evicted while the pool has room (the old rule capped an address at 8).
  const std::vector<WaitingSlot> waiting = {{1, "127.0.0.1", t0}, {2, "127.0.0.1", t0}, {3, "127.0.0.1", t0}};
  const Admission a = decide_admission(waiting, 5, t0 + 10s, small);
  EXPECT_TRUE(a.admit);
  EXPECT_EQ(a.evict, 0u);
}

TEST(Admission, AFullPoolEvictsTheOldestOfTheAddressHoldingTheMost) {
  // 10.0.0.9 holds three, 10.0.0.1 one (the oldest of all): the flood's
  // oldest goes, not the lone client's.
  const std::vector<WaitingSlot> waiting = {
      {1, "10.0.0.1", t0}, {2, "10.0.0.9", t0 + 1s}, {3, "10.0.0.9", t0 + 2s}, {4, "10.0.0.9", t0 + 3s}};
  const Admission a = decide_admission(waiting, 0, t0 + 10s, small);
  EXPECT_TRUE(a.admit);
  EXPECT_EQ(a.evict, 2u);
  EXPECT_NE(a.reason.find("3 from 10.0.0.9"), std::string::npos) << a.reason;
  EXPECT_NE(a.reason.find("no Hello after 9.0 s"), std::string::npos) << a.reason;
}

TEST(Admission, AConnectionInsideItsGraceIsNeverEvicted) {
  // The address holding the most has only fresh connections: the stale one
  // of the other address goes, though that address holds fewer.
  const std::vector<WaitingSlot> waiting = {
      {1, "10.0.0.1", t0}, {2, "10.0.0.9", t0 + 9500ms}, {3, "10.0.0.9", t0 + 9600ms}, {4, "10.0.0.9", t0 + 9700ms}};
  const Admission a = decide_admission(waiting, 0, t0 + 10s, small);
  EXPECT_TRUE(a.admit);
  EXPECT_EQ(a.evict, 1u);
}

TEST(Admission, APoolFullOfFreshConnectionsRefusesTheNewcomer) {
  const std::vector<WaitingSlot> waiting = {
      {1, "10.0.0.1", t0}, {2, "10.0.0.1", t0}, {3, "10.0.0.2", t0}, {4, "10.0.0.3", t0 + 100ms}};
  const Admission a = decide_admission(waiting, 0, t0 + 900ms, small);
  EXPECT_FALSE(a.admit);
  EXPECT_EQ(a.evict, 0u);
  EXPECT_NE(a.reason.find("4 connections are waiting to say Hello"), std::string::npos) << a.reason;
  EXPECT_NE(a.reason.find("try again"), std::string::npos) << a.reason;
}

TEST(Admission, AmongEquallyFullAddressesTheOldestStaleConnectionGoes) {
  const std::vector<WaitingSlot> waiting = {
      {1, "10.0.0.1", t0 + 2s}, {2, "10.0.0.1", t0 + 3s}, {3, "10.0.0.2", t0 + 1s}, {4, "10.0.0.2", t0 + 4s}};
  const Admission a = decide_admission(waiting, 0, t0 + 10s, small);
  EXPECT_TRUE(a.admit);
  EXPECT_EQ(a.evict, 3u);
}

TEST(Admission, TheGreetedDoNotTakeWaitingSlots) {
  // Nine greeted (one short of max_connections) and a pool with room: admitted.
  const std::vector<WaitingSlot> waiting = {{1, "10.0.0.1", t0}};
  EXPECT_TRUE(decide_admission(waiting, 9, t0, small).admit);
}

TEST(LogBudget, OneLineASecondAndTheRestCounted) {
  LogBudget log(1.0);
  EXPECT_TRUE(log.take(t0));
  EXPECT_EQ(log.held_back(), 0);
  for (int k = 1; k <= 5; ++k) EXPECT_FALSE(log.take(t0 + k * 100ms));
  EXPECT_TRUE(log.take(t0 + 1s));
  EXPECT_EQ(log.held_back(), 5);
  EXPECT_FALSE(log.take(t0 + 1500ms));
  EXPECT_TRUE(log.take(t0 + 2500ms));
  EXPECT_EQ(log.held_back(), 1);
}

}  // namespace
}  // namespace tactile
