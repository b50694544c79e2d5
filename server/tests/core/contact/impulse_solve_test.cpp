// The contact impulses on hand-built points (core/contact/impulse_solve.hpp):
// eq. (11)'s projection for one point, never a pull, Coulomb's cone, points
// that share nodes pushing no more than they need, and momentum passed
// exactly to a coupled body.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include <glm/geometric.hpp>

#include "core/contact/impulse_solve.hpp"

namespace tactile {
namespace {

// A point on the given slots and weights, of a kinematic proxy (0) at rest, its outward normal n.
ContactPoint point(std::vector<int32_t> slots, std::vector<double> w, const std::vector<double>& mass, const Vec3& n,
                   double mu = 0) {
  ContactPoint c{};
  c.proxy = 0;
  c.body = -1;
  c.slot.fill(-1);
  c.inv_mass = 0;
  for (size_t j = 0; j < slots.size(); ++j) {
    c.slot[j] = slots[j];
    c.w[j] = w[j];
    c.inv_mass += w[j] * w[j] / mass[size_t(slots[j])];
  }
  c.n = n;
  c.vp = c.v_held = c.r = Vec3(0.0);
  c.mu = mu;
  return c;
}

// The velocity of a point after the solve.
Vec3 velocity_after(const ImpulseSolve& solve, const ContactPoint& c, const std::vector<Vec3>& v) {
  Vec3 u = c.v_held;
  for (size_t j = 0; j < kPointCarriers && c.slot[j] >= 0; ++j)
    u += c.w[j] * (v[size_t(c.slot[j])] + solve.dv(c.slot[j]));
  return u;
}

TEST(ImpulseSolve, OnePointLosesItsNormalVelocityIntoTheProxyAndKeepsItsTangentialOne) {
  const std::vector<double> mass{0.2};
  const std::vector<Vec3> v{Vec3(0.3, -0.5, 0.0)};  // into a proxy below it (n points up, out of the proxy)
  std::vector<ContactPoint> points{point({0}, {1.0}, mass, Vec3(0, 1, 0))};
  std::vector<CoupledBodyState> bodies;
  ImpulseSolve solve;
  solve.reserve(1, 1, 1);
  solve.solve(points, 1, bodies, v, mass);
  const Vec3 u = velocity_after(solve, points[0], v);
  EXPECT_NEAR(u.y, 0.0, 1e-15);  // eq. (11): v - (v . n) n
  EXPECT_NEAR(u.x, 0.3, 1e-15);
  EXPECT_NEAR(points[0].jn, 0.2 * 0.5, 1e-15);  // m |v . n|
}

TEST(ImpulseSolve, APointMovingOutOfTheProxyIsNotPulledBack) {
  const std::vector<double> mass{0.2};
  const std::vector<Vec3> v{Vec3(0.0, 0.4, 0.0)};
  std::vector<ContactPoint> points{point({0}, {1.0}, mass, Vec3(0, 1, 0))};
  std::vector<CoupledBodyState> bodies;
  ImpulseSolve solve;
  solve.reserve(1, 1, 1);
  solve.solve(points, 1, bodies, v, mass);
  EXPECT_EQ(points[0].jn, 0.0);
  EXPECT_TRUE(solve.moved().empty());
}

TEST(ImpulseSolve, FrictionSticksWithinTheConeAndSlidesAtItsBound) {
  const std::vector<double> mass{1.0, 1.0};
  // Slot 0 slides slowly (sticks: 0.1 m/s of tangential motion against mu 0.5 of a 1 N s normal impulse);
  // slot 1 fast (slides: 2 m/s needs more than the cone allows).
  const std::vector<Vec3> v{Vec3(0.1, -1.0, 0.0), Vec3(2.0, -1.0, 0.0)};
  std::vector<ContactPoint> points{point({0}, {1.0}, mass, Vec3(0, 1, 0), 0.5),
                                   point({1}, {1.0}, mass, Vec3(0, 1, 0), 0.5)};
  std::vector<CoupledBodyState> bodies;
  ImpulseSolve solve;
  solve.reserve(2, 1, 2);
  solve.solve(points, 1, bodies, v, mass);
  EXPECT_NEAR(velocity_after(solve, points[0], v).x, 0.0, 1e-12);  // stuck
  EXPECT_NEAR(glm::length(points[0].jt), 0.1, 1e-12);
  EXPECT_NEAR(glm::length(points[1].jt), 0.5 * points[1].jn, 1e-12);  // on the cone
  EXPECT_NEAR(velocity_after(solve, points[1], v).x, 2.0 - 0.5, 1e-12);
  for (const ContactPoint& c : points) EXPECT_LE(glm::length(c.jt), c.mu * c.jn * (1 + 1e-12));
}

TEST(ImpulseSolve, PointsSharingANodeStopTogetherWithTheLeastImpulse) {
  // A face point halfway between slots 0 and 1, and slot 0's own point, all moving down at 1 m/s.
  const std::vector<double> mass{1.0, 1.0};
  const std::vector<Vec3> v{Vec3(0, -1, 0), Vec3(0, -1, 0)};
  std::vector<ContactPoint> points{point({0}, {1.0}, mass, Vec3(0, 1, 0)),
                                   point({0, 1}, {0.5, 0.5}, mass, Vec3(0, 1, 0))};
  std::vector<CoupledBodyState> bodies;
  ImpulseSolve solve;
  solve.reserve(2, 1, 2);
  solve.solve(points, 1, bodies, v, mass);
  for (const ContactPoint& c : points) EXPECT_GE(velocity_after(solve, c, v).y, -1e-6);
  // Stopping both nodes takes 2 N s; the sweeps reach it without pushing either node up.
  EXPECT_NEAR(points[0].jn + points[1].jn, 2.0, 1e-6);
  EXPECT_NEAR(solve.dv(0).y, 1.0, 1e-6);
  EXPECT_NEAR(solve.dv(1).y, 1.0, 1e-6);
}

TEST(ImpulseSolve, MomentumPassesExactlyToACoupledBody) {
  // Three nodes pressed by a coupled body moving down and spinning; the points off its centre.
  const std::vector<double> mass{0.05, 0.08, 0.11};
  const std::vector<Vec3> v{Vec3(0.0, 0.1, 0.0), Vec3(0.02, 0.0, 0.0), Vec3(0.0, -0.05, 0.01)};
  CoupledBodyState b;
  b.c.mass = 0.3;
  b.c.inertia = 2e-4;
  b.next.v = Vec3(0.05, -0.8, 0.0);
  b.next.w = Vec3(0.0, 0.0, 3.0);
  std::vector<CoupledBodyState> bodies{b};
  std::vector<ContactPoint> points;
  const Vec3 offsets[] = {Vec3(-0.01, -0.02, 0.0), Vec3(0.012, -0.019, 0.004), Vec3(0.0, -0.02, -0.01)};
  for (int32_t k = 0; k < 3; ++k) {
    ContactPoint c = point({k}, {1.0}, mass, glm::normalize(offsets[k]), 0.3);  // out of the body's sphere
    c.body = 0;
    c.r = offsets[k];
    points.push_back(c);
  }
  const std::vector<CoupledBodyState> before = bodies;
  ImpulseSolve solve;
  solve.reserve(3, 2, 3);
  solve.solve(points, 1, bodies, v, mass);
  Vec3 p_nodes(0.0), l_nodes(0.0);  // momentum and angular momentum (about the body's origin) the nodes gained
  for (int32_t k = 0; k < 3; ++k) {
    p_nodes += mass[size_t(k)] * solve.dv(k);
    l_nodes += glm::cross(offsets[k], mass[size_t(k)] * solve.dv(k));
  }
  const Vec3 p_body = b.c.mass * (bodies[0].next.v - before[0].next.v);
  const Vec3 l_body = b.c.inertia * (bodies[0].next.w - before[0].next.w);
  EXPECT_GT(glm::length(p_nodes), 1e-3);
  EXPECT_LE(glm::length(p_nodes + p_body), 1e-12 * glm::length(p_nodes));
  EXPECT_LE(glm::length(l_nodes + l_body), 1e-12 * glm::length(l_nodes));
  // And no point still moves into the body.
  for (const ContactPoint& c : points) {
    const Vec3 rel = velocity_after(solve, c, v) - proxy_velocity(bodies, c);
    EXPECT_GE(glm::dot(rel, c.n), -1e-6 * glm::length(b.next.v));
  }
}

// Warm starts: a guess is scaled to where it lowers the kinetic energy
// most, and a solve started from the answer keeps it.
TEST(ImpulseSolve, AGuessIsScaledToLowerTheEnergyMostAndASolveFromTheAnswerKeepsIt) {
  const std::vector<double> mass{0.5, 0.5};
  const std::vector<Vec3> v{Vec3(0.1, -1.0, 0.0), Vec3(0.0, -1.0, 0.0)};
  const auto pair = [&](double jn) {
    std::vector<ContactPoint> points{point({0}, {1.0}, mass, Vec3(0, 1, 0)), point({1}, {1.0}, mass, Vec3(0, 1, 0))};
    for (ContactPoint& c : points) c.jn = jn;
    return points;
  };
  ImpulseSolve solve;
  solve.reserve(2, 1, 2);
  EXPECT_NEAR(solve.warm_scale(pair(0.5), v, mass), 1.0, 1e-12);   // m |v . n|: the answer
  EXPECT_NEAR(solve.warm_scale(pair(2.0), v, mass), 0.25, 1e-12);  // four times it
  EXPECT_EQ(solve.warm_scale(pair(0.0), v, mass), 0.0);
  // Moving out of the proxy: any push adds energy.
  const std::vector<Vec3> out{Vec3(0, 0.3, 0), Vec3(0, 0.2, 0)};
  EXPECT_EQ(solve.warm_scale(pair(0.5), out, mass), 0.0);
  // Its friction counts: a guess pushing with the sliding point's tangential velocity is cut.
  std::vector<ContactPoint> rubbing = pair(0.5);
  for (ContactPoint& c : rubbing) c.mu = 0.5;
  EXPECT_NEAR(solve.warm_scale(rubbing, v, mass), 1.0, 1e-12);
  rubbing[0].jt = Vec3(0.2, 0, 0);
  EXPECT_LT(solve.warm_scale(rubbing, v, mass), 1.0);
  // Started from the answer, the solve has nothing to change.
  std::vector<CoupledBodyState> bodies;
  std::vector<ContactPoint> points = pair(0.5);
  solve.solve(points, 1, bodies, v, mass);
  for (const ContactPoint& c : points) EXPECT_NEAR(c.jn, 0.5, 1e-15);
  for (int32_t k = 0; k < 2; ++k) EXPECT_NEAR(velocity_after(solve, points[size_t(k)], v).y, 0.0, 1e-15);
  EXPECT_TRUE(solve.settled());
  // Started from a guess that pushes too hard, it takes the excess back.
  solve.clear();
  points = pair(0.8);
  solve.solve(points, 1, bodies, v, mass);
  for (const ContactPoint& c : points) EXPECT_NEAR(c.jn, 0.5, 1e-12);
}

TEST(ImpulseSolve, ClearForgetsTheChangesForTheNextSolve) {
  const std::vector<double> mass{1.0};
  const std::vector<Vec3> v{Vec3(0, -1, 0)};
  std::vector<ContactPoint> points{point({0}, {1.0}, mass, Vec3(0, 1, 0))};
  std::vector<CoupledBodyState> bodies;
  ImpulseSolve solve;
  solve.reserve(1, 1, 1);
  solve.solve(points, 1, bodies, v, mass);
  ASSERT_EQ(solve.moved().size(), 1u);
  solve.clear();
  EXPECT_TRUE(solve.moved().empty());
  EXPECT_EQ(solve.dv(0), Vec3(0.0));
}

}  // namespace
}  // namespace tactile
