// Proxy contact (paper section 5.1): shapes, motion, and the laws the
// contact pass must keep: eq. (13), momentum, Coulomb friction, no energy
// from nothing, no tunnelling, and forces routed per proxy.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <vector>

#include <glm/geometric.hpp>

#include "core/contact/contact.hpp"
#include "core/embedding.hpp"
#include "core/model.hpp"
#include "core/quadratic.hpp"
#include "core/stepper.hpp"
#include "mesh/primitives.hpp"

namespace tactile {
namespace {

constexpr double kPi = 3.14159265358979323846;

// ---- shapes and motion ---------------------------------------------------------

TEST(ProxyShape, SignedDistanceAndNormalOfEachShape) {
  ProxyGeometry sphere{ProxyShape::Sphere, 0.02, 0, Vec3(0.0)};
  SurfacePoint p = locate(sphere, Vec3(0.0, 0.05, 0.0));
  EXPECT_NEAR(p.phi, 0.03, 1e-15);
  EXPECT_NEAR(p.n.y, 1.0, 1e-15);
  EXPECT_NEAR(locate(sphere, Vec3(0.01, 0.0, 0.0)).phi, -0.01, 1e-15);

  ProxyGeometry capsule{ProxyShape::Capsule, 0.01, 0.05, Vec3(0.0)};
  p = locate(capsule, Vec3(0.03, 0.0, -0.02));  // beside the segment
  EXPECT_NEAR(p.phi, 0.01, 1e-15);
  EXPECT_NEAR(p.n.z, -1.0, 1e-15);
  p = locate(capsule, Vec3(0.08, 0.0, 0.0));  // past its round end
  EXPECT_NEAR(p.phi, 0.02, 1e-15);
  EXPECT_NEAR(p.n.x, 1.0, 1e-15);

  ProxyGeometry box{ProxyShape::Box, 0.0, 0, Vec3(0.02, 0.01, 0.03)};
  p = locate(box, Vec3(0.0, 0.008, 0.0));  // inside, nearest the top face
  EXPECT_NEAR(p.phi, -0.002, 1e-15);
  EXPECT_NEAR(p.n.y, 1.0, 1e-15);
  p = locate(box, Vec3(0.05, 0.05, 0.0));  // outside, off an edge
  EXPECT_NEAR(p.phi, std::sqrt(0.03 * 0.03 + 0.04 * 0.04), 1e-15);
  EXPECT_NEAR(glm::length(p.n), 1.0, 1e-15);

  ProxyGeometry plane{ProxyShape::Plane, 0, 0, Vec3(0.0)};
  EXPECT_NEAR(locate(plane, Vec3(3.0, -0.25, 7.0)).phi, -0.25, 1e-15);
}

// The deepest point of a triangle in each shape against a dense sampling of
// the triangle: never shallower than the samples (to their spacing), and
// with exact zero weights where it lies on an edge or at a corner.
TEST(ProxyShape, DeepestPointOfATriangleMatchesBruteForce) {
  const ProxyGeometry shapes[] = {{ProxyShape::Sphere, 0.01, 0, Vec3(0.0)},
                                  {ProxyShape::Capsule, 0.006, 0.02, Vec3(0.0)},
                                  {ProxyShape::Box, 0.003, 0, Vec3(0.02, 0.008, 0.012)}};
  uint64_t seed = 12345;
  const auto uniform = [&] {  // splitmix64 in [-1, 1)
    seed += 0x9E3779B97F4A7C15ull;
    uint64_t z = seed;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return double((z ^ (z >> 31)) >> 11) / double(1ull << 52) - 1.0;
  };
  constexpr int kGrid = 120;
  int interior = 0, on_edge = 0, at_corner = 0;
  for (const ProxyGeometry& g : shapes)
    for (int trial = 0; trial < 300; ++trial) {
      const Vec3 centre = 0.03 * Vec3(uniform(), uniform(), uniform());
      const double size = 0.005 + 0.03 * (uniform() + 1);
      const Vec3 a = centre + size * Vec3(uniform(), uniform(), uniform());
      const Vec3 b = centre + size * Vec3(uniform(), uniform(), uniform());
      const Vec3 c = centre + size * Vec3(uniform(), uniform(), uniform());
      const Vec3 w = deepest_on_triangle(g, a, b, c);
      ASSERT_NEAR(w.x + w.y + w.z, 1.0, 1e-12);
      ASSERT_TRUE(w.x >= 0 && w.y >= 0 && w.z >= 0) << w.x << " " << w.y << " " << w.z;
      const double found = locate(g, w.x * a + w.y * b + w.z * c).phi;
      double best = std::numeric_limits<double>::infinity();
      for (int i = 0; i <= kGrid; ++i)
        for (int j = 0; i + j <= kGrid; ++j) {
          const double u = double(i) / kGrid, v = double(j) / kGrid;
          best = std::min(best, locate(g, (1 - u - v) * a + u * b + v * c).phi);
        }
      // A box's core (beyond its rounding) is outside the exact search.
      if (g.shape == ProxyShape::Box && best < -g.radius) continue;
      const double spacing = std::max({glm::length(b - a), glm::length(c - a), glm::length(c - b)}) / kGrid;
      EXPECT_LE(found, best + 1e-12) << to_string(g.shape) << " trial " << trial;
      EXPECT_GE(found, best - spacing) << to_string(g.shape) << " trial " << trial;
      const int zeros = int(w.x == 0) + int(w.y == 0) + int(w.z == 0);
      (zeros == 0 ? interior : zeros == 1 ? on_edge : at_corner)++;
    }
  std::printf("  deepest points: %d inside a face, %d on an edge, %d at a corner\n", interior, on_edge, at_corner);
  EXPECT_GT(interior, 20);  // every kind of answer was checked
  EXPECT_GT(on_edge, 20);
  EXPECT_GT(at_corner, 20);
}

TEST(ProxyMotion, InterpolatesPoseAndGivesRigidVelocities) {
  ProxyMotion m;
  m.t0 = 1.0;
  m.t1 = 1.5;
  m.from.position = Vec3(0.0);
  m.to.position = Vec3(0.1, 0.0, 0.0);
  m.to.orientation = glm::angleAxis(kPi / 2, Vec3(0.0, 0.0, 1.0));  // a quarter turn about z in 0.5 s
  const Pose mid = m.at(1.25);
  EXPECT_NEAR(mid.position.x, 0.05, 1e-15);
  EXPECT_NEAR(glm::angle(mid.orientation), kPi / 4, 1e-12);
  EXPECT_NEAR(m.velocity().x, 0.2, 1e-12);
  EXPECT_NEAR(m.angular_velocity().z, kPi, 1e-12);
  // A point 1 m out along x from the proxy (at t = 1.25) moves with v + w x r.
  const Vec3 v = m.velocity_at(mid.position + Vec3(1.0, 0.0, 0.0), 1.25);
  EXPECT_NEAR(v.x, 0.2, 1e-12);
  EXPECT_NEAR(v.y, kPi, 1e-12);
  // Held at the ends outside the interval.
  EXPECT_EQ(m.at(0.0).position, m.from.position);
  EXPECT_EQ(m.at(9.0).position, m.to.position);
}

// ---- fixtures --------------------------------------------------------------------

// A soft block [0, 0.04] x [0, 0.02] x [0, 0.04] m.
ModelSpec block_spec(std::array<int, 3> cells = {8, 4, 8}, double E = 2e4) {
  ModelSpec spec;
  spec.mesh = make_box(Vec3(0.0), Vec3(0.04, 0.02, 0.04), cells);
  spec.materials = {MaterialSpec{MaterialModel::StVK, E, 0.3, 1000}};
  return spec;
}

ProxySpec sphere_proxy(const std::string& name, const std::string& device, const Vec3& at, double radius) {
  ProxySpec p;
  p.name = name;
  p.device = device;
  p.geometry = ProxyGeometry{ProxyShape::Sphere, radius, 0, Vec3(0.0)};
  p.pose.position = at;
  return p;
}

// Holds the nodes in the box [lo, hi] still: a base the proxies press against.
EssentialBc held_box(const std::string& name, const Vec3& lo, const Vec3& hi) {
  EssentialBc bc;
  bc.name = name;
  bc.where.kind = NodeSelector::Kind::Box;
  bc.where.lo = lo;
  bc.where.hi = hi;
  return bc;
}

// A floor: the half-space y <= `height`.
ProxySpec floor_proxy(double height, double friction = 0) {
  ProxySpec p;
  p.name = "floor";
  p.device = "scene";
  p.geometry.shape = ProxyShape::Plane;
  p.pose.position = Vec3(0.0, height, 0.0);
  p.friction = friction;
  return p;
}

template <class Real>
Vec3 node_position(const Model<Real>& model, const State<Real>& s, int32_t i) {
  const size_t j = 3 * size_t(i);
  return model.mesh.X[size_t(i)] + Vec3(double(s.u[j]), double(s.u[j + 1]), double(s.u[j + 2]));
}

template <class Real>
Vec3 momentum(const Model<Real>& model, const State<Real>& s) {
  Vec3 p(0.0);
  for (int32_t i = 0; i < model.n_nodes; ++i) {
    const size_t j = 3 * size_t(i);
    p += double(model.m[size_t(i)]) * Vec3(double(s.v[j]), double(s.v[j + 1]), double(s.v[j + 2]));
  }
  return p;
}

// Moves a proxy at constant velocity over the coming step.
template <class Real>
void move_proxy(Stepper<Real>& stepper, State<Real>& s, int32_t proxy, const Pose& from, const Vec3& velocity, double t,
                double dt) {
  ProxyMotion m;
  m.t0 = t;
  m.t1 = t + dt;
  m.from = from;
  m.to = from;
  m.to.position += velocity * dt;
  stepper.contact().set_motion(s, proxy, m);
}

// ---- the laws --------------------------------------------------------------------

// A block thrown down onto a floor. Eq. (13): a node that enters the floor
// in step n+1 is, at step n+2, exactly as far from it as at step n; and no
// node ever sinks deeper than one step of its approach.
TEST(Contact, PenetrationStopsGrowingWithinTwoSteps) {
  ModelSpec spec = block_spec();
  spec.proxies = {floor_proxy(0.0)};
  for (Vec3& X : spec.mesh.X) X.y += 0.001;  // 1 mm above the floor
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const double speed = 0.5;  // [m/s] downward
  for (int32_t i = 0; i < model.n_nodes; ++i) s.v[3 * size_t(i) + 1] = -speed;
  const double dt = 0.5 * model.dt_rest;

  std::vector<std::vector<double>> height, vy;  // per step, per node: y above the floor, y velocity
  auto record = [&] {
    std::vector<double> h(size_t(model.n_nodes)), v(size_t(model.n_nodes));
    for (int32_t i = 0; i < model.n_nodes; ++i) {
      h[size_t(i)] = node_position(model, s, i).y;
      v[size_t(i)] = s.v[3 * size_t(i) + 1];
    }
    height.push_back(std::move(h));
    vy.push_back(std::move(v));
  };
  record();
  double deepest = 0;
  int entries = 0;
  for (int k = 0; k < 400; ++k) {
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    record();
    for (double h : height.back()) deepest = std::min(deepest, h);
  }
  for (size_t n = 0; n + 2 < height.size(); ++n)
    for (size_t i = 0; i < height[n].size(); ++i) {
      // Entered in step n+1 and stopped there (v_y set to 0 exactly); a node
      // the elastic forces already turned back gets no impulse, and no eq. (13).
      if (!(height[n][i] > 0 && height[n + 1][i] <= 0 && vy[n + 1][i] == 0.0)) continue;
      ++entries;
      EXPECT_NEAR(height[n + 2][i], height[n][i], 1e-12) << "node " << i << " entering at step " << n + 1;
    }
  EXPECT_GT(entries, 20);  // most of the bottom face landed so
  // Bounded by a step or two of approach at the speeds the landing reaches, never growing with time.
  EXPECT_GT(deepest, -3.0 * speed * dt) << "a node sank deeper than a few steps of approach";
  EXPECT_LT(deepest, 0.0);
}

// Without gravity or damping, the body's momentum changes only by the contact
// impulses: P_{n+1} - P_n = -dt/2 (F_n + F_{n+1}) with F the force on the
// proxies, every step (eq. 9 applied to all nodes and summed); on linear
// and on quadratic tets (whose surface nodes include the edge nodes).
TEST(Contact, ReactionEqualsTheMomentumTheContactsGave) {
  for (const bool quadratic : {false, true}) {
    SCOPED_TRACE(quadratic ? "quadratic" : "linear");
    ModelSpec spec = block_spec(quadratic ? std::array<int, 3>{4, 2, 4} : std::array<int, 3>{8, 4, 8});
    if (quadratic) spec.mesh = make_quadratic_mesh(spec.mesh);
    spec.proxies = {sphere_proxy("tip", "left", Vec3(0.02, 0.03, 0.02), 0.01)};
    const Model<double> model = build_model<double>(spec);
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    const double dt = 0.5 * model.dt_rest;
    Pose pose = model.proxies[0].pose;
    const Vec3 velocity(0.0, -0.2, 0.05);  // down into the top face, and sideways
    Vec3 F_prev(0.0);
    int in_contact = 0;
    double push = 0;
    for (int k = 0; k < 600; ++k) {
      move_proxy(stepper, s, 0, pose, velocity, s.t, dt);
      const Vec3 P0 = momentum(model, s);
      ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
      const Vec3 F = s.contact.reports[0].force;
      const Vec3 dP = momentum(model, s) - P0;
      const Vec3 expected = -0.5 * dt * (F_prev + F);
      const double scale = 1e-9 * glm::length(expected) + 1e-15;  // elastic forces cancel to round-off
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(dP[c], expected[c], scale) << "step " << k << " component " << c;
      if (s.contact.reports[0].contacts > 0) ++in_contact;
      push = std::max(push, F.y);
      F_prev = F;
      pose.position += velocity * dt;
    }
    EXPECT_GT(in_contact, 100);  // (the free block is knocked away in the end)
    EXPECT_GT(push, 0.0);        // the body pushed the proxy back up
  }
}

// The per-node contact forces an output asks for (VTU point data) are the
// proxy's reaction spread over the nodes: summed over the body they give the
// impulse the proxy took back, to round-off, over the time reported.
TEST(Contact, NodeImpulsesSumToTheProxysReaction) {
  ModelSpec spec = block_spec();
  spec.proxies = {sphere_proxy("tip", "left", Vec3(0.02, 0.03, 0.02), 0.01)};
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  stepper.contact().track_node_impulses(s, true);
  const double dt = 0.5 * model.dt_rest;
  Pose pose = model.proxies[0].pose;
  const Vec3 velocity(0.0, -0.2, 0.05);
  std::vector<double> impulse(3 * size_t(model.n_nodes), 0.0);
  Vec3 reaction(0.0);
  double elapsed = 0;
  int taken = 0;
  for (int k = 0; k < 300; ++k) {
    move_proxy(stepper, s, 0, pose, velocity, s.t, dt);
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    reaction += s.contact.reports[0].force * dt;
    pose.position += velocity * dt;
    if (k % 37 == 36) elapsed += stepper.contact().take_node_impulses(s, impulse), ++taken;  // takes add up
  }
  elapsed += stepper.contact().take_node_impulses(s, impulse);
  Vec3 on_nodes(0.0);
  int pushed = 0;
  for (int32_t i = 0; i < model.n_nodes; ++i) {
    const Vec3 J(impulse[3 * size_t(i)], impulse[3 * size_t(i) + 1], impulse[3 * size_t(i) + 2]);
    on_nodes += J;
    pushed += J != Vec3(0.0) ? 1 : 0;
  }
  EXPECT_GT(taken, 5);
  EXPECT_GT(pushed, 4);
  EXPECT_GT(reaction.y, 1e-6);  // it pressed, and the body pushed it back up
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(on_nodes[c], -reaction[c], 1e-10 * glm::length(reaction)) << c;
  EXPECT_NEAR(elapsed, 300 * dt, 1e-12);
  // Taken again: nothing more, and nothing while tracking is off.
  std::vector<double> again(impulse.size(), 0.0);
  EXPECT_EQ(stepper.contact().take_node_impulses(s, again), 0.0);
  stepper.contact().track_node_impulses(s, false);
  move_proxy(stepper, s, 0, pose, velocity, s.t, dt);
  ASSERT_FALSE(stepper.step(s, dt));
  EXPECT_EQ(stepper.contact().take_node_impulses(s, again), 0.0);
  for (double x : again) EXPECT_EQ(x, 0.0);
}

// A block on a floor with friction, pulled sideways by a load: below mu m g it
// sticks, above it slides with acceleration (F - mu m g) / m.
double slide_acceleration(double pull_over_mu_mg, double* creep) {
  const double mu = 0.4;
  ModelSpec spec = block_spec({4, 2, 4}, 2e5);
  spec.proxies = {floor_proxy(0.0, mu)};
  spec.effects.friction = true;
  spec.effects.gravity = true;  // no damping: alpha M would drag the sliding block like air
  const double mass = 1000 * 0.04 * 0.02 * 0.04;
  NaturalLoad pull;
  pull.name = "pull";
  pull.where.kind = NodeSelector::Kind::Box;
  pull.where.lo = Vec3(0.0);
  pull.where.hi = Vec3(0.04, 0.02, 0.04);  // the whole block, in proportion to mass
  pull.force = Vec3(pull_over_mu_mg * mu * mass * 9.81, 0.0, 0.0);
  MotionProfile on;  // after the block has settled on the floor
  on.kind = MotionProfile::Kind::Ramp;
  on.start = 0.05;
  on.duration = 0.01;
  on.target = 1.0;
  pull.scale = on;
  spec.loads = {pull};
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const double dt = 0.5 * model.dt_rest;
  auto mean_x = [&] {
    double x = 0;
    for (int32_t i = 0; i < model.n_nodes; ++i) x += double(model.m[size_t(i)]) * s.u[3 * size_t(i)];
    return x / mass;
  };
  auto run_until = [&](double t) {
    while (s.t < t) EXPECT_FALSE(stepper.step(s, dt)) << s.fault.message;
  };
  run_until(0.08);
  const double x0 = mean_x(), t0 = s.t;
  run_until(0.13);
  const double x1 = mean_x(), t1 = s.t;
  run_until(0.18);
  const double x2 = mean_x(), t2 = s.t;
  *creep = std::fabs(x2 - x0);
  // x(t) = x0 + v0 t + a t^2 / 2 through the three samples.
  const double h1 = t1 - t0, h2 = t2 - t0;
  return 2.0 * ((x2 - x0) / h2 - (x1 - x0) / h1) / (h2 - h1);
}

TEST(Contact, FrictionSticksBelowMuTimesTheNormalLoadAndSlidesAbove) {
  double creep = 0;
  const double a_stick = slide_acceleration(0.5, &creep);
  EXPECT_LT(creep, 2e-4) << "held at half the friction limit, it crept " << creep << " m in 0.1 s";
  EXPECT_LT(std::fabs(a_stick), 0.05);
  const double a_slide = slide_acceleration(2.0, &creep);  // pulled at twice the limit
  const double expected = (2.0 - 1.0) * 0.4 * 9.81;        // (F - mu m g) / m
  EXPECT_NEAR(a_slide, expected, 0.1 * expected);
}

// Two proxies bound to two devices: each report holds only its own proxy's
// contacts. One presses the top face, the other hovers clear of the body.
// The block is held by its x = 0 face.
TEST(Contact, ForcesAreRoutedPerProxy) {
  ModelSpec spec = block_spec();
  spec.essential = {held_box("wall", Vec3(0.0), Vec3(0.0, 0.02, 0.04))};
  spec.proxies = {sphere_proxy("a", "left", Vec3(0.02, 0.028, 0.02), 0.01),
                  sphere_proxy("b", "right", Vec3(0.02, -0.015, 0.02), 0.01)};  // 5 mm below
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const double dt = 0.5 * model.dt_rest;
  Pose a = model.proxies[0].pose, b = model.proxies[1].pose;
  for (int k = 0; k < 100; ++k) {
    move_proxy(stepper, s, 0, a, Vec3(0.0, -0.1, 0.0), s.t, dt);
    move_proxy(stepper, s, 1, b, Vec3(0.0), s.t, dt);
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    a.position.y -= 0.1 * dt;
    const ProxyReport& rb = s.contact.reports[1];
    EXPECT_EQ(rb.contacts, 0);
    EXPECT_EQ(rb.force, Vec3(0.0));
  }
  EXPECT_GT(s.contact.reports[0].contacts, 0);
  EXPECT_GT(s.contact.reports[0].force.y, 0.0);
  // Now b presses the bottom face from below as well: each feels its own side.
  for (int pressed = 0, k = 0; pressed < 100 && k < 5000; ++k) {  // until b has pressed for 100 steps
    move_proxy(stepper, s, 0, a, Vec3(0.0), s.t, dt);
    move_proxy(stepper, s, 1, b, Vec3(0.0, 0.1, 0.0), s.t, dt);
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    b.position.y += 0.1 * dt;
    if (s.contact.reports[1].contacts > 0) ++pressed;
  }
  EXPECT_GT(s.contact.reports[0].force.y, 0.0);
  EXPECT_LT(s.contact.reports[1].force.y, 0.0);
}

// Over a press and a release, the body gains at most the work the proxy did:
// the contact takes energy out (inelastic normal impulses), never puts it in;
// and the stepper's energy balance, which counts the contact work, holds.
// Contact points on faces move with the triangle, not with the proxy, so
// both figures carry a discretization error: each must shrink as dt halves.
TEST(Contact, NeverAddsEnergy) {
  ModelSpec spec = block_spec();
  spec.proxies = {sphere_proxy("tip", "left", Vec3(0.02, 0.031, 0.02), 0.01)};
  const Model<double> model = build_model<double>(spec);
  struct Run {
    double body, by_proxy, balance;
    int32_t face_contacts;
  };
  const auto press = [&](int refine) {
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    const double dt = 0.5 * model.dt_rest / refine;
    Pose pose = model.proxies[0].pose;
    const int steps = 1600 * refine;
    int32_t faces = 0;
    for (int k = 0; k < steps; ++k) {
      const Vec3 velocity(0.0, k < steps / 2 ? -0.3 : 0.3, 0.0);
      move_proxy(stepper, s, 0, pose, velocity, s.t, dt);
      EXPECT_FALSE(stepper.step(s, dt)) << s.fault.message;
      pose.position += velocity * dt;
      faces = std::max(faces, stepper.contact().face_contacts());
    }
    const Energy e = stepper.compute_energy(s);
    return Run{e.kinetic + e.elastic, s.contact.reports[0].work, s.work_contact, faces};
  };
  const Run coarse = press(1), fine = press(2);
  std::printf(
      "  body %.6e J, proxy's work %.6e J (excess %+.2e), balance's contact work %.6e J; dt/2: "
      "excess %+.2e, balance %+.2e; up to %d face points\n",
      coarse.body, coarse.by_proxy, coarse.body / coarse.by_proxy - 1, coarse.balance, fine.body / fine.by_proxy - 1,
      fine.balance / fine.by_proxy - 1, coarse.face_contacts);
  EXPECT_GT(coarse.face_contacts, 0);  // the faces took part
  for (const Run& r : {coarse, fine}) {
    EXPECT_GT(r.by_proxy, 0.0);
    EXPECT_GT(r.body, 0.0);  // still ringing
    EXPECT_LE(r.body, r.by_proxy * (1 + 2e-3));
    // The balance counts the contact work: kinetic + elastic = work_contact, to the integrator's error.
    EXPECT_NEAR(r.body, r.balance, 0.02 * r.balance);
  }
  EXPECT_LE(fine.body / fine.by_proxy - 1, std::max(1e-5, 0.9 * (coarse.body / coarse.by_proxy - 1)));
  EXPECT_LT(std::fabs(fine.balance - fine.by_proxy), 0.5 * std::fabs(coarse.balance - coarse.by_proxy) + 1e-9);
}

// A ball smaller than the cells pressed into the middle of a cell's top face:
// no node is inside it until it is 1.6 mm deep, yet the face pushes back from
// the first contact, with the force upward and growing with depth, and the
// face moves down with the ball instead of letting it through.
TEST(Contact, FacesHoldABallThatFitsBetweenNodes) {
  ModelSpec spec = block_spec({4, 2, 4});  // 1 cm cells
  spec.essential = {held_box("base", Vec3(0.0), Vec3(0.04, 0.0, 0.04))};
  const double r = 0.004;
  const Vec3 cell_centre(0.015, 0.02, 0.015);  // the centre of a top-face cell (split into two triangles)
  spec.proxies = {sphere_proxy("tip", "left", cell_centre + Vec3(0.0, r + 0.0005, 0.0), r)};
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const double dt = 0.5 * model.dt_rest;
  Pose pose = model.proxies[0].pose;
  const Vec3 velocity(0.0, -0.05, 0.0);
  double first_force_depth = -1, force_at_1mm = 0;
  int32_t faces_seen = 0;
  for (int k = 0; k < 100000 && pose.position.y - r > cell_centre.y - 0.003; ++k) {
    move_proxy(stepper, s, 0, pose, velocity, s.t, dt);
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    pose.position += velocity * dt;
    const double depth = cell_centre.y - (pose.position.y - r);  // of the ball's bottom below the rest surface
    const ProxyReport& rep = s.contact.reports[0];
    faces_seen = std::max(faces_seen, stepper.contact().face_contacts());
    if (rep.force.y > 0 && first_force_depth < 0) first_force_depth = depth;
    if (depth < 0.0015) {
      EXPECT_EQ(stepper.contact().node_contacts(), 0) << "at depth " << depth;
    }
    if (force_at_1mm == 0 && depth >= 0.001) force_at_1mm = rep.force.y;
    EXPECT_GE(rep.force.y, 0.0);
  }
  // The face went down with the ball: the cell's four top corners (a base
  // held still) sank by more than 1 mm, and sit within 1 mm of the ball's
  // bottom: had the ball gone through, they would have sprung back to 20 mm.
  double corners = 0;
  int n_corners = 0;
  for (int32_t i = 0; i < model.n_nodes; ++i) {
    const Vec3& X = model.mesh.X[size_t(i)];
    if (std::fabs(X.x - cell_centre.x) < 0.006 && std::fabs(X.z - cell_centre.z) < 0.006 && X.y == cell_centre.y) {
      corners += node_position(model, s, i).y;
      ++n_corners;
    }
  }
  ASSERT_EQ(n_corners, 4);
  corners /= n_corners;
  const double bottom = pose.position.y - r;
  std::printf(
      "  ball r = %.0f mm: first force at %.3f mm deep, %.4f N at 1 mm, up to %d face points; "
      "the cell's corners at %.2f mm, the ball's bottom at %.2f mm\n",
      r * 1e3, first_force_depth * 1e3, force_at_1mm, faces_seen, corners * 1e3, bottom * 1e3);
  EXPECT_LT(corners, cell_centre.y - 0.001);
  EXPECT_LT(corners, bottom + 0.001);
  EXPECT_GT(faces_seen, 0);
  EXPECT_GE(first_force_depth, 0.0);
  EXPECT_LT(first_force_depth, 0.0002);  // pushes back from the first touch, not from a node's
  EXPECT_GT(force_at_1mm, 0.0);
}

// A skin 1 mm outside a coarse block (the fine surface a scene shows, 2.5 mm apart), bound to the block's tets.
std::shared_ptr<const EmbeddedSurface> skin(const TetMesh& block, std::array<int, 3> cells) {
  const Aabb box = compute_aabb(block.X);
  const TetMesh fine = make_box(box.lo - Vec3(0.001, 0.0, 0.001), box.hi + Vec3(0.001), cells);
  SurfaceMesh s;
  s.vertices = fine.X;
  s.triangles = compute_boundary_faces(fine);
  return std::make_shared<const EmbeddedSurface>(embed_surface(block, s, 0.002));
}

// A ball smaller than a coarse cell pressed on an embedded surface between the coarse nodes is stopped by
// that surface, 1 mm above the block's own: its vertices are what the proxy meets, neither the block's
// nodes nor its faces.
TEST(Contact, AnEmbeddedSurfaceStopsABallWhereItIsSeen) {
  for (const bool quadratic : {false, true}) {
    SCOPED_TRACE(quadratic ? "quadratic" : "linear");
    ModelSpec spec = block_spec({2, 1, 2});  // 2 cm cells
    if (quadratic) spec.mesh = make_quadratic_mesh(spec.mesh);
    spec.essential = {held_box("base", Vec3(0.0), Vec3(0.04, 0.0, 0.04))};
    spec.surface = skin(spec.mesh, {17, 9, 17});
    const double r = 0.003, top = 0.021;             // the skin's top
    const Vec3 above(0.01, top + r + 0.0005, 0.01);  // over the middle of a coarse cell's top
    spec.proxies = {sphere_proxy("tip", "left", above, r)};
    const Model<double> model = build_model<double>(spec);
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    const double dt = 0.5 * model.dt_rest;
    Pose pose = model.proxies[0].pose;
    const Vec3 velocity(0.0, -0.05, 0.0);
    double first_force_bottom = -1;
    int32_t embedded = 0;
    for (int k = 0; k < 100000 && pose.position.y - r > top - 0.0015; ++k) {
      move_proxy(stepper, s, 0, pose, velocity, s.t, dt);
      ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
      pose.position += velocity * dt;
      EXPECT_EQ(stepper.contact().node_contacts() + stepper.contact().face_contacts(), 0);
      embedded = std::max(embedded, stepper.contact().embedded_contacts());
      if (s.contact.reports[0].force.y > 0 && first_force_bottom < 0) first_force_bottom = pose.position.y - r;
      EXPECT_GE(s.contact.reports[0].force.y, 0.0);
    }
    // The skin under the ball went down with it, none of its vertices deep inside the ball.
    std::vector<Vec3> x(size_t(model.n_nodes)), fine(spec.surface->rest.vertices.size());
    std::vector<Vec3> given(size_t(model.n_nodes));
    for (int32_t i = 0; i < model.n_nodes; ++i) given[size_t(model.node_given[size_t(i)])] = node_position(model, s, i);
    compute_embedded_positions(*spec.surface, given, fine);
    double deepest = 0, under = 1;
    for (size_t v = 0; v < fine.size(); ++v) {
      deepest = std::max(deepest, r - glm::length(fine[v] - pose.position));
      const Vec3& X = spec.surface->rest.vertices[v];
      if (X.y == top && std::hypot(X.x - above.x, X.z - above.z) < 0.002) under = std::min(under, fine[v].y);
    }
    std::printf(
        "  ball r = 3 mm on a skin 1 mm over 2 cm cells: first force with its bottom at %.3f mm (skin at %.1f), "
        "up to %d skin points; the skin under it at %.2f mm, deepest vertex %.3f mm inside\n",
        first_force_bottom * 1e3, top * 1e3, embedded, under * 1e3, deepest * 1e3);
    EXPECT_GT(embedded, 0);
    EXPECT_GT(first_force_bottom, top - 0.0006);  // stopped at the skin: 1 mm above the block's top (20 mm)
    EXPECT_LT(under, top - 0.001);                // and the skin went down with the ball
    EXPECT_LT(deepest, 0.0003);
  }
}

// A ball that fits between an embedded surface's vertices (3 mm against a skin 14 mm apart, as a small tool
// meets a fine surface stretched around it) is stopped by the skin's triangles from the first touch: no
// vertex is inside it, no triangle lets it through, and the force pushes it back.
TEST(Contact, AnEmbeddedSurfacesTrianglesHoldABallThatFitsBetweenItsVertices) {
  for (const bool quadratic : {false, true}) {
    SCOPED_TRACE(quadratic ? "quadratic" : "linear");
    ModelSpec spec = block_spec({2, 1, 2});  // 2 cm cells
    if (quadratic) spec.mesh = make_quadratic_mesh(spec.mesh);
    spec.essential = {held_box("base", Vec3(0.0), Vec3(0.04, 0.0, 0.04))};
    spec.surface = skin(spec.mesh, {3, 2, 3});
    const double r = 0.003, top = 0.021;
    const Vec3 above(-0.001 + 0.014 * 0.3, top + r + 0.0005, -0.001 + 0.014 * 0.6);  // inside a top triangle
    spec.proxies = {sphere_proxy("tip", "left", above, r)};
    const Model<double> model = build_model<double>(spec);
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    const double dt = 0.5 * model.dt_rest;
    Pose pose = model.proxies[0].pose;
    const Vec3 velocity(0.0, -0.05, 0.0);
    double first_force_bottom = -1, force = 0;
    int32_t embedded = 0;
    for (int k = 0; k < 100000 && pose.position.y - r > top - 0.0015; ++k) {
      move_proxy(stepper, s, 0, pose, velocity, s.t, dt);
      ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
      pose.position += velocity * dt;
      embedded = std::max(embedded, stepper.contact().embedded_contacts());
      force = std::max(force, s.contact.reports[0].force.y);
      if (force > 0 && first_force_bottom < 0) first_force_bottom = pose.position.y - r;
      EXPECT_GE(s.contact.reports[0].force.y, 0.0);
    }
    std::vector<Vec3> given(size_t(model.n_nodes)), fine(spec.surface->rest.vertices.size());
    for (int32_t i = 0; i < model.n_nodes; ++i) given[size_t(model.node_given[size_t(i)])] = node_position(model, s, i);
    compute_embedded_positions(*spec.surface, given, fine);
    // How deep any point of the skin is inside the ball: each triangle sampled on a fine grid.
    double nearest_vertex = 1, deepest = -1;
    for (const Vec3& x : fine) nearest_vertex = std::min(nearest_vertex, glm::length(x - pose.position));
    constexpr int kGrid = 60;
    for (const Tri& t : spec.surface->rest.triangles)
      for (int i = 0; i <= kGrid; ++i)
        for (int j = 0; i + j <= kGrid; ++j) {
          const double a = double(i) / kGrid, b = double(j) / kGrid;
          const Vec3 x = (1 - a - b) * fine[size_t(t[0])] + a * fine[size_t(t[1])] + b * fine[size_t(t[2])];
          deepest = std::max(deepest, r - glm::length(x - pose.position));
        }
    std::printf(
        "  ball r = 3 mm on a skin 14 mm apart: first force with its bottom at %.3f mm (skin at %.1f), peak %.4f N, "
        "up to %d skin points; nearest vertex %.2f mm from its centre, deepest skin point %.3f mm inside\n",
        first_force_bottom * 1e3, top * 1e3, force, embedded, nearest_vertex * 1e3, deepest * 1e3);
    EXPECT_GT(nearest_vertex, r);                 // no vertex inside: the triangles held it
    EXPECT_GT(first_force_bottom, top - 0.0006);  // from the first touch
    EXPECT_GT(force, 0.0);
    EXPECT_LT(deepest, 0.0003);  // and none let it through
  }
}

// The momentum an embedded surface's points give the nodes (w_k J / m_k each, weights summing to 1, some
// negative for the skin outside its tets) is the proxy's reaction, every step: P_{n+1} - P_n =
// -dt/2 (F_n + F_{n+1}) on a free block, as for nodes and faces.
TEST(Contact, AnEmbeddedSurfacesReactionEqualsTheMomentumItGave) {
  ModelSpec spec = block_spec({4, 2, 4});
  spec.surface = skin(spec.mesh, {13, 7, 13});
  spec.proxies = {sphere_proxy("tip", "left", Vec3(0.02, 0.0311, 0.02), 0.01)};
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const double dt = 0.5 * model.dt_rest;
  Pose pose = model.proxies[0].pose;
  const Vec3 velocity(0.0, -0.2, 0.05);
  Vec3 F_prev(0.0);
  int in_contact = 0;
  for (int k = 0; k < 600; ++k) {
    move_proxy(stepper, s, 0, pose, velocity, s.t, dt);
    const Vec3 P0 = momentum(model, s);
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    const Vec3 F = s.contact.reports[0].force;
    const Vec3 expected = -0.5 * dt * (F_prev + F);
    const Vec3 dP = momentum(model, s) - P0;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(dP[c], expected[c], 1e-9 * glm::length(expected) + 1e-15) << k;
    in_contact += stepper.contact().embedded_contacts() > 0;
    EXPECT_EQ(stepper.contact().node_contacts() + stepper.contact().face_contacts(), 0);
    F_prev = F;
    pose.position += velocity * dt;
  }
  // The ball knocks the free block away (faster than itself: the block springs back) within some 80 steps.
  EXPECT_GT(in_contact, 10);
  EXPECT_LT(momentum(model, s).y, -0.01);
}

// A 10 m/s impact on a 2 mm plate clamped at its rim: no node passes through
// the sphere (each stays within one step of travel of its surface), and the
// run stays finite or ends in a reported fault.
TEST(Contact, FastImpactDoesNotTunnelThroughAThinPlate) {
  for (MaterialModel mm : {MaterialModel::StVK, MaterialModel::NeoHookean, MaterialModel::Corotational}) {
    ModelSpec spec;
    spec.mesh = make_box(Vec3(-0.02, 0.0, -0.02), Vec3(0.02, 0.002, 0.02), {10, 1, 10});
    spec.materials = {MaterialSpec{mm, 1e5, 0.3, 1000}};
    EssentialBc rim;
    rim.name = "rim";
    rim.where.kind = NodeSelector::Kind::Box;  // everything, minus the inside below
    for (int side = 0; side < 4; ++side) {
      EssentialBc edge = rim;
      const double lo = -0.02, hi = 0.02;
      edge.where.lo = Vec3(side == 1 ? hi : lo, 0.0, side == 3 ? hi : lo);
      edge.where.hi = Vec3(side == 0 ? lo : hi, 0.002, side == 2 ? lo : hi);
      edge.name = "edge" + std::to_string(side);
      spec.essential.push_back(edge);
    }
    spec.proxies = {sphere_proxy("bullet", "left", Vec3(0.0, 0.008, 0.0), 0.005)};
    Model<double> model = [&] {
      try {
        return build_model<double>(spec);
      } catch (const ModelError&) {  // edges overlap at the corners: drop them from two sides
        spec.essential[2].where.lo.x += 1e-6;
        spec.essential[2].where.hi.x -= 1e-6;
        spec.essential[3].where.lo.x += 1e-6;
        spec.essential[3].where.hi.x -= 1e-6;
        return build_model<double>(spec);
      }
    }();
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    const double dt = 0.5 * model.dt_rest;
    const Vec3 velocity(0.0, -10.0, 0.0);
    Pose pose = model.proxies[0].pose;
    double deepest = 0;
    bool faulted = false;
    for (int k = 0; pose.position.y > -0.01 && k < 20000; ++k) {
      move_proxy(stepper, s, 0, pose, velocity, s.t, dt);
      if (stepper.step(s, dt)) {
        faulted = true;  // a reported fault is an allowed end (elements crushed flat)
        break;
      }
      pose.position += velocity * dt;
      for (int32_t i = 0; i < model.n_nodes; ++i) {
        const Vec3 x = node_position(model, s, i);
        ASSERT_TRUE(std::isfinite(x.x) && std::isfinite(x.y) && std::isfinite(x.z));
        deepest = std::min(deepest, glm::length(x - pose.position) - 0.005);
      }
    }
    EXPECT_GT(deepest, -10.0 * dt * 1.5 - 1e-9) << to_string(mm) << ": a node went deep inside the sphere";
    if (!faulted) {
      EXPECT_LT(pose.position.y, -0.009) << to_string(mm);
    }
  }
}

TEST(Contact, BadProxiesAreRefusedByName) {
  ModelSpec spec = block_spec({2, 2, 2});
  spec.proxies = {sphere_proxy("tip", "left", Vec3(0.0, 0.1, 0.0), -0.01)};
  try {
    build_model<double>(spec);
    FAIL() << "a negative radius was accepted";
  } catch (const ModelError& e) {
    EXPECT_NE(std::string(e.what()).find("proxy 0 ('tip'): radius"), std::string::npos) << e.what();
  }
  spec.proxies = {sphere_proxy("tip", "left", Vec3(0.0, 0.1, 0.0), 0.01),
                  sphere_proxy("tip", "right", Vec3(0.0, 0.2, 0.0), 0.01)};
  EXPECT_THROW(build_model<double>(spec), ModelError);
  spec.proxies = {sphere_proxy("tip", "left", Vec3(0.0, 0.1, 0.0), 0.01)};
  spec.proxies[0].pose.orientation = Quat(2.0, 0.0, 0.0, 0.0);
  EXPECT_THROW(build_model<double>(spec), ModelError);
}

}  // namespace
}  // namespace tactile

