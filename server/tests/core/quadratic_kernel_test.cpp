// The quadratic tets' lane kernel (KernelTable::quadratic_forces) against the
// scalar reference (core/quadratic.hpp, compute_p2_forces), every ISA this CPU
// runs, every material, float and double: the same nodal forces and energy on
// an irregular mesh in a deformed state, padding lanes included; and a lane
// with det F <= 0 counted for the model that cannot invert.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <glm/geometric.hpp>

#include "core/fem_fixtures.hpp"
#include "core/kernels/kernels.hpp"
#include "core/model_build.hpp"
#include "core/quadratic.hpp"

namespace tactile {
namespace {

constexpr const char* kIsas[] = {"baseline", "v3", "v4"};

struct Case {
  TetMesh mesh;
  TetMesh nodes;        // mesh made quadratic
  std::vector<Vec3> u;  // displacement per node [m]
};

Case make_case(double amplitude) {
  Case c;
  c.mesh = test::make_jittered_box(Vec3(0.0), Vec3(0.06, 0.04, 0.02), {3, 2, 1}, 0.2);  // 36 tets: padding lanes
  c.nodes = make_quadratic_mesh(c.mesh);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (const Vec3& X : c.nodes.X)
    c.u.push_back(amplitude * Vec3(std::sin(40 * X.y) + 0.3 * unit(rng), std::cos(30 * X.x) + 0.3 * unit(rng),
                                   std::sin(50 * X.z + 20 * X.x) + 0.3 * unit(rng)));
  return c;
}

// The case's tets as quadratic lane blocks of one material, their node ids
// as the kernel reads them (4 x id), in the case's own numbering.
template <class Real>
QuadraticLaneBlocks<Real> lanes_of(const Case& c) {
  const std::vector<MaterialSpec> materials{MaterialSpec{MaterialModel::StVK, 1e5, 0.3, 1000}};
  const ElementConstants constants = compute_element_constants(c.mesh, materials);
  const ElementOrder order = compute_element_order(c.mesh, constants.volume, 1);
  QuadraticLaneBlocks<Real> lanes = make_quadratic_lane_blocks<Real>(c.nodes, constants, order);
  for (auto& B : lanes.blocks)
    for (auto& ids : B.node4)
      for (int32_t& id : ids) id *= 4;
  return lanes;
}

// The scalar reference, tet by tet: forces per node and the total energy.
double reference(const Case& c, MaterialModel model, double lambda, double mu, std::vector<Vec3>& f) {
  f.assign(c.nodes.X.size(), Vec3(0.0));
  double energy = 0;
  for (size_t e = 0; e < c.mesh.tets.size(); ++e) {
    std::array<int32_t, kP2Nodes> id{};
    for (int a = 0; a < 4; ++a) id[size_t(a)] = c.mesh.tets[e][size_t(a)];
    for (int k = 0; k < 6; ++k) id[size_t(4 + k)] = c.nodes.edges[e][size_t(k)];
    std::array<Vec3, kP2Nodes> X, x, fe;
    for (int a = 0; a < kP2Nodes; ++a) {
      X[size_t(a)] = c.nodes.X[size_t(id[size_t(a)])];
      x[size_t(a)] = X[size_t(a)] + c.u[size_t(id[size_t(a)])];
    }
    energy += compute_p2_forces(make_p2_element(X), x, model, lambda, mu, &fe);
    for (int a = 0; a < kP2Nodes; ++a) f[size_t(id[size_t(a)])] += fe[size_t(a)];
  }
  return energy;
}

template <class Real>
void check_against_reference(double squash = 0) {
  Case c = make_case(2e-4);
  // Squashed along z by `squash` (and sheared a little): elements near the
  // floor of invertible StVK and corotational, where the SVD takes over.
  for (size_t i = 0; i < c.u.size(); ++i) c.u[i] += Vec3(0.1 * squash * c.nodes.X[i].z, 0.0, -squash * c.nodes.X[i].z);
  const QuadraticLaneBlocks<Real> lanes = lanes_of<Real>(c);
  ASSERT_LT(std::count(lanes.lane_tet.begin(), lanes.lane_tet.end(), -1), kLanes<Real>) << "some padding";
  ASSERT_GT(std::count(lanes.lane_tet.begin(), lanes.lane_tet.end(), -1), 0) << "some padding";
  const size_t n = c.nodes.X.size();
  std::vector<Node4<Real>, CacheAlignedAllocator<Node4<Real>>> u4(n), f4(n);
  for (size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) u4[i].v[k] = Real(c.u[i][k]);
  const double lambda = 6e4, mu = 4e4;
  int runs = 0;
  for (const char* isa : kIsas) {
    const KernelTable<Real>* table = kernels_for<Real>(isa);
    if (!table) continue;
    for (MaterialModel model : test::kAllModels) {
      std::vector<Vec3> f_ref;
      const double e_ref = reference(c, model, lambda, mu, f_ref);
      for (auto& v : f4) v = Node4<Real>{};
      const ElasticSums sums = table->quadratic_forces[int(model)](lanes.blocks.data(), 0, int32_t(lanes.blocks.size()),
                                                                   Real(lambda), Real(mu), u4.data(), f4.data());
      double largest = 0;
      for (const Vec3& fr : f_ref) largest = std::max(largest, glm::length(fr));
      ASSERT_GT(largest, 0.0);
      const double tol = sizeof(Real) == 4 ? 2e-3 : 1e-9;
      EXPECT_NEAR(sums.energy, e_ref, tol * std::fabs(e_ref)) << isa << " " << to_string(model);
      if (squash == 0) {
        EXPECT_EQ(sums.inverted, 0) << isa << " " << to_string(model);
      }
      for (size_t i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k)
          ASSERT_NEAR(double(f4[i].v[k]), f_ref[i][k], tol * largest)
              << isa << " " << to_string(model) << " node " << i << " axis " << k;
      ++runs;
    }
  }
  EXPECT_GE(runs, 5);
}
TEST(QuadraticKernel, ForcesAndEnergyEqualTheScalarReferenceFloat) { check_against_reference<float>(); }
TEST(QuadraticKernel, ForcesAndEnergyEqualTheScalarReferenceDouble) { check_against_reference<double>(); }
// 70 % squashed: past plain StVK's 42 %, at the floor where the SVD models take the SVD.
TEST(QuadraticKernel, ForcesEqualTheReferenceWhereTheSvdTakesOverFloat) { check_against_reference<float>(0.7); }
TEST(QuadraticKernel, ForcesEqualTheReferenceWhereTheSvdTakesOverDouble) { check_against_reference<double>(0.7); }

TEST(QuadraticKernel, ALaneInvertedAtAPointIsCountedForPlainStVK) {
  Case c = make_case(0.0);
  const QuadraticLaneBlocks<double> lanes = lanes_of<double>(c);
  // Tet 0's fourth corner pushed through its opposite face: inverted there.
  const Tet& t = c.mesh.tets[0];
  const Vec3 centre = (c.mesh.X[size_t(t[0])] + c.mesh.X[size_t(t[1])] + c.mesh.X[size_t(t[2])]) / 3.0;
  c.u[size_t(t[3])] = 2.0 * (centre - c.mesh.X[size_t(t[3])]);
  std::vector<Node4<double>, CacheAlignedAllocator<Node4<double>>> u4(c.nodes.X.size()), f4(c.nodes.X.size());
  for (size_t i = 0; i < u4.size(); ++i)
    for (int k = 0; k < 3; ++k) u4[i].v[k] = c.u[i][k];
  const ElasticSums sums = kernels<double>().quadratic_forces[int(MaterialModel::StVK)](
      lanes.blocks.data(), 0, int32_t(lanes.blocks.size()), 6e4, 4e4, u4.data(), f4.data());
  EXPECT_GE(sums.inverted, 1);
}

}  // namespace
}  // namespace tactile
