// The thread pool: every index runs exactly once per run, runs are truly
// concurrent and include the caller, idle workers wake for the next run, the
// stepper gives the same motion on it as on one thread, and contact between
// bodies split over it finds the same points and gives the same impulses.
#include "parallel/thread_pool.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>
#include <vector>

#include "core/bodies.hpp"
#include "core/contact/body_contact.hpp"
#include "core/model.hpp"
#include "core/stepper.hpp"
#include "mesh/primitives.hpp"

namespace tactile {
namespace {

struct Counts {
  std::vector<std::atomic<int32_t>> hits;
  explicit Counts(size_t n) : hits(n) {}
};

void count_hit(void* ctx, int32_t i) { static_cast<Counts*>(ctx)->hits[size_t(i)].fetch_add(1); }

TEST(ThreadPool, ReportsItsWorkersCallerIncluded) {
  EXPECT_EQ(ThreadPool(3).workers(), 3);
  EXPECT_EQ(ThreadPool(1).workers(), 1);
  EXPECT_EQ(ThreadPool(0).workers(), 1);
}

TEST(ThreadPool, RunsEveryIndexExactlyOncePerRun) {
  ThreadPool pool(3);
  for (int32_t n : {0, 1, 2, 3, 5, 64, 1000}) {
    Counts counts(size_t(std::max(n, 1)));
    constexpr int kRuns = 200;  // back to back, so late workers meet the next run
    for (int r = 0; r < kRuns; ++r) pool.run(n, &count_hit, &counts);
    for (int32_t i = 0; i < n; ++i) {
      ASSERT_EQ(counts.hits[size_t(i)].load(), kRuns) << "n = " << n << ", i = " << i;
    }
    if (n == 0) {
      EXPECT_EQ(counts.hits[0].load(), 0);
    }
  }
}

// Each task waits until all `n` have started, which only concurrent workers
// can achieve; a bounded wait turns a serial pool into a failure, not a hang.
struct Rendezvous {
  int32_t n = 0;
  std::atomic<int32_t> arrived{0};
  std::atomic<bool> timed_out{false};
  std::vector<std::thread::id> ran_on;
};

void meet(void* ctx, int32_t i) {
  auto* r = static_cast<Rendezvous*>(ctx);
  r->ran_on[size_t(i)] = std::this_thread::get_id();
  r->arrived.fetch_add(1);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (r->arrived.load() < r->n) {
    if (std::chrono::steady_clock::now() > deadline) {
      r->timed_out = true;
      return;
    }
    std::this_thread::yield();
  }
}

TEST(ThreadPool, RunsConcurrentlyOnAllWorkersAndTheCaller) {
  ThreadPool pool(3);
  for (int round = 0; round < 20; ++round) {
    Rendezvous r;
    r.n = 3;
    r.ran_on.resize(3);
    pool.run(3, &meet, &r);
    ASSERT_FALSE(r.timed_out) << "tasks did not all run at once (round " << round << ")";
    std::vector<std::thread::id> ids = r.ran_on;
    std::sort(ids.begin(), ids.end());
    EXPECT_EQ(std::unique(ids.begin(), ids.end()), ids.end()) << "two tasks shared a thread";
    EXPECT_NE(std::find(ids.begin(), ids.end(), std::this_thread::get_id()), ids.end()) << "the caller took no part";
  }
}

TEST(ThreadPool, WorkersThatWentToSleepWakeForTheNextRun) {
  ThreadPool pool(2);
  for (int round = 0; round < 3; ++round) {
    // Long enough for the workers to stop spinning and block.
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
    Rendezvous r;
    r.n = 2;
    r.ran_on.resize(2);
    pool.run(2, &meet, &r);
    EXPECT_FALSE(r.timed_out);
  }
}  // and the destructor must wake and join blocked workers

// A beam swinging freely: two parts on the pool sum the same forces in
// another order, so the motion agrees with one thread to round-off.
template <class Real>
std::vector<Real> swing(ParallelFor* pool, int32_t threads) {
  ModelSpec spec;
  spec.mesh = make_box(Vec3(0.0), Vec3(0.4, 0.1, 0.1), {32, 8, 8});  // 12 k tets: enough for two parts
  spec.materials = {MaterialSpec{MaterialModel::StVK, 1e5, 0.3, 1000}};
  spec.integrator.threads = threads;
  const Model<Real> model = build_model<Real>(spec);
  Stepper<Real> stepper(model, pool);
  EXPECT_EQ(stepper.parts(), threads);
  State<Real> s = stepper.make_state();
  for (int32_t i = 0; i < model.n_nodes; ++i) {
    const Vec3& X = model.mesh.X[size_t(i)];
    s.v[3 * size_t(i) + 1] = Real(5.0 * X.x * X.x);  // a bending swing [m/s]
    s.v[3 * size_t(i) + 2] = Real(2.0 * X.x * (X.y - 0.05));
  }
  for (int k = 0; k < 100; ++k) EXPECT_FALSE(stepper.step(s, 0.5 * model.dt_rest)) << s.fault.message;
  return s.u;
}

TEST(ThreadPool, StepperOnTwoPartsMovesAsOnOne) {
  ThreadPool pool(2);
  const std::vector<double> one = swing<double>(nullptr, 1), two = swing<double>(&pool, 2);
  double scale = 0, diff = 0;
  for (size_t k = 0; k < one.size(); ++k) {
    scale = std::max(scale, std::fabs(one[k]));
    diff = std::max(diff, std::fabs(one[k] - two[k]));
  }
  ASSERT_GT(scale, 1e-3);  // it did move
  EXPECT_LT(diff, 1e-12 * scale);
}

// Two plates of 16 x 16 x 1 cells, the upper let fall onto the lower (held at
// its base) under gravity: over a thousand surface nodes and some thousands
// of listed pairs, enough for the body contact to split each pass. At each
// step the same state goes through a body contact on one thread and one on
// the pool: the listed pairs are tested in parts, and their points gathered
// in vertex order, so the two give the same velocities to the last bit.
TEST(ThreadPool, BodyContactSplitOverThreadsGivesTheSameImpulses) {
  std::vector<BodyParts> parts(2);
  for (int b = 0; b < 2; ++b) {
    parts[size_t(b)].name = b == 0 ? "bed" : "plate";
    const double y0 = b == 0 ? 0.0 : 0.0101;
    parts[size_t(b)].mesh = make_box(Vec3(-0.1, y0, -0.1), Vec3(0.1, y0 + 0.01, 0.1), {16, 1, 16});
    parts[size_t(b)].materials = {MaterialSpec{MaterialModel::Corotational, 5e4, 0.3, 1000}};
  }
  EssentialBc base;
  base.name = "base";
  base.where.kind = NodeSelector::Kind::Box;
  base.where.lo = Vec3(-1.0);
  base.where.hi = Vec3(1.0, 1e-9, 1.0);
  parts[0].essential = {base};
  ModelSpec spec;
  add_bodies(spec, std::move(parts));
  spec.effects.body_contact = true;
  spec.effects.gravity = true;
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  ThreadPool pool(2);
  BodyContact<double> one(model), split(model, &pool);
  State<double> s = stepper.make_state();
  const double dt = 0.5 * model.dt_rest;
  int32_t most = 0;
  for (int k = 0; k < 400; ++k) {
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    State<double> a = s, b = s;
    one.apply(a, dt, dt);
    split.apply(b, dt, dt);
    ASSERT_EQ(one.body_contacts(), split.body_contacts()) << "step " << k;
    most = std::max(most, one.body_contacts());
    ASSERT_EQ(a.v, b.v) << "step " << k;
    ASSERT_EQ(a.a, b.a) << "step " << k;
  }
  EXPECT_GT(most, 200);  // the plate lay on the bed
}

}  // namespace
}  // namespace tactile