namespace tactile {
namespace {

// ---- Hertz -------------------------------------------------------------------

// A block [-30, 30] x [-30, 0] x [-30, 30] mm, cells graded towards the top
// centre (each axis mapped by sinh, so the cells stay boxes and the tets keep
// their orientation), bottom fixed; a rigid sphere of radius R pressed slowly
// to depth delta at the centre of the top face and held. Returns the settled
// force on the sphere [N] and, through `stiffness`, the fitted dF/dy.
double settled_sphere_force(int cells, double R, double delta, double* stiffness) {
  const double W = 0.03, beta = 3.5;
  ModelSpec spec;
  spec.mesh = make_box(Vec3(-1.0, -1.0, -1.0), Vec3(1.0, 0.0, 1.0), {cells, cells / 2, cells});
  for (Vec3& X : spec.mesh.X) {
    X.x = W * std::sinh(beta * X.x) / std::sinh(beta);
    X.z = W * std::sinh(beta * X.z) / std::sinh(beta);
    X.y = W * std::sinh(beta * X.y) / std::sinh(beta);  // y in [-1, 0]: fine at the top
  }
  const double E = 1e5, nu = 0.3;
  spec.materials = {MaterialSpec{MaterialModel::StVK, E, nu, 1000}};
  spec.essential = {held_box("base", Vec3(-W, -W, -W), Vec3(W, -W, W))};
  spec.effects.damping = true;
  spec.effects.alpha = 600.0;  // about half the critical damping of the block's lowest modes [1/s]
  spec.proxies = {sphere_proxy("ball", "arm", Vec3(0.0, R, 0.0), R)};
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const double dt = 0.9 * model.dt_rest;
  const double ramp = 0.01, hold = 0.02;  // [s]
  Pose pose = model.proxies[0].pose;
  Vec3 mean(0.0);
  int samples = 0, k_samples = 0;
  double k_sum = 0;
  while (s.t < ramp + hold) {
    // Cycloidal press: zero speed at both ends.
    const double t0 = s.t, t1 = s.t + dt;
    auto depth = [&](double t) {
      const double x = std::min(t / ramp, 1.0);
      return delta * (x - std::sin(2 * kPi * x) / (2 * kPi));
    };
    ProxyMotion m;
    m.t0 = t0;
    m.t1 = t1;
    m.from = m.to = pose;
    m.from.position.y = R - depth(t0);
    m.to.position.y = R - depth(t1);
    stepper.contact().set_motion(s, 0, m);
    const Fault f = stepper.step(s, dt);
    EXPECT_FALSE(f) << f.message;
    if (f) return 0.0;
    if (s.t > ramp + 0.75 * hold) {
      mean += s.contact.reports[0].force;
      ++samples;
    }
    if (s.t > 0.45 * ramp && s.t < 0.55 * ramp) {  // around mid-ramp, depth delta / 2
      k_sum += s.contact.reports[0].stiffness[1][1];
      ++k_samples;
    }
  }
  *stiffness = k_sum / k_samples;
  mean /= double(samples);
  EXPECT_LT(std::fabs(mean.x) + std::fabs(mean.z), 0.02 * mean.y);  // symmetric: straight up
  return mean.y;
}

// Hertz: F = 4/3 E* sqrt(R) delta^(3/2), E* = E / (1 - nu^2), for a small
// depth. The settled force converges as the mesh refines and lands within
// 20 % of Hertz on the finest mesh; the stiffness fitted while pressing is
// the slope dF/d(delta) = 3/2 F / delta, with the sign of a restoring force.
TEST(Contact, SpherePressedIntoABlockAgreesWithHertz) {
  const double R = 0.02, delta = 0.001, E = 1e5, nu = 0.3;
  const double hertz = 4.0 / 3.0 * E / (1 - nu * nu) * std::sqrt(R) * std::pow(delta, 1.5);
  std::vector<double> F;
  double k = 0;
  for (int cells : {12, 16, 24}) {
    F.push_back(settled_sphere_force(cells, R, delta, &k));
    std::printf("  cells %2d: F = %.4f N (Hertz %.4f N, %+.1f %%), dFy/dy at mid-ramp %.1f N/m\n", cells, F.back(),
                hertz, 100 * (F.back() / hertz - 1), k);
  }
  EXPECT_LT(std::fabs(F[2] - F[1]), std::fabs(F[1] - F[0]));  // converging
  EXPECT_NEAR(F[2], hertz, 0.2 * hertz);
  // Pressing down (position -y) raises the upward force: dFy/dy < 0. Mid-ramp
  // depth is delta / 2, where Hertz's slope is 3/2 F(delta/2) / (delta/2).
  const double slope = 1.5 * hertz * std::pow(0.5, 1.5) / (0.5 * delta);
  EXPECT_LT(k, 0.0);
  EXPECT_NEAR(-k, slope, 0.3 * slope);
}

}  // namespace
}  // namespace tactile

