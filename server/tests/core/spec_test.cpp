#include "core/spec.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "core/fem_fixtures.hpp"

namespace tactile {
namespace {

TEST(MotionProfile, RampEasesFromZeroToTargetWithMatchingDerivatives) {
  MotionProfile p;
  p.kind = MotionProfile::Kind::Ramp;
  p.start = 0.5;
  p.duration = 2.0;
  p.target = std::numbers::pi / 2;
  // Before the start and after the end: at rest.
  for (double t : {-1.0, 0.0, 0.5}) {
    const ProfileValue v = compute_profile(p, t);
    EXPECT_EQ(v.s, 0.0);
    EXPECT_EQ(v.ds, 0.0);
    EXPECT_EQ(v.dds, 0.0);
  }
  for (double t : {2.5, 3.0, 10.0}) {
    const ProfileValue v = compute_profile(p, t);
    EXPECT_DOUBLE_EQ(v.s, p.target);
    EXPECT_EQ(v.ds, 0.0);
  }
  EXPECT_NEAR(compute_profile(p, 1.5).s, p.target / 2, 1e-15);  // half way
  // Inside: ds and dds are the derivatives of s (central differences).
  const double h = 1e-5;
  for (double t = 0.55; t < 2.5; t += 0.1) {
    const ProfileValue v = compute_profile(p, t);
    const ProfileValue vp = compute_profile(p, t + h), vm = compute_profile(p, t - h);
    EXPECT_NEAR(v.ds, (vp.s - vm.s) / (2 * h), 1e-8) << t;
    EXPECT_NEAR(v.dds, (vp.ds - vm.ds) / (2 * h), 1e-7) << t;
    EXPECT_GE(v.ds, 0.0);  // monotonic
  }
  // Continuous at both ends (zero velocity there), so a BC driven by it starts without a jolt.
  EXPECT_NEAR(compute_profile(p, 0.5 + 1e-9).s, 0.0, 1e-12);
  EXPECT_NEAR(compute_profile(p, 2.5 - 1e-9).s, p.target, 1e-12);
  EXPECT_NEAR(compute_profile(p, 0.5 + 1e-9).ds, 0.0, 1e-6);
  EXPECT_NEAR(compute_profile(p, 2.5 - 1e-9).ds, 0.0, 1e-6);
}

TEST(MotionProfile, ZeroDurationRampIsAStepAndConstantRateIsLinear) {
  MotionProfile step;
  step.duration = 0;
  step.target = 3;
  step.start = 1;
  EXPECT_EQ(compute_profile(step, 0.5).s, 0.0);
  EXPECT_EQ(compute_profile(step, 1.5).s, 3.0);
  MotionProfile rate;
  rate.kind = MotionProfile::Kind::ConstantRate;
  rate.start = 1;
  rate.rate = 0.25;
  EXPECT_EQ(compute_profile(rate, 0.5).s, 0.0);
  const ProfileValue v = compute_profile(rate, 5.0);
  EXPECT_DOUBLE_EQ(v.s, 1.0);
  EXPECT_EQ(v.ds, 0.25);
  EXPECT_EQ(v.dds, 0.0);
}

TEST(SelectNodes, BoxPlaneAndListPickTheExpectedNodes) {
  const TetMesh mesh = make_box(Vec3(0.0), Vec3(2.0, 1.0, 1.0), {2, 2, 2});  // nodes on a 3 x 3 x 3 grid
  auto grid = [](int i, int j, int k) { return int32_t(i + 3 * (j + 3 * k)); };

  NodeSelector plane;
  plane.kind = NodeSelector::Kind::Plane;
  plane.point = Vec3(0.0, 1.0, 0.0);
  plane.normal = Vec3(0.0, 2.0, 0.0);  // any length
  std::vector<int32_t> top;
  for (int k = 0; k < 3; ++k)
    for (int i = 0; i < 3; ++i) top.push_back(grid(i, 2, k));
  std::sort(top.begin(), top.end());
  EXPECT_EQ(select_nodes(mesh, plane), top);

  plane.normal = Vec3(1.0, 0.0, 0.0);  // the plane x = 0 through the same point
  EXPECT_EQ(select_nodes(mesh, plane).size(), 9u);
  plane.normal = Vec3(0.0);  // no direction: nothing
  EXPECT_TRUE(select_nodes(mesh, plane).empty());

  NodeSelector box;
  box.kind = NodeSelector::Kind::Box;
  box.lo = Vec3(0.5, -1.0, -1.0);
  box.hi = Vec3(1.5, 2.0, 2.0);  // the middle layer x = 1
  const std::vector<int32_t> mid = select_nodes(mesh, box);
  ASSERT_EQ(mid.size(), 9u);
  for (int32_t i : mid) EXPECT_EQ(mesh.X[size_t(i)].x, 1.0);
  box.lo.x = 1.0 + 1e-3;  // just past it, within the slack of a wider tolerance
  EXPECT_TRUE(select_nodes(mesh, box).empty());
  box.tolerance = 2e-3;
  EXPECT_EQ(select_nodes(mesh, box), mid);

  NodeSelector list;
  list.kind = NodeSelector::Kind::Nodes;
  list.nodes = {5, 3, 5, -1, 1000, 0};
  EXPECT_EQ(select_nodes(mesh, list), (std::vector<int32_t>{0, 3, 5}));  // sorted, unique, in range
}

}  // namespace
}  // namespace tactile
