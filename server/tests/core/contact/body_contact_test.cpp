// Contact between bodies and within one (core/contact/body_contact.hpp),
// against laws: momentum passes between the bodies and is conserved,
// contact never adds energy, a thin body hit fast is not tunnelled through,
// and a body resting on another comes to rest on it.
#include "core/contact/body_contact.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <glm/geometric.hpp>

#include "core/bodies.hpp"
#include "core/mesh.hpp"
#include "core/stepper.hpp"
#include "mesh/primitives.hpp"

namespace tactile {
namespace {

BodyParts block(const std::string& name, const Vec3& lo, const Vec3& hi, std::array<int, 3> cells, double E = 5e4) {
  BodyParts b;
  b.name = name;
  b.mesh = make_box(lo, hi, cells);
  b.materials = {MaterialSpec{MaterialModel::NeoHookean, E, 0.3, 1000}};
  return b;
}

EssentialBc hold_box(const Vec3& lo, const Vec3& hi) {
  EssentialBc bc;
  bc.name = "held";
  bc.where.kind = NodeSelector::Kind::Box;
  bc.where.lo = lo;
  bc.where.hi = hi;
  return bc;
}

ModelSpec scene(std::vector<BodyParts> parts, bool gravity, double alpha = 0) {
  ModelSpec spec;
  add_bodies(spec, std::move(parts));
  spec.effects.gravity = gravity;
  spec.effects.damping = alpha > 0;
  spec.effects.alpha = alpha;
  spec.effects.body_contact = true;
  return spec;
}

// Sum of m v over body b's nodes [N s], and its centre of mass [m].
struct BodySums {
  Vec3 momentum{0.0}, centre{0.0};
  double mass = 0;
};
BodySums sums_of(const Model<double>& m, const State<double>& s, int32_t b) {
  BodySums out;
  for (int32_t n = 0; n < m.n_nodes; ++n) {
    if (m.node_body[size_t(n)] != b) continue;
    const size_t j = 3 * size_t(n);
    const double mass = m.m[size_t(n)];
    out.momentum += mass * Vec3(s.v[j], s.v[j + 1], s.v[j + 2]);
    out.centre += mass * (m.mesh.X[size_t(n)] + Vec3(s.u[j], s.u[j + 1], s.u[j + 2]));
    out.mass += mass;
  }
  out.centre /= out.mass;
  return out;
}

void set_velocity(const Model<double>& m, State<double>& s, int32_t b, const Vec3& v) {
  for (int32_t n = 0; n < m.n_nodes; ++n)
    if (m.node_body[size_t(n)] == b)
      for (int d = 0; d < 3; ++d) s.v[3 * size_t(n) + size_t(d)] = v[d];
}

// The lowest point of body b minus the highest of body c along y [m]:
// negative when they overlap along y over the whole run (a coarse gap).
double lowest_y(const Model<double>& m, const State<double>& s, int32_t b) {
  double y = 1e30;
  for (int32_t n = 0; n < m.n_nodes; ++n)
    if (m.node_body[size_t(n)] == b) y = std::min(y, m.mesh.X[size_t(n)].y + s.u[3 * size_t(n) + 1]);
  return y;
}

// How far body b's nodes are below the faces of body c that lay at height
// `top` at rest, where they are over one: the deepest [m] (negative when all
// are above). Unlike lowest_y, it does not count c's dent.
double depth_under(const Model<double>& m, const State<double>& s, int32_t b, int32_t c, double top) {
  const auto at = [&](int32_t n) {
    const size_t j = 3 * size_t(n);
    return m.mesh.X[size_t(n)] + Vec3(s.u[j], s.u[j + 1], s.u[j + 2]);
  };
  double deepest = -1e30;
  for (const Tri& f : compute_boundary_faces(m.mesh)) {
    if (m.node_body[size_t(f[0])] != c) continue;
    if (std::any_of(f.begin(), f.end(), [&](int32_t n) { return std::fabs(m.mesh.X[size_t(n)].y - top) > 1e-9; }))
      continue;
    const Vec3 p0 = at(f[0]), e1 = at(f[1]) - p0, e2 = at(f[2]) - p0;
    const double det = e1.x * e2.z - e2.x * e1.z;
    for (int32_t n = 0; n < m.n_nodes; ++n) {
      if (m.node_body[size_t(n)] != b) continue;
      const Vec3 d = at(n) - p0;
      const double l1 = (d.x * e2.z - e2.x * d.z) / det, l2 = (e1.x * d.z - d.x * e1.z) / det;
      if (l1 < 0 || l2 < 0 || l1 + l2 > 1) continue;  // not over this face
      deepest = std::max(deepest, p0.y + l1 * e1.y + l2 * e2.y - at(n).y);
    }
  }
  return deepest;
}

TEST(BodyContact, TwoFreeBodiesExchangeMomentumAndConserveItsSum) {
  const Model<double> m =
      build_model<double>(scene({block("a", Vec3(0.0), Vec3(0.02), {2, 2, 2}),
                                 block("b", Vec3(0.0205, 0.005, 0.003), Vec3(0.0405, 0.025, 0.023), {2, 2, 2})},
                                false));
  Stepper<double> stepper(m);
  State<double> s = stepper.make_state();
  set_velocity(m, s, 0, Vec3(1.0, 0.1, 0.0));
  const Vec3 p0 = sums_of(m, s, 0).momentum + sums_of(m, s, 1).momentum;
  const Energy e0 = stepper.compute_energy(s);
  const double dt = 0.9 * m.dt_rest;
  // Each step's impulses J act twice: at once on v_{n+1}, and through the
  // acceleration they set (eq. 9) over the next half step.
  Vec3 given(0.0), last(0.0);
  int contact_steps = 0;
  const Vec3 pa0 = sums_of(m, s, 0).momentum;
  for (int k = 0; k < int(0.01 / dt); ++k) {
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    contact_steps += stepper.body_contact().body_contacts() > 0;
    last = stepper.body_contact().exchanged();
    given += 2.0 * last;
    const Vec3 sum = sums_of(m, s, 0).momentum + sums_of(m, s, 1).momentum;
    ASSERT_LT(glm::length(sum - p0), 1e-9 * glm::length(p0)) << "step " << k;
  }
  EXPECT_GT(contact_steps, 3);
  EXPECT_LT(glm::length(sums_of(m, s, 0).momentum - pa0 - (given - last)), 1e-9 * glm::length(p0));
  // The energy account closes: the contact's work between the bodies is counted, and what the
  // projection took out of the kinetic energy shows in it, not as a drift.
  const Energy e = stepper.compute_energy(s);
  EXPECT_LT(e.kinetic, e0.kinetic);                                     // some went into vibration and some was taken
  EXPECT_LT(std::fabs(e.balance() - e0.balance()), 0.05 * e0.kinetic);  // (the guard's tolerance)
  EXPECT_GT(sums_of(m, s, 1).momentum.x, 0.3 * p0.x);                   // b was pushed along x
  EXPECT_LT(sums_of(m, s, 0).momentum.x, p0.x);
}

// A soft cube dropped on a block held at its base: contact takes energy, so
// it bounces no higher than it fell from; and it never sinks into the block
// by more than a step's travel.
TEST(BodyContact, ADroppedCubeBouncesNoHigherThanItFellAndDoesNotSinkIn) {
  BodyParts base = block("base", Vec3(-0.03, 0, -0.03), Vec3(0.03, 0.02, 0.03), {3, 1, 3}, 2e5);
  base.essential.push_back(hold_box(Vec3(-1), Vec3(1, 0.0001, 1)));
  const double drop = 0.01;
  const Model<double> m = build_model<double>(scene(
      {base, block("cube", Vec3(-0.01, 0.02 + drop, -0.01), Vec3(0.01, 0.04 + drop, 0.01), {2, 2, 2}, 2e5)}, true));
  Stepper<double> stepper(m);
  State<double> s = stepper.make_state();
  const double y0 = sums_of(m, s, 1).centre.y;
  const double dt = 0.9 * m.dt_rest;
  double lowest = 1e30, after = -1e30;
  bool touched = false;
  for (int k = 0; k < int(0.2 / dt); ++k) {
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    touched = touched || stepper.body_contact().body_contacts() > 0;
    lowest = std::min(lowest, lowest_y(m, s, 1));
    if (touched) after = std::max(after, sums_of(m, s, 1).centre.y);
  }
  ASSERT_TRUE(touched);
  EXPECT_LE(after, y0);                                   // no higher than it fell from
  EXPECT_GT(lowest, 0.02 - 0.5e-3);                       // into the block by under half a millimetre
  EXPECT_LT(sums_of(m, s, 1).centre.y, y0 - 0.5 * drop);  // and it did fall
}

// A cube thrown at 2 m/s onto a block, 0.8 mm above it: its first step
// (2.7e-4 s) takes it 0.54 mm down, the second would take its bottom 0.27 mm
// into the block. By default (1 % of the shortest edge, 0.1 mm) the contact
// acts ahead of that and stops the bottom at the block's face; told it may
// let a vertex come 1 mm deep, it acts once the bottom is in, and holds it
// there. Measured against the block's top faces as they dent.
TEST(BodyContact, ALargerDepthToleranceLetsVerticesSinkFurther) {
  const auto deepest = [](double tolerance) {
    BodyParts base = block("base", Vec3(-0.03, 0, -0.03), Vec3(0.03, 0.02, 0.03), {3, 1, 3}, 2e5);
    base.essential.push_back(hold_box(Vec3(-1), Vec3(1, 0.0001, 1)));
    ModelSpec spec = scene(
        {base, block("cube", Vec3(-0.012, 0.0208, -0.007), Vec3(0.008, 0.0408, 0.013), {2, 2, 2}, 2e5)}, false, 20.0);
    spec.effects.body_depth_tolerance = tolerance;
    const Model<double> m = build_model<double>(spec);
    Stepper<double> stepper(m);
    State<double> s = stepper.make_state();
    set_velocity(m, s, 1, Vec3(0, -2, 0));
    const double dt = 0.9 * m.dt_rest;
    double depth = -1e30, lowest = 1e30;
    for (int k = 0; k < int(0.02 / dt); ++k) {
      EXPECT_FALSE(stepper.step(s, dt)) << s.fault.message;
      depth = std::max(depth, depth_under(m, s, 1, 0, 0.02));
      lowest = std::min(lowest, lowest_y(m, s, 1));
    }
    EXPECT_LT(lowest, 0.02 - 0.5e-3) << "the cube pressed the block";
    return depth;
  };
  const double held = deepest(0.0), loose = deepest(1e-3);
  EXPECT_LT(held, 0.1e-3);
  EXPECT_GT(loose, 0.2e-3);
  EXPECT_LT(loose, 1e-3);
}

// A cube at 5 m/s against a plate 2 mm thick, held at its rim: the cube
// stays on its side.
TEST(BodyContact, AThinPlateHitAtFiveMetresASecondIsNotTunnelled) {
  BodyParts plate = block("plate", Vec3(-0.03, 0, -0.03), Vec3(0.03, 0.002, 0.03), {6, 1, 6}, 1e7);
  plate.essential.push_back(hold_box(Vec3(-1), Vec3(-0.0299, 1, 1)));
  plate.essential.push_back(hold_box(Vec3(0.0299, -1, -1), Vec3(1)));
  const Model<double> m = build_model<double>(
      scene({plate, block("cube", Vec3(-0.005, 0.003, -0.005), Vec3(0.005, 0.013, 0.005), {1, 1, 1}, 1e6)}, false));
  Stepper<double> stepper(m);
  State<double> s = stepper.make_state();
  set_velocity(m, s, 1, Vec3(0, -5, 0));
  const double dt = 0.9 * m.dt_rest;
  double lowest = 1e30;
  for (int k = 0; k < int(0.01 / dt); ++k) {
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    lowest = std::min(lowest, lowest_y(m, s, 1));
  }
  EXPECT_GT(lowest, 0.0);                       // never through the plate
  EXPECT_GT(sums_of(m, s, 1).centre.y, 0.002);  // and still above it
}

// A cube resting on a block under gravity, with damping, comes to rest.
TEST(BodyContact, ABodyRestingOnAnotherComesToRest) {
  BodyParts base = block("base", Vec3(-0.03, 0, -0.03), Vec3(0.03, 0.02, 0.03), {3, 1, 3}, 1e5);
  base.essential.push_back(hold_box(Vec3(-1), Vec3(1, 0.0001, 1)));
  const Model<double> m = build_model<double>(
      scene({base, block("cube", Vec3(-0.01, 0.0201, -0.01), Vec3(0.01, 0.0401, 0.01), {2, 2, 2}, 1e5)}, true, 20.0));
  Stepper<double> stepper(m);
  State<double> s = stepper.make_state();
  const double dt = 0.9 * m.dt_rest;
  for (int k = 0; k < int(0.5 / dt); ++k) ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
  double fastest = 0;
  for (int k = 0; k < int(0.05 / dt); ++k) {
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    fastest = std::max(fastest, glm::length(sums_of(m, s, 1).momentum) / sums_of(m, s, 1).mass);
  }
  EXPECT_GT(stepper.body_contact().body_contacts(), 0);  // resting on it, not hovering
  EXPECT_LT(fastest, 1e-3);                              // its centre's jitter [m/s]
  EXPECT_GT(lowest_y(m, s, 1), 0.02 - 0.2e-3);
}

// A soft block resting on a plate: every vertex of its underside is held on
// the plate at every step, and none moves faster than a few mm/s. (With the
// paper's rule for proxies, a zero normal velocity at t_{n+1}, eq. (9) sends
// each vertex back off at the speed it came: about half of them are off at
// any step, and they strike again at 11-22 mm/s.)
TEST(BodyContact, ARestingUndersideStaysOnWhatItRestsOn) {
  BodyParts plate = block("plate", Vec3(-0.1, -0.01, -0.1), Vec3(0.1, 0, 0.1), {9, 1, 9}, 1e5);
  plate.essential.push_back(hold_box(Vec3(-1), Vec3(1, -0.0099, 1)));
  ModelSpec spec =
      scene({plate, block("block", Vec3(-0.03, 0.0001, -0.03), Vec3(0.03, 0.0301, 0.03), {6, 4, 6}, 2e4)}, true, 8.0);
  spec.effects.body_depth_tolerance = 1e-4;
  const Model<double> m = build_model<double>(spec);
  Stepper<double> stepper(m);
  State<double> s = stepper.make_state();
  const double dt = 0.9 * m.dt_rest;
  for (int k = 0; k < int(0.5 / dt); ++k) ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
  double fastest = 0;
  int32_t fewest = 1 << 30;
  for (int k = 0; k < int(0.05 / dt); ++k) {
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    for (int32_t n = 0; n < m.n_nodes; ++n)
      if (m.node_body[size_t(n)] == 1 && m.mesh.X[size_t(n)].y < 0.0002)
        fastest = std::max(fastest, std::fabs(s.v[3 * size_t(n) + 1]));
    fewest = std::min(fewest, stepper.body_contact().body_contacts());
  }
  EXPECT_GE(fewest, 7 * 7);  // its underside's vertices
  EXPECT_LT(fastest, 5e-3);  // [m/s]
}

// The same block, its steps now and then broken by a sliver (as an interval
// ending a hair past a whole number of steps leaves): it stays as still as
// without. The travel a sliver's points set is for the full step after it
// (BodyContact::apply's horizon); set for the sliver alone, a point's travel
// change du became an acceleration du / sliver that the full step after it
// integrated, and the block flew apart.
TEST(BodyContact, ASliverOfAStepLeavesARestingBlockAtRest) {
  BodyParts plate = block("plate", Vec3(-0.1, -0.01, -0.1), Vec3(0.1, 0, 0.1), {9, 1, 9}, 1e5);
  plate.essential.push_back(hold_box(Vec3(-1), Vec3(1, -0.0099, 1)));
  ModelSpec spec =
      scene({plate, block("block", Vec3(-0.03, 0.0001, -0.03), Vec3(0.03, 0.0301, 0.03), {6, 4, 6}, 2e4)}, true, 8.0);
  spec.effects.body_depth_tolerance = 1e-4;
  const Model<double> m = build_model<double>(spec);
  Stepper<double> stepper(m);
  State<double> s = stepper.make_state();
  const double dt = 0.9 * m.dt_rest;
  for (int k = 0; k < int(0.5 / dt); ++k) ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
  double fastest = 0;
  for (int k = 0; k < int(0.05 / dt); ++k) {
    if (k % 10 == 0) {
      ASSERT_FALSE(stepper.step(s, 1e-6 * dt)) << s.fault.message;
    }
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    for (int32_t n = 0; n < m.n_nodes; ++n)
      if (m.node_body[size_t(n)] == 1 && m.mesh.X[size_t(n)].y < 0.0002)
        fastest = std::max(fastest, std::fabs(s.v[3 * size_t(n) + 1]));
  }
  EXPECT_LT(fastest, 5e-3);  // [m/s], as ARestingUndersideStaysOnWhatItRestsOn
}

// A block resting on a plate of a coarser mesh: every step's projection
// settles within its sweeps, and no vertex sinks in deeper than the depth
// tolerance allows. (Tested both ways across the patch, each point nearly a
// combination of the reverse ones, the sweeps ran out every step.)
TEST(BodyContact, ARestingPatchSettlesWithinItsSweeps) {
  BodyParts plate = block("plate", Vec3(-0.1, -0.01, -0.1), Vec3(0.1, 0, 0.1), {9, 1, 9}, 1e5);
  plate.essential.push_back(hold_box(Vec3(-1), Vec3(1, -0.0099, 1)));
  ModelSpec spec =
      scene({plate, block("block", Vec3(-0.03, 0, -0.03), Vec3(0.03, 0.03, 0.03), {6, 3, 6}, 1e5)}, true, 20.0);
  spec.effects.body_depth_tolerance = 1e-4;
  const Model<double> m = build_model<double>(spec);
  Stepper<double> stepper(m);
  State<double> s = stepper.make_state();
  const double dt = 0.9 * m.dt_rest;
  int steps = 0, unsettled = 0;
  double lowest = 1;
  for (int k = 0; k < int(0.3 / dt); ++k) {
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    if (k < int(0.1 / dt)) continue;  // (settling onto it)
    ++steps;
    unsettled += !stepper.body_contact().settled();
    lowest = std::min(lowest, lowest_y(m, s, 1));
  }
  EXPECT_GT(stepper.body_contact().body_contacts(), 0);  // resting on it
  EXPECT_EQ(unsettled, 0) << "of " << steps << " steps";
  EXPECT_GT(lowest, -2 * spec.effects.body_depth_tolerance);
}

// A 4 x 3 x 4 cm block resting off centre on a plate: the normal impulses
// between them (take_moments) are centred under the block, spread over its
// footprint (a uniform pressure over a square of side L has variance L^2 / 12
// along each side), and carry its weight: by eq. (10) a velocity change dv
// is the force 2 m dv (1 + alpha dt / 2) / dt over the step.
TEST(BodyContact, TheImpulsesMomentsAreTheRestingBlocksFootprintAndWeight) {
  BodyParts plate = block("plate", Vec3(-0.1, -0.01, -0.1), Vec3(0.1, 0, 0.1), {9, 1, 9}, 1e5);
  plate.essential.push_back(hold_box(Vec3(-1), Vec3(1, -0.0099, 1)));
  const double L = 0.04, alpha = 20.0;
  const Vec3 lo(0.01, 0, -0.03);
  ModelSpec spec = scene({plate, block("block", lo, lo + Vec3(L, 0.03, L), {6, 3, 6}, 1e5)}, true, alpha);
  spec.effects.body_depth_tolerance = 1e-4;
  const Model<double> m = build_model<double>(spec);
  Stepper<double> stepper(m);
  State<double> s = stepper.make_state();
  const double dt = 0.9 * m.dt_rest;
  for (int k = 0; k < int(0.15 / dt); ++k) ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
  stepper.body_contact().take_moments();  // (settled onto it)
  const int n = int(0.1 / dt);
  for (int k = 0; k < n; ++k) ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
  const ContactMoments got = stepper.body_contact().take_moments();
  EXPECT_EQ(stepper.body_contact().take_moments().weight, 0.0) << "taken";
  ASSERT_GT(got.weight, 0);
  const Vec3 c = got.first / got.weight;
  EXPECT_NEAR(c.x, lo.x + L / 2, 1e-3);
  EXPECT_NEAR(c.z, lo.z + L / 2, 1e-3);
  EXPECT_NEAR(c.y, 0.0, 5e-4) << "on the plate's top";
  const double var_x = got.second[0] / got.weight - c.x * c.x, var_z = got.second[2] / got.weight - c.z * c.z;
  EXPECT_NEAR(var_x / (L * L / 12), 1.0, 0.35);
  EXPECT_NEAR(var_z / (L * L / 12), 1.0, 0.35);
  const double weight = 1000 * L * 0.03 * L * 9.81;
  EXPECT_NEAR(2 * (1 + 0.5 * alpha * dt) * got.weight / (n * dt), weight, 0.1 * weight) << "[N]";
}

TEST(BodyContact, AbsentTheBodiesPassThroughEachOther) {
  ModelSpec spec = scene({block("a", Vec3(0.0), Vec3(0.02), {1, 1, 1}),
                          block("b", Vec3(0.0205, 0, 0), Vec3(0.0405, 0.02, 0.02), {1, 1, 1})},
                         false);
  spec.effects.body_contact = false;
  const Model<double> m = build_model<double>(spec);
  Stepper<double> stepper(m);
  EXPECT_FALSE(stepper.body_contact().active());
  // a moves into b at 2 m/s for 10 ms: without the effect nothing stops it,
  // and its centre ends past b's near face.
  State<double> s = stepper.make_state();
  set_velocity(m, s, 0, Vec3(2.0, 0.0, 0.0));
  const double dt = 0.9 * m.dt_rest;
  for (int k = 0; k < int(0.01 / dt); ++k) {
    ASSERT_FALSE(stepper.step(s, dt)) << s.fault.message;
    ASSERT_EQ(stepper.body_contact().body_contacts(), 0);
  }
  EXPECT_GT(sums_of(m, s, 0).centre.x, 0.0205);
}

}  // namespace
}  // namespace tactile