namespace tactile {
namespace {

// ---- hard cases ----------------------------------------------------------------

// Runs a scene in frames of half the rest critical step (Stepper::advance:
// sub-steps as the deformed configuration needs), its proxies moving at
// constant velocities for `move_frames` frames and then holding, until
// `frames` or a fault. Every state before the fault must be finite and
// bounded (no node further than `bound` from the body's mean displacement).
Fault run_hard_case(ModelSpec spec, const std::vector<Vec3>& velocity, int move_frames, int frames, double bound) {
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const double frame = 0.5 * model.dt_rest;
  std::vector<Pose> pose;
  for (const ProxySpec& p : model.proxies) pose.push_back(p.pose);
  for (int k = 0; k < frames; ++k) {
    for (size_t j = 0; j < pose.size(); ++j) {
      const Vec3 v = k < move_frames ? velocity[j] : Vec3(0.0);
      move_proxy(stepper, s, int32_t(j), pose[j], v, s.t, frame);
      pose[j].position += v * frame;
    }
    if (Fault f = stepper.advance(s, frame).fault) return f;
    // Bounded deformation: no node far from where the body as a whole went
    // (a free body may be pushed away whole).
    Vec3 mean(0.0);
    for (int32_t i = 0; i < model.n_nodes; ++i)
      mean += Vec3(s.u[3 * size_t(i)], s.u[3 * size_t(i) + 1], s.u[3 * size_t(i) + 2]);
    mean /= double(model.n_nodes);
    for (int32_t i = 0; i < model.n_nodes; ++i) {
      const Vec3 u(s.u[3 * size_t(i)], s.u[3 * size_t(i) + 1], s.u[3 * size_t(i) + 2]);
      const double d = glm::length(u - mean);
      EXPECT_TRUE(std::isfinite(d)) << "node " << i << " step " << k;
      EXPECT_LT(d, bound) << "node " << i << " step " << k;
      if (!(d < bound)) return Fault{};
    }
  }
  return Fault{};
}

constexpr MaterialModel kContactModels[] = {MaterialModel::Linear, MaterialModel::StVK, MaterialModel::Corotational,
                                            MaterialModel::NeoHookean};

// A sphere crushing a 2 mm plate that lies on a floor, down past the plate's
// thickness: the elements flatten and invert. StVK must end in a reported
// fault or stay finite; the invertible models stay finite and bounded.
TEST(ContactHardCases, ProxyCrushesAThinPlateOnAFloor) {
  for (MaterialModel mm : kContactModels) {
    ModelSpec spec;
    spec.mesh = make_box(Vec3(-0.01, 0.0, -0.01), Vec3(0.01, 0.002, 0.01), {10, 2, 10});
    spec.materials = {MaterialSpec{mm, 5e4, 0.3, 1000}};
    spec.proxies = {sphere_proxy("press", "arm", Vec3(0.0, 0.0071, 0.0), 0.005), floor_proxy(0.0)};
    // Down 2.6 mm at 0.5 m/s: through the whole plate and 0.5 mm into the floor, then held.
    const double frame = 0.5 * build_model<double>(spec).dt_rest;
    const int move = int(std::ceil(0.0026 / 0.5 / frame));
    // The ball ends 0.5 mm into the floor: the nodes caught between have no
    // way out but sideways, and are squeezed out a little every step. The
    // nonlinear models' stiffening holds them within the bound; the linear
    // one's does not grow with the strain (it spreads past 10 cm): it must
    // only stay finite.
    const double bound = mm == MaterialModel::Linear ? std::numeric_limits<double>::infinity() : 0.05;
    const Fault f = run_hard_case(spec, {Vec3(0.0, -0.5, 0.0), Vec3(0.0)}, move, move + 2000, bound);
    if (f) {
      EXPECT_FALSE(f.message.empty());
      EXPECT_FALSE(f.kind == Fault::Kind::NonFinite) << to_string(mm) << ": " << f.message;  // caught before NaN
      std::printf("  %-12s crushed: fault after step %lld: %s\n", std::string(to_string(mm)).c_str(),
                  static_cast<long long>(f.step), f.message.substr(0, 90).c_str());
    } else {
      EXPECT_NE(mm, MaterialModel::StVK) << "StVK crushed flat without a fault";
      std::printf("  %-12s crushed: finite%s throughout\n", std::string(to_string(mm)).c_str(),
                  std::isfinite(bound) ? " and bounded" : "");
    }
  }
}

// Two small spheres closing on one corner node of a block (its base held)
// from opposite sides, past each other: the node is squeezed between them.
TEST(ContactHardCases, TwoProxiesPinchOneNode) {
  for (MaterialModel mm : kContactModels) {
    ModelSpec spec = block_spec({4, 2, 4}, 5e4);
    spec.materials[0].model = mm;
    spec.essential = {held_box("base", Vec3(0.0), Vec3(0.04, 0.0, 0.04))};
    const Vec3 corner(0.04, 0.02, 0.04);
    spec.proxies = {sphere_proxy("a", "left", corner + Vec3(-0.0031, 0.0, 0.0) + Vec3(0.0, 0.003, 0.0), 0.003),
                    sphere_proxy("b", "right", corner + Vec3(0.0031, 0.0, 0.0), 0.003)};
    const Fault f = run_hard_case(spec, {Vec3(0.1, -0.1, 0.0), Vec3(-0.1, 0.0, 0.0)}, 300, 1500, 0.05);
    if (f) {
      EXPECT_NE(f.kind, Fault::Kind::NonFinite) << to_string(mm) << ": " << f.message;
    }
  }
}

// A proxy that starts inside the body, then leaves it: no explosion, and
// once it is out the block is free of it.
TEST(ContactHardCases, ProxyStartingInsideTheBody) {
  for (MaterialModel mm : kContactModels) {
    ModelSpec spec = block_spec({8, 4, 8}, 5e4);
    spec.materials[0].model = mm;
    spec.proxies = {sphere_proxy("inside", "arm", Vec3(0.02, 0.015, 0.02), 0.006)};  // pokes out of the top
    const Fault f = run_hard_case(spec, {Vec3(0.0, 0.5, 0.0)}, 600, 600, 0.05);
    EXPECT_FALSE(f) << to_string(mm) << ": " << f.message;
  }
}

}  // namespace
}  // namespace tactile

