// Carrying a body into a model rebuilt from the same mesh (core/carry.hpp):
// every carried field comes through a model of the other precision, whose
// nodes are numbered otherwise; what is not carried starts afresh.
#include <gtest/gtest.h>

#include "core/carry.hpp"
#include "fem_fixtures.hpp"

namespace tactile {
namespace {

using test::make_spec;

TEST(Carry, EveryCarriedFieldComesThroughAModelOfTheOtherPrecision) {
  ModelSpec spec = make_spec(make_box(Vec3(0.0), Vec3(1.0), {3, 3, 3}), MaterialModel::StVK);
  ProxySpec tip;
  tip.name = "tip";
  tip.device = "stylus";
  tip.geometry = ProxyGeometry{ProxyShape::Sphere, 0.1, 0, Vec3(0.0)};
  tip.pose.position = Vec3(0.5, 1.3, 0.5);
  spec.proxies = {tip};
  const Model<float> from_model = build_model<float>(spec);
  const Model<double> to_model = build_model<double>(spec);
  ASSERT_NE(from_model.node_given, to_model.node_given) << "the two models number their nodes alike: "
                                                           "the test would not show the renumbering";
  Stepper<float> from_stepper(from_model);
  Stepper<double> to_stepper(to_model);
  State<float> from = from_stepper.make_state();
  State<double> to = to_stepper.make_state();

  // Every carried field, a value of its own (floats exact in double).
  for (size_t k = 0; k < from.u.size(); ++k) {
    from.u[k] = 0.001f * float(k + 1);
    from.v[k] = -0.002f * float(k + 1);
  }
  from.t = 1.25;
  from.step = 77;
  from.work_loads = 1.5;
  from.work_essential = 2.5;
  from.work_contact = 3.5;
  from.dissipated = 4.5;
  from.contact.motion[0] = ProxyMotion{1.2, 1.3, tip.pose, tip.pose};
  from.contact.motion[0].to.position = Vec3(0.5, 1.1, 0.5);
  DeviceLimits limits{4.0, 0.5, 1500.0};
  from_stepper.contact().couple(from, 0, &limits);
  ASSERT_EQ(from.contact.bodies.size(), 1u);
  from.contact.bodies[0].now.pose.position = Vec3(0.5, 1.2, 0.5);
  from.contact.bodies[0].now.v = Vec3(0.0, -0.3, 0.0);
  // And some it does not carry, to see them start afresh.
  from.fault.kind = Fault::Kind::EnergyGrowth;
  from.critical.dt = 1.0;
  from.contact.track_nodes = true;

  const Carried c = carry_out(from, from_model.node_given);
  carry_in(c, to_model.node_given, to);
  to_stepper.contact().take_bodies(to, c.bodies);

  for (int32_t g = 0; g < from_model.n_nodes; ++g)
    for (size_t d = 0; d < 3; ++d) {
      EXPECT_EQ(to.u[3 * size_t(to_model.node_model[size_t(g)]) + d],
                double(from.u[3 * size_t(from_model.node_model[size_t(g)]) + d]))
          << "node " << g;
      EXPECT_EQ(to.v[3 * size_t(to_model.node_model[size_t(g)]) + d],
                double(from.v[3 * size_t(from_model.node_model[size_t(g)]) + d]))
          << "node " << g;
    }
  EXPECT_EQ(to.t, 1.25);
  EXPECT_EQ(to.step, 77);
  EXPECT_EQ(to.work_loads, 1.5);
  EXPECT_EQ(to.work_essential, 2.5);
  EXPECT_EQ(to.work_contact, 3.5);
  EXPECT_EQ(to.dissipated, 4.5);
  ASSERT_EQ(to.contact.motion.size(), 1u);
  EXPECT_EQ(to.contact.motion[0].t0, 1.2);
  EXPECT_EQ(to.contact.motion[0].to.position, Vec3(0.5, 1.1, 0.5));
  ASSERT_EQ(to.contact.bodies.size(), 1u);
  EXPECT_EQ(to.contact.bodies[0].now.pose.position, Vec3(0.5, 1.2, 0.5));
  EXPECT_EQ(to.contact.bodies[0].now.v, Vec3(0.0, -0.3, 0.0));
  EXPECT_TRUE(to.contact.bodies[0].has_limits);
  EXPECT_EQ(to.contact.bodies[0].limits.max_force, 4.0);
  EXPECT_EQ(to.contact.proxy_body[0], 0) << "the proxy is coupled in the new model too";

  EXPECT_FALSE(to.fault);
  EXPECT_NE(to.critical.dt, 1.0);
  EXPECT_FALSE(to.contact.track_nodes);
}

}  // namespace
}  // namespace tactile
