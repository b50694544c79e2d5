// The precision-erased Simulation: float and double runs agree, and splitting
// the passes over threads does not change the motion.
#include <gtest/gtest.h>

#include <cmath>

#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include "app/simulation.hpp"
#include "scene/scene.hpp"

namespace tactile {
namespace {

ModelSpec make_beam_spec() {
  const nlohmann::json j = nlohmann::json::parse(R"({
    "mesh": { "primitive": "box", "lo": [0, 0, 0], "hi": [0.4, 0.1, 0.1], "cells": [16, 4, 4] },
    "material": { "model": "stvk", "E": 1e5, "nu": 0.3, "rho": 1000 },
    "boundary": [ { "select": { "box": { "lo": [0, 0, 0], "hi": [0, 0.1, 0.1] } }, "fixed": true } ],
    "effects": { "gravity": [0, -9.81, 0] },
    "run": { "duration": 0.1 }
  })");
  return parse_scene(j, "beam.json").at(0).spec;
}

// The node at the free end's centre.
int32_t tip_node(const TetMesh& m) {
  int32_t best = 0;
  for (int32_t i = 0; i < m.n_nodes(); ++i)
    if (glm::length(m.X[size_t(i)] - Vec3(0.4, 0.05, 0.05)) < glm::length(m.X[size_t(best)] - Vec3(0.4, 0.05, 0.05)))
      best = i;
  return best;
}

TEST(Simulation, FloatAndDoubleAgree) {
  ModelSpec spec = make_beam_spec();
  Simulation d(spec);
  spec.integrator.precision = Precision::Float;
  Simulation f(spec);
  EXPECT_EQ(d.precision(), Precision::Double);
  EXPECT_EQ(f.precision(), Precision::Float);
  EXPECT_EQ(f.n_tets(), d.n_tets());
  EXPECT_NEAR(f.dt_rest(), d.dt_rest(), 1e-12);
  for (int k = 0; k < 5; ++k) {
    ASSERT_FALSE(d.advance(0.02).fault);
    ASSERT_FALSE(f.advance(0.02).fault);
  }
  const int32_t tip = tip_node(d.mesh());
  const Vec3 ud = d.displacement(tip), uf = f.displacement(tip);
  EXPECT_LT(ud.y, -1e-3);
  EXPECT_NEAR(uf.y, ud.y, 1e-3 * std::fabs(ud.y));
  EXPECT_NEAR(f.energy().elastic, d.energy().elastic, 1e-2 * d.energy().elastic);
  EXPECT_NEAR(d.time(), 0.1, 1e-12);
  EXPECT_EQ(d.compute_element_energy().size(), size_t(d.n_tets()));
  std::vector<double> x, u;
  d.copy_positions(x);
  d.copy_displacement(u);
  for (size_t d3 = 0; d3 < 3; ++d3) EXPECT_EQ(x[3 * size_t(tip) + d3], d.mesh().X[size_t(tip)][int(d3)] + u[3 * size_t(tip) + d3]);
}

TEST(Simulation, ThreadsLeaveTheMotionAsItIs) {
  ModelSpec spec = make_beam_spec();
  Simulation one(spec);
  spec.integrator.threads = 2;
  Simulation two(spec);
  EXPECT_EQ(one.parts(), 1);
  EXPECT_GE(two.parts(), 1);
  EXPECT_LE(two.parts(), 2);
  for (int k = 0; k < 3; ++k) {
    ASSERT_FALSE(one.advance(0.02).fault);
    ASSERT_FALSE(two.advance(0.02).fault);
  }
  std::vector<double> a, b;
  one.copy_displacement(a);
  two.copy_displacement(b);
  ASSERT_EQ(a.size(), b.size());
  double worst = 0, scale = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    worst = std::max(worst, std::fabs(a[i] - b[i]));
    scale = std::max(scale, std::fabs(a[i]));
  }
  EXPECT_LE(worst, 1e-9 * scale);  // only the order of the force sums may differ
}

}  // namespace
}  // namespace tactile