namespace tactile {
namespace {

// A sphere driven into a soft Neo-Hookean block at 4 m/s, about the speed
// of its pressure waves, in the 1 ms intervals a device sends: the elements
// under it are squashed within the interval, so their critical step falls
// faster than the estimate's sweep of the whole mesh comes round. advance()
// re-examines them after every step that pushed a node and splits the rest of
// the interval: no fault, and the energy balance holds (its -dt^2/8 term is
// restated when the step changes, not counted as energy gained).
TEST(ContactHardCases, FastPokeShrinksTheStepWithinTheInterval) {
  ModelSpec spec;
  spec.mesh = make_box(Vec3(-0.02, 0.0, -0.02), Vec3(0.02, 0.02, 0.02), {12, 6, 12});
  spec.materials = {MaterialSpec{MaterialModel::NeoHookean, 3e4, 0.3, 1000}};
  spec.essential = {held_box("base", Vec3(-0.02, 0.0, -0.02), Vec3(0.02, 0.0, 0.02))};
  spec.proxies = {sphere_proxy("tip", "stylus", Vec3(0.0, 0.0285, 0.0), 0.008)};
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  const double interval = 0.001;
  Pose pose = model.proxies[0].pose;
  const double rest_dt = model.dt_rest;
  double smallest_dt = 1, peak = 0, worst = 0, gained = 0;
  for (int k = 0; k < 40; ++k) {
    const Vec3 velocity(0.0, k < 1 ? -4.0 : 0.0, 0.0);  // 4 mm down in the first interval, then held
    move_proxy(stepper, s, 0, pose, velocity, s.t, interval);
    pose.position += velocity * interval;
    const AdvanceReport r = stepper.advance(s, interval);
    ASSERT_FALSE(r.fault) << "interval " << k << ": " << r.fault.message;
    smallest_dt = std::min(smallest_dt, r.dt);
    const Energy& e = s.energy.latest;
    peak = std::max(peak, e.kinetic + e.elastic);
    worst = std::max(worst, std::fabs(e.balance()));
    gained = std::max(gained, e.balance());
  }
  std::printf("  fast poke: step from %.3g s down to %.3g s; balance within %.2e J (gain at most %.2e J) of %.2e J\n",
              rest_dt, smallest_dt, worst, gained, peak);
  EXPECT_LT(smallest_dt, 0.2 * rest_dt) << "the squashed elements' step was never taken";
  EXPECT_GT(peak, 1e-3);
  // A step past the critical one shows as energy gained, and grows. What the
  // balance loses comes in jumps of 1e-5 to 1e-4 J when the vibrating body
  // strikes the held sphere again (the contact's work is a trapezoid over the
  // step), and the steps taken set when those come and how large they are:
  // with the estimate's sweep (16 calls) in tet order the run lost 1.8 % of
  // the peak, in lane-block order 2.4 %, and with the whole body examined
  // every interval, whose steps come out longer, 9.5 %.
  EXPECT_LT(gained, 0.005 * peak);
  EXPECT_LT(worst, 0.03 * peak);
}

// A frictionless sphere pushes along its radii: the torque about its centre
// stays near zero. With friction, stroking sideways, the tangential force
// acts at the contact, a radius below the centre: the torque about the
// centre is about R times the friction force, about the axis r x F.
TEST(Contact, TorqueIsAboutTheProxyCentre) {
  for (bool friction : {false, true}) {
    ModelSpec spec = block_spec();
    spec.essential = {held_box("base", Vec3(0.0), Vec3(0.04, 0.0, 0.04))};
    const double R = 0.01;
    spec.proxies = {sphere_proxy("tip", "arm", Vec3(0.015, 0.02 + R, 0.02), R)};
    spec.proxies[0].friction = 0.8;
    spec.effects.friction = friction;
    const Model<double> model = build_model<double>(spec);
    Stepper<double> stepper(model);
    State<double> s = stepper.make_state();
    const double dt = 0.5 * model.dt_rest;
    Pose pose = model.proxies[0].pose;
    Vec3 F(0.0), T(0.0);
    int samples = 0;
    for (int k = 0; k < 2400; ++k) {
      const Vec3 v =
          k < 800 ? Vec3(0.0, -0.002 / (800 * dt), 0.0) : Vec3(0.01 / (1600 * dt), 0.0, 0.0);  // 2 mm in, 1 cm along x
      move_proxy(stepper, s, 0, pose, v, s.t, dt);
      ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
      pose.position += v * dt;
      if (k >= 1200) {
        F += s.contact.reports[0].force;
        T += s.contact.reports[0].torque;
        ++samples;
      }
    }
    F /= double(samples);
    T /= double(samples);
    ASSERT_GT(F.y, 0.0);
    if (!friction) {
      EXPECT_LT(glm::length(T), 0.05 * glm::length(F) * R) << "torque " << T.x << " " << T.y << " " << T.z;
      EXPECT_LT(std::fabs(F.x), 0.1 * F.y);  // no drag without friction
    } else {
      EXPECT_LT(F.x, -0.1 * F.y);  // held back by the body as it moves along +x
      // r = (0, -R, 0) to the contact, F = (Fx, Fy, 0): r x F = (0, 0, R Fx).
      EXPECT_NEAR(T.z, R * F.x, 0.25 * R * std::fabs(F.x));
    }
  }
}

// A sphere pressed 7 mm into a stiff, lightly damped block (300 kPa; it
// rings at a few hundred hertz) and lifted, in 4 ms frames: the stiffness
// the bridge extrapolates with stays symmetric and never positive along any
// direction (a contact that pulled the hand in would feed the device energy),
// while it is a real stiffness in the direction pressed.
TEST(Contact, StiffnessEstimateIsPassiveOnAStiffRingingBlock) {
  ModelSpec spec;
  spec.mesh = make_box(Vec3(-0.03, 0, -0.03), Vec3(0.03, 0.03, 0.03), {8, 4, 8});
  spec.materials = {MaterialSpec{MaterialModel::NeoHookean, 300e3, 0.3, 1000}};
  spec.essential = {held_box("floor", Vec3(-1.0, -1.0, -1.0), Vec3(1.0, 0.0, 1.0))};
  spec.effects.damping = true;
  spec.effects.alpha = 20;
  spec.proxies = {sphere_proxy("tip", "stylus", Vec3(0, 0.045, 0), 0.01)};
  const Model<double> model = build_model<double>(spec);
  Stepper<double> stepper(model);
  State<double> s = stepper.make_state();
  Pose pose = model.proxies[0].pose;
  const double frame = 0.004;
  int pressed = 0;
  double most_negative = 0;
  for (int k = 0; k < 750; ++k) {
    const double t = k * frame;
    const double depth = 0.012 * 0.5 * (1 - std::cos(2 * kPi * t / 3.0));  // 12 mm down (7 mm in) and up in 3 s
    const Vec3 to(0.0005 * std::sin(7 * t), 0.045 - depth, 0.0003 * std::cos(5 * t));
    ProxyMotion m;
    m.t0 = s.t;
    m.t1 = s.t + frame;
    m.from = pose;
    m.to = pose;
    m.to.position = to;
    stepper.contact().set_motion(s, 0, m);
    const AdvanceReport r = stepper.advance(s, frame);
    ASSERT_FALSE(r.fault) << r.fault.message;
    pose.position = to;
    const glm::dmat3& K = s.contact.reports[0].stiffness;
    double scale = 0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) scale = std::max(scale, std::fabs(K[i][j]));
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) ASSERT_NEAR(K[i][j], K[j][i], 1e-9 * scale) << "t = " << t;
    for (int d = 0; d < 64; ++d) {  // directions over the sphere
      const double a = 2 * kPi * d / 8, b = kPi * (d / 8 + 0.5) / 8;
      const Vec3 u(std::sin(b) * std::cos(a), std::cos(b), std::sin(b) * std::sin(a));
      ASSERT_LE(glm::dot(u, K * u), 1e-9 * scale) << "t = " << t << ": the contact pulls the proxy in along this";
    }
    if (s.contact.reports[0].contacts > 0) ++pressed;
    most_negative = std::min(most_negative, K[1][1]);
  }
  std::printf("  %d frames in contact; dFy/dy down to %.3g N/m\n", pressed, most_negative);
  EXPECT_GT(pressed, 100);
  EXPECT_LT(most_negative, -1000.0);  // it does resist being pressed
}

}  // namespace
}  // namespace tactile
